"""Where does fpk's +1.2 % at H_c = 2 (Example 1) come from? The same first passage with three restitution laws.

Example 1 (Duffing a = 1, b = 0.2, c = 0.025, D = 0.05, walls at +-1) from rest, T = first time H >= H_c, with
elastic walls, a constant Newton law e = 0.8 and Ma V_C = 0.4. fpk on two ring grids (order 1 in the rings,
Richardson) against Monte Carlo with the continuity-corrected level of ``first_passage_reference.py`` (same
machinery: ``simulate_first_passage``, scheme ``splitting``, tail term added). Results in
docs/results/first-passage-spectra.md.

    python benchmarks/first_passage_laws.py fpk LAW H_c                 # LAW: elastic | newton | ma
    python benchmarks/first_passage_laws.py mc LAW H_c DT PATHS SEED T_MAX
    python benchmarks/first_passage_laws.py impact LAW       # one noise-free impact: engine vs closed form
    python benchmarks/first_passage_laws.py overshoot LAW    # noise-free: how far below H_c the exit fires
    python benchmarks/first_passage_laws.py shifted LAW      # fpk with the level moved near the walls
    python benchmarks/first_passage_laws.py step_end LAW H_c DT PATHS SEED T_MAX   # level read on step ends only

Each mc/fpk run appends one JSON line to ``benchmarks/data/first_passage_laws.jsonl``.
"""

from __future__ import annotations

import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from hybrid import HybridAutomaton
from models import DuffingImpact, Elastic, Ma, Newton

DATA = Path(__file__).resolve().parent / "data"
OUT = DATA / "first_passage_laws.jsonl"
LAWS = {"elastic": Elastic, "newton": lambda: Newton(0.8), "ma": lambda: Ma(vc=0.4)}


def model_of(law):
    return DuffingImpact(restitution=LAWS[law]())


def automaton_of(law):
    base = model_of(law).to_automaton()
    return HybridAutomaton(base.states, {**base.parameters, "hc": 1.0, "kb": 0.0}, base.modes, base.transitions,
                           base.initial_mode, base.observables, base.positive, base.nonnegative)


def fpk(law, H_c, grids=((240, 256), (480, 256), (960, 256))):
    from averaging.phase_plane.passage import first_passage_fpk

    model = model_of(law)
    means = {}
    for g in grids:
        c0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            means[g[0]] = first_passage_fpk(model, f"H < {H_c}", grid=g, check=False, survival=False).mean_time
        print(law, H_c, g, means[g[0]], f"{time.process_time() - c0:.1f} CPU s", flush=True)
    n = sorted(means)
    limit = 2 * means[n[-1]] - means[n[-2]]
    row = {"kind": "fpk", "law": law, "H_c": H_c, "grids": {str(k): v for k, v in means.items()},
           "ring_richardson": limit, "previous_richardson": 2 * means[n[-2]] - means[n[-3]] if len(n) > 2 else None}
    print(json.dumps(row), flush=True)
    with OUT.open("a") as f:
        f.write(json.dumps(row) + "\n")


def mc(law, H_c, dt, paths, seed, t_max):
    from first_passage_reference import BETA, tail_term

    from hybrid.stochastic import simulate_first_passage

    model = automaton_of(law)
    kb = BETA * math.sqrt(2 * 0.05 * dt)
    c0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = simulate_first_passage(model, "H + kb*abs(y) < hc", "splitting", dt=dt, paths=paths, t_max=t_max,
                                   x0=(0.0, 0.0), seed=seed, snapshots=200, time_bins=40_000,
                                   params={"hc": H_c, "kb": kb}, chunk_paths=1000)
        est = r.mean_time()
    tail, rate = tail_term(r.times, r.survival, r.paths)
    row = {"kind": "mc", "law": law, "H_c": H_c, "dt": dt, "paths": paths, "seed": seed, "t_max": t_max,
           "kb": kb, "mean": est.value + tail, "ci95": est.ci, "tail": tail, "censored": r.censored,
           "cpu_seconds": time.process_time() - c0}
    print(json.dumps(row), flush=True)
    with OUT.open("a") as f:
        f.write(json.dumps(row) + "\n")


def step_end(law, H_c, dt, paths, seed, t_max, batch=100):
    """The Monte Carlo mean time with the level watched on the step ends only (the physical states), not on the
    splitting's sub-step states: the paths of ``sample_paths`` (the same scheme's kernel, for
    the model without the exit transition), every step stored, the first
    step end with H + kb |y| >= H_c (continuity-corrected) taken in numpy. Paths still inside at t_max add
    t_max plus the memoryless tail 1/lambda, lambda from the log-slope of the sample's own survival."""
    from first_passage_reference import BETA

    from hybrid.stochastic._runner import sample_paths

    model = model_of(law)
    kb = BETA * math.sqrt(2 * 0.05 * dt)
    c0 = time.process_time()
    times = []
    for k in range(paths // batch):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t, x, y = sample_paths(model, "splitting", dt=dt, t_end=t_max, paths=batch, every=1, seed=seed + k,
                                   check_dt=False)
        crossed = model.energy(x, y) + kb * np.abs(y) >= H_c
        first = np.where(crossed.any(axis=1), crossed.argmax(axis=1), -1)
        times.append(np.where(first >= 0, t[np.maximum(first, 0)], np.inf))
    T = np.concatenate(times)
    done = np.isfinite(T)
    grid = np.linspace(0.0, t_max, 201)
    R = np.array([(T > s).mean() for s in grid])
    pick = (R < 0.1) & (R > 0)
    rate = -np.polyfit(grid[pick], np.log(R[pick]), 1)[0] if pick.sum() > 3 else 1.0 / T[done].mean()
    Tc = np.where(done, T, t_max + 1.0 / rate)
    row = {"kind": "mc_step_end", "law": law, "H_c": H_c, "dt": dt, "paths": len(T), "seed": seed, "t_max": t_max,
           "kb": kb, "mean": float(Tc.mean()), "ci95": float(1.96 * Tc.std(ddof=1) / math.sqrt(len(T))),
           "censored": int((~done).sum()), "cpu_seconds": time.process_time() - c0}
    print(json.dumps(row), flush=True)
    with OUT.open("a") as f:
        f.write(json.dumps(row) + "\n")


