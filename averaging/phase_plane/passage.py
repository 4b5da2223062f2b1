r"""First passage and survival from the phase-plane generator (method ``fpk``).

The stationary solver assembles a matrix A whose rows are the net outflows of the cells: with cell masses
q = M p (M the cell areas over the angular speed), the forward equation is M dp/dt = -A p. Its adjoint is the
backward generator L = -M^{-1} A^T acting on functions of the cell. With the cells outside a safe domain S made
absorbing (their value 0):

* the mean first-passage time solves L T = -1 on S, i.e. one sparse solve A_SS^T T = M_S 1;
* the survival u(t, z) = P_z(T > t) solves du/dt = L u, u(0) = 1 on S (BDF2, one LU, a backward-Euler start);
  the first-passage density is f = -du/dt = -L u;
* the decay rate lambda_1 (R(t) ~ C exp(-lambda_1 t) for long t) is the smallest eigenvalue of A_SS^T v = lambda M v,
  found by ARPACK on (A_SS^T)^{-1} M.

Cells are classified by their centre. For an energy domain H < H_c the rings are laid out so that the outermost
ring is centred on H_c: the absorbing condition then sits exactly on the level. Any other domain (|x| < x_c, an
observable) cuts rings and angles: a cell is safe when its centre is, so the boundary is placed to within half a
cell, a first-order error. On Example 1 the mean time converges at first order in the rings (the impact map at
hard impacts dominates at high levels) and at about second order in the angles; the two errors have opposite
signs there, so a grid coarsened in both directions at once can agree with the fine one by cancellation. The
error estimate therefore halves each direction separately and adds the two Richardson terms.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
import sympy as sp

from hybrid.automaton import lambdify_numeric
from hybrid.errors import ParameterError, VibroWarning
from models import X, Y

from .solver import DEFAULT_GRID, DEFAULT_STRETCH, cell_values_at, solve_phase_plane

H_SYMBOL = sp.Symbol("H")
PASSAGE_GRID = (120, 128)
"""Default (rings, angles) for first passage: MFPT of Example 1 within about 0.2 % of the (240, 256) answer."""
DEFAULT_STEPS = 800
"""BDF2 steps over [0, t_max] for R(t)."""


class PassageWarning(VibroWarning):
    """A first-passage answer outside its accuracy (a grid too coarse, a domain the grid does not cover)."""


# --------------------------------------------------------------------------------------------------- domains
class Domain:
    """A safe domain ``phi(x, y) < 0`` parsed from text such as ``"H < 2"``, ``"abs(x) <= 0.8"`` or ``"x < 0.5"``.

    Attributes
    ----------
    text : str
    phi : sympy expression in x, y (and H)
        Negative inside the domain.
    energy_level : float or None
        H_c when the domain is H < H_c (the rings are then aligned with it).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> Domain("H < 2.0", DuffingImpact()).energy_level
    2.0
    >>> Domain("abs(x) <= 0.5", DuffingImpact()).contains(0.7, 0.0)
    False
    """

    def __init__(self, text, model):
        self.text = str(text)
        names = {"x": X, "y": Y, "H": H_SYMBOL, **{str(s): s for s in getattr(model, "parameter_symbols", ())}}
        try:
            rel = sp.sympify(text, locals=names) if isinstance(text, str) else text
        except (sp.SympifyError, SyntaxError, TypeError, ValueError) as exc:
            raise ParameterError(f"domain {text!r} is not an inequality in x, y, H (e.g. 'H < 2.0')") from exc
        if not isinstance(rel, (sp.StrictLessThan, sp.LessThan, sp.StrictGreaterThan, sp.GreaterThan)):
            raise ParameterError(f"domain {text!r} must be one inequality in x, y, H such as 'H < 2.0' or "
                                 "'abs(x) <= 0.8'")
        phi = rel.lhs - rel.rhs if isinstance(rel, (sp.StrictLessThan, sp.LessThan)) else rel.rhs - rel.lhs
        phi = model.substitute(phi)
        extra = phi.free_symbols - {X, Y, H_SYMBOL}
        if extra:
            raise ParameterError(f"domain {text!r}: unknown names {sorted(map(str, extra))}; use x, y, H and the "
                                 "model's parameters")
        if not phi.free_symbols:
            raise ParameterError(f"domain {text!r} does not depend on the state")
        self.phi = phi
        self.energy_level = None
        if phi.free_symbols == {H_SYMBOL} and sp.degree(phi, H_SYMBOL) == 1 and phi.diff(H_SYMBOL).is_positive:
            self.energy_level = float(sp.solve(phi, H_SYMBOL)[0])
            if not (np.isfinite(self.energy_level) and self.energy_level > 0):
                raise ParameterError(f"domain {text!r}: the level H_c = {self.energy_level:g} must be positive")
        self._model = model
        self._f = lambdify_numeric((X, Y, H_SYMBOL), phi)

    def value(self, x, y):
        """phi(x, y): negative inside."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        with np.errstate(all="ignore"):  # an overflowing H is +inf, outside every bounded domain
            H = self._model.energy(x, y)
            return np.broadcast_to(np.asarray(self._f(x, y, H), dtype=float), np.broadcast_shapes(x.shape, y.shape))

    def contains(self, x, y):
        """Whether (x, y) lies inside (phi < 0)."""
        v = self.value(x, y)
        return bool(v < 0) if np.ndim(v) == 0 else v < 0

    def __repr__(self):
        return f"Domain({self.text!r})"


