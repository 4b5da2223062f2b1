"""The forced ``fpk`` solver (periodic density of a harmonically forced impact oscillator): error against grid and
time, phase-resolved.

1. The forced Duffing impact oscillator of example 08 (c = 0.1, A = 0.5, Omega = 1.2, Newton r = 0.8, walls at
   +-1) at D = 0.02 and D = 0.05: L1 of p(H | t_k) on 40 bins of [0, 4] at the 16 phases t_k = k T / 16 against
   the Monte Carlo of ``vibro mc --phases 16`` (splitting, dt = T / 1056, 128 paths x 3000 periods per seed; the
   histograms are stored in ``benchmarks/data/fpk_forced_mc.npz``). The Monte Carlo noise is the L1 between two
   independent seeds over sqrt(2), divided by sqrt(seeds) for their mean. The baseline, measured in the same run,
   is the previous default: the energy-angle rings (120, 128) with 64 Crank-Nicolson steps.
2. The linear oscillator without walls (c = 0.5, w0 = 1, W = 1.3, A = 0.4, D = 0.05): the largest relative error
   over 8 sections of the means of x and y (relative to their amplitudes) and of their variances, against the
   closed form (Gaussian sections, mean = the periodic response, variance D / c).

Times are CPU seconds (``time.process_time``, 2 shared cores), the check's solve on the grid twice coarser
included; memory is the peak resident size of the process so far (the runs go from small to large).
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

from averaging.phase_plane.cartesian import moments  # noqa: E402
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


def against_mc(runs, D: str = "0.02"):
    """``runs``: (label, keyword arguments of periodic_density_xy); the first is the baseline."""
    edges, ref, noise = mc_reference(D)
    eh, eh_ci, rate = mc_summary(D)
    print(f"Forced Duffing, D = {D}: L1 of p(H | t_k) on {len(edges) - 1} bins against Monte Carlo "
          f"(noise {noise.mean():.4f} mean, {noise.max():.4f} max over the phases); Monte Carlo time-averaged "
          f"E[H] = {eh:.5f} ± {eh_ci:.5f}, impact rate {rate:.5f}")
    print("   run                                  cells  factors  maps   CPU s  peak MB  L1 mean  L1 max   estimate"
          "   E[H]    impact rate")
    base = None
    for label, kw in runs:
        t0 = time.process_time()
        sol = periodic_density_xy(duffing(float(D)), h_max=4.0, phases=PHASES, **kw)
        cpu = time.process_time() - t0
        l1 = np.array([np.abs(s.bin_masses(edges) - r).sum() for s, r in zip(sol.sections(PHASES), ref)])
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        est = "-" if sol.error_estimate is None else (
            f"{sol.error_estimate:.4f}" if sol.time_estimate is None else
            f"{sol.error_estimate:.4f} = {sol.grid_estimate:.4f} + {sol.time_estimate:.4f}")
        print(f"   {label:36s} {sol.grid.n:6d}  {sol.factors:6d}  {sol.iterations:4d}  {cpu:6.1f}  {peak:7.0f}  "
              f"{l1.mean():.4f}   {l1.max():.4f}   {est:8s}  {sol.mean_energy:.4f}  {sol.impact_rate:.4f}", flush=True)
        if base is None:
            base = (l1.mean(), cpu)
        else:
            print(f"      against the baseline: L1 {base[0] / l1.mean():.1f}x smaller, CPU {cpu / base[1]:.2f}x; "
                  "per phase: " + " ".join(f"{v:.4f}" for v in l1))
    print("   Monte Carlo noise per phase: " + " ".join(f"{v:.4f}" for v in noise))


def linear(runs):
    c, w0, W, A, D = 0.5, 1.0, 1.3, 0.4, 0.05
    model = ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t)", barriers=None,
                             parameters={"c": c, "w0": w0, "W": W, "A": A, "D": D})
    z = A / (w0**2 - W**2 + 1j * c * W)
    var = D / (c * w0**2)
    print("Linear oscillator, no walls: largest relative error over 8 sections (mean / amplitude, variance)")
    print("   run                                  CPU s   mean      variance  estimate")
    for label, kw in runs:
        t0 = time.process_time()
        sol = periodic_density_xy(model, h_max=3.0, phases=8, **kw)
        cpu = time.process_time() - t0
        err_m, err_v = 0.0, 0.0
        for t, s in zip(sol.phase_times(8), sol.sections(8)):
            if sol.cells == "cartesian":
                _h, ex2, ey2, mx, my = moments(s.grid, model.potential, s.cell_p)
            else:
                mx, my = s.cell_mass @ s.cell_x, s.cell_mass @ s.cell_y
                ex2, ey2 = s.cell_mass @ s.cell_x**2, s.cell_mass @ s.cell_y**2
            err_m = max(err_m, abs(mx - (z * np.exp(1j * W * t)).real) / abs(z),
                        abs(my - (1j * W * z * np.exp(1j * W * t)).real) / abs(W * z))
            err_v = max(err_v, abs((ex2 - mx**2) / var - 1.0), abs((ey2 - my**2) / var - 1.0))
        est = "-" if sol.error_estimate is None else f"{sol.error_estimate:.1e}"
        print(f"   {label:36s} {cpu:6.1f}   {err_m:.2e}  {err_v:.2e}  {est}", flush=True)


RINGS = {"cells": "rings", "grid": (120, 128), "scheme": "cn", "steps": 64, "check": False}
"""The baseline: the previous default (energy-angle rings, Crank-Nicolson with 64 steps)."""


def main(quick: bool) -> None:
    runs = [("baseline: rings (120, 128), CN 64", RINGS),
            ("(40, 80), CN 32 + 64", {"grid": (40, 80), "steps": 32}),
            ("(60, 120), CN 32 + 64 (previous default)", {"grid": (60, 120), "steps": 32}),
            ("(64, 128), CN 64 + 128 (default)", {})]
    if not quick:
        runs += [("(60, 120), CN 64 alone", {"grid": (60, 120), "scheme": "cn", "steps": 64}),
                 ("(60, 120), CN 16 + 32", {"grid": (60, 120), "steps": 16}),
                 ("(60, 120), CN 64 + 128", {"grid": (60, 120), "steps": 64}),
                 ("(80, 160), CN 32 + 64", {"grid": (80, 160), "steps": 32})]
    against_mc(runs, "0.02")
    if not quick:
        against_mc(runs[:4], "0.05")
    lin = [("rings (120, 128), CN 64", {**RINGS, "grid": (120, 128)}),
           ("(32, 32), CN 64 alone", {"grid": (32, 32), "scheme": "cn", "steps": 64, "check": False}),
           ("(32, 32), CN 16 + 32", {"grid": (32, 32), "steps": 16}),
           ("(32, 32), CN 32 + 64", {"grid": (32, 32), "steps": 32}),
           ("(64, 64), CN 32 + 64", {"grid": (64, 64), "steps": 32})]
    if not quick:
        lin += [("(32, 32), CN 64 + 128", {"grid": (32, 32), "steps": 64}),
                ("(60, 120), CN 32 + 64", {"grid": (60, 120), "steps": 32})]
    linear(lin if not quick else lin[1:4])


if __name__ == "__main__":
    main("--quick" in sys.argv)
