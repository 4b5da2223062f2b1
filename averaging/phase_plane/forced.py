r"""Periodic stationary density of a harmonically forced impact oscillator (method ``fpk``, forced models).

A model with a periodic forcing F(t) (period T) has no stationary density; its statistics are periodic: the
density p(x, y, t) of the state at time t of the forcing period tends to a periodic p(x, y, t + T) = p(x, y, t).

Method, and why
---------------
The density obeys M dp/dt = -A(t) p with A(t) the operator of :mod:`averaging.phase_plane` with the drift m(x, y)
plus F(t): the impact boundary stays exact and every flux leaves one cell and enters another, so each A(t)
conserves probability. Only the drift-dependent fluxes are re-assembled at each time (``operator_with_drift`` of
the discretisation).

Cells. A forced density is a blob that moves across the free orbits at the forcing frequency. The energy-angle rings
of the autonomous solver were designed for densities that are nearly constant along the orbits (their along-ring
error then moves no probability between energies); for the moving blob that error counts, and the rings converged
slowly (L1 0.024 against Monte Carlo on example 08 at (120, 128) cells). The Cartesian (x, y) cells of
:mod:`._cartesian` (fifth-order upwind-biased convection, face averages to fourth order, the wall as a cell face
with the same impact map) resolve the blob to high order: they are the default (``cells="cartesian"``); the rings
remain as ``cells="rings"``. The Cartesian scheme suits moderate noise (D/c of 0.1 and above); at much lower noise
its cross-orbit truncation error grows relative to the noise, and the two-grid estimate says so.

Time. The periodic density is the fixed point of the period map P, the product of K implicit steps over one
period (dt = T/K), Crank-Nicolson

    (M/dt + A(t_{k+1})/2) p_{k+1} = (M/dt - A(t_k)/2) p_k.

Its error has an expansion in even powers of dt, so the default (``scheme="richardson"``) runs K and 2K steps and
combines them as (4 p_2K - p_K) / 3 at the K step times: fourth order (on the linear oscillator the variance error
falls from 7.8e-3 with Crank-Nicolson alone at 64 steps to 4.5e-4 with 32 + 64). ``scheme="cn"`` and ``"bdf2"``
(L-stable, an 8 times larger error constant) are the single runs. Every step conserves probability exactly (the
columns of every A sum to zero). The fixed point p = P p with w.p = 1 (w the cell areas) is found by GMRES on
(I - P + p0 w^T) p = p0, started at the unforced density p0 (the 2K run at the K run's answer): the rank-one term
removes the eigenvalue 1 of P without changing the fixed point, and the other eigenvalues of P (the decay of a
transient over one period, exp(-c T) for the slowest) keep I - P well conditioned: GMRES needs 8-11 period maps
to the default relative residual 1e-6 (10-16 to 1e-10, which changed p(H | t) on example 08 by 4.5e-7 in L1).

Why not the alternatives: a space-time grid with periodic phase couples all K time levels in one system K times
larger than the plane's (a direct solve does not fit, and its solution is the same fixed point); Fourier modes in
the phase (harmonic balance) need many harmonics for the sharp, phase-dependent densities of an impacting orbit,
and their coupling makes the blocks dense. The period map needs one sparse LU per distinct step matrix, factored
once and reused by every GMRES iteration; a forcing A cos(Omega t + phi) takes each value twice per period, so
about K/2 factors are computed per run (the matrices are keyed by the drift they hold); a model unchanged by
(x, y, t) -> (-x, -y, t + T/2) (symmetric walls and potential) halves that again, its step matrix at t + T/2 being
the mirror image of that at t (found by comparing the matrices, solved with the permuted LU).

Error estimate. With ``check`` (default), ``error_estimate`` = ``grid_estimate`` + ``time_estimate`` (L1 of
p(H | t) on 100 bins, worst phase), and a :class:`GridWarning` names the larger part when the sum exceeds ``l1_tol``.
The cells' part: the same problem solved on the grid twice coarser (same steps), the L1 between the two over 3
(order 2, conservative). The time steps' part: on that coarser grid, the same scheme at half the steps, the L1
between the results at K and K/2 over 3 (order 2 assumed for a combination whose observed order is 2.9-3.8: it
bounded the time error by 1.1-6 times on example 08 and the linear oscillator, docs/results/fpk-forced.md); the
cells' error cancels in that difference. ``time_correction`` (the L1 of the cell densities between Crank-Nicolson
alone at 2K steps and the combination) is still reported.

Accuracy (``benchmarks/fpk_forced.py``, docs/results/fpk-forced.md): on example 08 (D = 0.02) the L1 of p(H | t)
against converged Monte Carlo (noise 0.0022) is 0.0028 mean and 0.0045 worst over 16 phases at the default grid
(64, 128) with 64 + 128 steps (estimate 0.0045), in 25-26 s CPU and 1.5 GB (44-48 s and 2.5 GB before
the nested-dissection factors, the looser GMRES tolerance and the mirror images); the linear oscillator's section means
and variances are within 2.3e-6 and 3.5e-5 of the closed form at 64 + 128 steps.

Outputs (:class:`PeriodicDensity`): the density at any time of the period (``section(t)``, a
:class:`~averaging.phase_plane.PhaseDensity` with p(H | t), p(x, y | t), marginals and impacts; between the K
stored steps a periodic cubic spline in time), the time average (``mean``), E[H](t) and the impact rate at each
time. Times are those of ``vibro mc --phases N``: t = k T / N, the forcing evaluated at t from t = 0.

Examples
--------
>>> from models import ForcedDuffingImpact, Newton
>>> pd_ = periodic_density_xy(ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=0.02),
...                           grid=(24, 48), steps=16, h_max=4.0, check=False)
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
from ._cartesian import CartesianDiscretisation, CartesianGrid, confining_range
from ._core import Discretisation, null_vector
from ._grid import RingGrid
from .cartesian import CartesianDensity, moments
from .solver import DEFAULT_STRETCH, GridWarning, PhaseDensity, _coefficients, _walls, grid_pair

FORCED_GRID = (64, 128)
"""Default (cells in x, cells in y) of the forced solver on Cartesian cells: with :data:`DEFAULT_STEPS`, the finest
that keeps example 08 (D = 0.02) within the default ``l1_tol`` of 0.005 with both parts of the estimate (cells
0.0039, time steps 0.0006; at (60, 120) 0.0045 + 0.0006 = 0.0050 just missed it; docs/results/fpk-forced.md)."""
FORCED_RING_GRID = (120, 128)
"""Default (rings, angles) with ``cells="rings"``."""
PHASE_ORDER = 3
"""Order of the convection along the rings (3: upwind-biased kappa = 1/3, as the autonomous solver)."""
DEFAULT_STEPS = 64
"""Default time steps per forcing period of the result (``scheme="richardson"`` also runs twice as many; rounded up
to a multiple of the phases asked for). 64: the time estimate of example 08 is 0.0006 (measured time error 0.00016);
at 32 it is 0.0045 (measured 0.0022), which with the cells' estimate would miss the default ``l1_tol``."""
SCHEMES = ("richardson", "cn", "bdf2")
"""Time integrations: Crank-Nicolson at K and 2K steps combined (fourth order), Crank-Nicolson, BDF2."""
CUT_TAIL = 1e-6
"""Probability above the energy range that the Cartesian cells may leave out when the range is cut to the mass (far
below the L1 the solver reaches)."""
BYTES_PER_CELL_FACTOR = {"rings": 1800, "cartesian": 3500}
"""Peak memory per cell and stored LU factor (rings: 1.7 kB measured at (160, 192); Cartesian: 2.0e6 nonzeros of
L + U at (60, 120) with COLAMD, 3.4 kB)."""
SECONDS_PER_CELL_FACTOR = {"rings": 3e-5, "cartesian": 4e-5}
"""CPU time per cell and factor, solves included, for the estimate in the refusal (rings: 2.8e-5 s measured at
(160, 192), 64 steps; Cartesian: 2.1e-5 s per factor at (60, 120) and the solves)."""


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
    cells : str
        ``"cartesian"`` or ``"rings"``.
    error_estimate : float or None
        Estimated L1 error of p(H | t) on 100 bins (the largest over the phases), ``grid_estimate`` +
        ``time_estimate`` (``check=True``).
    grid_estimate, time_estimate : float or None
        The cells' part (the solve on the grid twice coarser, same steps) and the time steps' part (on that grid,
        the same scheme at half the steps); :meth:`estimate_parts` gives them on other bins or phases.
    time_correction : float or None
        max over the stored times of the L1 (cell densities) between the 2K-step run and the extrapolated density
        (``scheme="richardson"``; None otherwise): the time error of Crank-Nicolson alone at 2K steps, an upper
        bound on the time error of the extrapolated density.
    timing : dict
        Seconds spent assembling, factoring, solving and marching.

    Examples
    --------
    >>> from models import ForcedDuffingImpact
    >>> pd_ = periodic_density_xy(ForcedDuffingImpact(), grid=(24, 48), steps=8, phases=4, check=False)
    >>> t = pd_.phase_times(4)  # the sections of vibro mc --phases 4: stored steps
    >>> bool(abs(pd_.mean_energy_at(t).mean() - pd_.mean_energy) < 0.05 * pd_.mean_energy)
    True
    >>> [round(float(s.bin_masses([0.0, 4.0])[0]), 6) for s in pd_.sections(2)], pd_.impact_rate_at(t).shape
    ([1.0, 1.0], (4,))
    """

    method = "fpk"

    def __init__(self, model, plane, times, period, snapshots, operators, points, h_max):
        self.model = model
        self.grid = plane.grid
        self.cells = plane.kind
        self._plane = plane
        self.period = float(period)
        self.times = np.asarray(times, dtype=float)
        self.cell_p = np.asarray(snapshots)
        self._operators = operators  # A(t_k), for the sections' impact fluxes
        self.h_max = float(h_max)
        self._points = int(points)
        self.timing = {}
        closed = np.vstack([self.cell_p, self.cell_p[:1]])
        from scipy.interpolate import CubicSpline  # here only: scipy.interpolate imports scipy.optimize

        self._spline = CubicSpline(np.append(self.times, self.period), closed, axis=0, bc_type="periodic")
        self.conservation = float(np.max(np.abs(self.cell_p @ plane.mass_weight - 1.0)))
        self.mean = self._section(self.cell_p.mean(axis=0), None)
        self.mean_energy_t = np.array([plane.mean_energy(p) for p in self.cell_p])
        self.impact_rate_t = np.array([plane.impact_rate(p) for p in self.cell_p])
        self.mean_energy = float(self.mean_energy_t.mean())
        self.impact_rate = float(self.impact_rate_t.mean())
        self.periodicity = np.nan
        self.iterations = 0
        self.factors = 0
        self.error_estimate = None
        self.grid_estimate = None
        self.time_estimate = None
        self.time_correction = None
        self._check = None

    # ------------------------------------------------------------------ sections
    def _section(self, p, k):
        A = self._operators[k] if k is not None else self._plane.A
        sd = self._plane.section(p, A, self.timing if k is None else {})
        sd.residual = np.nan  # a section is not stationary: its A p is the rate of change, not a residual
        sd.h_max = self.h_max
        sd.H = np.linspace(sd.h_min, self.h_max, self._points)
        sd.p = sd.density(sd.H)
        return sd

    def cells_at(self, t):
        """The cell densities at time ``t`` (mod T): the stored step, or a periodic cubic spline between steps.

        Examples
        --------
        >>> from models import ForcedDuffingImpact
        >>> pd_ = periodic_density_xy(ForcedDuffingImpact(), grid=(24, 48), steps=8, check=False)
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
        >>> pd_ = periodic_density_xy(ForcedDuffingImpact(), grid=(24, 48), steps=8, check=False)
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
        return np.array([self._plane.mean_energy(self.cells_at(s)) for s in t])

    def impact_rate_at(self, t):
        """The impact rate (impacts per unit time, both walls) at times ``t`` (mod T)."""
        t = np.atleast_1d(np.asarray(t, dtype=float)) % self.period
        return np.array([self._plane.impact_rate(self.cells_at(s)) for s in t])

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

    def estimate_parts(self, edges, phases: int | None = None, average: bool = False):
        """(grid, time) estimates of the L1 error of p(H | t) on the energy bins ``edges``, worst over ``phases``
        sections k T / phases (default: those of the check), or of the time-averaged p(H) with ``average``.

        grid: the L1 between this solve and the check's on the grid twice coarser (same steps), over 3 (order 2:
        conservative, the Cartesian cells converge at order 2 next to an inelastic wall and faster elsewhere).
        time: on the check's grid, the L1 between the result at the steps K and the same scheme at K / 2, over 3
        (order 2 assumed: the Richardson combination's order rises from 2 to 4 as the steps shrink, so this
        overestimates, 2-6 times in docs/results/fpk-forced.md); its cells' error cancels in the difference.
        Needs ``check=True`` (else :class:`~hybrid.errors.ParameterError`).

        Examples
        --------
        >>> from models import ForcedDuffingImpact
        >>> pd_ = periodic_density_xy(ForcedDuffingImpact(), grid=(24, 48), steps=8, l1_tol=1.0)
        >>> grid, time = pd_.estimate_parts(np.linspace(0.0, 2.0, 41), average=True)
        >>> bool(0 < grid < 1 and 0 < time < 1)
        True
        """
        check = getattr(self, "_check", None)
        if check is None:
            raise ParameterError("no error estimate: the density was solved with check=False")
        coarse, half, default = check
        edges = np.asarray(edges, dtype=float)

        def gap(a, b, k, pick=None):
            if average:
                return float(np.abs(a.mean.bin_masses(edges) - b.mean.bin_masses(edges)).sum())
            times = a.phase_times(k) if pick is None else pick
            return max(float(np.abs(a.section(t).bin_masses(edges) - b.section(t).bin_masses(edges)).sum())
                       for t in times)

        k = default if phases is None else _count("phases", phases)
        grid = gap(self, coarse, k) / 3.0
        if half is None:
            return grid, None
        # the times both runs store: the half run's steps that are also sections asked for (or 8 of them)
        common = int(np.gcd(len(half.times), k))
        if common < min(k, 4):
            common = min(8, len(half.times))
        return grid, gap(coarse, half, common, half.phase_times(common)) / 3.0

    def metadata(self) -> dict:
        """Method, model, grid, period and summary statistics (JSON-friendly)."""
        return {**self.mean.metadata(), "period": self.period, "steps": len(self.times),
                "mean_energy": self.mean_energy, "impact_rate": self.impact_rate, "periodicity": self.periodicity,
                "conservation": self.conservation, "gmres_iterations": self.iterations, "factors": self.factors,
                "cells": self.cells, "error_estimate": self.error_estimate, "grid_estimate": self.grid_estimate,
                "time_estimate": self.time_estimate, "time_correction": self.time_correction}

    def __repr__(self) -> str:
        return (f"PeriodicDensity(model={self.model.name!r}, method='fpk', cells={self.grid.n}, "
                f"steps={len(self.times)}, period={self.period:.6g}, E[H]={self.mean_energy:.6g}, "
                f"impact_rate={self.impact_rate:.6g})")


