"""Monte Carlo histograms as densities, and the windows they are taken on: shared by the runner and the renderer."""

from __future__ import annotations

import numpy as np

from .specs import Case

JOINT_GRID = 121
"""Analytic joint density grid points per axis (CSV and contour plot)."""


def mc_h_density(stats):
    """Monte Carlo p(H) on the histogram bins."""
    d = stats.h_density()
    return np.asarray(d[1] if isinstance(d, tuple) else d, dtype=float)


def mc_xy_density(stats):
    """Monte Carlo p(x, y) on the joint-histogram cells, shape (ny, nx)."""
    d = stats.xy_density()
    return np.asarray(d[-1] if isinstance(d, tuple) else d, dtype=float)


def mass_outside(stats) -> float:
    """Fraction of Monte Carlo samples above h_max (NaN when the engine does not count them)."""
    total = getattr(stats, "total", None)
    if callable(total):
        try:
            n = total("samples")
            return total("h_over") / n if n else float("nan")
        except (ValueError, KeyError, IndexError):
            pass
    return float("nan")


def xy_outside(stats) -> float:
    """Fraction of samples outside the joint-histogram window (NaN when not counted)."""
    try:
        n = stats.total("samples")
        return stats.total("xy_out") / n if n else float("nan")
    except Exception:  # engine without the count
        return float("nan")


def xy_range(case: Case) -> tuple[tuple[float, float], tuple[float, float]]:
    """Joint-density window: x in [-Δ, Δ] and |y| <= sqrt(2 h_max) (H <= h_max there).

    Examples
    --------
    >>> from vibro.studies.figures import FIGURES
    >>> xy_range(FIGURES[2].cases[1])[0]
    (-1.0, 1.0)
    """
    d = case.delta
    ymax = float(np.sqrt(2.0 * case.h_max))
    return ((-d, d), (-ymax, ymax))
