"""The phase-plane solver on Cartesian cells (``scheme="cartesian"``): potentials with several wells.

See :mod:`._cartesian` for the discretisation and why; this module turns its solution into the same result as the
ring solver (:class:`~averaging.phase_plane.solver.PhaseDensity`: p(H), the joint density, marginals, impacts).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from hybrid.errors import NormalisationError, ParameterError
from hybrid.sizes import check_size

from ..stationary import output_grid
from ._cartesian import (
    CartesianDiscretisation,
    CartesianGrid,
    _slopes,
    confining_range,
    critical_energies,
    energy_cdf,
    point_values,
)
from ._core import null_vector
from ._monotone import MonotoneCubic
from .solver import BYTES_PER_CELL, SECONDS_PER_CELL, GridWarning, PhaseDensity, _coefficients, _walls, grid_pair

CARTESIAN_GRID = (120, 120)
"""(cells in x, cells in y): L1 about 1e-5 of the joint density on the bistable Duffing benchmark (D/c = 0.5)."""
ENERGY_FACES = 4
"""Energy faces of the p(H) interpolant per cell of the longer grid side."""


class CartesianDensity(PhaseDensity):
    """The stationary density on Cartesian (x, y) cells: the interface of :class:`PhaseDensity`.

    ``H`` and ``p`` cover [h_min, h_max], h_min = min G (negative below a saddle at G = 0, as in a double well);
    ``cell_x``, ``cell_y``, ``cell_p``, ``cell_mass`` are the cells and their averages; ``H_faces`` and
    ``ring_mass`` bin the mass on a fine energy grid (with a face at every well bottom, saddle and wall energy), from
    the piecewise-linear density integrated exactly across the level sets.
    """

    scheme = "cartesian"

    def __init__(self, model, grid: CartesianGrid, disc: CartesianDiscretisation, p, timing, walls):
        self.model = model
        self.grid = grid
        self.h_max = self.h_support = grid.h_max
        self.h_min = grid.g_min
        self.timing = timing
        self.walls = walls
        self._coarse_solve = None  # the solve on a grid twice coarser (stationary_density_cartesian's check)
        self._estimate_order = 2.0
        self.error_method = "not estimated (no check)"
        self.cell_x, self.cell_y = grid.x, grid.y
        self.cell_H = 0.5 * grid.y**2 + model.potential(grid.x)
        self.cell_psi = None
        self.cell_p = p
        self.cell_mass = p * disc.mass_weight
        Ap = disc.A @ p
        scale = float(np.max(abs(disc.A) @ np.abs(p)))
        self.residual = float(np.max(np.abs(Ap)) / scale) if scale > 0 else 0.0
        self.conservation = float(np.max(np.abs(np.asarray(disc.A.sum(axis=0)))))
        px, py = _slopes(grid, p)
        n_f = ENERGY_FACES * max(grid.nx, grid.ny)
        special = [grid.g_min, grid.h_max, *critical_energies(model.potential, grid.x_faces[0], grid.x_faces[-1])]
        special += [float(model.potential(np.array([w]))[0]) for w in grid.walls.values()]
        faces = np.linspace(grid.g_min, grid.h_max, n_f + 1)
        faces = np.unique(np.clip(np.concatenate([faces, special]), grid.g_min, grid.h_max))
        faces = faces[np.concatenate([[True], np.diff(faces) > 1e-9 * (grid.h_max - grid.g_min)])]
        self._linear = (p, px, py)
        cdf = energy_cdf(grid, model.potential, p, px, py, faces)
        cdf[0], cdf[-1] = 0.0, 1.0  # the normalisation (sum of the cell masses) up to round-off
        cdf = np.maximum.accumulate(cdf)
        self.H_faces = faces
        self.ring_mass = np.diff(cdf)
        self._cdf = MonotoneCubic(faces, cdf)
        self._pdf = self._cdf.derivative()
        self.mean_energy, self.mean_x2, self.mean_y2 = moments(grid, model.potential, p, px, py)[:3]
        wall_H = [float(model.potential(np.array([x]))[0]) for x in grid.walls.values()]
        self.prob_below_barrier = float(self._cdf(min(min(wall_H), grid.h_max))) if wall_H else 1.0
        self.impact_rates, self._impacts = {}, {}
        for side in disc.walls:
            v, flux = disc.wall_flux(p, side)
            self.impact_rates[side] = float(np.sum(flux))
            self._impacts[side] = (v, flux)
        self.impact_rate = float(sum(self.impact_rates.values()))
        self.error_estimate = None
        full = np.zeros((grid.nx, grid.ny))
        full[grid.i, grid.j] = point_values(grid, p)
        bbox = [grid.x_faces[0], grid.x_faces[-1], grid.y_faces[0], grid.y_faces[-1]]
        from scipy.interpolate import RectBivariateSpline  # here: it imports scipy.optimize and scipy.special

        self._spline = RectBivariateSpline(grid.xc, grid.yc, full, bbox=bbox, kx=3, ky=3, s=0)
        self.H = np.array([])
        self.p = np.array([])

    def estimate_error(self, edges=None, order: float | None = None) -> float:
        """L1 error of p(H) on the bins ``edges`` (default 100 bins of [h_min, h_max]) from two grids.

        The distance to the solve on a grid twice coarser (kept by :func:`stationary_density_cartesian`) over
        2**order - 1 (Richardson; ``order`` 2 by default, conservative: the scheme converges at order 2 next to
        inelastic walls and 4 to 5 elsewhere). NaN without that check.

        Examples
        --------
        >>> from models import ImpactOscillator
        >>> m = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
        >>> sd = stationary_density_cartesian(m, grid=(40, 40), h_max=7.0)
        >>> 0 < sd.estimate_error(np.linspace(-1.0, 7.0, 41)) < 0.01
        True
        """
        if self._coarse_solve is None:
            return float("nan")
        if edges is None:
            edges = np.linspace(self.h_min, self.h_support, 101)
        order = self._estimate_order if order is None else float(order)
        gap = np.abs(self.bin_masses(edges) - self._coarse_solve.bin_masses(edges)).sum()
        return float(gap) / (2.0**order - 1.0)

    def bin_masses(self, edges):
        """Probability of each energy bin [edges[k], edges[k+1]]: the piecewise-linear density integrated exactly
        across the level sets at the edges themselves (no interpolation in H, which the logarithmic peak of p(H) at
        a saddle's energy would spoil).

        Examples
        --------
        >>> from models import ImpactOscillator
        >>> m = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
        >>> sd = solve_cartesian(m, grid=(40, 40), h_max=8.0)
        >>> round(float(sd.bin_masses([-1.0, 0.0, 8.0]).sum()), 6)
        1.0
        """
        edges = np.clip(np.asarray(edges, dtype=float), self.h_min, self.h_support)
        F = energy_cdf(self.grid, self.model.potential, *self._linear, edges)
        F[edges >= self.h_support] = 1.0
        F[edges <= self.h_min] = 0.0
        return np.diff(F)

    def impact_speed_density(self, side: str = "right"):
        """(v, f): impact speeds at wall ``side`` (the incoming cells' centres) and their density over impacts.

        Examples
        --------
        >>> from models import ImpactOscillator, Elastic
        >>> m = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5, "delta": 2.5})
        >>> sd = solve_cartesian(m, grid=(40, 40), h_max=6.0)
        >>> v, f = sd.impact_speed_density("right")
        >>> round(float(np.sum(f) * (v[1] - v[0])), 9)
        1.0
        """
        if side not in self._impacts:
            raise ParameterError(f"no wall on the {side!r} side; walls: {sorted(self._impacts)}")
        v, flux = self._impacts[side]
        return v, flux / (self.impact_rates[side] * self.grid.hy)

    def joint(self, x, y):
        """p(x, y) on the grid x (nx) by y (ny) -> array (ny, nx): a bicubic spline through the point values at the
        cell centres (fourth-order deconvolution of the averages); 0 outside the walls and the box.

        Examples
        --------
        >>> from models import ImpactOscillator
        >>> m = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
        >>> solve_cartesian(m, grid=(40, 40), h_max=6.0).joint(np.linspace(-2, 2, 5), np.zeros(3)).shape
        (3, 5)
        """
        x = np.atleast_1d(np.asarray(x, dtype=float))
        y = np.atleast_1d(np.asarray(y, dtype=float))
        g = self.grid
        inside_x = (x >= g.x_faces[0]) & (x <= g.x_faces[-1])
        inside_y = (y >= g.y_faces[0]) & (y <= g.y_faces[-1])
        val = np.zeros((len(y), len(x)))
        if inside_x.any() and inside_y.any():
            xs, ys = x[inside_x], y[inside_y]
            ox, oy = np.argsort(xs), np.argsort(ys)
            v = np.empty((len(xs), len(ys)))
            v[np.ix_(ox, oy)] = self._spline(xs[ox], ys[oy], grid=True)
            H = 0.5 * ys[None, :] ** 2 + self.model.potential(xs)[:, None]
            v = np.where(H <= self.h_support, np.maximum(v, 0.0), 0.0)  # no mass above h_max: the spline's ringing
            val[np.ix_(inside_y, inside_x)] = v.T
        return val

    def _x_range(self):
        return float(self.grid.x_faces[0]), float(self.grid.x_faces[-1])

    def metadata(self) -> dict:
        """Method, scheme, model, grid and summary statistics (JSON-friendly)."""
        return {
            "method": self.method, "scheme": self.scheme, "model": self.model.describe(), "h_min": self.h_min,
            "h_max": self.h_max, "grid": [int(self.grid.nx), int(self.grid.ny)], "cells": int(self.grid.n),
            "walls": list(self.walls), "mean_energy": self.mean_energy, "mean_x2": self.mean_x2,
            "prob_below_barrier": self.prob_below_barrier, "impact_rate": self.impact_rate,
            "residual": self.residual, "conservation": self.conservation, "error_estimate": self.error_estimate,
        }

    def __repr__(self) -> str:
        return (f"PhaseDensity(model={self.model.name!r}, method='fpk', scheme='cartesian', cells={self.grid.n}, "
                f"E[H]={self.mean_energy:.6g}, impact_rate={self.impact_rate:.6g})")


def moments(grid, potential, p, px=None, py=None):
    """(E[H], E[x**2], E[y**2], E[x], E[y]) of the piecewise-linear density p + px (x - x_c) + py (y - y_c) on the
    cells (3 x 3 Gauss points per cell; the slopes from :func:`._cartesian._slopes` when not given).

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("x", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
    >>> sd = solve_cartesian(m, grid=(40, 40), h_max=8.0)
    >>> [round(float(v), 3) + 0.0 for v in moments(sd.grid, m.potential, sd.cell_p)]  # D / c = 0.5: E[x**2], E[y**2]
    [0.5, 0.5, 0.5, 0.0, 0.0]
    """
    if px is None:
        px, py = _slopes(grid, p)
    t, w = np.polynomial.legendre.leggauss(3)
    xq = grid.x[:, None, None] + 0.5 * grid.hx * t[None, :, None]
    yq = grid.y[:, None, None] + 0.5 * grid.hy * t[None, None, :]
    pq = p[:, None, None] + px[:, None, None] * (xq - grid.x[:, None, None]) \
        + py[:, None, None] * (yq - grid.y[:, None, None])
    wpq = grid.hx * grid.hy * w[None, :, None] * w[None, None, :] / 4.0 * pq
    Hq = 0.5 * yq * yq + potential(xq)
    return tuple(float(np.sum(wpq * f)) for f in (Hq, xq * xq, yq * yq, xq, yq))


def solve_cartesian(model, grid=CARTESIAN_GRID, h_max: float = 4.0, walls="model", restitution=None,
                    points: int = 2000) -> CartesianDensity:
    """One solve on Cartesian cells, no accuracy check: any confining potential, one or several wells.

    Parameters
    ----------
    model : ImpactOscillator
        g, the Itô drift, sigma**2 and, by default, the walls and the restitution law.
    grid : (int, int)
        Cells in x and in y (y rounded up to even, so that y = 0 is a face).
    h_max : float
        Upper energy; the cells above it are left out (zero flux). Energies start at min G.
    walls, restitution, points
        See :func:`~averaging.phase_plane.solve_phase_plane`.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
    >>> sd = solve_cartesian(m, grid=(60, 60), h_max=8.0)
    >>> round(sd.h_min, 6), round(float(sd.bin_masses([-1.0, 8.0])[0]), 9)
    (-1.0, 1.0)
    """
    model.require_autonomous("the stationary phase-plane equations")
    if not (np.isfinite(h_max)):
        raise ParameterError(f"h_max={h_max!r} must be a finite energy")
    nx, ny = grid_pair(grid, "cells in x, cells in y", (8, 8))
    cells = float(nx) * float(ny)
    check_size(f"the phase-plane grid {nx} x {ny}", memory=cells * BYTES_PER_CELL,
               detail=f"{cells:.3g} cells x {BYTES_PER_CELL} bytes, about {cells * SECONDS_PER_CELL:.3g} s",
               fix=f"use a coarser grid (the default {CARTESIAN_GRID} reaches 1e-5 in L1 on the bistable Duffing)")
    if int(points) != points or points < 3:
        raise ParameterError(f"points={points!r} must be an integer >= 3")
    law = restitution if restitution is not None else model.restitution
    left, right = _walls(model, walls)
    t0 = time.perf_counter()
    lo, hi, g_min = confining_range(model.potential, float(h_max), left, right)
    if not h_max > g_min:
        raise ParameterError(f"h_max={h_max:g} must lie above the lowest potential energy min G = {g_min:.6g}")
    wall_x = {k: v for k, v in (("left", left), ("right", right)) if v is not None}
    g = CartesianGrid(lo, hi, g_min, float(h_max), nx, ny, model.potential, wall_x)
    disc = CartesianDiscretisation(g, _coefficients(model, law), law.coefficient)
    t1 = time.perf_counter()
    p = null_vector(disc.A, disc.mass_weight)
    t2 = time.perf_counter()
    out = CartesianDensity(model, g, disc, p, {"assemble": t1 - t0, "solve": t2 - t1}, (left, right))
    out.H = np.linspace(g_min, float(h_max), int(points))
    out.p = out.density(out.H)
    return out


def stationary_density_cartesian(model, grid=None, h_max: float = 4.0, *, walls="model", restitution=None,
                                 points: int = 2000, check: bool = True, tol: float = 0.005,
                                 order: float = 2.0) -> CartesianDensity:
    """:func:`solve_cartesian` with the checks of :func:`~averaging.phase_plane.stationary_density_xy`.

    The energy range is fitted to the mass (solved again on min G + 1.25 (top - min G) where all but
    ``FIT_TAIL`` of it lies in the lowest quarter of [min G, h_max]); with ``check`` the density must decay towards
    h_max, and the L1 error of p(H) on 100 bins is estimated from a solve on a grid twice coarser (Richardson with
    ``order``: 2 is conservative, the scheme converges at order 2 next to inelastic walls and 4 to 5 elsewhere).

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
    >>> sd = stationary_density_cartesian(m, grid=(60, 60), h_max=10.0)
    >>> sd.scheme, round(sd.mean_energy, 3)
    ('cartesian', -0.477)
    """
    from .solver import FIT_TAIL, _l1_bins

    grid = CARTESIAN_GRID if grid is None else grid
    h = float(h_max)
    sd = solve_cartesian(model, grid, h, walls, restitution, points)
    for _ in range(16):
        # a range far wider than the mass would put it into a few cells: solve where it is
        above = 1.0 - np.cumsum(sd.ring_mass)
        k = int(np.argmax(above <= FIT_TAIL)) if np.any(above <= FIT_TAIL) else len(above) - 1
        top = float(sd.H_faces[k + 1])
        if top >= sd.h_min + 0.25 * (h - sd.h_min):
            break
        h = sd.h_min + 1.25 * (top - sd.h_min)
        sd = solve_cartesian(model, grid, h, walls, restitution, 3)
    report_up_to(sd, h, h_max, points)
    if not check:
        return sd
    box_top_mass(sd, h, stacklevel=4)
    coarse = solve_cartesian(model, (max(8, grid[0] // 2), max(8, grid[1] // 2)), h, walls, restitution, 3)
    est = _l1_bins(sd, coarse) / (2.0**order - 1.0)
    sd.error_estimate = est
    sd._coarse_solve, sd._estimate_order = coarse, float(order)
    sd.error_method = (f"two grids: L1(p on {tuple(grid)}, p on the grid twice coarser) / (2**{order:g} - 1) "
                       "(Richardson at order 2, the lowest the Cartesian scheme shows; no model error: the full "
                       "(x, y) problem is solved)")
    if est > tol:
        warnings.warn(f"grid {tuple(grid)} too coarse: estimated L1 error of p(H) {est:.2g} > tol={tol:g} "
                      "(from the solve on a grid twice coarser); refine the grid", GridWarning, stacklevel=3)
    return sd


def report_up_to(sd, h: float, h_max: float, points: int) -> None:
    """Report p(H) of ``sd``, solved in the box [min G, h], on [min G, h_max] when the box stops below h_max."""
    if h < h_max:
        sd.h_max = float(h_max)
        sd.H = sd.h_min + output_grid(h - sd.h_min, float(h_max) - sd.h_min, int(points))
        sd.p = sd.density(sd.H)


def box_top_mass(sd, h: float, stacklevel: int = 3) -> float:
    """The probability in the top tenth of the box [min G, h] of ``sd``: refuse a p(H) that does not decay towards
    h, warn (:class:`GridWarning`) when that tenth holds more than 1e-4."""
    rho = sd.ring_mass / np.diff(sd.H_faces)
    if rho[-1] > 0.2 * rho.max():
        raise NormalisationError(
            f"p(H) does not decay towards the top of the box h = {h:.4g} (p(h)/max p = {rho[-1] / rho.max():.2g}): "
            "the energy grows without bound (no confinement) or h_max is far too small; raise h_max or add "
            "dissipation")
    centre = 0.5 * (sd.H_faces[1:] + sd.H_faces[:-1])
    tail = float(sd.ring_mass[centre > sd.h_min + 0.9 * (h - sd.h_min)].sum())
    if tail > 1e-4:
        warnings.warn(f"{tail:.2g} of the probability lies in the top 10% of the box [min G, {h:.4g}]: raise h_max",
                      GridWarning, stacklevel=stacklevel)
    return tail