class _Shim:
    """What a section's density class reads from a discretisation, with another operator (a section's A(t))."""

    def __init__(self, disc, A):
        self.A = A
        self._disc = disc

    def __getattr__(self, name):
        return getattr(self._disc, name)


class _RingPlane:
    """The energy-angle rings of the autonomous solver as the forced solver's cells (``cells="rings"``)."""

    kind = "rings"

    def __init__(self, model, free, law, h, n_e, n_p, left, right):
        wall_H = {}
        if right is not None:
            wall_H["right"] = float(model.potential(np.array([right]))[0])
        if left is not None:
            wall_H["left"] = float(model.potential(np.array([left]))[0])
        self.grid = g = RingGrid(float(h), n_e, n_p, wall_H, DEFAULT_STRETCH)
        self.disc = Discretisation(g, _coefficients(free, law), law.coefficient, 2, PHASE_ORDER)
        self.model, self.walls_at = model, (left, right)
        self.mass_weight, self.A, self.n = self.disc.mass_weight, self.disc.A, g.n
        (xr, yr), (xa, ya) = self.disc.drift_points()
        self._split = len(xr)
        self.drift_xy = (np.concatenate([xr, xa]), np.concatenate([yr, ya]))
        self._g = free.restoring(self.drift_xy[0])  # the rings take the non-conservative drift m + g
        self._energy = self.mass_weight * g.H_c[g.ring]
        self.h_min = 0.0

    def operator(self, m):
        m = m + self._g
        return self.disc.operator_with_drift(m[:self._split], m[self._split:])

    def unforced(self):
        return self.disc.solve()

    def section(self, p, A, timing):
        return PhaseDensity(self.model, self.grid, _Shim(self.disc, A), p, timing, self.walls_at)

    def mean_energy(self, p):
        return float(p @ self._energy)

    def impact_rate(self, p):
        return float(sum(p[cin] @ self.grid.dH[rings] for rings, cin, _cout, _W in self.disc.walls.values()))

    def top_mass(self, p):
        """Probability in the top 10 % of the energy range."""
        ring_mass = np.bincount(self.grid.ring, p * self.mass_weight, self.grid.n_rings)
        return float(ring_mass[self.grid.H_c > 0.9 * self.grid.h_max].sum())