def impact(law, H0=2.0, c=0.0, dts=(0.01, 0.005, 0.0025, 0.00125), phases=200):
    """Noise-free: one impact from (0, sqrt(2 H0)) towards the wall, c = 0, so the exact post-impact energy is the
    closed form H_after = V(1) + e(v)**2 v**2 / 2, v = sqrt(2 (H0 - V(1))). The engine (``drive_automaton``, zero
    increments, stopped at t = 0.75, after the impact and before the next) over ``phases`` steps dt (1 + u),
    u in [0, 0.1), so that the impact falls at every place inside a step: mean, rms and max of engine - exact."""
    from hybrid.stochastic._auto_runner import drive_automaton

    model = model_of(law)
    aut = model.to_automaton()
    v = math.sqrt(2 * (H0 - float(model.energy(1.0, 0.0))))
    e = float(np.asarray(model.restitution.coefficient(np.array([v])))[0])
    exact = float(model.energy(1.0, 0.0)) + e * e * v * v / 2
    for dt0 in dts:
        err = []
        for u in np.linspace(0.0, 0.1, phases, endpoint=False):
            dt = dt0 * (1 + u)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                x, y = drive_automaton(aut, "splitting", dt, np.zeros((1, int(math.ceil(0.75 / dt)), 1)),
                                       x0=(0.0, math.sqrt(2 * H0)), params={"c": c})[0]
            err.append(float(model.energy(x, y)) - exact)
        err = np.array(err)
        print(f"{law} dt={dt0}: v={v:.4f} e={e:.5f} H_after exact {exact:.6f}; engine - exact: mean {err.mean():+.2e} "
              f"(+-{2 * err.std() / math.sqrt(len(err)):.1e}), rms {np.sqrt(np.mean(err**2)):.2e}, "
              f"max {np.abs(err).max():.2e}", flush=True)


def overshoot(law, H_c=2.0, t_max=0.6, dts=(0.01, 0.005, 0.0025, 0.00125)):
    """Noise-free (D = 0, c = 0: H is constant along the exact orbit) from (0, sqrt(2 H0)) with H0 < H_c: the
    exact orbit never leaves, the engine's exit fires for H0 above H_c - overshoot. Bisection on H0 per step."""
    from hybrid.stochastic import simulate_first_passage

    aut = automaton_of(law)

    def fires(H0, dt):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = simulate_first_passage(aut, "H + kb*abs(y) < hc", "splitting", dt=dt, paths=1, t_max=t_max,
                                       x0=(0.0, math.sqrt(2 * H0)), seed=1, check_dt=False, snapshots=10,
                                       time_bins=100, chunk_paths=1,
                                       params={"hc": H_c, "kb": 0.0, "c": 0.0, "D": 0.0})
        return r.censored == 0

    for dt in dts:
        lo, hi = H_c - 0.1, H_c
        for _ in range(14):
            mid = (lo + hi) / 2
            lo, hi = (lo, mid) if fires(mid, dt) else (mid, hi)
        print(f"{law} dt={dt}: the exit fires from H0 > {hi:.5f}: overshoot {H_c - hi:.5f} = {(H_c - hi) / dt:.3f} dt",
              flush=True)


def shifted(law, H_c=2.0, grid=(480, 256), kappas=(0.0, 0.01, 0.02, 0.04)):
    """fpk with the level moved by kappa max(0, y G'(x)) (the splitting's after-flight overshoot is y G' dt / 2):
    how much an exit read early near the walls shortens the mean time (cells classified at their centres)."""
    from averaging.phase_plane.passage import first_passage_fpk

    model = model_of(law)
    for k in kappas:
        dom = f"H + {k}*(abs(y*(x+0.2*x**3)) + y*(x+0.2*x**3))/2 + 1e-12*x < {H_c}"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = first_passage_fpk(model, dom, grid=grid, check=False, survival=False)
        print(f"{law} {grid[0]}x{grid[1]} kappa {k}: {r.mean_time:.4f}", flush=True)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    what, args = sys.argv[1], sys.argv[2:]
    if what == "fpk":
        fpk(args[0], float(args[1]))
    elif what == "mc":
        mc(args[0], float(args[1]), float(args[2]), int(args[3]), int(args[4]), float(args[5]))
    elif what in ("impact", "overshoot", "shifted"):
        {"impact": impact, "overshoot": overshoot, "shifted": shifted}[what](args[0])
    elif what == "step_end":
        step_end(args[0], float(args[1]), float(args[2]), int(args[3]), int(args[4]), float(args[5]))
    else:
        print(__doc__)
        sys.exit(2)