def aligned_h_max(level: float, rings: int, stretch: float = DEFAULT_STRETCH) -> float:
    """The grid's h_max that puts the centre of its outermost ring on ``level``.

    Examples
    --------
    >>> round(aligned_h_max(2.0, 100), 6) > 2.0
    True
    """
    t = 1.0 - 1.0 / rings
    below = stretch * t + (1.0 - stretch) * t * t
    return 2.0 * level / (1.0 + below)


# --------------------------------------------------------------------------------------------------- core
class BackwardProblem:
    """The backward equation M du/dt = -K u on the safe states, u = 0 outside: K = A_SS^T with M the cell masses
    (fpk), or K = -Q_SS with M = 1 (an averaged chain). Mean time K T = M 1; survival u(0) = 1; decay rate the
    smallest eigenvalue of K v = lambda M v.

    Examples
    --------
    >>> import scipy.sparse as sps
    >>> bp = BackwardProblem(sps.csc_matrix([[2.0]]), [1.0])     # one state left at rate 2
    >>> float(bp.mean_time()[0]), bp.decay_rate()
    (0.5, 2.0)
    """

    def __init__(self, K, m):
        self.K = sps.csc_matrix(K)
        self.m = np.asarray(m, dtype=float)
        self._lu = None

    @property
    def lu(self):
        if self._lu is None:
            self._lu = _factor(self.K)
        return self._lu

    def mean_time(self):
        return self.lu.solve(self.m)

    def decay_rate(self):
        n = len(self.m)
        if n < 3:
            return float(1.0 / np.max(self.mean_time()))
        op = spla.LinearOperator((n, n), matvec=lambda v: self.lu.solve(self.m * v), dtype=float)
        try:
            mu = spla.eigs(op, k=1, which="LM", return_eigenvectors=False, tol=1e-10, maxiter=5000)
        except spla.ArpackNoConvergence:
            return float("nan")
        return float(1.0 / np.real(mu[0]))

    def survival(self, times, weights):
        """R(t) and f(t) = -dR/dt at ``times`` (uniform from 0) for the start ``weights`` over the safe cells."""
        n_t = len(times)
        dt = times[1] - times[0]
        M = sps.diags(self.m)
        # backward Euler over the first step in 8 substeps (the start is discontinuous), then BDF2 at dt
        h = dt / 8
        lu_be = _factor((M + h * self.K).tocsc())
        lu_bdf = _factor((3.0 * M + 2.0 * dt * self.K).tocsc())
        u = np.ones(len(self.m))
        R = np.empty(n_t)
        f = np.empty(n_t)
        R[0] = 1.0
        f[0] = float(weights @ (self.K @ u / self.m))
        prev = u
        for _ in range(8):
            u = lu_be.solve(self.m * u)
        R[1] = weights @ u
        f[1] = weights @ (self.K @ u / self.m)
        for k in range(2, n_t):
            u, prev = lu_bdf.solve(self.m * (4.0 * u - prev)), u
            R[k] = weights @ u
            f[k] = weights @ (self.K @ u / self.m)
        return R, f


def _factor(K):
    try:
        return spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1)
    except RuntimeError:  # exactly singular with this pivoting: let SuperLU pivot freely
        return spla.splu(K, permc_spec="COLAMD")


