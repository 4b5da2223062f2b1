"""Monte Carlo references for ``benchmarks/density_accuracy.py``, cached in ``benchmarks/data/mc_references.npz``.

For each energy case of the paper's Figs. 2, 6 and 10-14 two independent half-ensembles (seeds s and s + 1) are
run with the project's engine (``splitting``, weak order 2, at the figure's dt); their histograms of H on 400
bins of [0, h_max] are stored, so the merged histogram, its noise (half the L1 between halves) and the mean
energy with its CI can be recomputed without re-running. A second, coarser dt (2 dt) on a few cases measures
the dt bias. Run: ``python benchmarks/mc_references.py`` (a few minutes on 2 cores; skipped cases are cached).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hybrid.stochastic import simulate_ensemble  # noqa: E402
from vibro.studies.figures.specs import ENERGY_FIGURES, FIGURES  # noqa: E402

DATA = Path(__file__).resolve().parent / "data" / "mc_references.npz"
PATHS = 32  # paths per half
T_SAMPLE = 6000.0  # recorded time per path
BINS = 400
BIAS_CASES = ("f2_1", "f12_0", "f14_0")
HALF_DT_CASES = (
    "f2_0",
    "f6_0",
    "f11_0",
    "f12_0",
    "f12_2",
    "f14_0",
    "eq0.8",
    "eq0.6",
)  # rerun at dt/2 with as many pairs: the dt bias
NOISE_GOAL = 0.0025  # L1 noise aimed at on 100 bins
MAX_FACTOR = 8  # at most 8 pairs of halves per case


def cases(equilibrium: bool = True):
    """(key, figure number, Case, dt, t_burn) for every energy case, then the equilibrium-wall cases (n = 0)."""
    for n in ENERGY_FIGURES:
        spec = FIGURES[n]
        burn = spec.size("default").t_burn
        for i, c in enumerate(spec.cases):
            yield f"f{n}_{i}", n, c, spec.dt, burn
    if equilibrium:
        for r in EQ_RESTITUTION:
            yield f"eq{r}", 0, _EqCase(r), 0.01, 300.0


EQ_RESTITUTION = (0.8, 0.6)
EQ_H_MAX = 4.0


def eq_model(r, wall=1e-9):
    """Linear oscillator x'' + 0.05 x' + x = xi, D = 0.05, one wall at the equilibrium (Newton r).

    The Monte Carlo engine takes the wall at x = 1e-9 (models require left < 0 < right; G(1e-9) = 5e-19 is
    negligible); the phase-plane solver takes it at exactly 0.
    """
    from models import ImpactOscillator, Newton

    return ImpactOscillator(
        "x",
        "c*y",
        parameters={"c": 0.05, "D": 0.05},
        barriers=("-oo", str(wall)),
        restitution=Newton(r),
        name=f"equilibrium-wall-r{r}",
    )


class _EqCase:
    def __init__(self, r):
        self.r, self.h_max, self.label = r, EQ_H_MAX, f"eq r={r}"

    def build(self):
        return eq_model(self.r)


def run_case(case, dt, burn, seed):
    m = case.build()
    x0 = (-0.5, 0.0) if isinstance(case, _EqCase) else (0.0, 0.0)
    out = []
    for k in range(2):
        s = simulate_ensemble(
            m,
            "splitting",
            dt=dt,
            paths=PATHS,
            t_end=burn + T_SAMPLE,
            t_burn=burn,
            seed=seed + k,
            h_max=case.h_max,
            bins=BINS,
            xy_bins=None,
            x0=x0,
        )
        out.append(s)
    return out


def main():
    store = dict(np.load(DATA)) if DATA.exists() else {}
    for j, (key, _n, c, dt, burn) in enumerate(cases()):
        todo = [(key, dt)] + ([(key + "_2dt", 2 * dt)] if key in BIAS_CASES else [])
        for name, step in todo:
            if name + "_a" in store:
                continue
            t0 = time.perf_counter()
            a, b = run_case(c, step, burn, seed=1000 + 10 * j)
            wall = time.perf_counter() - t0
            store[name + "_a"] = a.h_counts
            store[name + "_b"] = b.h_counts
            store[name + "_E"] = np.array([a.mean_energy.value, b.mean_energy.value])
            ea, eb = a.mean_energy, b.mean_energy
            store[name + "_info"] = np.array([c.h_max, step, PATHS, T_SAMPLE, wall, ea.value, ea.ci, eb.value, eb.ci])
            np.savez_compressed(DATA, **store)
            print(f"{name:10s} dt={step:g} E[H]={ea.value:.4f}/{eb.value:.4f} wall={wall:.1f}s", flush=True)
        # noisy cases (low D, slow energy relaxation) get more pairs of halves, up to MAX_FACTOR times the base
        if key + "_pairs" not in store:
            pairs = (
                MAX_FACTOR
                if key.startswith("eq")
                else min(MAX_FACTOR, int(2 ** np.ceil(np.log2(max(1.0, (halves_noise(store, key) / NOISE_GOAL) ** 2)))))
            )
            t0 = time.perf_counter()
            for k in range(1, pairs):
                a, b = run_case(c, dt, burn, seed=100000 + 100 * j + 2 * k)
                store[key + "_a"] = store[key + "_a"] + a.h_counts
                store[key + "_b"] = store[key + "_b"] + b.h_counts
                store[key + "_E"] = np.r_[store.get(key + "_E", []), a.mean_energy.value, b.mean_energy.value]
            store[key + "_pairs"] = np.array([pairs])
            np.savez_compressed(DATA, **store)
            print(
                f"{key:10s} {pairs} pairs, noise {halves_noise(store, key):.4f} (+{time.perf_counter() - t0:.1f}s)",
                flush=True,
            )

    for j, (key, _n, c, dt, burn) in enumerate(cases()):
        name = key + "_half"
        if key not in HALF_DT_CASES or name + "_pairs" in store:
            continue
        t0 = time.perf_counter()
        pairs = int(store[key + "_pairs"][0])
        for k in range(pairs):
            a, b = run_case(c, dt / 2, burn, seed=200000 + 100 * j + 2 * k)
            store[name + "_a"] = store.get(name + "_a", 0) + a.h_counts
            store[name + "_b"] = store.get(name + "_b", 0) + b.h_counts
            store[name + "_E"] = np.r_[store.get(name + "_E", []), a.mean_energy.value, b.mean_energy.value]
        store[name + "_pairs"] = np.array([pairs])
        store[name + "_info"] = np.array([c.h_max, dt / 2, PATHS, T_SAMPLE, time.perf_counter() - t0])
        np.savez_compressed(DATA, **store)
        print(
            f"{name:10s} dt={dt / 2:g} {pairs} pairs, noise {halves_noise(store, name):.4f} "
            f"({time.perf_counter() - t0:.1f}s)",
            flush=True,
        )


def halves_noise(store, key, bins=100):
    """Expected L1 noise of the merged histogram on ``bins`` bins: half the L1 between the two halves."""
    a = store[key + "_a"].reshape(bins, -1).sum(axis=1)
    b = store[key + "_b"].reshape(bins, -1).sum(axis=1)
    return 0.5 * float(np.abs(a / a.sum() - b / b.sum()).sum())


if __name__ == "__main__":
    main()
