"""Rare events: fixed-level splitting against brute force and against an exact answer, with their costs.

1. Brownian motion, P(max_{t<=1} W >= b) = 2 P(W_1 >= b + 0.5826 sqrt(dt)) for a path watched every dt (the
   reflection principle with Broadie and Glasserman's continuity correction), at b = 3.5 (4e-4) and b = 4.75 (2e-6).
2. Example 1 (Duffing, Ma V_C = 0.4, walls at +-1) from rest: P(H reaches H_c before t = 10), by splitting and by
   brute-force event-exact Monte Carlo (simulate_first_passage) where brute force is affordable.

For each: the estimate, its 95 % interval, the exact or brute-force value, the path-steps and wall seconds spent,
and the cost brute force would need for the same relative error, in path-steps and in seconds at the brute-force
throughput measured in this run (the splitting steps go through the kernel's general event step, which costs more
per step than the fast loop of brute force; both ratios are printed).

Run:  python benchmarks/rare_events.py [--quick]
"""

import argparse
import math
import time

import numpy as np
import sympy as sp
from scipy.stats import norm

from hybrid.automaton import HybridAutomaton, Mode
from hybrid.stochastic import simulate_first_passage, splitting_probability
from models import DuffingImpact, Ma


def brownian():
    x = sp.Symbol("x")
    return HybridAutomaton((x,), {"s": 1.0}, [Mode("m", (sp.Integer(0),), (sp.Symbol("s"),))])


def brute_force(automaton, domain, *, dt, t_max, x0, paths, scheme, seed=1):
    """P(leave the domain before t_max) by brute force: (estimate, Wilson interval, path-steps per second)."""
    started = time.perf_counter()
    run = simulate_first_passage(automaton, domain, scheme, dt=dt, paths=paths, t_max=t_max, x0=x0, snapshots=1,
                                 chunk_paths=max(1, paths // 32), seed=seed)
    wall = time.perf_counter() - started - run.ensemble.settings.get("compile_time", 0.0)
    lo, hi = run.survival_interval()
    steps = paths * t_max / dt
    return 1 - run.survival[-1], (1 - hi[-1], 1 - lo[-1]), steps / max(wall, 1e-9)


def report(name, est, reference, rate):
    brute_seconds = est.brute_force_steps / rate
    print(f"{name}")
    print(f"  splitting   P = {est.probability:.4g} ± {est.ci:.2g} (95 %, {len(est.replicas)} replicas; "
          f"relative {est.relative_error:.1%})   reference {reference}")
    print(f"  cost        {est.path_steps:.3g} path-steps in {est.wall_time:.1f} s; brute force for the same "
          f"relative error: {est.brute_force_steps:.3g} path-steps, ~{brute_seconds:.3g} s at {rate / 1e6:.1f} M "
          f"path-steps/s")
    print(f"  ratio       {est.speedup:.3g}x fewer path-steps, {brute_seconds / max(est.wall_time, 1e-9):.3g}x less "
          "wall time")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer clones (a smoke run)")
    args = parser.parse_args()
    scale = 4 if args.quick else 1
    dt = 1e-3
    bm = brownian()
    # warm both kernels first: compile time is not the method's cost
    splitting_probability(bm, "x", 1.0, levels=1, t_max=0.1, x0=(0.0,), dt=dt, clones=2, replicas=2, scheme="em")
    _, _, rate = brute_force(bm, "x < 3", dt=dt, t_max=1.0, x0=(0.0,), paths=64, scheme="em")
    _, _, rate = brute_force(bm, "x < 3", dt=dt, t_max=1.0, x0=(0.0,), paths=20_000, scheme="em")
    for b, levels, clones in ((3.5, 8, 1600), (4.75, 24, 3200)):
        exact = 2 * norm.sf(b + 0.5826 * math.sqrt(dt))
        est = splitting_probability(bm, "x", b, levels=levels, t_max=1.0, x0=(0.0,), dt=dt, clones=clones // scale,
                                    replicas=8, scheme="em", seed=9)
        report(f"Brownian motion, b = {b} ({levels} levels, {clones // scale} clones)", est,
               f"{exact:.4g} (exact; within the interval: {abs(est.probability - exact) <= est.ci})", rate)

    model = DuffingImpact(restitution=Ma(0.4))
    dt = 0.01
    splitting_probability(model, "H", 0.2, levels=1, t_max=0.1, x0=(0.0, 0.0), dt=dt, clones=2, replicas=2)
    brute_force(model, "H < 1.5", dt=dt, t_max=10.0, x0=(0.0, 0.0), paths=64, scheme="splitting")
    p, (lo, hi), rate = brute_force(model, "H < 1.5", dt=dt, t_max=10.0, x0=(0.0, 0.0), paths=40_000 // scale,
                                    scheme="splitting")
    est = splitting_probability(model, "H", 1.5, levels=10, t_max=10.0, x0=(0.0, 0.0), dt=dt, clones=800 // scale,
                                replicas=8, seed=3)
    report("Example 1 from rest, H reaches 1.5 before t = 10 (10 levels)", est,
           f"{p:.4g} [{lo:.4g}, {hi:.4g}] (brute force, {40_000 // scale} paths; intervals overlap: "
           f"{abs(est.probability - p) <= est.ci + (hi - lo) / 2})", rate)
    est = splitting_probability(model, "H", 3.0, levels=np.linspace(0.15, 3.0, 20), t_max=10.0, x0=(0.0, 0.0),
                                dt=dt, clones=1600 // scale, replicas=8, seed=4)
    report("Example 1 from rest, H reaches 3.0 before t = 10 (20 levels)", est, "none affordable", rate)


if __name__ == "__main__":
    main()
