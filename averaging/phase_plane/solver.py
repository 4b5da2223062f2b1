"""Public entry points of the phase-plane solver: :func:`stationary_density_xy` and :func:`solve_phase_plane`."""

from __future__ import annotations

import time
import warnings

import numpy as np

from hybrid.automaton import lambdify_numeric
from hybrid.errors import ModelError, NormalisationError, ParameterError
from hybrid.sizes import check_size
from models import X, Y

from ..stationary import check_energy_range, output_grid
from ._core import Coefficients, Discretisation
from ._grid import RingGrid
from ._monotone import MonotoneCubic

DEFAULT_GRID = (160, 192)
"""(rings in H, angles per ring): L1 discretisation error of p(H) below 1e-3 on the paper's cases."""
BYTES_PER_CELL = 800
"""Peak memory per cell of the assembly and the sparse solve (measured 790-910 bytes on grids of 7e3-1.1e5 cells)."""
SECONDS_PER_CELL = 8e-5
"""Solve time per cell (measured 85-165 us on 2 shared cores), for the estimate in the refusal."""
L1_BINS = 100
DEFAULT_STRETCH = 0.4
ESTIMATE_ORDER = 1.3
"""Highest order the a-posteriori error estimate L1(p_h, p_2h) / (2**p - 1) assumes: the lowest order fitted in
``benchmarks/fpk_convergence.py`` (E[H] with a wall at the equilibrium; p(H) converges at 1.4-2.2 elsewhere). The
order observed on three grids (h, 2h, 4h) is taken where it is lower: with an inelastic stop at the equilibrium the
40-bin L1 converges at order 0.5-0.75 on grids up to (256, 320) (successive differences 5.7e-3, 4.0e-3, 2.4e-3)."""
EQUILIBRIUM_ORDER = 0.6
"""Highest order assumed where an inelastic wall sits at the equilibrium (it meets the equilibrium at a corner of
the domain): the 40-bin L1 of the linear oscillator with a stop at x = 0, r = 0.6, converges at order 0.5-0.75 from
(48, 64) to (256, 320), while the three grids of a coarse solve can look faster (pre-asymptotic)."""
MIN_ORDER = 0.25
"""Lowest order the estimate assumes (an observed order below it: not yet converging, estimate 5.3 L1(p_h, p_2h))."""


class GridWarning(UserWarning):
    """The grid is too coarse for the requested accuracy (the message gives the estimated L1 error)."""


