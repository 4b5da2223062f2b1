"""One check, for every density that is written out, that its grid resolves it.

A density is written either as values at grid nodes (``vibro pdf``: p(H), p(x, y)), read with the trapezoid rule,
or as a histogram (``vibro mc``: counts per bin). Both are resolved when, along every axis, the central
:data:`CENTRAL_MASS` of the mass spreads over at least :data:`MIN_CELLS` cells (or half of a coarser grid), and a
sampled density integrates to its mass (and to its mean, when one is printed beside it) on its own grid. Where that
fails, one :class:`~hybrid.errors.DensityResolutionWarning` says where the mass is and what range or cell count
would resolve it. Non-finite values are refused: no NaN or inf is ever written.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from hybrid.errors import DensityResolutionWarning, NormalisationError

MIN_CELLS = 10
"""Fewest cells across the central mass of a resolved density: with fewer, its shape (mode, width) and the moments
read from the written file are off by a sizeable share of a cell."""
CENTRAL_MASS = 0.99
"""The share of the mass (between the 0.5 % and 99.5 % quantiles) whose spread in cells is counted."""
INTEGRAL_TOL = 1e-3
"""Relative tolerance on the integral and the mean of a sampled density on its own grid (trapezoid rule)."""


@dataclass(frozen=True)
class AxisSpread:
    """Where the mass of a density lies along one axis of its grid.

    Attributes
    ----------
    cells : int
        Cells covering the central :data:`CENTRAL_MASS` of the mass (1 for a point mass).
    total_cells : int
        Cells along the axis.
    lo, hi : float
        Edges of those cells: the range holding that mass.
    start, stop : float
        The range of the axis.
    """

    cells: int
    total_cells: int
    lo: float
    hi: float
    start: float
    stop: float

    @property
    def resolved(self) -> bool:
        """At least :data:`MIN_CELLS` cells across the mass (half the grid, where the grid asked for is coarser)."""
        return self.cells >= min(MIN_CELLS, max(1, self.total_cells // 2))

    def cells_needed(self) -> int:
        """Cells along the axis that would put :data:`MIN_CELLS` (times 2, for margin) across the mass."""
        return int(math.ceil(self.total_cells * 2 * MIN_CELLS / max(self.cells, 1)))


def axis_spread(edges, cell_mass) -> AxisSpread:
    """:class:`AxisSpread` of the masses ``cell_mass`` of the cells between ``edges`` (len(edges) - 1 of them).

    Examples
    --------
    >>> s = axis_spread(np.linspace(0.0, 1000.0, 401), np.r_[1.0, 0.2, np.zeros(398)])
    >>> s.cells, s.resolved, s.hi
    (2, False, 5.0)
    >>> axis_spread(np.linspace(0.0, 4.0, 401), np.exp(-np.linspace(0.0, 4.0, 400))).resolved
    True
    """
    edges = np.asarray(edges, dtype=float)
    m = np.clip(np.asarray(cell_mass, dtype=float), 0.0, None)
    total = float(m.sum())
    n = len(m)
    if not total > 0:
        return AxisSpread(0, n, float(edges[0]), float(edges[-1]), float(edges[0]), float(edges[-1]))
    cdf = np.cumsum(m) / total
    tail = 0.5 * (1.0 - CENTRAL_MASS)
    first = int(np.searchsorted(cdf, tail, side="right"))
    last = int(min(np.searchsorted(cdf, 1.0 - tail, side="left"), n - 1))
    first = min(first, last)
    return AxisSpread(last - first + 1, n, float(edges[first]), float(edges[last + 1]), float(edges[0]),
                      float(edges[-1]))


def _marginals(masses: np.ndarray) -> list[np.ndarray]:
    """The cell masses summed over every other axis, one array per axis (axis order of ``masses``)."""
    return [masses.sum(axis=tuple(j for j in range(masses.ndim) if j != k)) if masses.ndim > 1 else masses
            for k in range(masses.ndim)]


def sampled_cell_masses(grids: Sequence, values) -> np.ndarray:
    """Trapezoid masses of the cells of a density given at the nodes of ``grids`` (values indexed like the grids).

    Examples
    --------
    >>> float(sampled_cell_masses([np.linspace(0, 1, 3)], np.ones(3)).sum())
    1.0
    """
    v = np.asarray(values, dtype=float)
    for k, g in enumerate(grids):
        w = np.diff(np.asarray(g, dtype=float))
        lo = np.take(v, np.arange(len(w)), axis=k)
        hi = np.take(v, np.arange(1, len(w) + 1), axis=k)
        shape = [1] * v.ndim
        shape[k] = len(w)
        v = 0.5 * (lo + hi) * w.reshape(shape)
    return v


def check_density(what: str, edges: Sequence, masses, *, hint: Callable[[dict[int, AxisSpread]], str],
                  axes: Sequence[str] | None = None, mass: float | None = None, mean: float | None = None,
                  sampled_on: Sequence | None = None, mass_tol: float = INTEGRAL_TOL, refine: str = "",
                  stacklevel: int = 2) -> bool:
    """Warn unless the density ``what`` is resolved by its grid; True when it is.

    Parameters
    ----------
    what : str
        What is written, for the message (``"p(H) in p.csv"``).
    edges : sequence of arrays
        Cell edges per axis (a sampled density: its grid nodes).
    masses : array
        Cell masses (a histogram's counts), or, with ``sampled_on``, the density's values at the nodes.
    hint : callable ({axis index: AxisSpread of each unresolved axis}) -> str
        The fix, in the caller's own words and option names (e.g. ``"use --h-max 5.1 or --bins 3200"``).
    axes : sequence of str
        Axis names (default H for one axis, x and y for two).
    mass, mean : float, optional
        What a sampled density must integrate to on its own grid, and its mean along the first axis as printed
        beside it (both to :data:`INTEGRAL_TOL`; the mean for a one-axis density).
    sampled_on : sequence of arrays, optional
        The grid of a sampled density (its nodes): ``masses`` are then values at the nodes.
    mass_tol : float
        Relative tolerance on ``mass`` (a density with jumps inside its grid, such as p(x, y) at the walls, is
        integrated only to first order in the cell size).
    refine : str
        The fix when only the integral or the mean is off (e.g. ``"use --points 8000"``).

    Raises
    ------
    NormalisationError
        A value is not finite (nothing is written).

    Examples
    --------
    >>> import warnings
    >>> H = np.linspace(0.0, 1000.0, 2000)
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     ok = check_density("p(H)", [H], 2 * np.exp(-2 * H), sampled_on=[H], mass=1.0,
    ...                        hint=lambda spreads: f"use h_max {4 * spreads[0].hi:.3g}")
    >>> ok, len(w), "integrates to" in str(w[0].message), "use h_max" in str(w[0].message)
    (False, 1, True, True)
    """
    values = np.asarray(masses, dtype=float)
    if not np.all(np.isfinite(values)):
        bad = int(np.count_nonzero(~np.isfinite(values)))
        raise NormalisationError(f"{what}: {bad} of its {values.size} values are not finite (NaN or inf); nothing "
                                 "is written")
    axes = list(axes) if axes is not None else (["H"] if values.ndim == 1 else ["x", "y"][:values.ndim])
    problems = []
    if sampled_on is not None:
        cells = sampled_cell_masses(sampled_on, values)
        total = float(cells.sum())
        if mass is not None and not abs(total - mass) <= mass_tol * max(mass, 1e-300):
            problems.append(f"{what} integrates to {total:.6g} on its own grid (trapezoid), not {mass:.6g}")
        if mean is not None and total > 0:  # p(H) only: the trapezoid rule on H p, as a reader would apply it
            H = np.asarray(sampled_on[0], dtype=float)
            got = float(np.sum(sampled_cell_masses([H], H * values)) / total)
            if not abs(got - mean) <= INTEGRAL_TOL * max(abs(mean), 1e-300):
                problems.append(f"{what} has mean {got:.6g} on its own grid against the printed {mean:.6g}")
    else:
        cells = values
    unresolved = {}
    for k, (e, m) in enumerate(zip(edges, _marginals(np.asarray(cells)))):
        s = axis_spread(e, m)
        if not s.resolved and s.cells:
            unresolved[k] = s
            where = ("a single cell" if s.cells == 1 else f"{s.cells} of its {s.total_cells} cells")
            problems.append(f"{'' if len(unresolved) > 1 else what + ' is '}not resolved along {axes[k]}: "
                            f"{CENTRAL_MASS:.0%} of its mass lies in {where} ([{s.lo:.4g}, {s.hi:.4g}] of "
                            f"[{s.start:.4g}, {s.stop:.4g}])" + (", a point mass or a range far wider than the mass"
                                                                 if s.cells == 1 else ""))
    if not problems:
        return True
    fix = (hint(unresolved) if unresolved else "") or refine
    warnings.warn("; ".join(problems) + (f": {fix}" if fix else ""), DensityResolutionWarning,
                  stacklevel=stacklevel + 1)
    return False


__all__ = ["CENTRAL_MASS", "INTEGRAL_TOL", "MIN_CELLS", "AxisSpread", "axis_spread", "check_density",
           "sampled_cell_masses"]