class _CartesianPlane:
    """Cartesian (x, y) cells (:mod:`._cartesian`) as the forced solver's cells (``cells="cartesian"``)."""

    kind = "cartesian"

    def __init__(self, model, free, law, h, nx, ny, left, right):
        lo, hi, g_min = confining_range(free.potential, float(h), left, right)
        wall_x = {k: v for k, v in (("left", left), ("right", right)) if v is not None}
        self.grid = CartesianGrid(lo, hi, g_min, float(h), nx, ny, free.potential, wall_x)
        self.disc = CartesianDiscretisation(self.grid, _coefficients(free, law), law.coefficient)
        self.model, self.free, self.walls_at = model, free, (left, right)
        self.mass_weight, self.A, self.n = self.disc.mass_weight, self.disc.A, self.grid.n
        self.drift_xy = self.disc.drift_points()
        self.h_min = g_min

    def operator(self, m):
        return self.disc.operator_with_drift(m)

    def mirror(self):
        """The cell of (-x, -y) for every cell (an involution), or None where some cell has no mirror image."""
        g = self.grid
        ij = np.column_stack([(g.x - g.x.min()) / g.hx, (g.y - g.y.min()) / g.hy])
        back = np.column_stack([(-g.x - g.x.min()) / g.hx, (-g.y - g.y.min()) / g.hy])
        if np.max(np.abs(back - np.rint(back))) > 1e-6:
            return None
        index = {(int(a), int(b)): k for k, (a, b) in enumerate(np.rint(ij).astype(int))}
        perm = np.array([index.get((int(a), int(b)), -1) for a, b in np.rint(back).astype(int)])
        return perm if np.all(perm >= 0) and np.array_equal(perm[perm], np.arange(len(perm))) else None

    def unforced(self):
        return null_vector(self.disc.A, self.mass_weight)

    def section(self, p, A, timing):
        return CartesianDensity(self.model, self.grid, _Shim(self.disc, A), p, timing, self.walls_at)

    def mean_energy(self, p):
        return moments(self.grid, self.free.potential, p)[0]

    def impact_rate(self, p):
        return float(sum(np.sum(self.disc.wall_flux(p, side)[1]) for side in self.disc.walls))

    def mass_energy(self, snapshots, tail):
        """The lowest cell-centre energy above which every density of ``snapshots`` holds at most ``tail``."""
        g = self.grid
        H = 0.5 * g.y**2 + self.free.potential(g.x)
        order = np.argsort(H)[::-1]
        above = np.cumsum(np.abs(snapshots[:, order]) * self.mass_weight[order], axis=1).max(axis=0)
        k = int(np.argmax(above > tail))  # the cells from the top down to k hold at most tail
        return float(H[order][k])

    def top_mass(self, p):
        """Probability in the cells whose centre lies in the top 10 % of the energy range."""
        g = self.grid
        H = 0.5 * g.y**2 + self.free.potential(g.x)
        return float(np.sum((p * self.mass_weight)[H > g.g_min + 0.9 * (g.h_max - g.g_min)]))


