"""The command line's side of :func:`hybrid.resolution.check_density`: its fixes, in ``vibro mc``'s options."""

from __future__ import annotations

import math

from hybrid.resolution import AxisSpread, check_density

SPAN_OF_MEAN = 8.0
"""--h-max suggested as this many times the samples' E[H]: an energy whose tail beyond 8 E[H] is small (about
e**-8 for an exponential law), so the histogram spreads its mass over most of its bins."""


def _h_max_fix(mean_energy: float) -> str:
    if not (math.isfinite(mean_energy) and mean_energy > 0):
        return "every sample has H = 0, a point mass that no histogram resolves (no noise, D = 0, from rest?)"
    return f"use --h-max {SPAN_OF_MEAN * mean_energy:.3g} (8 E[H])"


def check_energy_histogram(path, edges, counts, mean_energy: float) -> bool:
    """Warn unless the H histogram written to ``path`` resolves its samples (names --h-max and --bins)."""
    return check_observable_histogram(path, "H", edges, counts, mean_energy, stacklevel=4)


def check_xy_histogram(path, x_edges, y_edges, counts_yx, mean_energy: float) -> bool:
    """Warn unless the (x, y) histogram (counts indexed [y, x]) written to ``path`` resolves its samples.

    Its window is set by --h-max (|y| <= sqrt(2 h_max), x within the walls or the turning points)."""
    import numpy as np

    def hint(spreads: dict) -> str:
        fix = _h_max_fix(mean_energy)
        if fix.startswith("every"):
            return fix
        bins = [spreads[k].cells_needed() if k in spreads else n for k, n in enumerate(np.shape(counts_yx)[::-1])]
        return f"{fix} or --xy-bins {bins[0]} {bins[1]}"

    return check_density(f"the (x, y) histogram in {path}", [x_edges, y_edges], np.asarray(counts_yx).T,
                         axes=["x", "y"], hint=hint, stacklevel=3)


def check_observable_histogram(path, name: str, edges, counts, mean: float, stacklevel: int = 3) -> bool:
    """Warn unless the histogram of observable ``name`` written to ``path`` resolves its samples (names --range)."""

    def hint(spreads: dict) -> str:
        s = spreads[0]
        if name == "H":
            return _energy_fix(s, mean)
        half = max(s.hi - s.lo, 1e-300)
        return (f"use --range {name}={s.lo - half:.4g}:{s.hi + half:.4g}:{s.total_cells} (around the samples) or "
                f"--range {name}={s.start:.4g}:{s.stop:.4g}:{s.cells_needed()}")

    return check_density(f"the {name} histogram in {path}", [edges], counts, axes=[name], hint=hint,
                         stacklevel=stacklevel)


def _energy_fix(s: AxisSpread, mean_energy: float) -> str:
    fix = _h_max_fix(mean_energy)
    return fix if fix.startswith("every") else f"{fix} or --bins {s.cells_needed()}"
