"""Event-exact Monte Carlo reference for the first passage of Example 1's energy.

Results in docs/results/first-passage-spectra.md.

Example 1 (Duffing a = 1, b = 0.2, c = 0.025, D = 0.05, walls at +-1, Ma V_C = 0.4) from rest. The levels
H_c = 0.25 ... 2.0 are a chain of modes (mode k goes to k + 1 when H crosses level k, identity reset; every mode keeps
the walls), so one ensemble gives every level's first-passage time; baoab locates the level crossings inside the
step, on states whose positions and velocities belong to one instant (issue 26's fix of the velocity guards).
Prints per level and step: mean, 95 % CI, censored paths, R(t) at a few times.

    python benchmarks/first_passage_mc.py [paths] [dt ...]
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
import sympy as sp

from hybrid import HybridAutomaton, Mode, Transition
from hybrid.stochastic import simulate_automaton
from models import DuffingImpact, Ma

LEVELS = (0.25, 0.5, 1.0, 1.5, 2.0)


def level_chain(levels=LEVELS):
    base = DuffingImpact(restitution=Ma(vc=0.4)).to_automaton()
    H = base.observables["H"]
    free = base.modes[0]
    modes = [Mode(f"m{k}", free.flow, free.noise) for k in range(len(levels) + 1)]
    transitions = []
    for k in range(len(levels) + 1):
        if k < len(levels):
            transitions.append(Transition(f"level{k}", f"m{k}", f"m{k + 1}", H - sp.Float(levels[k]), 1, base.states))
        transitions += [Transition(f"{t.name}{k}", f"m{k}", f"m{k}", t.guard, t.direction, t.reset,
                                   priority=t.priority + 1, check=t.check) for t in base.transitions]
    return HybridAutomaton(base.states, dict(base.parameters), modes, transitions, observables={"H": H})


def run(paths=4000, dt=0.002, t_end=1000.0, events=2000, seed=11):
    t0 = time.process_time()
    ens = simulate_automaton(level_chain(), "baoab", dt=dt, paths=paths, t_end=t_end, x0=(0.0, 0.0), seed=seed,
                             events=events, histograms={"H": None}, check_dt=False, chunk_paths=64)
    out = {"paths": paths, "dt": dt, "t_end": t_end, "cpu_seconds": time.process_time() - t0, "levels": {}}
    overflow = ens.event_totals > events
    for k, level in enumerate(LEVELS):
        T = ens.first_event_times(f"level{k}")
        censored = ~np.isfinite(T)
        Tf = T[~censored]
        mean = float(Tf.mean())
        half = float(1.96 * Tf.std(ddof=1) / np.sqrt(len(Tf)))
        grid = mean * np.array([0.25, 0.5, 1.0, 2.0])
        R = [float(np.mean(np.where(censored, True, T > t))) for t in grid]
        out["levels"][str(level)] = {"mean": mean, "ci95": half, "censored": int(censored.sum()),
                                     "censored_by_log": int((censored & overflow).sum()),
                                     "R_at": dict(zip([f"{t:.6g}" for t in grid], R))}
    return out


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 4000
    steps = [float(v) for v in sys.argv[2:]] or [0.002]
    for dt in steps:
        print(json.dumps(run(n, dt), indent=1), flush=True)
