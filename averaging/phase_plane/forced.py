r"""Periodic stationary density of a harmonically forced impact oscillator (method ``fpk``, forced models).

A model with a periodic forcing F(t) (period T) has no stationary density; its statistics are periodic: the
density p(x, y, t) of the state at time t of the forcing period tends to a periodic p(x, y, t + T) = p(x, y, t).

Method, and why
---------------
The density obeys M dp/dt = -A(t) p with A(t) the operator of :mod:`averaging.phase_plane` (its drift m(x, y)
plus F(t)) on the same energy-angle cells: the impact boundary stays exact and every flux leaves one cell and enters
another, so each A(t) conserves probability. Only the drift-dependent fluxes are re-assembled at each time
(:meth:`~averaging.phase_plane._core.Discretisation.operator_with_drift`). The periodic density is the fixed point
of the period map P, the product of K implicit steps over one period (dt = T/K): Crank-Nicolson by default,

    (M/dt + A(t_{k+1})/2) p_{k+1} = (M/dt - A(t_k)/2) p_k,

second order with a small error constant, or BDF2 (``scheme="bdf2"``: L-stable, so no undamped stiff modes, but an
8 times larger error constant: L1 0.034 against 0.024 for CN on example 08 at the default grid). Both conserve the
probability exactly (the columns of every A sum to zero). The fixed point p = P p with w.p = 1 (w the cell areas)
is found by GMRES on (I - P + p0 w^T) p = p0, started at the unforced density p0: the rank-one term removes the
eigenvalue 1 of P without changing the fixed point, and the other eigenvalues of P (the decay of a transient over
one period, exp(-c T) for the slowest) keep I - P well conditioned: GMRES needs 10-16 period maps.

Why not the alternatives: a space-time grid with periodic phase couples all K time levels in one system K times
larger than the plane's (a direct solve does not fit, and its solution is the same fixed point); Fourier modes in
the phase (harmonic balance) need many harmonics for the sharp, phase-dependent densities of an impacting orbit,
and their coupling makes the blocks dense. The period map needs one sparse LU per distinct step matrix, factored
once and reused by every GMRES iteration; a forcing A cos(Omega t + phi) takes each value twice per period, so
about K/2 factors are computed (the matrices are keyed by the drift they hold).

Accuracy (``benchmarks/fpk_forced.py``, docs/results/fpk-forced.md): the grid was designed for densities that are
uniform along the free orbits, where the convection along the rings costs nothing; a forced density is a blob that
moves around the rings, and its along-ring discretisation error dominates. On example 08 (D = 0.02) the L1 of
p(H | t) against Monte Carlo is 0.024 at the default grid and 64 steps (8 s CPU, 0.8 GB) and 0.014 at (160, 192)
(24 s, 1.9 GB), second order in the grid; ``extrapolate=True`` combines the grid with the grid twice coarser
(Richardson): 0.009 at the default grid (12 s). The linear oscillator's section moments are within 1.3e-2 (mean)
and 8e-3 (variance) at (160, 192).

Outputs (:class:`PeriodicDensity`): the density at any time of the period (``section(t)``, a
:class:`~averaging.phase_plane.PhaseDensity` with p(H | t), p(x, y | t), marginals and impacts; between the K
stored steps a periodic cubic spline in time), the time average (``mean``), E[H](t) and the impact rate at each
time. Times are those of ``vibro mc --phases N``: t = k T / N, the forcing evaluated at t from t = 0.

Examples
--------
>>> from models import ForcedDuffingImpact, Newton
>>> pd_ = periodic_density_xy(ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=0.02),
...                           grid=(40, 48), steps=16, h_max=4.0)
>>> len(pd_.times), round(float(pd_.mean.bin_masses([0.0, 4.0])[0]), 9)
(16, 1.0)
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
import sympy as sp

from hybrid.automaton import lambdify_numeric
from hybrid.errors import ModelError, NormalisationError, ParameterError
from hybrid.sizes import check_size
from models import X, Y
from models.oscillator import _CACHED, T

from ..stationary import check_energy_range
from ._core import Discretisation
from ._grid import RingGrid
from .solver import DEFAULT_STRETCH, GridWarning, PhaseDensity, _coefficients, _walls, grid_pair

FORCED_GRID = (120, 128)
"""Default (rings, angles) of the forced solver (``benchmarks/fpk_forced.py``, example 08's forced Duffing impact
model at 16 phases: L1 of p(H | t) against Monte Carlo 0.024 at D = 0.02 and 0.009 at D = 0.05, in 8-11 s CPU and
0.8 GB; 0.009 and 0.005 with ``extrapolate=True``)."""
PHASE_ORDER = 3
"""Order of the convection along the rings (3: upwind-biased kappa = 1/3, as the autonomous solver)."""
DEFAULT_STEPS = 64
"""Default Crank-Nicolson steps per forcing period (rounded up to a multiple of the phases asked for)."""
BYTES_PER_CELL_FACTOR = 1800
"""Peak memory per grid cell (rings x angles) and stored LU factor (measured 1.7 kB at (160, 192), 33 factors)."""
SECONDS_PER_CELL_FACTOR = 3e-5
"""CPU time per grid cell and factor, solve included (measured 2.8e-5 s at (160, 192), 64 steps), for the estimate
in the refusal."""


class PeriodicDensity:
    """The periodic density of a forced model over one forcing period, and what follows from it.

    Built by :func:`periodic_density_xy`.

    Attributes
    ----------
    method : str
        ``"fpk"``.
    period : float
        The forcing period T.
    times : ndarray
        The K step times k T / K in [0, T) at which the cell densities are stored.
    cell_p : ndarray (K, cells)
        The density p(x, y) at the cell centres at each stored time.
    mean : PhaseDensity
        The time average over the period (p(H), p(x, y), E[H], the mean impact rate): ``mean.H``, ``mean.p``.
    mean_energy_t, impact_rate_t : ndarray (K,)
        E[H] and the impact rate (impacts per unit time, both walls) at each stored time.
    mean_energy, impact_rate : float
        Their time averages.
    periodicity : float
        max |P p - p| / max |p| of the fixed point (round-off to the GMRES tolerance).
    conservation : float
        max |1 - total probability| over the stored times.
    iterations : int
        Period maps applied by GMRES.
    factors : int
        Distinct step matrices factored.
    timing : dict
        Seconds spent assembling, factoring, solving and marching.
    """

    method = "fpk"

    def __init__(self, model, grid, disc, times, period, snapshots, operators, points, h_max):
        self.model = model
        self.grid = grid
        self._disc = disc
        self.period = float(period)
        self.times = np.asarray(times, dtype=float)
        self.cell_p = np.asarray(snapshots)
        self._operators = operators  # A(t_k), for the sections' residual and conservation
        self.h_max = float(h_max)
        self._points = int(points)
        self.timing = {}
        closed = np.vstack([self.cell_p, self.cell_p[:1]])
        from scipy.interpolate import CubicSpline  # here only: scipy.interpolate imports scipy.optimize

        self._spline = CubicSpline(np.append(self.times, self.period), closed, axis=0, bc_type="periodic")
        w = disc.mass_weight
        self.conservation = float(np.max(np.abs(self.cell_p @ w - 1.0)))
        self.mean = self._section(self.cell_p.mean(axis=0), None)
        self.mean_energy_t = self.cell_p @ (w * disc.cell_H)
        self.impact_rate_t = np.zeros(len(self.times))
        for _side, (rings, cin, _cout, _W) in disc.walls.items():
            self.impact_rate_t += self.cell_p[:, cin] @ grid.dH[rings]
        self.mean_energy = float(self.mean_energy_t.mean())
        self.impact_rate = float(self.impact_rate_t.mean())
        self.periodicity = np.nan
        self.iterations = 0
        self.factors = 0

    # ------------------------------------------------------------------ sections
    def _section(self, p, k):
        A = self._operators[k] if k is not None else self._disc.A
        sd = PhaseDensity(self.model, self.grid, _Shim(self._disc, A), p, self.timing if k is None else {},
                          self._disc.walls_at)
        sd.residual = np.nan  # a section is not stationary: its A p is the rate of change, not a residual
        sd.h_max = self.h_max
        sd.H = np.linspace(0.0, self.h_max, self._points)
        sd.p = sd.density(sd.H)
        return sd

    def cells_at(self, t):
        """The cell densities at time ``t`` (mod T): the stored step, or a periodic cubic spline between steps.

        Examples
        --------
        >>> from models import ForcedDuffingImpact
        >>> pd_ = periodic_density_xy(ForcedDuffingImpact(), grid=(40, 48), steps=16)
        >>> pd_.cells_at(pd_.period).shape == pd_.cell_p[0].shape
        True
        """
        t = float(t) % self.period
        k = np.flatnonzero(np.isclose(self.times, t, rtol=0, atol=1e-9 * self.period))
        if k.size:
            return self.cell_p[k[0]]
        return self._spline(t)

    def section(self, t) -> PhaseDensity:
        """The density at time ``t`` of the period (mod T) as a :class:`PhaseDensity`: p(H | t) (``H``, ``p``,
        ``density``, ``bin_masses``), p(x, y | t) (``joint``), marginals, E[H | t] and the impact rate at t.

        Examples
        --------
        >>> from models import ForcedDuffingImpact
        >>> pd_ = periodic_density_xy(ForcedDuffingImpact(), grid=(40, 48), steps=16)
        >>> round(float(pd_.section(0.3 * pd_.period).bin_masses([0.0, 4.0])[0]), 6)
        1.0
        """
        t = float(t) % self.period
        k = np.flatnonzero(np.isclose(self.times, t, rtol=0, atol=1e-9 * self.period))
        return self._section(self.cells_at(t), int(k[0]) if k.size else None)

    def phase_times(self, phases: int) -> np.ndarray:
        """The times k T / phases, k = 0 .. phases - 1 (the sections of ``vibro mc --phases``)."""
        phases = _count("phases", phases)
        return self.period * np.arange(phases) / phases

    def sections(self, phases: int) -> list[PhaseDensity]:
        """The densities at the times k T / ``phases`` (:meth:`phase_times`)."""
        return [self.section(t) for t in self.phase_times(phases)]

    def mean_energy_at(self, t):
        """E[H | t] at times ``t`` (mod T)."""
        t = np.atleast_1d(np.asarray(t, dtype=float)) % self.period
        w = self._disc.mass_weight * self._disc.cell_H
        return np.array([float(self.cells_at(s) @ w) for s in t])

    def impact_rate_at(self, t):
        """The impact rate (impacts per unit time, both walls) at times ``t`` (mod T)."""
        t = np.atleast_1d(np.asarray(t, dtype=float)) % self.period
        out = np.zeros(len(t))
        for _side, (rings, cin, _cout, _W) in self._disc.walls.items():
            out += np.array([self.cells_at(s)[cin] @ self.grid.dH[rings] for s in t])
        return out

    # ------------------------------------------------------------------ output
    def phase_histograms(self, phases: int, edges) -> np.ndarray:
        """(phases, bins) array of p(H | t_k) averaged over the energy bins ``edges`` (exact ring masses)."""
        edges = np.asarray(edges, dtype=float)
        return np.array([s.bin_masses(edges) / np.diff(edges) for s in self.sections(phases)])

    def phase_to_pandas(self, phases: int, bins: dict):
        """Long-form table of the phase-resolved densities, in the columns of ``vibro mc --phases``.

        ``bins`` maps ``"H"``, ``"x"``, ``"y"`` to (lo, hi, count); each row is one bin at one phase: observable,
        phase, t_phase, lo, hi, density (the bin average; H from the exact ring masses, x and y from the marginals
        at 8 points per bin).
        """
        import pandas as pd

        frames = []
        for k, (tk, sd) in enumerate(zip(self.phase_times(phases), self.sections(phases))):
            for name, (lo, hi, n) in bins.items():
                e = np.linspace(lo, hi, int(n) + 1)
                if name == "H":
                    d = sd.bin_masses(e) / np.diff(e)
                else:
                    fine = np.linspace(lo, hi, 8 * int(n) + 1)
                    mid = 0.5 * (fine[1:] + fine[:-1])
                    f = sd.marginal_x(mid) if name == "x" else sd.marginal_y(mid)
                    d = f.reshape(int(n), 8).mean(axis=1)
                frames.append(pd.DataFrame({"observable": name, "phase": k, "t_phase": tk, "lo": e[:-1], "hi": e[1:],
                                            "density": d}))
        return pd.concat(frames, ignore_index=True)

    def metadata(self) -> dict:
        """Method, model, grid, period and summary statistics (JSON-friendly)."""
        return {**self.mean.metadata(), "period": self.period, "steps": len(self.times),
                "mean_energy": self.mean_energy, "impact_rate": self.impact_rate, "periodicity": self.periodicity,
                "conservation": self.conservation, "gmres_iterations": self.iterations, "factors": self.factors}

    def __repr__(self) -> str:
        return (f"PeriodicDensity(model={self.model.name!r}, method='fpk', cells={self.grid.n}, "
                f"steps={len(self.times)}, period={self.period:.6g}, E[H]={self.mean_energy:.6g}, "
                f"impact_rate={self.impact_rate:.6g})")


class _Shim:
    """What :class:`PhaseDensity` reads from a discretisation, with another operator (a section's A(t))."""

    def __init__(self, disc, A):
        self.A = A
        self.cell = disc.cell
        self.mass_weight = disc.mass_weight
        self.walls = disc.walls


class ExtrapolatedSection:
    """Richardson extrapolation (4 fine - coarse) / 3 of two :class:`PhaseDensity` on grids a factor 2 apart.

    The phase-plane solver converges at second order in the grid, so the combination removes the leading error of
    every linear functional: p(H) and its bin masses, the marginals, p(x, y), E[H], E[x**2], the impact rate. The
    combination may dip slightly below 0 where the density is near 0 (it keeps the total probability exactly).
    """

    method = "fpk"

    def __init__(self, fine: PhaseDensity, coarse: PhaseDensity):
        self.fine, self.coarse = fine, coarse
        self.model, self.grid, self.walls = fine.model, fine.grid, fine.walls
        self.h_max, self.h_support = fine.h_max, max(fine.h_support, coarse.h_support)
        for name in ("mean_energy", "mean_x2", "mean_y2", "prob_below_barrier", "impact_rate"):
            setattr(self, name, self._combine(getattr(fine, name), getattr(coarse, name)))
        self.impact_rates = {k: self._combine(v, coarse.impact_rates[k]) for k, v in fine.impact_rates.items()}
        self.H = fine.H
        self.p = self.density(self.H)
        self.error_estimate = None

    @staticmethod
    def _combine(fine, coarse):
        return (4.0 * np.asarray(fine) - np.asarray(coarse)) / 3.0

    def density(self, H):
        """p(H) at the energies ``H``."""
        return self._combine(self.fine.density(H), self.coarse.density(H))

    def bin_masses(self, edges):
        """Probability of each energy bin [edges[k], edges[k+1]]."""
        return self._combine(self.fine.bin_masses(edges), self.coarse.bin_masses(edges))

    def joint(self, x, y):
        """p(x, y) on the grid x by y -> array (ny, nx)."""
        return self._combine(self.fine.joint(x, y), self.coarse.joint(x, y))

    def marginal_x(self, x, points: int = 801):
        """p(x)."""
        return self._combine(self.fine.marginal_x(x, points), self.coarse.marginal_x(x, points))

    def marginal_y(self, y, points: int = 801):
        """p(y)."""
        return self._combine(self.fine.marginal_y(y, points), self.coarse.marginal_y(y, points))

    def metadata(self) -> dict:
        """The fine grid's metadata with the extrapolated statistics."""
        return {**self.fine.metadata(), "mean_energy": float(self.mean_energy), "mean_x2": float(self.mean_x2),
                "prob_below_barrier": float(self.prob_below_barrier), "impact_rate": float(self.impact_rate),
                "extrapolated_from": [self.fine.metadata()["grid"], self.coarse.metadata()["grid"]]}


class ExtrapolatedPeriodicDensity(PeriodicDensity):
    """:class:`PeriodicDensity` of two solves on grids a factor 2 apart, combined by Richardson extrapolation.

    Built by :func:`periodic_density_xy` with ``extrapolate=True``. Its sections (:meth:`section`) and ``mean`` are
    :class:`ExtrapolatedSection`; ``fine`` and ``coarse`` are the two solves. On example 08 the L1 of p(H | t)
    against Monte Carlo falls from 0.024 to 0.009 (D = 0.02) and from 0.009 to 0.005 (D = 0.05) at the default grid,
    for 1.3 times the time (docs/results/fpk-forced.md).
    """

    def __init__(self, fine: PeriodicDensity, coarse: PeriodicDensity):
        self.fine, self.coarse = fine, coarse
        self.model, self.grid, self.period, self.times = fine.model, fine.grid, fine.period, fine.times
        self.h_max = fine.h_max
        self.mean = ExtrapolatedSection(fine.mean, coarse.mean)
        self.mean_energy_t = ExtrapolatedSection._combine(fine.mean_energy_t, coarse.mean_energy_t)
        self.impact_rate_t = ExtrapolatedSection._combine(fine.impact_rate_t, coarse.impact_rate_t)
        self.mean_energy = float(self.mean_energy_t.mean())
        self.impact_rate = float(self.impact_rate_t.mean())
        self.periodicity = max(fine.periodicity, coarse.periodicity)
        self.conservation = max(fine.conservation, coarse.conservation)
        self.iterations = fine.iterations + coarse.iterations
        self.factors = fine.factors + coarse.factors
        self.timing = {k: fine.timing[k] + coarse.timing[k] for k in fine.timing}

    def cells_at(self, t):
        raise ParameterError("an extrapolated density has no cells of its own: use .fine.cells_at or .section(t)")

    def section(self, t) -> ExtrapolatedSection:
        """The extrapolated density at time ``t`` of the period (mod T)."""
        return ExtrapolatedSection(self.fine.section(t), self.coarse.section(t))

    def mean_energy_at(self, t):
        """E[H | t] at times ``t`` (mod T)."""
        return ExtrapolatedSection._combine(self.fine.mean_energy_at(t), self.coarse.mean_energy_at(t))

    def impact_rate_at(self, t):
        """The impact rate at times ``t`` (mod T)."""
        return ExtrapolatedSection._combine(self.fine.impact_rate_at(t), self.coarse.impact_rate_at(t))

    def __repr__(self) -> str:
        return "Extrapolated" + super().__repr__()


def _count(name, value) -> int:
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ParameterError(f"{name}={value!r} must be a whole number >= 1")
    return int(value)


def unforced(model):
    """``model`` without its forcing F (the same g, h, noise, walls and restitution): the autonomous part.

    Examples
    --------
    >>> from models import ForcedDuffingImpact
    >>> unforced(ForcedDuffingImpact()).is_forced
    False
    """
    twin = object.__new__(type(model))
    twin.__dict__.update({k: v for k, v in model.__dict__.items() if k not in _CACHED})
    twin.forcing = sp.Integer(0)
    return twin


def periodic_density_xy(model, grid=FORCED_GRID, h_max: float = 4.0, *, steps: int = DEFAULT_STEPS,
                        phases: int | None = None, walls="model", restitution=None, points: int = 2000,
                        tol: float = 1e-10, max_iterations: int = 300,
                        scheme: str = "cn", extrapolate: bool = False) -> PeriodicDensity:
    """Periodic density p(x, y, t) of a periodically forced ``model`` with impact boundary conditions.

    Parameters
    ----------
    model : ImpactOscillator
        A forced model (``forcing="A*cos(Omega*t + phi)"``, any periodic F(t, x, y) with a period): single-well g,
        any h, f_k / D_kl and restitution law.
    grid : (int, int)
        Rings in H and angle cells per ring (as :func:`~averaging.phase_plane.stationary_density_xy`).
    h_max : float
        Upper energy (reflecting): choose it in the tail of every section.
    steps : int
        Time steps per period (second order in T / steps).
    phases : int, optional
        Make ``steps`` a multiple of ``phases`` so that the sections k T / phases are stored steps.
    walls, restitution, points
        As :func:`~averaging.phase_plane.solve_phase_plane` (``points``: energies of each section's p(H)).
    tol : float
        Relative residual of GMRES for the fixed point of the period map.
    max_iterations : int
        Most period maps GMRES may apply.
    scheme : {'cn', 'bdf2'}
        Crank-Nicolson (default, the smaller error) or BDF2 (L-stable: no undamped stiff modes).
    extrapolate : bool
        Also solve on the grid twice coarser and combine the two (Richardson, second order): an
        :class:`ExtrapolatedPeriodicDensity`, about 2.5 times more accurate for 1.3 times the time.

    Returns
    -------
    PeriodicDensity or ExtrapolatedPeriodicDensity

    Raises
    ------
    ModelError
        When the model is not forced, its forcing has no period, or its potential is not a single well.
    NormalisationError
        When GMRES does not find the periodic density (no confinement, or a singular period map).

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", forcing="A*cos(W*t)", barriers=None,
    ...                        parameters={"c": 0.5, "A": 0.4, "W": 1.3, "D": 0.05})
    >>> pd_ = periodic_density_xy(lin, grid=(60, 64), steps=32, h_max=3.0)
    >>> exact = 0.05 / 0.5 + 0.25 * 0.4**2 * (1 + 1.3**2) / abs(1 - 1.3**2 + 0.65j)**2  # D/c + |response|^2 / 2
    >>> round(pd_.mean_energy, 3), round(exact, 3)
    (0.214, 0.22)
    """
    if not getattr(model, "is_forced", False):
        raise ModelError(f"model {model.name!r} has no forcing: use stationary_density_xy for its stationary density")
    period = model.forcing_period
    if period is None:
        raise ModelError(f"the forcing F = {model.forcing} has no period (harmonic terms with commensurate "
                         "frequencies); the periodic density needs one")
    free = unforced(model)
    try:
        free.check_single_well()
    except ModelError as exc:
        raise ModelError(f"no periodic density by fpk: {exc}") from exc
    if not (np.isfinite(h_max) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    n_e, n_p = grid_pair(grid, "rings, angles", (8, 16))
    steps = _count("steps", steps)
    if phases is not None:
        phases = _count("phases", phases)
        steps = phases * -(-steps // phases)
    if steps < 4:
        raise ParameterError(f"steps={steps} must be at least 4 per period")
    if int(points) != points or points < 3:
        raise ParameterError(f"points={points!r} must be an integer >= 3")
    if scheme not in ("bdf2", "cn"):
        raise ParameterError(f"scheme={scheme!r}: use 'bdf2' (L-stable) or 'cn' (Crank-Nicolson)")
    cells = float(n_e) * float(n_p)
    factors = steps // 2 + 1
    check_size(f"the forced phase-plane solve on {n_e} x {n_p} cells and {steps} steps",
               memory=cells * BYTES_PER_CELL_FACTOR * factors,
               detail=f"{factors} LU factors of {cells:.3g} cells x {BYTES_PER_CELL_FACTOR} bytes, about "
                      f"{cells * factors * SECONDS_PER_CELL_FACTOR:.3g} s",
               fix=f"use a coarser grid or fewer steps (the defaults are {FORCED_GRID} and {DEFAULT_STEPS})")

    check_energy_range(free, float(h_max), walls)
    from .solver import _first_range

    def solve_on(h):
        t0 = time.perf_counter()
        law = restitution if restitution is not None else model.restitution
        left, right = _walls(model, walls)
        wall_H = {}
        if right is not None:
            wall_H["right"] = float(model.potential(np.array([right]))[0])
        if left is not None:
            wall_H["left"] = float(model.potential(np.array([left]))[0])
        g = RingGrid(float(h), n_e, n_p, wall_H, DEFAULT_STRETCH)
        disc = Discretisation(g, _coefficients(free, law), law.coefficient, 2, PHASE_ORDER)
        disc.cell_H = g.H_c[g.ring]
        disc.walls_at = (left, right)
        drift = lambdify_numeric((X, Y, T), model.substitute(model.ito_drift + model.g))
        (xr, yr), (xa, ya) = disc.drift_points()
        dt = period / steps
        times = dt * np.arange(steps)
        M = sps.diags(disc.mass_weight / dt)
        operators, drifts = [], []
        for t in times:
            with np.errstate(all="ignore"):
                mr = np.broadcast_to(np.asarray(drift(xr, yr, t), dtype=float), xr.shape)
                ma = np.broadcast_to(np.asarray(drift(xa, ya, t), dtype=float), xa.shape)
            if not (np.all(np.isfinite(mr)) and np.all(np.isfinite(ma))):
                raise ModelError(f"the drift with the forcing F = {model.forcing} is not finite at t = {t:.6g}")
            operators.append(disc.operator_with_drift(mr, ma))
            drifts.append(np.concatenate([mr, ma]))
        t1 = time.perf_counter()
        # implicit steps: BDF2 (3/2 M + A(t_{k+1})) p_{k+1} = M (2 p_k - p_{k-1} / 2), or Crank-Nicolson
        # (M + A(t_{k+1}) / 2) p_{k+1} = (M - A(t_k) / 2) p_k; one LU per distinct drift (a harmonic forcing takes each
        # value twice a period)
        bdf2 = scheme == "bdf2"
        mass_coef, op_coef = (1.5, 1.0) if bdf2 else (1.0, 0.5)
        scale = max(float(np.max(np.abs(d))) for d in drifts)
        distinct, lus, step_lu = [], [], []
        for k in range(steps):
            d = drifts[(k + 1) % steps]
            same = next((i for i, e in enumerate(distinct) if np.allclose(d, e, rtol=1e-12, atol=1e-12 * scale)), None)
            if same is None:
                distinct.append(d)
                lus.append(_factor((mass_coef * M + op_coef * operators[(k + 1) % steps]).tocsc()))
                same = len(lus) - 1
            step_lu.append(lus[same])
        explicit = None if bdf2 else [(M - 0.5 * A).tocsr() for A in operators]
        t2 = time.perf_counter()
        w = disc.mass_weight
        n = g.n

        def march(before, now, count):
            """``count`` steps from (p_{-1}, p_0) = (before, now) (CN ignores p_{-1}); yields every new density."""
            for k in range(count):
                rhs = M @ (2.0 * now - 0.5 * before) if bdf2 else explicit[k] @ now
                before, now = now, step_lu[k].solve(rhs)
                yield now

        p0 = disc.solve()  # the unforced density: the start, and the vector of the rank-one term
        p0 = p0 / (w @ p0)
        rho0 = np.bincount(g.ring, p0 * w, g.n_rings) / g.dH
        if h >= h_max and rho0[-1] > 0.2 * rho0.max():  # not even the unforced density fits: refuse before GMRES
            raise NormalisationError(f"p(H) does not decay towards h_max={h_max:g} even without the forcing: raise "
                                     "h_max or add dissipation")
        size = 2 * n if bdf2 else n
        start = np.concatenate([p0, p0]) if bdf2 else p0
        maps = [0]

        def apply(z):
            # z - P z + start I(z): I is the probability the steps keep (BDF2: (3 m_k - m_{k-1}) / 2, CN: m_k; 1 at the
            # fixed point); the rank-one term removes P's eigenvalue 1 without moving the fixed point
            maps[0] += 1
            before, now = (z[:n], z[n:]) if bdf2 else (z, z)
            *_, last, end = march(before, now, steps)
            kept = 0.5 * (3.0 * (w @ now) - w @ before) if bdf2 else w @ now
            return z - (np.concatenate([last, end]) if bdf2 else end) + start * kept

        op = spla.LinearOperator((size, size), matvec=apply, dtype=float)
        z, info = spla.gmres(op, start, x0=start, rtol=tol, atol=0.0, restart=min(max_iterations, 100),
                             maxiter=max(1, max_iterations // 100 + 1))
        if info != 0 or not np.all(np.isfinite(z)):
            raise NormalisationError(f"GMRES did not find the periodic density in {maps[0]} period maps (info {info}): "
                                     "the forcing may drive the energy without bound, or h_max is far too small")
        before, p = (z[:n], z[n:]) if bdf2 else (z, z)
        snapshots = [p, *march(before, p, steps)]
        back = snapshots.pop()
        t3 = time.perf_counter()
        out = PeriodicDensity(model, g, disc, times, period, snapshots, operators, points, h_max)
        out.periodicity = float(np.max(np.abs(back - p)) / np.max(np.abs(p)))
        out.iterations = maps[0]
        out.factors = len(lus)
        out.timing = {"assemble": t1 - t0, "factor": t2 - t1, "solve": t3 - t2}
        return out

    # the rings on the energies the unforced density reaches (e**-40 below its peak), doubled for the forcing's
    # energy, so that a large h_max does not put the mass into the first few rings; widened while mass reaches the top
    h = min(float(h_max), 2.0 * _first_range(free, float(h_max)))
    out = solve_on(h)

    def top_mass(sol):
        return float(sol.mean.ring_mass[sol.grid.H_c > 0.9 * sol.grid.h_max].sum())

    for _ in range(4):
        if top_mass(out) <= 1e-4 or h >= h_max:
            break
        h = min(float(h_max), 4.0 * h)
        out = solve_on(h)
    rho = out.mean.ring_mass / out.grid.dH
    if h >= h_max and rho[-1] > 0.2 * rho.max():
        raise NormalisationError(f"p(H) does not decay towards h_max={h_max:g}: raise h_max or add dissipation")
    tail = top_mass(out)
    if tail > 1e-4:
        warnings.warn(f"{tail:.2g} of the time-averaged probability lies in the top 10% of [0, h_max={h_max:g}]: "
                      "raise h_max", GridWarning, stacklevel=2)
    if extrapolate:
        n_e, n_p = max(8, n_e // 2), max(16, n_p // 2)
        return ExtrapolatedPeriodicDensity(out, solve_on(h))
    return out


def _factor(A):
    try:
        return spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1)
    except RuntimeError:  # exactly singular with this pivoting
        return spla.splu(A, permc_spec="COLAMD")
