"""Averaging (paper, jump, chain) and fpk on every wall geometry against converged Monte Carlo: L1 of p(H) on 100
bins, E[H], time per method.

Cases (c = 0.05, D = 0.05 throughout):

- one-sided stop at an offset: Duffing x + 0.5 x**3, one wall at x = 0.8 (none on the left), Newton 0.7 and Ma
  V_C = 0.2;
- asymmetric gap: the same spring, walls at -0.6 and 1.0 (levels 0.196 and 0.625), Newton 0.8 and Ma V_C = 0.2;
- a wall at the equilibrium: x'' + 0.05 x' + x = noise on x >= 0, Newton r = 0.8 and 0.6 (every orbit impacts at
  its highest speed, once per half period).

Monte Carlo: the project's engine (``splitting``), two independent halves of 128 paths x 6000 time units after a
burn-in of 200, at dt = 0.01 and again at dt = 0.005. The reference is the dt = 0.005 ensemble; its L1 noise on
100 bins is half the L1 between its halves, and L1(dt, dt/2) bounds the step bias. The averaging densities are
normalised on [0, h_max]; the Monte Carlo masses are counts over all samples (the share above h_max is printed).
L1 and binning come from :mod:`vibro.solve.metrics`. Each averaging time is one call of ``stationary_density``
with empty table caches (the symbolic derivation of the model is warmed up first).

Run:  python benchmarks/geometry_averaging.py   (about 2 minutes on 2 cores)
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from averaging import quadrature as _quadrature  # noqa: E402
from averaging import stationary as _stationary  # noqa: E402
from averaging import stationary_density  # noqa: E402
from averaging.phase_plane import stationary_density_xy  # noqa: E402
from hybrid.stochastic import simulate_ensemble  # noqa: E402
from models import ImpactOscillator, Ma, Newton  # noqa: E402
from vibro.solve.metrics import bin_masses, l1_masses, rebin_counts  # noqa: E402

PATHS = 128  # per half
T_SAMPLE = 6000.0
BURN = 200.0
BINS = 100


def duffing(barriers, law):
    return ImpactOscillator("x + b*x**3", "c*y", parameters={"b": 0.5, "c": 0.05, "D": 0.05}, barriers=barriers,
                            restitution=law)


def equilibrium(r):
    return ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=(0, None), restitution=Newton(r))


CASES = [
    ("one-sided 0.8, Newton 0.7", duffing((None, 0.8), Newton(0.7)), 6.0, (0.0, 0.0)),
    ("one-sided 0.8, Ma V_C=0.2", duffing((None, 0.8), Ma(0.2)), 6.0, (0.0, 0.0)),
    ("asymmetric -0.6/1.0, Newton 0.8", duffing((-0.6, 1.0), Newton(0.8)), 4.0, (0.0, 0.0)),
    ("asymmetric -0.6/1.0, Ma V_C=0.2", duffing((-0.6, 1.0), Ma(0.2)), 4.0, (0.0, 0.0)),
    ("equilibrium wall, Newton 0.8", equilibrium(0.8), 4.0, (0.5, 0.0)),
    ("equilibrium wall, Newton 0.6", equilibrium(0.6), 4.0, (0.5, 0.0)),
]


def monte_carlo(model, h_max, x0, dt, seed):
    t0 = time.perf_counter()
    halves = [simulate_ensemble(model, "splitting", dt=dt, paths=PATHS, t_end=BURN + T_SAMPLE, t_burn=BURN,
                                seed=seed + k, h_max=h_max, bins=4 * BINS, xy_bins=None, x0=x0) for k in (0, 1)]
    wall = time.perf_counter() - t0
    masses = [rebin_counts(s.h_counts, BINS) / s.total("samples") for s in halves]
    both = halves[0].merge(halves[1])
    return {"masses": 0.5 * (masses[0] + masses[1]), "noise": 0.5 * l1_masses(*masses), "E": both.mean_energy,
            "above": 1.0 - float(both.h_counts.sum()) / both.total("samples"), "wall": wall}


def averaging(model, method, h_max):
    stationary_density(model, method, h_max=h_max)  # warm the symbolic derivation and lambdify caches
    _stationary._TABLES.clear()
    _quadrature._GEOMETRY.clear()
    t0 = time.perf_counter()
    sd = stationary_density(model, method, h_max=h_max)
    return sd, time.perf_counter() - t0


def main() -> int:
    rows = []
    head = (f"{'case':34s} {'MC E[H] (dt/2)':>20s} {'noise':>6s} {'dt bias':>7s} | {'paper':>6s} {'jump':>6s} "
            f"{'chain':>6s} {'fpk':>6s} | {'E paper':>8s} {'E jump':>8s} {'E chain':>8s} {'E fpk':>8s} | "
            f"{'t paper':>7s} {'t jump':>6s} {'t chain':>7s} {'t fpk':>6s} {'t MC':>6s}")
    print(head)
    print("-" * len(head))
    for j, (name, model, h_max, x0) in enumerate(CASES):
        mc = monte_carlo(model, h_max, x0, 0.01, 1000 + 10 * j)
        ref = monte_carlo(model, h_max, x0, 0.005, 5000 + 10 * j)
        edges = np.linspace(0.0, h_max, BINS + 1)
        res = {}
        for method in ("paper", "jump", "chain"):
            sd, wall = averaging(model, method, h_max)
            res[method] = (l1_masses(bin_masses(sd.H, sd.p, edges), ref["masses"]),
                           sd.mean_energy / ref["E"].value - 1.0, wall)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sd = stationary_density_xy(model, h_max=h_max)
        res["fpk"] = (l1_masses(sd.bin_masses(edges), ref["masses"]), sd.mean_energy / ref["E"].value - 1.0,
                      time.perf_counter() - t0)
        bias = l1_masses(mc["masses"], ref["masses"])
        E = ref["E"]
        ms = ("paper", "jump", "chain", "fpk")
        line = (f"{name:34s} {E.value:9.5f}±{E.ci:.5f}   {ref['noise']:6.4f} {bias:7.4f} | "
                + " ".join(f"{res[m][0]:6.4f}" for m in ms) + " | " + " ".join(f"{res[m][1]:+8.2%}" for m in ms)
                + " | " + " ".join(f"{res[m][2]:6.3f}s" for m in ms) + f" {ref['wall']:5.1f}s")
        print(line, flush=True)
        rows.append(line)
        if ref["above"] > 1e-4:
            print(f"    ({ref['above']:.2g} of the Monte Carlo samples lie above h_max = {h_max:g})")
    print(f"\nMonte Carlo: splitting, 2 x {PATHS} paths x {T_SAMPLE:g} time units (burn-in {BURN:g}) at dt = 0.005 "
          "(reference) and dt = 0.01; noise = half the L1 between the halves; dt bias = L1(dt, dt/2) (includes "
          "the noise of both).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