class FirstPassage:
    """First passage out of a safe domain: mean time, survival R(t), density f(t), decay rate, error estimate.

    Attributes
    ----------
    method : str
        ``"fpk"``, ``"paper"``, ``"jump"`` or ``"mc"``.
    domain : str
    start : tuple or str
        The start state (x, y), or ``"stationary"`` (the stationary density restricted to the domain).
    mean_time : float
        E[T].
    error_estimate : float or None
        Estimated discretisation error of ``mean_time`` (from half the rings and half the angles), or the 95 %
        half-width (mc).
    t, R, density : ndarray
        Times, survival P(T > t) and first-passage density -dR/dt.
    decay_rate : float
        lambda_1 with R(t) ~ C exp(-lambda_1 t) for long t (NaN where not computed).
    poisson : ndarray or None
        exp(-nu t), the Poisson estimate of R(t) from the stationary out-crossing rate nu (x-level domains).
    details : dict
        Grid, cells, timing and the method's own figures.
    """

    def __init__(self, method, domain, start, mean_time, t, R, density, decay_rate=float("nan"),
                 error_estimate=None, details=None, poisson=None):
        self.method, self.domain, self.start = method, domain, start
        self.mean_time = float(mean_time)
        self.t, self.R, self.density = np.asarray(t), np.asarray(R), np.asarray(density)
        self.decay_rate = float(decay_rate)
        self.error_estimate = error_estimate
        self.details = dict(details or {})
        self.poisson = poisson

    def survival(self, t):
        """R at arbitrary times (linear interpolation; 1 before 0, NaN past the computed range)."""
        t = np.asarray(t, dtype=float)
        return np.where(t < 0, 1.0, np.interp(t, self.t, self.R, right=np.nan))

    def to_pandas(self):
        """DataFrame t, R, density (and R_poisson where available), with :meth:`metadata` in ``.attrs``.

        Examples
        --------
        >>> r = FirstPassage("fpk", "H < 1", (0.0, 0.0), 2.0, [0.0, 1.0], [1.0, 0.6], [0.0, 0.3])
        >>> list(r.to_pandas().columns)
        ['t', 'R', 'density']
        """
        import pandas as pd

        cols = {"t": self.t, "R": self.R, "density": self.density}
        if self.poisson is not None:
            cols["R_poisson"] = self.poisson
        df = pd.DataFrame(cols)
        df.attrs.update(self.metadata())
        return df

    def metadata(self) -> dict:
        """Method, domain, start and the summary figures (JSON-friendly)."""
        start = list(self.start) if isinstance(self.start, tuple) else self.start
        est = None if self.error_estimate is None else float(self.error_estimate)
        rate = self.decay_rate if np.isfinite(self.decay_rate) else None
        return {"method": self.method, "domain": self.domain, "start": start, "mean_time": self.mean_time,
                "error_estimate": est, "decay_rate": rate,
                **{k: v for k, v in self.details.items() if isinstance(v, (int, float, str, list, dict, type(None)))}}

    def __repr__(self):
        est = "" if self.error_estimate is None else f" ± {self.error_estimate:.2g}"
        return (f"FirstPassage(method={self.method!r}, domain={self.domain!r}, mean_time={self.mean_time:.6g}{est}, "
                f"decay_rate={self.decay_rate:.4g})")

    def _repr_html_(self):
        from hybrid.display import summary_html

        rows = {"domain": self.domain, "start": str(self.start), "E[T]": self.mean_time}
        if self.error_estimate is not None:
            rows["error estimate"] = self.error_estimate
        rows["decay rate"] = self.decay_rate
        return summary_html(f"First passage ({self.method})", rows)