PLANES = {"cartesian": (_CartesianPlane, FORCED_GRID, "cells in x, cells in y", (8, 8)),
          "rings": (_RingPlane, FORCED_RING_GRID, "rings, angles", (8, 16))}
"""The cells of the forced solver: (builder, default grid, the grid's axes, least grid)."""


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
    :class:`ExtrapolatedSection`; ``fine`` and ``coarse`` are the two solves. For the rings (second order) on
    example 08, with Crank-Nicolson at 64 steps, the L1 of p(H | t) against Monte Carlo falls from 0.024 to 0.009
    (D = 0.02) at (120, 128), for 1.3 times the time (docs/results/fpk-forced.md).
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
        self.cells, self._plane = fine.cells, fine._plane
        self.error_estimate = self.grid_estimate = self.time_estimate = None
        self._check = None
        self.time_correction = fine.time_correction

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


def periodic_density_xy(model, grid=None, h_max: float = 4.0, *, cells: str = "cartesian",
                        steps: int = DEFAULT_STEPS, phases: int | None = None, walls="model", restitution=None,
                        points: int = 2000, tol: float = 1e-6, max_iterations: int = 300,
                        scheme: str = "richardson", check: bool = True, l1_tol: float = 0.005,
                        extrapolate: bool = False) -> PeriodicDensity:
    """Periodic density p(x, y, t) of a periodically forced ``model`` with impact boundary conditions.

    Parameters
    ----------
    model : ImpactOscillator
        A forced model (``forcing="A*cos(Omega*t + phi)"``, any periodic F(t, x, y) with a period): single-well g,
        any h, f_k / D_kl and restitution law.
    grid : (int, int), optional
        Cells: (x, y) for ``cells="cartesian"`` (default :data:`FORCED_GRID`), (rings, angles) for ``"rings"``
        (default :data:`FORCED_RING_GRID`).
    h_max : float
        Upper energy (reflecting): choose it in the tail of every section.
    cells : {'cartesian', 'rings'}
        Cartesian (x, y) cells (default: the forced density is a blob that moves across the orbits, which the
        Cartesian scheme resolves to high order) or the energy-angle rings of the autonomous solver.
    steps : int
        Time steps per period of the result (second order in T / steps; ``scheme="richardson"`` also runs twice as
        many and combines the two).
    phases : int, optional
        Make ``steps`` a multiple of ``phases`` so that the sections k T / phases are stored steps.
    walls, restitution, points
        As :func:`~averaging.phase_plane.solve_phase_plane` (``points``: energies of each section's p(H)).
    tol : float
        Relative residual of GMRES for the fixed point of the period map (1e-6: on example 08, p(H | t) moved by
        4.5e-7 in L1 from 1e-10, four orders below the discretisation's error, for 7 fewer period maps).
    max_iterations : int
        Most period maps GMRES may apply.
    scheme : {'richardson', 'cn', 'bdf2'}
        Time integration: Crank-Nicolson with ``steps`` and ``2 steps`` combined as (4 p_2K - p_K) / 3 (default:
        fourth order, the time error of a section's moments falls from 8e-3 to 5e-4 on the linear oscillator),
        Crank-Nicolson alone, or BDF2 (L-stable, larger error).
    check : bool
        Also solve on the grid twice coarser (same steps, and again at half the steps) and estimate the L1 error of
        p(H | t) on 100 bins: the cells' part from the two grids and the time steps' part from the two step counts
        (``error_estimate`` = ``grid_estimate`` + ``time_estimate``, order 2 assumed for both: conservative);
        warn (:class:`GridWarning`) when it exceeds ``l1_tol``. Rounds ``steps`` up to even, and refuses fewer than 8.
    l1_tol : float
        The L1 error of p(H | t) above which ``check`` warns.
    extrapolate : bool
        Return the Richardson combination (4 fine - coarse) / 3 of the two grids (second order assumed): an
        :class:`ExtrapolatedPeriodicDensity`. It helps the rings (second order); on Cartesian cells measure first
        (docs/results/fpk-forced.md).

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
    >>> pd_ = periodic_density_xy(lin, grid=(32, 32), steps=16, h_max=3.0, check=False)
    >>> exact = 0.05 / 0.5 + 0.25 * 0.4**2 * (1 + 1.3**2) / abs(1 - 1.3**2 + 0.65j)**2  # D/c + |response|^2 / 2
    >>> round(pd_.mean_energy, 4), round(exact, 4)
    (0.2197, 0.2197)
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
    if model.substitute(model.diffusion_squared) == 0:
        # without noise the periodic state is a deterministic orbit (a density concentrated on a curve): no grid
        # holds it, and the scheme's own diffusion would stand in for the missing noise
        raise ParameterError(f"model {model.name!r} has no noise (sigma**2 = 0): fpk needs a positive noise "
                             "intensity D; simulate the deterministic orbit instead")
    if cells not in PLANES:
        raise ParameterError(f"cells={cells!r}: use 'cartesian' or 'rings'")
    plane_of, default, axes, least = PLANES[cells]
    n1, n2 = grid_pair(default if grid is None else grid, axes, least)
    steps = _count("steps", steps)
    unit = 1
    if phases is not None:
        phases = _count("phases", phases)
        unit = phases
    if check and unit % 2:
        unit *= 2  # the time estimate runs at half the steps
    steps = unit * -(-steps // unit)
    if steps < (8 if check else 4):
        raise ParameterError(f"steps={steps} must be at least {8 if check else 4} per period"
                             + (" (the check's time estimate runs at half the steps)" if check else ""))
    if int(points) != points or points < 3:
        raise ParameterError(f"points={points!r} must be an integer >= 3")
    if scheme not in SCHEMES:
        raise ParameterError(f"scheme={scheme!r}: use 'richardson' (Crank-Nicolson at two steps, fourth order), 'cn' "
                             "(Crank-Nicolson) or 'bdf2' (L-stable)")
    if not (np.isfinite(l1_tol) and l1_tol > 0):
        raise ParameterError(f"l1_tol={l1_tol!r} must be a positive number")
    n_cells = float(n1) * float(n2)
    factors = (steps // 2 + 1) * (3 if scheme == "richardson" else 1) * (1.25 if check or extrapolate else 1.0)
    per = BYTES_PER_CELL_FACTOR[cells]
    check_size(f"the forced phase-plane solve on {n1} x {n2} cells and {steps} steps",
               memory=n_cells * per * factors,
               detail=f"{factors:.0f} LU factors of {n_cells:.3g} cells x {per} bytes, about "
                      f"{n_cells * factors * SECONDS_PER_CELL_FACTOR[cells]:.3g} s",
               fix=f"use a coarser grid or fewer steps (the defaults are {default} and {DEFAULT_STEPS})"
                   + ("" if phases is None else f"; the steps are a multiple of phases={phases}"))

    check_energy_range(free, float(h_max), walls)
    from .solver import _first_range

    law = restitution if restitution is not None else model.restitution
    left, right = _walls(model, walls)
    drift = lambdify_numeric((X, Y, T), model.substitute(model.ito_drift))

    def solve_on(h, n1, n2, probe=False):
        t0 = time.perf_counter()
        plane = plane_of(model, free, law, h, n1, n2, left, right)
        fine = 2 * steps if scheme == "richardson" else steps
        dt = period / fine
        xs, ys = plane.drift_xy
        operators, drifts = [], []
        for t in dt * np.arange(fine):
            with np.errstate(all="ignore"):
                m = np.broadcast_to(np.asarray(drift(xs, ys, t), dtype=float), xs.shape)
            if not np.all(np.isfinite(m)):
                raise ModelError(f"the drift with the forcing F = {model.forcing} is not finite at t = {t:.6g}")
            operators.append(plane.operator(m))
            drifts.append(m)
        t1 = time.perf_counter()
        p0 = plane.unforced()  # the unforced density: the start, and the vector of the rank-one term
        p0 = p0 / (plane.mass_weight @ p0)
        if h >= h_max and plane.top_mass(p0) > 0.1:  # not even the unforced density fits: refuse before GMRES
            raise NormalisationError(f"p(H) does not decay towards h_max={h_max:g} even without the forcing: raise "
                                     "h_max or add dissipation")
        if scheme == "richardson":
            coarse = _fixed_point(plane, operators[::2], drifts[::2], 2 * dt, "cn", p0, tol, max_iterations)
            finer = _fixed_point(plane, operators, drifts, dt, "cn", coarse[0][0], tol, max_iterations)
            snapshots = (4.0 * finer[0][::2] - coarse[0]) / 3.0
            runs = (coarse, finer)
        else:
            runs = (_fixed_point(plane, operators, drifts, dt, scheme, p0, tol, max_iterations),)
            snapshots = runs[0][0]
        t2 = time.perf_counter()
        out = PeriodicDensity(model, plane, period * np.arange(steps) / steps, period, snapshots,
                              operators[::len(operators) // steps], points, h_max)
        out.periodicity = max(r[1] for r in runs)
        out.iterations = sum(r[2] for r in runs)
        out.factors = sum(r[3] for r in runs)
        out.timing = {"assemble": t1 - t0, "solve": t2 - t1, **{k: sum(r[4][k] for r in runs) for k in runs[0][4]}}
        if scheme == "richardson":
            w = plane.mass_weight
            out.time_correction = float(np.max(np.abs(runs[1][0][::2] - snapshots) @ w))
        if probe:
            # the same scheme at half the steps, for the time error: Richardson takes Crank-Nicolson at K / 2 with
            # the K run it already has; a single scheme runs again at K / 2
            half = steps // 2
            if scheme == "richardson":
                slow = _fixed_point(plane, operators[::4], drifts[::4], 4 * dt, "cn", runs[0][0][0], tol,
                                    max_iterations)
                probe_p = (4.0 * runs[0][0][::2] - slow[0]) / 3.0
            else:
                slow = _fixed_point(plane, operators[::2], drifts[::2], 2 * dt, scheme, snapshots[0], tol,
                                    max_iterations)
                probe_p = slow[0]
            out.half_steps = PeriodicDensity(model, plane, period * np.arange(half) / half, period, probe_p,
                                             operators[::len(operators) // half], points, h_max)
        return out

    # the cells on the energies the unforced density reaches (e**-40 below its peak), doubled for the forcing's
    # energy, so that a large h_max does not put the mass into the first few cells; widened while mass reaches the top
    h = min(float(h_max), 2.0 * _first_range(free, float(h_max)))
    out = solve_on(h, n1, n2)

    def top_mass(sol):
        return sol._plane.top_mass(sol.cell_p.mean(axis=0))

    for _ in range(4):
        if top_mass(out) <= 1e-4 or h >= h_max:
            break
        h = min(float(h_max), 4.0 * h)
        out = solve_on(h, n1, n2)
    if h >= h_max and top_mass(out) > 0.1:
        raise NormalisationError(f"p(H) does not decay towards h_max={h_max:g}: raise h_max or add dissipation")
    if out.cells == "cartesian":
        # uniform cells spend their resolution evenly: a range far above the mass (where every section leaves less
        # than CUT_TAIL) is cut to 1.25 times the energy that holds it, and solved again
        for _ in range(2):
            top = out._plane.mass_energy(out.cell_p, CUT_TAIL)
            if 1.25 * top >= 0.6 * (h - out.mean.h_min) + out.mean.h_min:
                break
            h = out.mean.h_min + 1.25 * (top - out.mean.h_min)
            out = solve_on(h, n1, n2)
    tail = top_mass(out)
    if tail > 1e-4:
        warnings.warn(f"{tail:.2g} of the time-averaged probability lies in the top 10% of the energy range "
                      f"[.., h_max={h_max:g}]: raise h_max", GridWarning, stacklevel=2)
    if not (check or extrapolate):
        return out
    lo1, lo2 = max(least[0], n1 // 2), max(least[1], n2 // 2)
    coarse = solve_on(h, lo1, lo2, probe=check)
    out._check = (coarse, getattr(coarse, "half_steps", None), phases or 8)
    # the L1 of p(H | t) at the phases asked for (8 without), on 100 bins of the energy range
    edges = np.linspace(out.mean.h_min, out.grid.h_max, 101)
    parts = out.estimate_parts(edges)
    if extrapolate:
        out = ExtrapolatedPeriodicDensity(out, coarse)
        out._check = None  # the estimate is the fine grid's (the extrapolation is not estimated on its own)
    out.grid_estimate, out.time_estimate = parts
    estimate = parts[0] + (parts[1] or 0.0)
    out.error_estimate = estimate
    out.mean.error_estimate = estimate
    if check and estimate > l1_tol:
        space = parts[0] >= (parts[1] or 0.0)
        what, fix = ((f"grid {(n1, n2)}", "refine the grid") if space else
                     (f"time step (T / {steps})", "raise steps"))
        timed = "" if parts[1] is None else f", time steps {parts[1]:.2g} from a run at {steps // 2} steps"
        warnings.warn(f"{what} too coarse: estimated L1 error of p(H | t) {estimate:.2g} > l1_tol={l1_tol:g} (cells "
                      f"{parts[0]:.2g} from the solve on {(lo1, lo2)}{timed}); {fix}", GridWarning, stacklevel=2)
    return out


def _fixed_point(plane, operators, drifts, dt, scheme, start, tol, max_iterations):
    """The periodic solution of K = len(operators) implicit steps of M dp/dt = -A(t) p: (snapshots (K, n) at the
    step times, periodicity, period maps applied, factors, timing)."""
    t0 = time.perf_counter()
    steps = len(operators)
    M = sps.diags(plane.mass_weight / dt)
    # implicit steps: BDF2 (3/2 M + A(t_{k+1})) p_{k+1} = M (2 p_k - p_{k-1} / 2), or Crank-Nicolson
    # (M + A(t_{k+1}) / 2) p_{k+1} = (M - A(t_k) / 2) p_k; one LU per distinct drift (a harmonic forcing takes each
    # value twice a period)
    bdf2 = scheme == "bdf2"
    mass_coef, op_coef = (1.5, 1.0) if bdf2 else (1.0, 0.5)
    scale = max(float(np.max(np.abs(d))) for d in drifts)
    order = _dissection(plane, operators[0]) if plane.kind == "cartesian" else None
    # a probe of each drift: drifts whose probes differ by more than the allclose bound can differ nowhere less,
    # so the search compares arrays only for near-equal probes (the K^2 comparisons cost seconds at 128 steps)
    probe = np.random.default_rng(0).standard_normal(drifts[0].size)
    sums = [float(d.ravel() @ probe) for d in drifts]
    bound = float(np.abs(probe).sum()) * scale * (4e-12 + 4.0 * probe.size * np.finfo(float).eps)  # + round-off
    # a model symmetric under (x, y, t) -> (-x, -y, t + T / 2) (symmetric walls and potential, a harmonic force)
    # has the step matrix of t + T / 2 equal to the mirror image P S P^T of that of t: one LU serves both
    perm = plane.mirror() if hasattr(plane, "mirror") else None
    mirrored_probes = []  # per factored matrix S_i: (its index in lus, P S_i P^T r, S_i), to find mirror images
    r = np.random.default_rng(1).standard_normal(plane.n)
    distinct, lus, step_lu = [], [], []
    for k in range(steps):
        d, s = drifts[(k + 1) % steps], sums[(k + 1) % steps]
        same = next((i for i, (e, se) in enumerate(distinct) if abs(s - se) <= bound
                     and np.allclose(d, e, rtol=1e-12, atol=1e-12 * scale)), None)
        if same is not None:
            step_lu.append(lus[same])
            continue
        S = (mass_coef * M + op_coef * operators[(k + 1) % steps]).tocsr()
        image = None
        if perm is not None:
            Sr = S @ r
            # equal to round-off: the forcing's cos at t and t + T / 2 and the cancelling sums on the diagonals
            # leave 5e-10 of max|S| (measured at (16, 32)); a factor within 1e-8 solves the same step to that
            tol_r = 1e-8 * float(np.abs(Sr).max())
            image = next((i for i, q, Si in mirrored_probes if np.abs(Sr - q).max() <= tol_r
                          and abs(S - Si[perm][:, perm]).max() <= 1e-8 * abs(S).max()), None)
        distinct.append((d, s))
        if image is None:
            lus.append(_factor(S.tocsc(), order))
            if perm is not None:
                mirrored_probes.append((len(lus) - 1, (S @ r[perm])[perm], S))
        else:
            lus.append(_MirroredLU(lus[image], perm))
        step_lu.append(lus[-1])
    explicit = None if bdf2 else [(M - 0.5 * A).tocsr() for A in operators]
    t1 = time.perf_counter()
    w = plane.mass_weight
    n = plane.n

    def march(before, now, count):
        """``count`` steps from (p_{-1}, p_0) = (before, now) (CN ignores p_{-1}); yields every new density."""
        for k in range(count):
            rhs = M @ (2.0 * now - 0.5 * before) if bdf2 else explicit[k] @ now
            before, now = now, step_lu[k].solve(rhs)
            yield now

    size = 2 * n if bdf2 else n
    p0 = start
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
    t2 = time.perf_counter()
    periodicity = float(np.max(np.abs(back - p)) / np.max(np.abs(p)))
    factors = sum(not isinstance(f, _MirroredLU) for f in lus)  # LU factorisations computed
    # free the factors now: the closures above held them past the return (the K run's factors stayed resident
    # through the 2K run, 0.8 GB at the default grid)
    lus.clear()
    step_lu.clear()
    mirrored_probes.clear()
    _release_freed_memory()
    return np.array(snapshots), periodicity, maps[0], factors, {"factor": t1 - t0, "march": t2 - t1}


def _release_freed_memory():
    """Hand the heap's free pages back to the system (glibc): the factors' memory, freed, otherwise stays resident
    (glibc raises its mmap threshold after large frees), and the 2K run's factors came on top of the K run's: peak
    2.9 GB instead of 2.0 GB at the default grid. Elsewhere nothing is done."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _factor(A, order=None):
    """Sparse LU of a step matrix: Cartesian cells in the nested-dissection ``order`` of :func:`_dissection` (35 %
    less factor time and 10 % less fill than COLAMD at (64, 128)); the rings in the minimum degree ordering of
    A + A^T, which fills least there."""
    try:
        if order is None:
            return spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1)
        return _PermutedLU(spla.splu(A[order][:, order].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.1,
                                     relax=4, panel_size=16), order)
    except RuntimeError:  # exactly singular with this pivoting
        return spla.splu(A, permc_spec="COLAMD")