class PhaseDensity:
    """The stationary density of the (x, y) problem on the energy-angle grid, and what follows from it.

    Built by :func:`stationary_density_xy`. ``H`` and ``p`` follow :class:`averaging.StationaryDensity`: ``points``
    energies on [0, h_max] and p(H) normalised to 1 there.

    Attributes
    ----------
    method : str
        ``"fpk"``.
    H, p : ndarray
        Energy grid and p(H) (derivative of a monotone interpolant of the exact cumulative ring masses).
    H_faces, ring_mass : ndarray
        Ring boundaries and the probability of each ring (sums to 1).
    cell_H, cell_psi, cell_x, cell_y, cell_p, cell_mass : ndarray
        Cell centres (energy, angle and the corresponding x, y), the density p(x, y) there and the cell masses.
    mean_energy, mean_x2, mean_y2, prob_below_barrier : float
    impact_rate : float
        Impacts per unit time, both walls; ``impact_rates`` per wall.
    residual : float
        max |A p| / max(|A| |p|) of the discrete equation (round-off level when solved).
    conservation : float
        max |column sum| of the discrete operator (0 up to round-off: probability is conserved).
    error_estimate : float or None
        Estimated L1 error of p(H) on 100 bins of [0, h_support], when checked (see :meth:`estimate_error`).
    error_method : str or None
        How ``error_estimate`` was made (three grids, the observed order, the tail term).
    timing : dict
        Seconds spent assembling and solving.
    """

    method = "fpk"
    scheme = "rings"
    h_min = 0.0
    """Lowest energy of p(H) (min G; 0 for a single well)."""

    def __init__(self, model, grid: RingGrid, disc: Discretisation, p, timing, walls):
        self.model = model
        self.grid = grid
        self.h_max = grid.h_max  # the range asked for (stationary_density_xy may solve on less: h_support)
        self.h_support = grid.h_max
        self.timing = timing
        self.walls = walls
        c = disc.cell
        self.cell_H, self.cell_psi = grid.H_c[grid.ring], grid.psi
        self.cell_x, self.cell_y = c["x"], c["y"]
        self.cell_p = p
        self.cell_mass = p * disc.mass_weight
        self.H_faces = grid.H_faces
        self.ring_mass = np.bincount(grid.ring, self.cell_mass, grid.n_rings)
        Ap = disc.A @ p
        scale = float(np.max(abs(disc.A) @ np.abs(p)))
        self.residual = float(np.max(np.abs(Ap)) / scale) if scale > 0 else 0.0
        self.conservation = float(np.max(np.abs(np.asarray(disc.A.sum(axis=0)))))
        self._cdf = MonotoneCubic(grid.H_faces, np.concatenate([[0.0], np.cumsum(self.ring_mass)]))
        self._pdf = self._cdf.derivative()
        self.mean_energy = float(np.sum(self.cell_mass * self.cell_H))
        self.mean_x2 = float(np.sum(self.cell_mass * self.cell_x**2))
        self.mean_y2 = float(np.sum(self.cell_mass * self.cell_y**2))
        wall_H = [h for h in grid.walls.values()]
        Gw = min(wall_H) if wall_H else np.inf
        self.prob_below_barrier = float(self._cdf(min(Gw, self.h_support)))
        self.impact_rates = {}
        self._impacts = {}
        for side, (rings, cin, _cout, _W) in disc.walls.items():
            Hw = grid.walls[side]
            flux = p[cin]  # exit flux per unit H
            self.impact_rates[side] = float(np.sum(flux * grid.dH[rings]))
            self._impacts[side] = (np.sqrt(2.0 * (grid.H_c[rings] - Hw)), flux, grid.dH[rings])
        self.impact_rate = float(sum(self.impact_rates.values()))
        self.error_estimate = None
        self.error_method = None
        self._coarse = None  # the solves on grids twice and four times coarser, kept for estimate_error on any bins
        self._tail = 0.0
        self._order = ESTIMATE_ORDER
        self.H = np.array([])
        self.p = np.array([])

    # ------------------------------------------------------------------ energy
    def density(self, H):
        """p(H) at arbitrary energies (0 outside [0, h_max]).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> float(sd.density([5.0])[0])
        0.0
        """
        H = np.asarray(H, dtype=float)
        inside = (H >= self.h_min) & (H <= self.h_support)
        return np.where(inside, np.maximum(self._pdf(np.clip(H, self.h_min, self.h_support)), 0.0), 0.0)

    def bin_masses(self, edges):
        """Probability of each energy bin [edges[k], edges[k+1]] (exact ring masses, monotone interpolation).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> round(float(sd.bin_masses([0.0, 4.0]).sum()), 12)
        1.0
        """
        edges = np.clip(np.asarray(edges, dtype=float), self.h_min, self.h_support)
        return np.diff(self._cdf(edges))

    def estimate_error(self, edges=None, order: float | None = None) -> float:
        """A-posteriori L1 error of p(H) on the bins ``edges`` (default 100 bins of [0, h_support]).

        Three grids: with d1 = L1(p_h, p_2h) and d2 = L1(p_2h, p_4h) from the solves on grids twice and four times
        coarser in both directions (kept from the check), the observed order is log2(d2 / d1); Richardson's
        estimate of the fine grid's error is d1 / (2**p - 1) with p the observed order, but at most ``order``
        (default: the lowest the convergence study fitted, :data:`ESTIMATE_ORDER`, or :data:`EQUILIBRIUM_ORDER` with
        an inelastic wall at the equilibrium) and at least :data:`MIN_ORDER`. Added: the
        probability in the top 10 % of the range (the reflecting top at h_max moves at most that much; the model
        itself is solved without approximation).

        Returns NaN when the density was computed without the check (no coarse solves to compare with).

        Examples
        --------
        >>> from models import DuffingImpact, Ma
        >>> sd = stationary_density_xy(DuffingImpact(restitution=Ma(0.4)), grid=(40, 48))
        >>> 0 < sd.estimate_error(np.linspace(0.0, 4.0, 41)) < 0.05
        True
        """
        if self._coarse is None:
            return float("nan")
        if edges is None:
            edges = np.linspace(0.0, self.h_support, L1_BINS + 1)
        if order is None:
            order = self._order
        half, quarter = self._coarse
        d1 = float(np.abs(self.bin_masses(edges) - half.bin_masses(edges)).sum())
        p = order
        if quarter is not None:
            d2 = float(np.abs(half.bin_masses(edges) - quarter.bin_masses(edges)).sum())
            if d1 > 0 and d2 > 0:
                p = min(order, max(MIN_ORDER, float(np.log2(d2 / d1))))
            elif d1 > 0:
                p = MIN_ORDER
        return d1 / (2.0**p - 1.0) + self._tail

    # ------------------------------------------------------------------ impacts
    def impact_speed_density(self, side: str = "right"):
        """(v, f): impact speeds at wall ``side`` and their density (normalised to 1 over impacts).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> v, f = sd.impact_speed_density("left")
        >>> bool(abs(np.sum(f[1:] * np.diff(v)) - 1) < 0.05)
        True
        """
        if side not in self._impacts:
            raise ParameterError(f"no wall on the {side!r} side; walls: {sorted(self._impacts)}")
        v, flux, dH = self._impacts[side]
        rate = float(np.sum(flux * dH))
        return v, flux * v / rate  # dH = v dv

    # ------------------------------------------------------------------ phase plane
    def joint(self, x, y):
        """p(x, y) on the grid x (nx) by y (ny) -> array (ny, nx); 0 outside the walls and above h_max.

        Linear in H between the cells of neighbouring rings at the same angle, piecewise constant in angle.

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> sd.joint(np.linspace(-1, 1, 5), np.linspace(-2, 2, 3)).shape
        (3, 5)
        """
        XX, YY = np.meshgrid(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        return cell_values_at(self.model, self.grid, self.walls, self.cell_p, XX, YY)

    def box(self):
        """((x_lo, x_hi), y_max): the rectangle of the phase plane that holds the density (H < h_support).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> sd.box()
        ((-1.0, 1.0), 2.8284271247461903)
        """
        return self._x_range(), float(np.sqrt(2.0 * (self.h_support - self.h_min)))

    def _x_range(self):
        lo, hi = self.walls
        tl, tr = self.model.turning_points(self.h_support) if hasattr(self.model, "turning_points") else (-5, 5)
        return (lo if lo is not None else float(tl)), (hi if hi is not None else float(tr))

    def marginal_x(self, x, points: int = 801):
        """p(x) = int p(x, y) dy (midpoint rule on ``points`` speeds).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> bool(sd.marginal_x(np.array([0.0]))[0] > 0)
        True
        """
        x = np.atleast_1d(np.asarray(x, dtype=float))
        ym = self.box()[1]
        e = np.linspace(-ym, ym, points + 1)
        yc = 0.5 * (e[1:] + e[:-1])
        return self.joint(x, yc).sum(axis=0) * (e[1] - e[0])

    def marginal_y(self, y, points: int = 801):
        """p(y) = int p(x, y) dx over the walls (midpoint rule on ``points`` positions).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
        >>> bool(sd.marginal_y(np.array([0.0]))[0] > 0)
        True
        """
        y = np.atleast_1d(np.asarray(y, dtype=float))
        a, b = self._x_range()
        e = np.linspace(a, b, points + 1)
        xc = 0.5 * (e[1:] + e[:-1])
        return self.joint(xc, y).sum(axis=1) * (e[1] - e[0])

    # ------------------------------------------------------------------ output
    def to_pandas(self):
        """DataFrame with columns H, p (metadata in ``.attrs``), as :meth:`averaging.StationaryDensity.to_pandas`."""
        import pandas as pd

        df = pd.DataFrame({"H": self.H, "p": self.p})
        df.attrs.update(self.metadata())
        return df

    def joint_to_pandas(self, x=None, y=None):
        """Long-format DataFrame x, y, p of :meth:`joint` (default 101 x 101 over the walls, |y| <= sqrt(2 h_max))."""
        import pandas as pd

        if x is None:
            x = np.linspace(*self._x_range(), 101)
        if y is None:
            ym = self.box()[1]
            y = np.linspace(-ym, ym, 101)
        XX, YY = np.meshgrid(x, y)
        return pd.DataFrame({"x": XX.ravel(), "y": YY.ravel(), "p": self.joint(x, y).ravel()})

    def metadata(self) -> dict:
        """Method, model, grid and summary statistics (JSON-friendly)."""
        return {
            "method": self.method, "scheme": self.scheme, "model": self.model.describe(), "h_max": self.h_max,
            "grid": [int(self.grid.n_rings), int(round((2 * np.pi) / self.grid.dpsi))], "cells": int(self.grid.n),
            "walls": list(self.walls), "mean_energy": self.mean_energy, "mean_x2": self.mean_x2,
            "prob_below_barrier": self.prob_below_barrier, "impact_rate": self.impact_rate,
            "residual": self.residual, "conservation": self.conservation, "error_estimate": self.error_estimate,
            "error_method": self.error_method,
        }

    def __repr__(self) -> str:
        return (f"PhaseDensity(model={self.model.name!r}, method='fpk', cells={self.grid.n}, "
                f"E[H]={self.mean_energy:.6g}, impact_rate={self.impact_rate:.6g})")

    def _repr_html_(self) -> str:
        from hybrid.display import summary_html

        rows = {"cells": self.grid.n, "E[H]": self.mean_energy, "P(H < G(delta))": self.prob_below_barrier,
                "E[x^2]": self.mean_x2, "impact rate": self.impact_rate, "residual": self.residual}
        if self.error_estimate is not None:
            rows["estimated L1 error of p(H)"] = self.error_estimate
        return summary_html(f"PhaseDensity of {self.model.name} (fpk)", rows)


def cell_values_at(model, grid: RingGrid, walls, values, x, y):
    """A function known at the cell centres (``values``), at the states (x, y): linear in H between the cells of
    neighbouring rings at the same angle (extrapolated from rings 0 and 1 below the first centre), piecewise
    constant in angle; 0 outside the walls and above the grid.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> sd = stationary_density_xy(DuffingImpact(), grid=(40, 48), check=False)
    >>> ones = np.ones(sd.grid.n)
    >>> cell_values_at(sd.model, sd.grid, sd.walls, ones, np.array([0.0, 0.5]), np.array([0.0, 0.1])).tolist()
    [1.0, 1.0]
    """
    XX = np.asarray(x, dtype=float)
    YY = np.asarray(y, dtype=float)
    G = model.potential(XX)
    u = np.sign(XX) * np.sqrt(2.0 * np.maximum(G, 0.0))
    H = 0.5 * YY**2 + G
    psi = np.arctan2(YY, u)
    psi = np.where(psi < -0.5 * np.pi, psi + 2 * np.pi, psi)
    g = grid
    k = g.locate(H, psi)
    lo, hi = walls
    inside = (k >= 0) & (XX >= (lo if lo is not None else -np.inf)) & (XX <= (hi if hi is not None else np.inf))
    kk = np.maximum(k, 0)
    ring = g.ring[kk]
    Hc = g.H_c[ring]
    other = np.where(H > Hc, ring + 1, ring - 1)
    other = np.where(other < 0, 1, other)  # extrapolate from rings 0 and 1 down to H = 0
    other = np.clip(other, 0, g.n_rings - 1)
    k2 = g.locate(g.H_c[other], psi)
    ok = inside & (k2 >= 0) & (other != ring)
    t = np.where(ok, (H - Hc) / np.where(ok, g.H_c[other] - Hc, 1.0), 0.0)
    val = (1.0 - t) * values[kk] + t * values[np.maximum(k2, 0)]
    return np.where(inside, val, 0.0)


def _coefficients(model, law):
    sub = model.substitute
    m_nc = lambdify_numeric((X, Y), sub(model.ito_drift + model.g))
    s2 = lambdify_numeric((X, Y), sub(model.diffusion_squared))
    return Coefficients(model.restoring, model.potential, m_nc, s2, law.coefficient)


def grid_pair(grid, axes: str, least: tuple[int, int]) -> tuple[int, int]:
    """The two cell counts of ``grid`` (named ``axes``, e.g. ``"rings, angles"``), at least ``least``, or a one-line
    :class:`ParameterError`.

    Examples
    --------
    >>> grid_pair((60, 64), "rings, angles", (8, 16))
    (60, 64)
    """
    try:
        first, second = (int(v) for v in grid)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"grid={grid!r} must be a pair ({axes}) of integers") from exc
    if first < least[0] or second < least[1]:
        raise ParameterError(f"grid={grid!r} too small: use at least {least} ({axes})")
    return first, second


