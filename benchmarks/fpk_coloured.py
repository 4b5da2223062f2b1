"""The coloured-noise ``fpk`` solver (OU-filtered impact oscillator): error of p(H) against grid, time and memory.

Model: the OU-filtered Duffing impact oscillator of ``benchmarks/fpk_coloured_mc.py`` (x'' + 0.2 x' + x + 0.2 x**3
= eta, walls at +-0.6, Newton r = 0.8, eta the OU filter output with alpha = 1 and D = 0.1). Reference: the Monte
Carlo histograms stored in ``benchmarks/data/fpk_coloured_mc.npz`` (splitting scheme, 64 paths x 2e5 time units per
seed, two seeds at dt = 0.01, one at dt = 0.005). The L1 of p(H) is taken on 60 bins of width 0.05 on [0, 3]. The
Monte Carlo noise is the L1 between the two seeds at dt = 0.01 over sqrt(2) (one seed), over 2 for their mean; the
time-step bias is bounded by the L1 between dt = 0.005 and that mean (it holds the noise of both).

Baseline measured in the same run: the white-noise solver (rings, default grid) on the oscillator of the same
intensity, the cost of the method the coloured solver generalises (ratio of CPU seconds).

Times are CPU seconds (``time.process_time``; the level factors and GMRES run in one thread), memory the peak
resident size of the process after each solve (it only grows: the largest grid last).
Run: ``python benchmarks/fpk_coloured.py [--quick]``.
"""

from __future__ import annotations

import json
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from averaging.phase_plane import stationary_density_xy  # noqa: E402
from averaging.phase_plane.coloured import COLOURED_GRID, solve_coloured, stationary_density_coloured  # noqa: E402
from benchmarks.fpk_coloured_mc import DATA, model  # noqa: E402

MERGE = 10  # 600 Monte Carlo bins of width 0.005 -> 60 bins of width 0.05


def _masses(data, run):
    counts = data[f"{run}_H"].astype(float)
    return counts[1:-1].reshape(-1, MERGE).sum(axis=1) / counts.sum()


def mc_reference():
    """(edges, masses of the mean of the two dt = 0.01 seeds, L1 noise of that mean)."""
    data = np.load(DATA)
    edges = np.linspace(0.0, 3.0, 601)[::MERGE]
    a, b = _masses(data, "dt0.01_seed1"), _masses(data, "dt0.01_seed2")
    return edges, 0.5 * (a + b), float(np.abs(a - b).sum()) / np.sqrt(2.0) / np.sqrt(2.0)


def mc_summary():
    data = np.load(DATA)
    return {run: json.loads(str(data[f"{run}_info"])) for run in ("dt0.01_seed1", "dt0.01_seed2", "dt0.005_seed3")}


def peak_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9


def main(quick: bool) -> None:
    edges, ref, noise = mc_reference()
    info = mc_summary()
    data = np.load(DATA)
    dt_gap = float(np.abs(_masses(data, "dt0.005_seed3") - ref).sum())
    eh = np.mean([info[r]["E[H]"] for r in ("dt0.01_seed1", "dt0.01_seed2")])
    print(f"Monte Carlo: L1 noise of the reference {noise:.5f}; L1(dt = 0.005, reference) {dt_gap:.5f} (noise of both "
          f"included); E[H] {eh:.5f} (dt 0.01) and {info['dt0.005_seed3']['E[H]']:.5f} ± "
          f"{info['dt0.005_seed3']['E[H]_ci95']:.5f} (dt 0.005)")
    t0 = time.process_time()
    white = stationary_density_xy(model().oscillator, check=False)
    base = time.process_time() - t0
    print(f"baseline: white-noise rings solve, default grid: {base:.2f} CPU s, E[H] {white.mean_energy:.5f}")
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sd = stationary_density_coloured(model())
    cpu = time.process_time() - t0
    h = sd.h_support
    print(f"default call with its check (white-noise start, box fit, the grid and the one twice coarser): {cpu:.2f} "
          f"CPU s, peak {peak_gb():.2f} GB, error estimate {sd.error_estimate:.5f}, L1 against Monte Carlo "
          f"{float(np.abs(sd.bin_masses(edges) - ref).sum()):.5f}, box h = {h:.4g}")
    print(f"grids on that box (h = {h:.4g}):")
    print("   grid (x, y, eta)   cells     GMRES   CPU s   ratio   peak GB   L1 p(H)   E[H]      impact rate")
    grids = [(24, 24, 12), (32, 32, 16), (48, 48, 24), COLOURED_GRID]
    if not quick:
        grids += [(48, 48, 48), (64, 64, 48)]
    for grid in grids:
        t0 = time.process_time()
        sd = solve_coloured(model(), grid, h)
        cpu = time.process_time() - t0
        l1 = float(np.abs(sd.bin_masses(edges) - ref).sum())
        print(f"   {str(grid):18} {sd.grid.n * sd.levels.nz:8d}  {sd.iterations:5d}  {cpu:7.2f}  {cpu / base:6.1f}  "
              f"{peak_gb():7.2f}   {l1:.5f}   {sd.mean_energy:.5f}   {sd.impact_rate:.5f}")


if __name__ == "__main__":
    main("--quick" in sys.argv)
