"""The forced ``fpk`` solver (periodic density of a harmonically forced impact oscillator): error against grid and
time, phase-resolved.

1. The forced Duffing impact oscillator of example 08 (c = 0.1, A = 0.5, Omega = 1.2, Newton r = 0.8, walls at
   +-1) at D = 0.02 and D = 0.05: L1 of p(H | t_k) on 40 bins of [0, 4] at the 16 phases t_k = k T / 16 against
   the Monte Carlo of ``vibro mc --phases 16`` (splitting, dt = T / 1056, 128 paths x 3000 periods per seed; the
   histograms are stored in ``benchmarks/data/fpk_forced_mc.npz``). The Monte Carlo noise is stated as the L1
   between two independent seeds divided by 2 (the noise of their mean, for independent bins).
2. The linear oscillator without walls (c = 0.5, w0 = 1, W = 1.3, A = 0.4, D = 0.05): the largest relative error
   of the section means (relative to the response amplitude) and variances against the closed form.

Times are CPU seconds (``time.process_time``, 2 shared cores); memory is the peak resident size.
Run: ``python benchmarks/fpk_forced.py [--quick]``.
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from averaging.phase_plane.forced import periodic_density_xy  # noqa: E402
from models import ForcedDuffingImpact, ImpactOscillator, Newton  # noqa: E402

DATA = ROOT / "benchmarks" / "data" / "fpk_forced_mc.npz"
PHASES = 16
MERGE = 10  # 400 Monte Carlo bins of width 0.01 -> 40 bins of width 0.1


def mc_reference(D: str):
    """(edges, masses (phases, bins) of the mean of the seeds, noise per phase) for noise level ``D``."""
    data = np.load(DATA)
    edges = data["edges"][::MERGE]
    runs = []
    for key in sorted(k for k in data.files if k.startswith(f"D{D}_seed") and not k.endswith("_summary")):
        counts = data[key].astype(float)
        inside = counts[:, 1:-1].reshape(PHASES, -1, MERGE).sum(axis=2)
        runs.append(inside / counts.sum(axis=1, keepdims=True))
    runs = np.array(runs)
    mean = runs.mean(axis=0)
    # the L1 between two seeds is about sqrt(2) x the noise of one (averaged over the pairs of seeds); the mean of
    # n seeds has 1/sqrt(n) of it
    pairs = [np.abs(runs[i] - runs[j]).sum(axis=1) / np.sqrt(2.0) for i in range(len(runs)) for j in range(i)]
    return edges, mean, np.mean(pairs, axis=0) / np.sqrt(len(runs))


def mc_summary(D: str):
    """(E[H], its 95 % half-width, impact rate) of the time averages, pooled over the seeds."""
    data = np.load(DATA)
    rows = np.array([data[k] for k in data.files if k.startswith(f"D{D}_seed") and k.endswith("_summary")])
    return rows[:, 0].mean(), rows[:, 1].mean() / np.sqrt(len(rows)), rows[:, 2].mean()


def duffing(D: float):
    return ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=D)


def against_mc(grids, D: str = "0.02"):
    edges, ref, noise = mc_reference(D)
    eh, eh_ci, rate = mc_summary(D)
    print(f"Forced Duffing, D = {D}: L1 of p(H | t_k) on {len(edges) - 1} bins against Monte Carlo "
          f"(noise {noise.mean():.4f} mean, {noise.max():.4f} max over the phases); Monte Carlo time-averaged "
          f"E[H] = {eh:.5f} ± {eh_ci:.5f}, impact rate {rate:.5f}")
    print("   grid        steps  cells   factors  GMRES   CPU s   wall s   peak MB   L1 mean   L1 max    E[H]    "
          "impact rate")
    rows, masses_of = [], {}
    for grid, steps in grids:
        t0, w0 = time.process_time(), time.perf_counter()
        sol = periodic_density_xy(duffing(float(D)), grid=grid, steps=steps, h_max=4.0, phases=PHASES)
        cpu, wall = time.process_time() - t0, time.perf_counter() - w0
        masses = np.array([s.bin_masses(edges) for s in sol.sections(PHASES)])
        masses_of[grid] = (masses, cpu)
        l1 = np.abs(masses - ref).sum(axis=1)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"   {str(grid):11s} {steps:5d}  {sol.grid.n:6d}  {sol.factors:7d}  {sol.iterations:5d}  {cpu:6.1f}  "
              f"{wall:7.1f}  {peak:8.0f}   {l1.mean():.4f}    {l1.max():.4f}   {sol.mean_energy:.4f}  "
              f"{sol.impact_rate:.4f}")
        rows.append((grid, steps, l1))
    for (g1, (m1, c1)), (g2, (m2, c2)) in zip(list(masses_of.items()), list(masses_of.items())[1:]):
        if g2 == (2 * g1[0], 2 * g1[1]):
            l1 = np.abs((4.0 * m2 - m1) / 3.0 - ref).sum(axis=1)
            print(f"   Richardson {g1} + {g2}: CPU {c1 + c2:.1f} s, L1 {l1.mean():.4f} mean, {l1.max():.4f} max: "
                  + " ".join(f"{v:.4f}" for v in l1))
    grid, steps, l1 = rows[-1]
    print(f"   per phase at {grid}, {steps} steps: " + " ".join(f"{v:.4f}" for v in l1))
    print("   Monte Carlo noise per phase:           " + " ".join(f"{v:.4f}" for v in noise))
    return rows


def linear(grids):
    c, w0, W, A, D = 0.5, 1.0, 1.3, 0.4, 0.05
    model = ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t)", barriers=None,
                             parameters={"c": c, "w0": w0, "W": W, "A": A, "D": D})
    z = A / (w0**2 - W**2 + 1j * c * W)
    var = D / (c * w0**2)
    print("Linear oscillator, no walls: largest relative error over 8 sections (mean / amplitude, variance)")
    print("   grid        steps   CPU s   mean      variance")
    for grid, steps in grids:
        t0 = time.process_time()
        sol = periodic_density_xy(model, grid=grid, steps=steps, h_max=4.0, phases=8)
        cpu = time.process_time() - t0
        err_m, err_v = 0.0, 0.0
        for t, s in zip(sol.phase_times(8), sol.sections(8)):
            mx = float(s.cell_mass @ s.cell_x)
            vx = float(s.cell_mass @ s.cell_x**2) - mx**2
            err_m = max(err_m, abs(mx - (z * np.exp(1j * W * t)).real) / abs(z))
            err_v = max(err_v, abs(vx / var - 1.0))
        print(f"   {str(grid):11s} {steps:5d}  {cpu:6.1f}   {err_m:.2e}  {err_v:.2e}")


def main(quick: bool) -> None:
    # consecutive grids a factor 2 apart with the same steps also give the Richardson row
    grids = [((60, 64), 64), ((120, 128), 64)]
    if not quick:
        grids += [((80, 96), 64), ((160, 192), 64)]
    against_mc(grids, "0.02")
    if not quick:
        against_mc(grids[:2], "0.05")
    linear(grids[:2] if quick else [grids[0], grids[1], grids[3]])


if __name__ == "__main__":
    main("--quick" in sys.argv)