def _walls(model, walls):
    if isinstance(walls, str) and walls == "model":
        left, right = model.barriers
        left = None if not np.isfinite(left) else float(left)
        right = None if not np.isfinite(right) else float(right)
    elif walls is None:
        left, right = None, None
    else:
        try:
            left, right = walls
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"walls={walls!r} must be 'model' or a pair (left, right), None for no wall") from exc
        left = None if left is None or not np.isfinite(left) else float(left)
        right = None if right is None or not np.isfinite(right) else float(right)
    if (left is not None and left > 0) or (right is not None and right < 0) or (left == 0 and right == 0):
        raise ParameterError(f"walls ({left}, {right}) must satisfy left <= 0 <= right, not both at 0")
    return left, right


def solve_phase_plane(model, grid=DEFAULT_GRID, h_max: float = 4.0, walls="model", restitution=None,
                      points: int = 2000, *, impact_order: int = 2, phase_order: int = 3,
                      stretch: float = DEFAULT_STRETCH, arc_end_order: int = 1) -> PhaseDensity:
    """One solve on one grid, no accuracy check: the lower-level entry (walls given by position).

    Parameters
    ----------
    model : ImpactOscillator
        Supplies g, G, the Itô drift and sigma**2 (Wong-Zakai term included) and, by default, the walls and
        the restitution law.
    grid : (int, int)
        Rings in energy on [0, h_max] and angle cells per ring.
    h_max : float
        Upper energy (reflecting): choose it in the tail.
    walls : 'model', None or (left, right)
        Wall positions from the model, no walls, or given (None for no wall on a side); left <= 0 <= right.
        A wall at x = 0 is allowed (a barrier at the equilibrium), as is a single wall.
    restitution : RestitutionLaw or None
        Overrides the model's law.
    points : int
        Energies of the output p(H) grid.
    arc_end_order : {1, 2}
        The phase convection's order where an arc ends at a wall (its cells cut by the wall, no cell upstream of
        the upwind one) and at the wall itself: 1, first-order upwind (the default); 2, linear reconstruction
        (upwind-biased where possible, else between the face's two cells; the density at the wall extrapolated
        from the two cells before it). The spectrum uses 2: on the folded oscillator (80 x 96) its L1 error falls
        from 0.010 to 0.0007.

    Examples
    --------
    >>> from models import ImpactOscillator, Newton
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=None)
    >>> sd = solve_phase_plane(lin, grid=(60, 64), h_max=3.0, walls=(None, 0.0), restitution=Newton(0.8))
    >>> sorted(sd.impact_rates), sd.impact_rate > 0
    (['right'], True)
    """
    model.require_autonomous()
    if not (np.isfinite(h_max) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    n_e, n_p = grid_pair(grid, "rings, angles", (8, 16))
    cells = float(n_e) * float(n_p)
    check_size(f"the phase-plane grid {n_e} x {n_p}", memory=cells * BYTES_PER_CELL,
               detail=f"{cells:.3g} cells x {BYTES_PER_CELL} bytes, about {cells * SECONDS_PER_CELL:.3g} s",
               fix=f"use a coarser grid (the default {DEFAULT_GRID} reaches 1e-3 in L1)")
    if int(points) != points or points < 3:
        raise ParameterError(f"points={points!r} must be an integer >= 3")
    law = restitution if restitution is not None else model.restitution
    left, right = _walls(model, walls)
    t0 = time.perf_counter()
    wall_H = {}
    if right is not None:
        wall_H["right"] = float(model.potential(np.array([right]))[0])
    if left is not None:
        wall_H["left"] = float(model.potential(np.array([left]))[0])
    if not 0.0 < stretch <= 1.0:
        raise ParameterError(f"stretch={stretch!r} must lie in (0, 1]")
    g = RingGrid(h_max, n_e, n_p, wall_H, stretch)
    if arc_end_order not in (1, 2):
        raise ParameterError(f"arc_end_order={arc_end_order!r}; use 1 or 2")
    disc = Discretisation(g, _coefficients(model, law), law.coefficient, impact_order, phase_order, arc_end_order)
    t1 = time.perf_counter()
    p = disc.solve()
    t2 = time.perf_counter()
    out = PhaseDensity(model, g, disc, p, {"assemble": t1 - t0, "solve": t2 - t1}, (left, right))
    out.discretisation = disc  # the operator itself, for first passage and spectra (averaging.phase_plane.passage)
    out.H = np.linspace(0.0, float(h_max), int(points))
    out.p = out.density(out.H)
    return out


def _l1_bins(a: PhaseDensity, b: PhaseDensity, bins: int = L1_BINS) -> float:
    edges = np.linspace(a.h_min, a.h_support, bins + 1)
    return float(np.abs(a.bin_masses(edges) - b.bin_masses(edges)).sum())


FIT_TAIL = 1e-8
"""The ring mass left above the range :func:`stationary_density_xy` fits to the density (see ``h_max`` there)."""


def _first_range(model, h_max: float) -> float:
    """h_max, or less where the no-impact averaged density p0 has fallen by e**-40 below it (p0 has the heavier
    tail, so the mass lies below): rings over [0, 1e300] would hold nothing in floating point. Where the averaged
    coefficients overflow at h_max, the first of sqrt(h_max), h_max**(1/4), ... at which they do not."""
    from ..chain import _NO_LOSS
    from ..quadrature import DEFAULT_NODES
    from ..stationary import _mass_range

    h = h_max
    for _ in range(10):  # 1e300 -> 1e150 -> ... -> 1e9 -> 1e5 -> 10; a model the tables cannot average keeps h_max
        try:
            with np.errstate(all="ignore"):
                fit, covered = _mass_range(model, _NO_LOSS, model.restitution, DEFAULT_NODES, h)
        except (ValueError, ArithmeticError):  # overflow at h (or a model the tables cannot average)
            h = float(np.sqrt(h)) if h > 1e8 else h * 1e-4
            continue
        return fit if covered and np.isfinite(fit) and fit > 0 else h
    return h_max


def _mass_energy(sd: PhaseDensity) -> float:
    """The energy (a ring face) below which all but :data:`FIT_TAIL` of the probability lies."""
    above = 1.0 - np.cumsum(sd.ring_mass) / sd.ring_mass.sum()
    k = int(np.argmax(above <= FIT_TAIL)) if np.any(above <= FIT_TAIL) else len(above) - 1
    return float(sd.H_faces[k + 1])


SCHEMES = ("auto", "rings", "cartesian")
"""Discretisations of :func:`stationary_density_xy`: energy-angle rings (one well), Cartesian cells (any number
of wells), or ``auto``: rings for a single well, Cartesian cells otherwise."""


def is_single_well(model) -> bool:
    """True when x g(x) > 0 between the model's walls (one closed orbit per energy, the rings apply).

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> is_single_well(ImpactOscillator("-x + x**3/4", parameters={"D": 0.5}, barriers=None))
    False
    """
    try:
        model.check_single_well()
    except ModelError:
        return False
    return True


def stationary_density_xy(model, grid=None, h_max: float = 4.0, *, walls="model", restitution=None,
                          points: int = 2000, check: bool = True, tol: float = 0.005,
                          order: float | None = None, scheme: str = "auto",
                          stretch: float = DEFAULT_STRETCH, arc_end_order: int = 1) -> PhaseDensity:
    """Stationary density p(x, y) of ``model`` with impact boundary conditions, and p(H), marginals, impacts.

    Parameters
    ----------
    model : ImpactOscillator
        Any confining g (one well or several), h, f_k / D_kl and restitution law; walls from the model or ``walls``.
    grid : (int, int) or None
        Rings: (rings in H, angle cells per ring), default :data:`DEFAULT_GRID`; Cartesian: (cells in x, cells in
        y), default ``CARTESIAN_GRID``. The cost grows like their product (about 1 s per 30 000 cells).
    h_max : float
        Upper end of the energy range (reflecting); mass above it is lost, so choose it in the tail. Where all but
        :data:`FIT_TAIL` of the mass lies below h_max / 4, the rings are fitted to the mass instead (solved again on
        1.25 times that energy, ``h_support``), so a huge h_max does not put the density into the first few rings;
        ``H`` then follows :func:`averaging.stationary.output_grid`.
    walls, restitution, points
        See :func:`solve_phase_plane`.
    check : bool
        Check confinement and estimate the error of p(H) (L1 on 100 bins, ``error_estimate``; on other bins by
        :meth:`PhaseDensity.estimate_error`) from solves on grids twice and four times coarser (Richardson at the
        observed order, at most ``order``; about 30 % of the cost of the first); warn with :class:`GridWarning` when
        it exceeds ``tol``.
    tol : float
        Target L1 error of p(H) on 100 bins for the grid check.
    order : float, optional
        Convergence order assumed by the estimate (default: :data:`ESTIMATE_ORDER`, the lowest fitted one, on
        rings; 2 on Cartesian cells).
    scheme : {'auto', 'rings', 'cartesian'}
        ``auto``: energy-angle rings for a single well, Cartesian finite volumes (:mod:`.cartesian`) for several
        wells (a double-well Duffing); p(H) then starts at min G < 0.
    stretch : float
        Rings only: the ratio of the innermost ring's width to the uniform one (see :func:`solve_phase_plane`).
    arc_end_order : {1, 2}
        Rings only: the phase flux's order at the ends of the arcs that walls cut (see :func:`solve_phase_plane`).

    Returns
    -------
    PhaseDensity

    Raises
    ------
    NormalisationError
        When the density does not decay towards h_max (energy grows without bound, or h_max far too small), or
        ``scheme='rings'`` is asked for a potential with several wells.
    ModelError
        When the potential does not confine the motion (no wall and G does not grow on a side).

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> sd = stationary_density_xy(DuffingImpact(restitution=Ma(0.4)), grid=(60, 64), check=False)
    >>> list(sd.to_pandas().columns), round(float(sd.bin_masses([0, 4.0])[0]), 9)
    (['H', 'p'], 1.0)
    """
    if scheme not in SCHEMES:
        raise ParameterError(f"scheme={scheme!r}; use one of {', '.join(SCHEMES)}")
    if scheme == "auto":
        scheme = "rings" if is_single_well(model) else "cartesian"
    if scheme == "cartesian":
        from .cartesian import stationary_density_cartesian

        return stationary_density_cartesian(model, grid, h_max, walls=walls, restitution=restitution, points=points,
                                            check=check, tol=tol, order=2.0 if order is None else order)
    grid = DEFAULT_GRID if grid is None else grid
    order = ESTIMATE_ORDER if order is None else order
    if check:
        try:
            model.check_single_well()
        except ModelError as exc:
            raise NormalisationError(f"no stationary density on rings: {exc}; use scheme='cartesian'") from exc
    if not (np.isfinite(h_max) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    check_energy_range(model, float(h_max), walls)
    h = _first_range(model, float(h_max))
    sd = solve_phase_plane(model, grid, h, walls, restitution, points if h == h_max else 3, stretch=stretch,
                           arc_end_order=arc_end_order)
    for _ in range(16):
        # rings spread over a range far wider than the mass would put it into the first few: solve where it is
        top = _mass_energy(sd)
        if top >= sd.grid.H_faces[-1] and h < h_max:  # shrunk too far: the mass reaches the top
            h = min(float(h_max), 4.0 * h)
        elif top >= h / 4.0:
            break
        else:
            h = 1.25 * top
        sd = solve_phase_plane(model, grid, h, walls, restitution, 3, stretch=stretch, arc_end_order=arc_end_order)
    if h < h_max or len(sd.H) != int(points):  # the last solve may have widened back to h_max with 3 points
        sd.h_max = float(h_max)
        sd.H = output_grid(h, float(h_max), int(points))
        sd.p = sd.density(sd.H)
    if not check:
        return sd
    rho = sd.ring_mass / sd.grid.dH
    if rho[-1] > 0.2 * rho.max():
        raise NormalisationError(
            f"p(H) does not decay towards h_max={h_max:g} (p(h_max)/max p = {rho[-1] / rho.max():.2g}): the energy "
            "grows without bound (no confinement) or h_max is far too small; raise h_max or add dissipation"
        )
    tail = float(sd.ring_mass[sd.grid.H_c > 0.9 * h].sum())
    if tail > 1e-4:
        warnings.warn(f"{tail:.2g} of the probability lies in the top 10% of [0, h_max={h_max:g}]: raise h_max",
                      GridWarning, stacklevel=2)
    coarse_grid = (max(8, grid[0] // 2), max(16, grid[1] // 2))
    quarter_grid = (max(8, grid[0] // 4), max(16, grid[1] // 4))
    half = solve_phase_plane(model, coarse_grid, h, walls, restitution, 3, stretch=stretch,
                             arc_end_order=arc_end_order)
    # the third grid costs 1/16 of the first: the observed order (the estimate is safe where convergence is slow)
    quarter = (solve_phase_plane(model, quarter_grid, h, walls, restitution, 3, stretch=stretch,
                                 arc_end_order=arc_end_order)
               if quarter_grid != coarse_grid else None)
    sd._coarse = (half, quarter)
    sd._tail = tail
    law = restitution if restitution is not None else model.restitution
    if any(h_w == 0.0 for h_w in sd.grid.walls.values()) and not law.is_elastic:
        order = min(order, EQUILIBRIUM_ORDER)
    sd._order = order
    est = sd.estimate_error(order=order)
    sd.error_estimate = est
    sd.error_method = (f"three grids: L1(p on {tuple(grid)}, p on {coarse_grid}) / (2**p - 1) (Richardson), p the "
                       f"order observed against {quarter_grid} within [{MIN_ORDER:g}, {order:g}] (the lowest fitted "
                       f"{'with an inelastic wall at the equilibrium' if order < ESTIMATE_ORDER else ''}), "
                       f"+ {tail:.2g} (probability in the top 10 % of [0, h_max], where the reflecting top moves it); "
                       "no model error (the full (x, y) problem is solved)")
    if est > tol:
        warnings.warn(f"grid {tuple(grid)} too coarse: estimated L1 error of p(H) {est:.2g} > tol={tol:g} "
                      "(from the solve on a grid twice coarser); refine the grid", GridWarning, stacklevel=2)
    return sd