# --------------------------------------------------------------------------------------------------- crossings
def crossing_rate(sd, level: float, direction: int = 1, points: int = 4001) -> float:
    """Rice's rate of crossings of x = ``level`` from the joint density: ``nu+(b) = int_0^inf y p(b, y) dy``
    (``direction=1``, upwards) or ``int_-inf^0 |y| p(b, y) dy`` (``-1``), per unit time.

    Parameters
    ----------
    sd : PhaseDensity
        A stationary density of the phase-plane solver.
    level : float
    direction : {1, -1}
    points : int
        Midpoint rule in y on (0, sqrt(2 h_support)).

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> from averaging.phase_plane import solve_phase_plane
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.1}, barriers=None)
    >>> sd = solve_phase_plane(lin, (60, 64), h_max=12.0, walls=None)
    >>> round(crossing_rate(sd, 0.0) * 2 * np.pi, 2)                # one upcrossing of 0 per period 2 pi
    1.0
    """
    if direction not in (1, -1):
        raise ParameterError(f"direction={direction!r} must be 1 (upwards) or -1 (downwards)")
    top = np.sqrt(2.0 * sd.h_support)
    edges = np.linspace(0.0, top, int(points) + 1)
    y = 0.5 * (edges[1:] + edges[:-1])
    p = sd.joint(np.array([float(level)]), direction * y)[:, 0]
    return float(np.sum(y * p) * (edges[1] - edges[0]))


def out_crossing_rate(sd, domain: Domain) -> float | None:
    """Stationary rate of exits through the boundary of a domain of x alone (Rice at each boundary point, in
    the outward direction); None for a domain that depends on y or H (its boundary is crossed by diffusion)."""
    if domain.phi.free_symbols != {X}:
        return None
    lo, hi = sd._x_range()
    xs = np.linspace(lo, hi, 4001)
    inside = domain.value(xs, np.zeros_like(xs)) < 0
    rate = 0.0
    for k in np.flatnonzero(inside[:-1] != inside[1:]):
        a, b = xs[k], xs[k + 1]
        for _ in range(60):  # bisection to the boundary point
            mid = 0.5 * (a + b)
            if (domain.value(mid, 0.0) < 0) == inside[k]:
                a = mid
            else:
                b = mid
        rate += crossing_rate(sd, 0.5 * (a + b), 1 if inside[k] else -1)  # leaving upwards or downwards
    return rate


# --------------------------------------------------------------------------------------------------- fpk
def _safe_cells(domain: Domain, sd):
    g = sd.grid
    if domain.energy_level is not None:
        return g.H_c[g.ring] < domain.energy_level * (1.0 - 1e-9)
    return domain.value(sd.cell_x, sd.cell_y) < 0


def _start_weights(sd, safe, start, domain, model, walls, restitution, h_max):
    """Weights over the safe cells that give a start's value from cell values (rows sum to 1)."""
    idx = np.flatnonzero(safe)
    if isinstance(start, str):
        if start != "stationary":
            raise ParameterError(f"start={start!r}: give a state (x, y) or 'stationary'")
        from .solver import stationary_density_xy

        top = domain.energy_level * 1.5 if domain.energy_level is not None else h_max
        st = stationary_density_xy(model, grid=DEFAULT_GRID, h_max=max(top, 4.0), walls=walls,
                                   restitution=restitution, check=False)
        p = cell_values_at(st.model, st.grid, st.walls, st.cell_p, sd.cell_x[idx], sd.cell_y[idx])
        w = p * sd.discretisation.mass_weight[idx]
        if w.sum() <= 0:
            raise ParameterError("the stationary density puts no mass inside the domain")
        return w / w.sum()
    x0, y0 = start
    if not domain.contains(x0, y0):
        raise ParameterError(f"the start (x, y) = ({x0:g}, {y0:g}) lies outside the domain {domain.text!r}")
    # cell_values_at is linear in the values: its weights are its answers for the unit vectors of its stencil
    n = sd.grid.n
    w = np.zeros(len(idx))
    pos = np.full(n, -1)
    pos[idx] = np.arange(len(idx))
    vals_a = cell_values_at(model, sd.grid, sd.walls, np.ones(n), np.array([x0]), np.array([y0]))[0]
    if vals_a == 0:
        raise ParameterError(f"the start ({x0:g}, {y0:g}) lies outside the grid (beyond a wall or above h_max)")
    for j in _stencil(model, sd, x0, y0):
        e = np.zeros(n)
        e[j] = 1.0
        c = cell_values_at(model, sd.grid, sd.walls, e, np.array([x0]), np.array([y0]))[0]
        if c != 0 and pos[j] >= 0:
            w[pos[j]] += c
    return w


