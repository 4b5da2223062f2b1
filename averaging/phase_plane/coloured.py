r"""Stationary density of an impact oscillator driven by Ornstein-Uhlenbeck (coloured) noise (method ``fpk``).

The model is an :class:`~models.ImpactOscillator` whose white noise is replaced by the output eta of the OU
filter of :func:`models.excitation.ou_filter`:

    x' = y,   y' = -g(x) - m_d(x, y) + f(x, y) eta,   d eta = -alpha eta dt + sqrt(2 kappa) dW,   kappa = alpha**2 D,

so that Var eta = kappa / alpha = alpha D (the filter's normalisation: the same white-noise intensity D as
alpha -> inf). The state (x, y, eta) is Markov, and its stationary density solves

    0 = -d_x(y p) - d_y((-g - m_d + f eta) p) + d_eta(alpha eta p) + kappa d_eta_eta p,

with the impact boundary condition of the white-noise problem at each eta: the flux y p dy reaching a wall at
speed v leaves at speed e(v) v with the same eta (the filter's state passes through an impact unchanged).

Discretisation, and why
-----------------------
The noise acts on eta only: in the (x, y) plane at fixed eta the equation is a pure convection, and no energy
coordinate makes it tangent to the cell faces (the flow at fixed eta circles a shifted centre). We therefore use
the Cartesian finite volumes of the white-noise solver for several wells (:mod:`._cartesian`: fifth-order
upwind-biased fluxes, face averages corrected to fourth order, the wall a cell face with the exact impact map) on
each eta level, with the level's drift -g - m_d + f eta_k and no diffusion, and couple the levels by
Scharfetter-Gummel fluxes in eta (drift -alpha eta, diffusion kappa). Scharfetter-Gummel is exact for the filter
alone: the discrete eta-marginal is the Gaussian of variance alpha D sampled at the level centres, whatever the
grid (summing the equation over the plane cells removes every plane flux, since each conserves probability), so
its moments are exact up to the range cut (eta within +-``Z_SPAN`` standard deviations). Every flux leaves one
cell and enters another: probability is conserved to round-off.

Solution: the unknowns are ordered level by level, and the operator A (net outflow of each cell) is singular with
the left null vector 1. The density is the solution of (A + s 1 w^T) p = s 1 (w the cell volumes, so w.p = 1),
found by GMRES, right-preconditioned by symmetric block Gauss-Seidel over the levels (each level's plane block
factored once by a sparse LU), started from the white-noise density times the Gaussian in eta. A direct LU of the
three-dimensional operator fills too much (3-D fill); the level blocks are two-dimensional and small.

Outputs (:class:`ColouredDensity`, the interface of :class:`~averaging.phase_plane.PhaseDensity`): p(H) and the
joint p(x, y) of the (x, y)-marginal, the eta marginal (``eta``, ``p_eta``), E[H], impacts, and an error estimate
from a grid twice coarser in every direction.

Examples
--------
>>> from models import DuffingImpact, Newton
>>> from models.excitation import ou_filter
>>> sd = stationary_density_coloured(ou_filter(DuffingImpact(restitution=Newton(0.8), c=0.2, D=0.1, delta=0.6),
...                                            alpha=1.0), grid=(24, 24, 12), check=False)
>>> round(float(sd.bin_masses([sd.h_min, sd.h_support]).sum()), 9), sd.scheme
(1.0, 'coloured')
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
import sympy as sp

from hybrid.errors import ModelError, NormalisationError, ParameterError
from hybrid.sizes import check_size
from models import X, Y

from ._cartesian import CartesianDiscretisation, CartesianGrid, confining_range
from ._core import Coefficients, _bernoulli
from .cartesian import CartesianDensity
from .solver import FIT_TAIL, GridWarning, _walls

ALPHA_CHECKED = 16.0
"""The largest filter bandwidth checked (against the white-noise limit: L1 0.019 at alpha = 16 on (24, 24, 12));
above it the result carries a :class:`GridWarning` (at alpha = 1e5, E[H] came out 4 % high and the two-grid
estimate did not see it)."""

COLOURED_GRID = (48, 48, 32)
"""(cells in x, cells in y, levels in eta): the default grid. On the OU-filtered Duffing impact model of
``benchmarks/fpk_coloured.py``, L1 of p(H) 0.0018 against Monte Carlo in 13-19 CPU s and 0.55 GB."""
Z_SPAN = 5.0
"""Half-width of the eta range in standard deviations of the filter output (mass outside: 6e-7)."""
BYTES_PER_CELL = 4500
"""Peak memory per cell of the assembly, the level factors and GMRES: measured 3.5-4 kB above the imports on
(48, 48, 48) and (64, 64, 48) (``benchmarks/fpk_coloured.py``)."""
SECONDS_PER_CELL = 3e-4
"""CPU seconds per cell on 2 shared cores (measured 2.3e-4 to 3.4e-4: GMRES iterations grow with the levels)."""
TAIL_PROBE = 1e-4
"""Probability above the energy that sets the box (twice that energy; see :func:`stationary_density_coloured`)."""
MAX_ITERATIONS = 400
"""GMRES iterations before the solve is declared not converged."""


def _parts(model, params):
    """(oscillator with the parameters, alpha, kappa, drift m(x, y, eta) of y, coefficient f(x, y) of eta) of an
    OU-filtered oscillator, or a one-line error."""
    from models.excitation import FilteredAutomaton

    if not isinstance(model, FilteredAutomaton):
        raise ModelError(f"the coloured-noise solver takes a model built by models.excitation.ou_filter, got "
                         f"{type(model).__name__}")
    if model.filter.get("kind") != "ou":
        # a 4-D grid at this solver's default resolution, (48, 48) cells by 32 x 32 levels, at BYTES_PER_CELL
        cells = COLOURED_GRID[0] * COLOURED_GRID[1] * COLOURED_GRID[2] ** 2
        raise ModelError(f"the coloured-noise solver handles the OU filter (state (x, y, eta)); a "
                         f"{model.filter.get('kind')} filter adds two states, so its density is 4-D, on "
                         f"{tuple(s.name for s in model.states)}: {COLOURED_GRID[0]} x {COLOURED_GRID[1]} cells by "
                         f"{COLOURED_GRID[2]} x {COLOURED_GRID[2]} filter levels ({cells:.2g} cells) would need about "
                         f"{cells * BYTES_PER_CELL / 1e9:.0f} GB, and no 4-D solver is built: use Monte Carlo "
                         "(vibro mc on the filtered automaton, hybrid.stochastic.simulate_automaton)")
    if model.oscillator is None or model.filter.get("noises") != 1:
        raise ModelError("the coloured-noise solver needs an ImpactOscillator with one noise under the OU filter")
    values = model.resolve_parameters(params)
    osc = model.oscillator
    own = {k: v for k, v in values.items() if k in osc.params and v != osc.params[k]}
    osc = osc.with_params(**own) if own else osc
    alpha_name = model.filter["parameters"]["alpha"]
    alpha = float(values[alpha_name])
    z_name = model.filter["outputs"][0]
    z = next(s for s in model.states if s.name == z_name)
    mode = model.modes[0]
    k = [s.name for s in model.states].index(z_name)
    subs = {sp.Symbol(n, real=True): v for n, v in values.items()}
    subs.update({sp.Symbol(n): v for n, v in values.items()})
    flow_y = sp.sympify(mode.flow[1]).subs(subs)
    drift_z = sp.sympify(mode.flow[k]).subs(subs)
    amp = sp.sympify(mode.noise[k][0]).subs(subs)
    f = sp.diff(flow_y, z)
    if f.free_symbols - {X, Y} or sp.diff(drift_z, z).free_symbols:
        raise ModelError("the OU filter's output must enter the velocity equation linearly (x'' = ... + f(x, y) eta)")
    if sp.simplify(drift_z + alpha * z) != 0:
        raise ModelError(f"the filter's drift {drift_z} is not -alpha * {z_name}")
    kappa = 0.5 * float(amp) ** 2
    base = sp.lambdify((X, Y), flow_y.subs(z, 0), "numpy")
    drive = sp.lambdify((X, Y), f, "numpy")
    return osc, alpha, kappa, base, drive


class _Levels:
    """The assembled three-dimensional operator: a plane operator per eta level, coupled in eta."""

    def __init__(self, osc, law, grid: CartesianGrid, alpha, kappa, base, drive, nz):
        self.grid, self.nz = grid, nz
        self.sigma = math.sqrt(kappa / alpha)
        L = Z_SPAN * self.sigma
        self.z_faces = np.linspace(-L, L, nz + 1)
        self.hz = self.z_faces[1] - self.z_faces[0]
        self.z = 0.5 * (self.z_faces[1:] + self.z_faces[:-1])
        n = grid.n
        zero = np.zeros(1)

        def m_nc(x, y):  # the level eta = 0; each level replaces the drift (operator_with_drift)
            return base(x, y) + osc.restoring(x)

        self.plane = CartesianDiscretisation(grid, Coefficients(osc.restoring, osc.potential, m_nc,
                                                                lambda x, y: zero, law), law)
        xs, ys = self.plane.drift_points()
        m0 = np.broadcast_to(np.asarray(base(xs, ys), dtype=float), xs.shape)
        f = np.broadcast_to(np.asarray(drive(xs, ys), dtype=float), xs.shape)
        self.levels = [self.plane.operator_with_drift(m0 + f * zk) for zk in self.z]
        # eta fluxes (Scharfetter-Gummel) between levels k and k+1: out of k  (kappa/h) [B(-Pe) p_k - B(Pe) p_k+1]
        zf = self.z_faces[1:-1]
        Pe = -alpha * zf * self.hz / kappa
        up, down = kappa / self.hz * _bernoulli(-Pe), kappa / self.hz * _bernoulli(Pe)
        k = np.arange(nz - 1)
        Z = sps.csr_matrix((np.r_[up, -down, -up, down], (np.r_[k, k, k + 1, k + 1], np.r_[k, k + 1, k, k + 1])),
                           shape=(nz, nz))
        self.Z = Z
        area = grid.hx * grid.hy
        self.coupling = area / self.hz  # plane operators are per unit eta depth
        self.A = (sps.block_diag(self.levels) + sps.kron(Z, sps.identity(n) * self.coupling)).tocsr()
        self.mass_weight = np.full(n * nz, area * self.hz)

    def solve(self, start, rtol: float = 1e-10):
        """The normalised null vector by preconditioned GMRES; returns (p, iterations)."""
        n, nz, A = self.grid.n, self.nz, self.A
        s = float(np.mean(np.abs(A.diagonal())))
        w = self.mass_weight
        ones = np.ones(n * nz)

        def matvec(v):
            return A @ v + s * ones * (w @ v)

        Zd = self.Z.diagonal() * self.coupling
        lower = self.Z.diagonal(-1) * self.coupling
        upper = self.Z.diagonal(1) * self.coupling
        lus = [spla.splu((level + sps.identity(n) * Zd[k]).tocsc(), permc_spec="COLAMD")
               for k, level in enumerate(self.levels)]

        def precondition(r):
            r = r.reshape(nz, n)
            x = np.empty_like(r)
            for k in range(nz):  # forward sweep
                rhs = r[k] - (lower[k - 1] * x[k - 1] if k > 0 else 0.0)
                x[k] = lus[k].solve(rhs)
            for k in range(nz - 2, -1, -1):  # backward sweep (symmetric Gauss-Seidel)
                x[k] = lus[k].solve(r[k] - (lower[k - 1] * x[k - 1] if k > 0 else 0.0) - upper[k] * x[k + 1])
            return x.ravel()

        op = spla.LinearOperator((n * nz, n * nz), matvec=matvec)
        M = spla.LinearOperator((n * nz, n * nz), matvec=precondition)
        count = [0]

        def callback(_):
            count[0] += 1

        rhs = s * ones
        p, info = spla.gmres(op, rhs, x0=start, M=M, rtol=rtol, restart=60, maxiter=MAX_ITERATIONS // 60 + 1,
                             callback=callback, callback_type="pr_norm")
        if info != 0 or not np.all(np.isfinite(p)):
            raise NormalisationError(f"GMRES did not converge on the coloured-noise density ({count[0]} iterations); "
                                     "use a finer grid or report the model")
        return p, count[0]


class _PlaneView:
    """The (x, y)-marginal seen as a plane discretisation: what :class:`CartesianDensity` reads (cell areas, the
    walls' flux reconstruction, which is linear in p and the same on every level). Its operator is not the
    marginal's (the marginal obeys no closed plane equation): the residual and conservation of the result are
    those of the three-dimensional operator, set by :class:`ColouredDensity`."""

    def __init__(self, level: CartesianDiscretisation):
        n = level.grid.n
        self.mass_weight = level.mass_weight
        self.walls = level.walls
        self.wall_flux = level.wall_flux
        self.A = sps.csr_matrix((n, n))


class ColouredDensity(CartesianDensity):
    """The stationary density of an OU-filtered impact oscillator: p(x, y, eta) and its marginals.

    The interface of :class:`~averaging.phase_plane.PhaseDensity` for the (x, y)-marginal (``H``, ``p``,
    ``density``, ``bin_masses``, ``joint``, ``marginal_x``, ``marginal_y``, ``mean_energy``, impacts,
    ``to_pandas``), plus the filter's:

    Attributes
    ----------
    eta, p_eta : ndarray
        Level centres and the eta-marginal density there (Gaussian of variance alpha D up to round-off).
    alpha, eta_variance : float
        The filter's bandwidth and its closed-form stationary variance alpha D (kappa / alpha).
    cell_p3 : ndarray (levels, cells)
        p(x, y, eta) on the cells of each level.
    iterations : int
        GMRES iterations of the solve.
    """

    scheme = "coloured"

    def __init__(self, filtered, osc, grid, levels: _Levels, p, timing, walls, iterations):
        P = p.reshape(levels.nz, grid.n)
        marginal = P.sum(axis=0) * levels.hz
        super().__init__(osc, grid, _PlaneView(levels.plane), marginal, timing, walls)
        self.filtered = filtered
        self.levels = levels
        self.cell_p3 = P
        self.eta = levels.z
        self.p_eta = P.sum(axis=1) * grid.hx * grid.hy
        self.alpha = float(levels.alpha)
        self.eta_variance = float(levels.sigma**2)
        self.mean_eta2 = float(np.sum(self.p_eta * self.eta**2) * levels.hz)
        self.iterations = iterations
        A = levels.A
        scale = float(np.max(abs(A) @ np.abs(p)))
        self.residual = float(np.max(np.abs(A @ p)) / scale) if scale > 0 else 0.0
        self.conservation = float(np.max(np.abs(np.asarray(A.sum(axis=0)))))

    def marginal_eta(self, eta):
        """The eta-marginal density at ``eta`` (linear between level centres, 0 outside the range).

        Examples
        --------
        >>> from models import DuffingImpact, Newton
        >>> from models.excitation import ou_filter
        >>> sd = stationary_density_coloured(ou_filter(DuffingImpact(restitution=Newton(0.8), c=0.2, D=0.1,
        ...                                  delta=0.6), alpha=1.0), grid=(24, 24, 12), check=False)
        >>> gauss = np.exp(-sd.eta**2 / (2 * sd.eta_variance)) / np.sqrt(2 * np.pi * sd.eta_variance)
        >>> bool(np.allclose(sd.marginal_eta(sd.eta), gauss, rtol=1e-4))
        True
        """
        eta = np.atleast_1d(np.asarray(eta, dtype=float))
        return np.interp(eta, self.eta, self.p_eta, left=0.0, right=0.0)

    def metadata(self) -> dict:
        """Method, scheme, the filtered model, grid and summary statistics (JSON-friendly)."""
        meta = super().metadata()
        meta.update(model=self.filtered.describe(), grid=[int(self.grid.nx), int(self.grid.ny), int(self.levels.nz)],
                    cells=int(self.grid.n * self.levels.nz), alpha=self.alpha, eta_variance=self.eta_variance,
                    mean_eta2=self.mean_eta2, eta_range=[float(self.levels.z_faces[0]), float(self.levels.z_faces[-1])],
                    gmres_iterations=self.iterations)
        return meta

    def __repr__(self) -> str:
        return (f"PhaseDensity(model={self.model.name!r}, method='fpk', scheme='coloured', alpha={self.alpha:g}, "
                f"cells={self.grid.n * self.levels.nz}, E[H]={self.mean_energy:.6g}, "
                f"impact_rate={self.impact_rate:.6g})")


def _grid_triple(grid) -> tuple[int, int, int]:
    try:
        nx, ny, nz = (int(v) for v in grid)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"grid={grid!r} must be three integers (cells in x, cells in y, levels in eta)") from exc
    if nx < 8 or ny < 8 or nz < 6:
        raise ParameterError(f"grid={grid!r} too small: use at least (8, 8, 6) (cells in x, y, levels in eta)")
    return nx, ny, nz


def _check_grid_size(nx: int, ny: int, nz: int, max_memory: float) -> None:
    """Refuse, with the estimate, a grid whose solve needs more than ``max_memory`` bytes."""
    cells = float(nx) * float(ny + ny % 2) * nz
    check_size(f"the coloured-noise grid {nx} x {ny} x {nz}", memory=cells * BYTES_PER_CELL, max_memory=max_memory,
               detail=f"{cells:.3g} cells x {BYTES_PER_CELL} bytes, about {cells * SECONDS_PER_CELL:.3g} s",
               fix=f"use a coarser grid (the default is {COLOURED_GRID})")


def solve_coloured(model, grid=COLOURED_GRID, h_max: float = 4.0, *, params=None, walls="model", points: int = 2000,
                   start=None, max_memory: float | None = None) -> ColouredDensity:
    """One solve on one grid, no accuracy check: the lower-level entry of :func:`stationary_density_coloured`.

    Parameters
    ----------
    model : FilteredAutomaton
        ``models.excitation.ou_filter(oscillator, alpha=...)``.
    grid : (int, int, int)
        Cells in x, cells in y (rounded up to even) and levels in eta (on +-``Z_SPAN`` standard deviations).
    h_max : float
        Upper energy of the (x, y) box (reflecting): choose it in the tail.
    params : dict, optional
        Parameter overrides (the oscillator's and ``alpha``), as for ``simulate_automaton``.
    walls, points
        See :func:`~averaging.phase_plane.solve_phase_plane`.
    start : ColouredDensity, optional
        A solution on another grid: its (x, y)-marginal times the Gaussian in eta starts GMRES (default: the
        white-noise density on the same plane grid).
    max_memory : float, optional
        Memory limit in bytes (default ``hybrid.sizes.MAX_MEMORY``).

    Examples
    --------
    >>> from models import DuffingImpact, Newton
    >>> from models.excitation import ou_filter
    >>> sd = solve_coloured(ou_filter(DuffingImpact(restitution=Newton(0.8), c=0.2, D=0.1, delta=0.6), alpha=1.0),
    ...                     grid=(24, 24, 12), h_max=2.0)
    >>> round(sd.mean_eta2 / sd.eta_variance, 4), sd.conservation < 1e-12
    (1.0, True)
    """
    from hybrid.sizes import MAX_MEMORY

    from ._core import null_vector
    from .solver import _coefficients

    nx, ny, nz = _grid_triple(grid)
    _check_grid_size(nx, ny, nz, MAX_MEMORY if max_memory is None else max_memory)
    if not (np.isfinite(h_max) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    if int(points) != points or points < 3:
        raise ParameterError(f"points={points!r} must be an integer >= 3")
    osc, alpha, kappa, base, drive = _parts(model, params)
    osc.require_autonomous("the coloured-noise stationary density")
    law = osc.restitution
    left, right = _walls(osc, walls)
    t0 = time.perf_counter()
    lo, hi, g_min = confining_range(osc.potential, float(h_max), left, right)
    wall_x = {k: v for k, v in (("left", left), ("right", right)) if v is not None}
    g = CartesianGrid(lo, hi, g_min, float(h_max), nx, ny, osc.potential, wall_x)
    levels = _Levels(osc, law.coefficient, g, alpha, kappa, base, drive, nz)
    levels.alpha = alpha
    t1 = time.perf_counter()
    if start is None:  # the white-noise density of the same intensity on this plane grid
        white = CartesianDiscretisation(g, _coefficients(osc, law), law.coefficient)
        plane = null_vector(white.A, white.mass_weight)
    else:
        plane = np.maximum(_on_grid(start, g), 0.0)
    gauss = np.exp(-0.5 * (levels.z / levels.sigma) ** 2)
    guess = (gauss[:, None] * plane[None, :]).ravel()
    guess /= guess @ levels.mass_weight
    p, iterations = levels.solve(guess)
    t2 = time.perf_counter()
    out = ColouredDensity(model, osc, g, levels, p, {"assemble": t1 - t0, "solve": t2 - t1}, (left, right),
                          iterations)
    out.H = np.linspace(g.g_min, float(h_max), int(points))
    out.p = out.density(out.H)
    return out


def _on_grid(sd: ColouredDensity, grid: CartesianGrid) -> np.ndarray:
    """The (x, y)-marginal of ``sd`` at the cell centres of ``grid``."""
    vals = np.empty(grid.n)
    for j in np.unique(grid.j):
        sel = grid.j == j
        col = sd.joint(grid.x[sel], np.array([grid.yc[j]]))[0]
        vals[sel] = col
    return vals


def stationary_density_coloured(model, grid=None, h_max: float = 4.0, *, params=None, walls="model",
                                points: int = 2000, check: bool = True, tol: float = 0.005, order: float = 2.0,
                                max_memory: float | None = None) -> ColouredDensity:
    """Stationary density of an OU-filtered (coloured-noise) impact oscillator, with p(H), p(x, y) and p(eta).

    Parameters
    ----------
    model : FilteredAutomaton
        ``models.excitation.ou_filter(oscillator, alpha=...)`` of an :class:`~models.ImpactOscillator` with one
        noise; the oscillator's walls and restitution law give the impact boundary condition.
    grid : (int, int, int), optional
        Cells in x, cells in y and levels in eta (default :data:`COLOURED_GRID`); cost about their product.
    h_max : float
        Upper end of the energy range asked for. The (x, y) box is fitted to the mass: to the range that holds all
        but ``FIT_TAIL`` of the white-noise density of the same intensity (the OU filter passes less power at every
        frequency), then to twice the energy above which the coarse solve of the check holds ``TAIL_PROBE``
        (1e-8 left above for an exponential tail; the check warns when the top tenth of the box holds more than
        1e-4); p(H) is reported on [min G, h_max].
    params : dict, optional
        Parameter overrides (the oscillator's and the filter's ``alpha``).
    walls, points
        See :func:`~averaging.phase_plane.solve_phase_plane`.
    check : bool
        Check that the density decays towards the top of the box, and estimate the L1 error of p(H) on 100 bins
        from a solve on a grid twice coarser in every direction (Richardson with ``order``); warn with
        :class:`GridWarning` above ``tol``.
    max_memory : float, optional
        Memory limit in bytes of one solve (default ``hybrid.sizes.MAX_MEMORY``, 4 GB): a grid whose estimate is
        above it is refused at once with the estimate.

    Returns
    -------
    ColouredDensity

    Warns
    -----
    GridWarning
        Above ``tol``, and for ``alpha`` above :data:`ALPHA_CHECKED`, where the solver was not checked.

    Examples
    --------
    >>> from models import DuffingImpact, Newton
    >>> from models.excitation import ou_filter
    >>> model = ou_filter(DuffingImpact(restitution=Newton(0.8), c=0.2, D=0.1, delta=0.6), alpha=1.0)
    >>> sd = stationary_density_coloured(model, grid=(24, 24, 12), tol=0.05)
    >>> round(sd.mean_energy, 2), sd.error_estimate > 0
    (0.11, True)
    """
    from hybrid.sizes import MAX_MEMORY

    from .cartesian import CARTESIAN_GRID, box_top_mass, report_up_to, stationary_density_cartesian

    grid = COLOURED_GRID if grid is None else grid
    nx, ny, nz = _grid_triple(grid)
    _check_grid_size(nx, ny, nz, MAX_MEMORY if max_memory is None else max_memory)  # before the white and coarse solves
    osc, alpha, *_ = _parts(model, params)
    if alpha > ALPHA_CHECKED:
        warnings.warn(
            f"alpha = {alpha:g} is above the bandwidths this solver was checked at (alpha <= {ALPHA_CHECKED:g}, in "
            "units of the oscillator's time): the y-convection error grows like sqrt(alpha) and the two-grid estimate "
            "can miss it (alpha = 1e5 gave E[H] 4 % high with an estimate of 0.0055); for so wide a filter the "
            "white-noise density (vibro pdf --method fpk without --filter) is the better answer", GridWarning,
            stacklevel=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GridWarning)
        white = stationary_density_cartesian(osc, (min(nx, CARTESIAN_GRID[0]), min(ny, CARTESIAN_GRID[1])),
                                             float(h_max), walls=walls, points=3, check=False)
    # the box: first where all but FIT_TAIL of the white-noise density of the same intensity lies (it holds more
    # energy: the OU filter passes less power at every frequency), then fitted to the coloured density on the coarse
    # grid: twice the energy above which it holds TAIL_PROBE (an exponential tail then leaves TAIL_PROBE**2 above)
    above = 1.0 - np.cumsum(white.ring_mass)
    k = int(np.argmax(above <= FIT_TAIL)) if np.any(above <= FIT_TAIL) else len(above) - 1
    top = float(white.H_faces[k + 1])
    h = float(white.h_support)
    if top < white.h_min + 0.8 * (h - white.h_min):
        h = white.h_min + 1.25 * (top - white.h_min)
    coarse_grid = (max(8, nx // 2), max(8, ny // 2), max(6, nz // 2))
    coarse = solve_coloured(model, coarse_grid, h, params=params, walls=walls, points=3, max_memory=max_memory)
    by_energy = np.argsort(coarse.cell_H)[::-1]
    # absolute cell masses: a coarse solve may undershoot below zero in the tail
    probe = float(coarse.cell_H[by_energy][np.argmax(np.cumsum(np.abs(coarse.cell_mass[by_energy])) > TAIL_PROBE)])
    fitted = coarse.h_min + 2.0 * (probe - coarse.h_min)
    if fitted < coarse.h_min + 0.8 * (h - coarse.h_min):
        h, coarse = fitted, None
    sd = solve_coloured(model, (nx, ny, nz), h, params=params, walls=walls, points=points, max_memory=max_memory,
                        start=coarse)
    report_up_to(sd, h, h_max, points)
    if not check:
        return sd
    tail = box_top_mass(sd, h)
    if coarse is None:
        coarse = solve_coloured(model, coarse_grid, h, params=params, walls=walls, points=3, start=sd,
                                max_memory=max_memory)
    sd._coarse_solve, sd._estimate_order = coarse, float(order)  # estimate_error on other bins
    sd.tail_mass = tail
    est = sd.estimate_error(np.linspace(sd.h_min, sd.h_support, 101)) + tail
    sd.error_estimate = est
    sd.error_method = (f"two grids: L1(p on {(nx, ny, nz)}, p on {coarse_grid}) / (2**{order:g} - 1) (Richardson) "
                       f"+ {tail:.2g} (probability in the top 10 % of the box)")
    if est > tol:
        warnings.warn(f"grid {(nx, ny, nz)} too coarse: estimated L1 error of p(H) {est:.2g} > tol={tol:g} (from "
                      "the solve on a grid twice coarser); refine the grid", GridWarning, stacklevel=2)
    return sd


__all__ = ["COLOURED_GRID", "ColouredDensity", "solve_coloured", "stationary_density_coloured"]