class _MirroredLU:
    """Solves P S P^T x = b with the LU of S (P an involution of the cells): x = P S^-1 P^T b."""

    def __init__(self, lu, perm):
        self._lu, self._perm = lu, perm

    def solve(self, b):
        return self._lu.solve(b[self._perm])[self._perm]


class _PermutedLU:
    """The LU of P A P^T (P the permutation ``order``) solving A x = b."""

    def __init__(self, lu, order):
        self._lu, self._order = lu, order

    def solve(self, b):
        x = np.empty(len(self._order))
        x[self._order] = self._lu.solve(b[self._order])
        return x


def _dissection(plane, A, leaf=48):
    """A nested-dissection order of the Cartesian cells: halve the cells across their longer side, put the cells of
    the first half that couple to the second (``A``'s pattern, both directions) last, and recurse down to ``leaf``
    cells. The order sets only the fill of the factors: any order solves exactly."""
    g = plane.grid
    ij = np.column_stack([np.rint((g.x - g.x.min()) / g.hx), np.rint((g.y - g.y.min()) / g.hy)]).astype(int)
    pattern = abs(A).tocsr()
    pattern = (pattern + pattern.T).tocsr()
    inside = np.zeros(A.shape[0], dtype=bool)
    order = []

    def cut(cells):
        if len(cells) <= leaf:
            order.append(cells)
            return
        spans = ij[cells].max(axis=0) - ij[cells].min(axis=0)
        key = ij[cells, int(spans[1] > spans[0])]
        low, high = cells[key < np.median(key)], cells[key >= np.median(key)]
        if not (len(low) and len(high)):
            order.append(cells)
            return
        inside[high] = True
        coupled = pattern[low] @ inside.astype(float) > 0
        inside[high] = False
        cut(low[~coupled])
        cut(high)
        order.append(low[coupled])

    cut(np.arange(A.shape[0]))
    return np.concatenate(order)