def _stencil(model, sd, x0, y0):
    """The cells whose values the interpolant at (x0, y0) reads (its own and the neighbour ring's)."""
    g = sd.grid
    G = float(model.potential(np.array([x0]))[0])
    H = 0.5 * y0 * y0 + G
    u = np.sign(x0) * np.sqrt(2.0 * max(G, 0.0))
    psi = np.arctan2(y0, u)
    psi = psi + 2 * np.pi if psi < -0.5 * np.pi else psi
    k = int(g.locate(np.array([H]), np.array([psi]))[0])
    if k < 0:
        return []
    ring = g.ring[k]
    out = [k]
    for other in (ring - 1, ring + 1, 1):
        if 0 <= other < g.n_rings:
            k2 = int(g.locate(np.array([g.H_c[other]]), np.array([psi]))[0])
            if k2 >= 0:
                out.append(k2)
    return sorted(set(out))


def _fpk_once(model, domain, start, grid, h_max, walls, restitution, times, want_survival, want_rate):
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    n_e, n_p = grid
    h_grid = aligned_h_max(domain.energy_level, n_e) if domain.energy_level is not None else h_max
    sd = solve_phase_plane(model, grid, h_grid, walls, restitution, points=3)
    t1 = time.perf_counter()
    disc = sd.discretisation
    safe = _safe_cells(domain, sd)
    if safe.all():
        raise ParameterError(f"the domain {domain.text!r} holds the whole grid (H <= {h_grid:g}): no exit to "
                             "reach; raise h_max above the domain or give a bounded domain")
    if not safe.any():
        raise ParameterError(f"the domain {domain.text!r} holds no cell of the grid: refine the grid")
    idx = np.flatnonzero(safe)
    A = disc.A
    K = A[idx][:, idx].T.tocsc()
    back = BackwardProblem(K, disc.mass_weight[idx])
    w = _start_weights(sd, safe, start, domain, model, walls, restitution, h_max)
    T = back.mean_time()
    mean = float(w @ T)
    out = {"mean_time": mean, "cells": int(sd.grid.n), "safe_cells": int(len(idx)), "h_grid": float(h_grid)}
    if want_survival:
        out["R"], out["density"] = back.survival(times, w)
    if want_rate:
        out["decay_rate"] = back.decay_rate()
    out["seconds"] = time.perf_counter() - t0
    out["cpu_seconds"] = time.process_time() - cpu0
    out["assemble_seconds"] = t1 - t0
    out["_sd"], out["_safe"] = sd, safe
    return out


def _estimate_orders(order, domain):
    """(rings, angles) convergence orders of the mean time for the error estimate.

    Measured on Example 1 from rest (H_c = 0.25 ... 2): first order in the rings (the impact map at hard impacts;
    clean from 120 to 1920 rings at H_c = 2), about 2.6 in the angles where the level is a ring (energy domains);
    a domain that cuts the angles is placed to within half a cell, first order in both.
    """
    if order is None:
        return (1.0, 2.0) if domain.energy_level is not None else (1.0, 1.0)
    if np.ndim(order) == 0:
        return float(order), float(order)
    p_rings, p_angles = (float(v) for v in order)
    return p_rings, p_angles


