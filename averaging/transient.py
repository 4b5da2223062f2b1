"""Transient FPK (eqs. 27-29) and mean first-passage times of the averaged energy.

Both use the conservative generator of :mod:`averaging.jump` on an H grid (with the impact jumps for the ``jump``
method). The transition density p(H, t | H0) evolves the node masses pi by d pi/dt = Q^T pi. ``scheme="expm"`` is
exact in time without jumps (the chain is reversible, so its symmetrised tridiagonal generator is diagonalised once;
the exponential of a generator is a stochastic matrix); with jumps it integrates the same linear system by BDF with
the exact sparse Jacobian (rtol 1e-10). ``scheme="implicit-euler"`` is first order but positivity-preserving by
construction (M-matrix). Mass is conserved because the rows of Q sum to zero. Mean first-passage times solve the
backward equation -Q tau = 1 with the target level absorbing.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from hybrid.errors import ParameterError
from hybrid.sizes import check_size

from .jump import EnergyChain
from .methods import get_method
from .quadrature import DEFAULT_NODES
from .stationary import check_confinement, energy_table


class TransientDensity:
    """p(H, t | H0) on a grid: ``p[k]`` is the density at ``times[k]``.

    Attributes
    ----------
    H, times : ndarray
    p : ndarray (len(times), len(H))
        Densities, each normalised to 1 on [0, h_max].
    masses : ndarray
        Node probabilities (rows sum to 1).
    mean_energy : ndarray
        E[H(t)] (exact for the piecewise-linear representation).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> tr = transient_density(DuffingImpact(), 1.0, [0.0, 5.0], points=200)
    >>> tr.p.shape
    (2, 200)
    """

    def __init__(self, H, times, masses, ratio_scale, method, H0):
        self.H = H
        self.times = np.asarray(times, dtype=float)
        self.masses = masses
        self.p = masses * ratio_scale[None, :]
        self.mean_energy = masses @ H
        self.method = method
        self.H0 = H0

    def to_pandas(self):
        """Long DataFrame with columns t, H, p."""
        import pandas as pd

        nt, nh = self.p.shape
        return pd.DataFrame({"t": np.repeat(self.times, nh), "H": np.tile(self.H, nt), "p": self.p.ravel()})

    def __repr__(self) -> str:
        return f"TransientDensity(method={self.method!r}, H0={self.H0:g}, {len(self.times)} times)"


def _energy_grid(top: float, points, top_name: str) -> np.ndarray:
    """``points`` equally spaced energies on [0, top], after checking both (no silent truncation of points)."""
    if isinstance(points, bool) or int(points) != points or points < 3:
        raise ParameterError(f"points={points!r} must be an integer >= 3")
    if not (np.isfinite(top) and top > 0):
        raise ParameterError(f"{top_name}={top!r} must be a finite positive energy")
    return np.linspace(0.0, float(top), int(points))


BYTES_PER_POINT = 400
"""Memory per energy node of the sparse chain: the grid, about 15 node arrays, the tridiagonal generator in CSR and
CSC and its LU factors (a low figure: a refused grid is surely too large)."""


def _check_grid_size(what: str, points, n_times: int, dense: bool) -> None:
    """Refuse, before anything is allocated, an energy grid whose arrays exceed :data:`hybrid.sizes.MAX_MEMORY`."""
    try:
        n = float(points)
    except (TypeError, ValueError):
        return  # not a number: _energy_grid says so
    memory = n * BYTES_PER_POINT + 16.0 * n * n_times + (16.0 * n * n if dense else 0.0)
    check_size(f"{what} on points={n:.6g}", memory=memory,
               detail=(f"{BYTES_PER_POINT} bytes per node" + (f", {n_times} output times" if n_times else "")
                       + (", two dense N x N matrices for the exact-in-time scheme" if dense else "")),
               fix="use fewer points" + (", or scheme='implicit-euler' (sparse)" if dense else ""))


def _initial_masses(grid, H0):
    if not (grid[0] <= H0 <= grid[-1]):
        raise ParameterError(f"initial energy H0={H0!r} must lie in [0, h_max={grid[-1]:g}]")
    j = min(int(np.searchsorted(grid, H0, side="right")) - 1, len(grid) - 2)
    th = (H0 - grid[j]) / (grid[j + 1] - grid[j])
    pi = np.zeros(len(grid))
    pi[j] += 1.0 - th
    pi[j + 1] += th
    return pi


def _exact_in_time(chain, A, pi, times):
    """exp(Q^T t) pi0. Without jumps the chain is reversible (detailed balance for W), so the symmetrised
    tridiagonal generator is diagonalised once (exact in time); with jumps, BDF at rtol 1e-10."""
    from scipy.linalg import eigh_tridiagonal

    out = np.empty((len(times), len(pi)))
    if len(chain.jump_from) == 0:
        W = np.maximum(chain.W, 1e-300)
        Q = chain.generator()
        diag = Q.diagonal()
        off = chain.kappa / np.sqrt(W[:-1] * W[1:])
        lam, V = eigh_tridiagonal(diag, off)
        lam = np.minimum(lam, 0.0)
        sw = np.sqrt(W)
        coef = V.T @ (pi / sw)
        for k, t in enumerate(times):
            v = sw * (V @ (np.exp(lam * t) * coef))
            v = np.maximum(v, 0.0)  # exact values are >= 0; remove round-off
            out[k] = v / v.sum()
        return out
    # with jumps the chain is not reversible: integrate the linear ODE with BDF and the exact sparse Jacobian
    # (dense matrix exponentials cost O(N^3) per time step); BDF conserves the total mass (1^T Q^T = 0) exactly
    from scipy.integrate import solve_ivp

    A = A.tocsc()
    sol = solve_ivp(lambda t, y: A @ y, (0.0, float(times[-1]) if times[-1] > 0 else 1.0), pi, method="BDF",
                    t_eval=times, jac=A, rtol=1e-10, atol=1e-13)
    if not sol.success:  # pragma: no cover - BDF on a generator does not fail in practice
        raise RuntimeError(f"transient integration failed: {sol.message}")
    for k in range(len(times)):
        v = sol.y[:, k]
        if v.min() < -1e-9:  # pragma: no cover
            raise RuntimeError(f"transient integration lost positivity (min mass {v.min():.3g}); use implicit-euler")
        v = np.maximum(v, 0.0)
        out[k] = v / v.sum()
    return out


def _implicit_euler(A, pi, times, dt):
    """(I - dt Q^T) pi_new = pi: an M-matrix solve, so masses stay >= 0 and sum to 1 (first order in time)."""
    step = dt if dt is not None else max(times[-1], 1e-300) / 200.0
    if not step > 0:
        raise ParameterError(f"dt={dt!r} must be positive")
    from scipy.sparse.linalg import splu  # here only: start-up of commands that need no transient

    eye = sparse.identity(A.shape[0], format="csc")
    lu = splu((eye - step * A).tocsc())
    out = np.empty((len(times), len(pi)))
    t_now = 0.0
    for k, t in enumerate(times):
        while t - t_now > 1e-12 * max(t, 1.0):
            h = min(step, t - t_now)
            pi = lu.solve(pi) if h == step else splu((eye - h * A).tocsc()).solve(pi)
            t_now += h
        out[k] = pi
    return out


def transient_density(model, H0: float, times, method="paper", h_max: float = 4.0, points: int = 1000,
                      scheme: str = "expm", dt: float | None = None, nodes: int = DEFAULT_NODES) -> TransientDensity:
    """The transition density p(H, t | H0) of the averaged energy (eqs. 27-29).

    Parameters
    ----------
    model : ImpactOscillator
    H0 : float
        Initial energy (a delta at t = 0, eq. 28; split between the two nearest nodes).
    times : array_like
        Output times >= 0, increasing.
    method : str
        ``paper``, ``exact-two-impact`` or ``jump``.
    h_max, points : float, int
        Grid [0, h_max] (reflecting at h_max; choose it in the tail).
    scheme : {'expm', 'implicit-euler'}
    dt : float, optional
        Step of the implicit Euler scheme (default: 1/200 of the last time).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> tr = transient_density(DuffingImpact(), 1.0, [0.0, 50.0], method="jump", points=200)
    >>> bool(abs(tr.masses.sum(axis=1) - 1.0).max() < 1e-12)
    True
    """
    m = get_method(method)
    _refuse_flights(m)
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or not np.all(np.isfinite(times)) or np.any(times < 0) or np.any(np.diff(times) < 0):
        raise ParameterError("times must be a 1-D increasing array of finite values >= 0")
    dense = scheme == "expm" and not m.jumps  # the reversible chain is diagonalised: N x N eigenvectors
    _check_grid_size("transient_density", points, len(times), dense)
    grid = _energy_grid(h_max, points, "h_max")
    check_confinement(model, m, h_max, nodes)
    chain = EnergyChain(energy_table(model, h_max, nodes), grid, m, model.restitution)
    A = chain.generator().T.tocsr()
    pi = _initial_masses(grid, float(H0))
    if scheme == "expm":
        out = _exact_in_time(chain, A, pi, times)
    elif scheme == "implicit-euler":
        out = _implicit_euler(A, pi, times, dt)
    else:
        raise ParameterError(f"unknown scheme {scheme!r}; use 'expm' or 'implicit-euler'")
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(chain.W > 0, np.exp(chain.logp0_nodes - chain.shift) / chain.W, 0.0)
    return TransientDensity(grid, times, out, scale, m.name, float(H0))


def mean_first_passage_time(model, H_c: float, H0=0.0, method="paper", points: int = 2000,
                            nodes: int = DEFAULT_NODES):
    """Mean time for the averaged energy to first reach ``H_c`` from ``H0`` < H_c (backward equation).

    Parameters
    ----------
    model : ImpactOscillator
    H_c : float
        Target level (absorbing).
    H0 : float or array
        Starting energies in [0, H_c].
    method : str
    points : int
        Grid nodes on [0, H_c].

    Returns
    -------
    float or ndarray

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.1}, barriers=None)
    >>> bool(mean_first_passage_time(lin, 1.0, points=400) > 0)
    True
    """
    m = get_method(method)
    _refuse_flights(m)
    _check_grid_size("mean_first_passage_time", points, 0, False)
    grid = _energy_grid(H_c, points, "H_c")
    H0a = np.asarray(H0, dtype=float)
    if not np.all((H0a >= 0) & (H0a <= H_c)):  # also refuses NaN
        raise ParameterError(f"starting energies must lie in [0, H_c={H_c:g}]")
    from scipy.sparse.linalg import splu

    chain = EnergyChain(energy_table(model, H_c, nodes), grid, m, model.restitution)
    Q = chain.generator().tocsc()
    n = len(grid) - 1  # the last node is absorbing
    tau = np.zeros(len(grid))
    tau[:n] = splu(-Q[:n, :n].tocsc()).solve(np.ones(n))
    out = np.interp(H0a, grid, tau)
    return float(out) if out.ndim == 0 else out


def passage_generator(model, H_c: float, method="paper", points: int = 2000, nodes: int = DEFAULT_NODES):
    """The energy grid on [0, H_c] and the averaged chain's backward generator Q (the last node absorbing, as in
    :func:`mean_first_passage_time`), for survival functions and decay rates of the averaged energy.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.1}, barriers=None)
    >>> grid, Q = passage_generator(lin, 1.0, points=50)
    >>> len(grid), Q.shape
    (50, (50, 50))
    """
    m = get_method(method)
    _refuse_flights(m)
    _check_grid_size("passage_generator", points, 0, False)
    grid = _energy_grid(H_c, points, "H_c")
    chain = EnergyChain(energy_table(model, H_c, nodes), grid, m, model.restitution)
    return grid, chain.generator().tocsc()


def _refuse_flights(m) -> None:
    if m.flights:
        raise ParameterError(f"method {m.name!r} has no transient form here (its flight clock is a stationary "
                             "construction); use 'jump', 'paper' or 'exact-two-impact'")
