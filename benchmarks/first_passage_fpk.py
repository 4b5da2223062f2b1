"""First passage of Example 1's energy by fpk: accuracy and cost against the Monte Carlo reference, and the
converged fpk answer that explains the residual.

    python benchmarks/first_passage_fpk.py table       # default grid per level, with check: -> first_passage_fpk.json
    python benchmarks/first_passage_fpk.py converged   # rings to 960 (Richardson) and angles to 512, per level,
                                                       # and the Cartesian cross-check at H_c = 2
                                                       # -> first_passage_fpk_converged.json

``table`` prints, per level, the grid ``vibro.first_passage`` uses by default, the mean time, the Monte Carlo
reference with its 95 % CI (``first_passage_reference.json``), the error, the two-direction error estimate
(half the rings, half the angles) and the CPU seconds of the whole call (``time.process_time``, one process,
the estimate's two extra solves included), with the CPU time of the 240 x 256 grid measured in the same run as
the baseline. ``converged`` gives the answer of the same discretisation with both grid errors removed (order 1
in the rings, measured clean from 120 to 1920 rings; the angle error read from 256 -> 512 at 480 rings) and that
of an independent discretisation on Cartesian cells, where the walls are cell faces and the level a staircase
(order 1, two grids).
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from averaging.phase_plane import first_passage_fpk
from averaging.phase_plane.passage import PASSAGE_GRID, BackwardProblem
from models import DuffingImpact, Ma

DATA = Path(__file__).resolve().parent / "data"
LEVELS = (0.25, 0.5, 1.0, 1.5, 2.0)
BASELINE_GRID = (240, 256)


def example1():
    return DuffingImpact(restitution=Ma(vc=0.4))


def _mean(model, H_c, grid, check=False):
    c0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = first_passage_fpk(model, f"H < {H_c}", grid=grid, check=check, survival=False)
    return r, time.process_time() - c0


def table():
    model = example1()
    ref = json.loads((DATA / "first_passage_reference.json").read_text())["levels"]
    out = {}
    print("| H_c | grid | fpk | reference +- 95% CI | error % | estimate | CPU s | CPU s 240x256 (ratio) |")
    for H_c in LEVELS:
        grid = PASSAGE_GRID
        r, cpu = _mean(model, H_c, grid, check=True)
        base, cpu_base = _mean(model, H_c, BASELINE_GRID)
        row = ref[str(H_c)]
        err = r.mean_time / row["mean"] - 1
        out[str(H_c)] = {"grid": list(grid), "mean": r.mean_time, "estimate": r.error_estimate,
                         "coarse_rings": r.details["mean_time_coarse_rings"],
                         "coarse_angles": r.details["mean_time_coarse_angles"], "cpu_seconds_with_check": cpu,
                         "reference": row["mean"], "reference_ci95": row["ci95"], "relative_error": err,
                         "baseline_grid": list(BASELINE_GRID), "baseline_mean": base.mean_time,
                         "baseline_cpu_seconds": cpu_base}
        print(f"| {H_c} | {grid[0]}x{grid[1]} | {r.mean_time:.5g} | {row['mean']:.5g} +- {row['ci95']:.2g} | "
              f"{100 * err:+.2f} | {r.error_estimate:.3g} ({100 * r.error_estimate / r.mean_time:.2f} %) | {cpu:.2f} | "
              f"{cpu_base:.2f} ({cpu_base / cpu:.1f}x) |", flush=True)
    (DATA / "first_passage_fpk.json").write_text(json.dumps(out, indent=1) + "\n")


def cartesian_mean(model, H_c, grid):
    """Mean time from rest on Cartesian cells (cells with centre H < H_c safe), bilinear at the origin."""
    from averaging.phase_plane._cartesian import CartesianDiscretisation, CartesianGrid, confining_range
    from averaging.phase_plane.solver import _coefficients

    h_top = 1.08 * H_c  # the cells above are absorbing anyway
    lo, hi, g_min = confining_range(model.potential, h_top, -1.0, 1.0)
    g = CartesianGrid(lo, hi, g_min, h_top, grid[0], grid[1], model.potential, {"left": -1.0, "right": 1.0})
    disc = CartesianDiscretisation(g, _coefficients(model, model.restitution), model.restitution.coefficient)
    safe = np.flatnonzero(model.energy(g.x, g.y) < H_c)
    T = np.zeros(g.n)
    T[safe] = BackwardProblem(disc.A[safe][:, safe].T.tocsc(), disc.mass_weight[safe]).mean_time()
    near = np.argsort(np.hypot(g.x / g.hx, g.y / g.hy))[:4]  # x = 0 and y = 0 are faces (nx, ny even)
    return float(T[near].mean())


def converged(cartesian_grids=((300, 600), (400, 800))):
    model = example1()
    out = {}
    for H_c in LEVELS:
        rings = {n: _mean(model, H_c, (n, 256))[0].mean_time for n in (240, 480, 960)}
        angles_512 = _mean(model, H_c, (480, 512))[0].mean_time
        ring_limit = 2 * rings[960] - rings[480]  # order 1
        angle_correction = angles_512 - rings[480]  # the 256 -> 512 step; order >= 2 leaves at most 1/3 of it
        row = {"rings_256_angles": rings, "480x512": angles_512, "ring_richardson": ring_limit,
               "angle_correction": angle_correction, "converged": ring_limit + angle_correction,
               "uncertainty": abs(ring_limit - (2 * rings[480] - rings[240])) + abs(angle_correction) / 3}
        if H_c == 2.0 and cartesian_grids:
            (n1, _), (n2, _) = cartesian_grids
            c = [cartesian_mean(model, H_c, g) for g in cartesian_grids]
            row["cartesian"] = {f"{g[0]}x{g[1]}": v for g, v in zip(cartesian_grids, c)}
            row["cartesian_richardson"] = (n2 * c[1] - n1 * c[0]) / (n2 - n1)  # order 1 in the cell size
        out[str(H_c)] = row
        print(json.dumps({str(H_c): row}), flush=True)
    (DATA / "first_passage_fpk_converged.json").write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "table"
    if what not in ("table", "converged"):
        print(__doc__)
        sys.exit(2)
    table() if what == "table" else converged()