def first_passage_fpk(model, domain, start=(0.0, 0.0), *, grid=PASSAGE_GRID, h_max: float = 4.0, walls="model",
                      restitution=None, t_max: float | None = None, steps: int = DEFAULT_STEPS, check: bool = True,
                      survival: bool = True, order: float | None = None, tol: float = 0.01) -> FirstPassage:
    """First passage out of ``domain`` from ``start``, from the phase-plane generator (method ``fpk``).

    Parameters
    ----------
    model : ImpactOscillator
    domain : str or Domain
        The safe domain, one inequality in x, y and H (``"H < 2.0"``, ``"abs(x) <= 0.8"``).
    start : (x, y) or 'stationary'
        Start state, or the stationary density restricted to the domain.
    grid : (int, int)
        (rings, angles per ring).
    h_max : float
        Top of the grid for domains not of the form H < H_c (reflecting there: choose it above the domain's reach).
    walls, restitution
        As in :func:`averaging.phase_plane.solve_phase_plane`.
    t_max : float, optional
        End of R(t) (default: 5 mean times, where R is about exp(-5)).
    steps : int
        Time steps of R(t) (BDF2).
    check : bool
        Also solve with half the rings and with half the angles and estimate the error of the mean time as the
        sum of the two Richardson terms (orders ``order``); warn with :class:`PassageWarning` when it exceeds
        ``tol`` relative. Costs about one more solve on the grid.
    survival : bool
        Compute R(t), f(t) and the decay rate (the mean time alone is one sparse solve).
    order : float or (float, float), optional
        Convergence orders in the rings and in the angles for the estimate (default (1, 2) for a domain H < H_c,
        (1, 1) otherwise; measured on Example 1 from rest, see :func:`_estimate_orders`).

    Returns
    -------
    FirstPassage

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=None)
    >>> r = first_passage_fpk(lin, "H < 0.5", grid=(40, 48), check=False, survival=False)
    >>> 5 < r.mean_time < 15
    True
    """
    model.require_autonomous()
    if not isinstance(domain, Domain):
        domain = Domain(domain, model)
    try:
        n_e, n_p = (int(v) for v in grid)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"grid={grid!r} must be a pair (rings, angles) of integers") from exc
    if int(steps) != steps or steps < 10:
        raise ParameterError(f"steps={steps!r} must be an integer >= 10")
    if t_max is not None and not (np.isfinite(t_max) and t_max > 0):
        raise ParameterError(f"t_max={t_max!r} must be a finite positive time")
    if not (np.isfinite(h_max) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    if not isinstance(start, str):
        try:
            start = tuple(float(v) for v in start)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"start={start!r} must be a state (x, y) or 'stationary'") from exc
        if len(start) != 2 or not all(np.isfinite(start)):
            raise ParameterError(f"start={start!r} must be a finite state (x, y)")
        if not domain.contains(*start):
            raise ParameterError(f"the start (x, y) = ({start[0]:g}, {start[1]:g}) lies outside the domain "
                                 f"{domain.text!r}")
    first = _fpk_once(model, domain, start, (n_e, n_p), h_max, walls, restitution, None, False, False)
    mean = first["mean_time"]
    if not (np.isfinite(mean) and mean > 0):
        raise ParameterError(f"no finite mean first-passage time out of {domain.text!r} (the domain is never left "
                             "within the grid: check the domain and h_max)")
    details = {k: v for k, v in first.items() if not k.startswith("_") and k != "mean_time"}
    details["grid"] = [n_e, n_p]
    t = R = f = np.array([])
    rate = float("nan")
    poisson = None
    if survival:
        t_end = 5.0 * mean if t_max is None else float(t_max)
        t = np.linspace(0.0, t_end, int(steps) + 1)
        sd, safe = first["_sd"], first["_safe"]
        idx = np.flatnonzero(safe)
        back = BackwardProblem(sd.discretisation.A[idx][:, idx].T.tocsc(), sd.discretisation.mass_weight[idx])
        w = _start_weights(sd, safe, start, domain, model, walls, restitution, h_max)
        t0 = time.perf_counter()
        R, f = back.survival(t, w)
        rate = back.decay_rate()
        details["survival_seconds"] = time.perf_counter() - t0
        nu = out_crossing_rate(sd, domain) if domain.energy_level is None else None
        if nu is not None:
            details["out_crossing_rate"] = nu
            poisson = np.exp(-nu * t)
    if first["_sd"].impact_rates and domain.energy_level is None:  # the grid then holds the stationary problem
        details["stationary_impact_rate"] = first["_sd"].impact_rate
    est = None
    if check:
        p_rings, p_angles = _estimate_orders(order, domain)
        coarse_rings = _fpk_once(model, domain, start, (max(8, n_e // 2), n_p), h_max, walls, restitution, None,
                                 False, False)["mean_time"]
        coarse_angles = _fpk_once(model, domain, start, (n_e, max(16, n_p // 2)), h_max, walls, restitution, None,
                                  False, False)["mean_time"]
        # the two directions separately: their errors differ in order and can cancel on a grid coarsened in both
        est = abs(mean - coarse_rings) / (2.0**p_rings - 1.0) + abs(mean - coarse_angles) / (2.0**p_angles - 1.0)
        details["mean_time_coarse_rings"] = coarse_rings
        details["mean_time_coarse_angles"] = coarse_angles
        details["order"] = [p_rings, p_angles]
        if est > tol * mean:
            warnings.warn(f"grid {n_e} x {n_p}: estimated error of the mean first-passage time {est:.3g} is "
                          f"{est / mean:.2%} > tol={tol:g}; refine the grid", PassageWarning, stacklevel=2)
    out = FirstPassage("fpk", domain.text, start, mean, t, R, f, rate, est, details, poisson)
    out.phase_density = first["_sd"]
    return out
