"""Rare events: fixed-level splitting against exact answers and brute force, with the variance reduction at equal cost.

1. An Ornstein-Uhlenbeck process dx = -x dt + sqrt(2) dW (em scheme, dt = 0.01) from 0: P(max_{t <= 1} x >= b) at
   b = 3.25, 4.69, 5.80 (1.0e-3, 1.03e-6, 1.02e-9). The exact answer is that of the simulated Euler chain, by
   quadrature (tests/problems.py ``euler_ou_exceedance``, relative accuracy ~1e-7), so it judges the estimator and
   its interval with no step-size error in between.
2. Example 1 (Duffing, Ma V_C = 0.4, walls at +-1) from rest: P(H reaches H_c before t = 10), splitting scheme at
   dt = 0.01, at H_c = 2.7 (about 1e-3, where brute force is affordable and run), 4.1 (about 1e-6) and 5.2 (about
   1e-9).

Cost is CPU seconds of this process (compile excluded; brute force uses two threads, counted both). The variance
reduction at equal cost is the ratio of work-normalised relative variances,

    VR = ((1 - P) / P * c_bf) / (RE^2 * C_split),

c_bf the measured CPU seconds of one brute-force path to t_max, RE^2 = (replica relative variance) / replicas the
splitting estimate's squared relative error and C_split its CPU seconds (``RareEventEstimate.variance_reduction``).
Where brute force is run (P ~ 1e-3) its own work-normalised variance, (1 - P) / (P n) * C_bf, is printed beside the
formula's. The splitting estimates use 16-32 replicas: the relative variance from 8 skewed replicas is often several
times too small (docs/results/rare-events.md), and VR with it. ``--coverage`` instead repeats the OU estimates over
seeds and counts how often the 95 % interval holds the exact answer.

Run:  python benchmarks/rare_events.py [--quick] [--coverage]
"""

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import sympy as sp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from problems import euler_ou_exceedance  # noqa: E402

from hybrid.automaton import HybridAutomaton, Mode  # noqa: E402
from hybrid.stochastic import (  # noqa: E402
    RareEventWarning,
    StepSizeWarning,
    simulate_first_passage,
    splitting_probability,
)
from models import DuffingImpact, Ma  # noqa: E402

OU_LEVELS = ((3.25, 5, 1000), (4.69, 10, 1000), (5.80, 15, 2000))  # (b, levels, clones): P about 1e-3, 1e-6, 1e-9
EXAMPLE_LEVELS = ((2.7, 6, 300, 32), (4.1, 14, 1000, 32), (5.2, 18, 1500, 16))  # + replicas


def ou():
    x = sp.Symbol("x")
    return HybridAutomaton((x,), {"th": 1.0, "s": math.sqrt(2.0)},
                           [Mode("m", (-sp.Symbol("th") * x,), (sp.Symbol("s"),))])


def brute_force(automaton, domain, *, dt, t_max, x0, paths, scheme, seed=1):
    """P(leave the domain before t_max) by brute force: (P, its 95 % Wilson interval, CPU s per path)."""
    started = time.process_time()
    run = simulate_first_passage(automaton, domain, scheme, dt=dt, paths=paths, t_max=t_max, x0=x0, snapshots=1,
                                 chunk_paths=max(1, paths // 32), seed=seed)
    cpu = time.process_time() - started
    lo, hi = run.survival_interval()
    return 1 - run.survival[-1], (1 - hi[-1], 1 - lo[-1]), cpu / paths


def row(name, est, reference, per_path, measured_bf=None):
    vr = est.variance_reduction(per_path)
    bf = f"; brute force measured: {measured_bf}" if measured_bf else ""
    print(f"{name}\n  splitting P = {est.probability:.4g} ± {est.ci:.2g} (95 %, {len(est.replicas)} replicas x "
          f"{est.settings['clones']} clones, {len(est.levels)} levels; relative {est.relative_error:.1%})   "
          f"reference {reference}")
    print(f"  cost {est.cpu_time:.2f} CPU s ({est.path_steps:.3g} path-steps); one replica's relative variance "
          f"{est.replica_relative_variance:.3f}; brute force {per_path * 1e6:.1f} CPU us per path{bf}")
    print(f"  variance reduction at equal CPU: {vr:.3g}x   (brute force for the same interval: "
          f"{vr * est.cpu_time:.3g} CPU s; in path-steps {est.speedup:.3g}x)")
    return vr


def coverage(calls: int, replicas: int = 8, clone_counts=(200, 1000), first_seed: int = 10_000) -> None:
    """The 95 % interval's coverage of the exact answer over seeds ``first_seed`` .. ``first_seed + calls - 1``."""
    print(f"\nCoverage over {calls} seeds (OU, {replicas} replicas each):")
    print("| P (exact) | clones | pooled mean / exact | coverage | misses low / high | one replica's rel. var. | CPU s "
          "per estimate |")
    print("|---|---|---|---|---|---|---|")
    for b, levels, _ in OU_LEVELS:
        exact = euler_ou_exceedance(b)
        for clones in clone_counts:
            est = [splitting_probability(ou(), "x", b, levels=levels, t_max=1.0, x0=(0.0,), dt=0.01, clones=clones,
                                         replicas=replicas, scheme="em", seed=first_seed + k) for k in range(calls)]
            reps = np.concatenate([e.replicas for e in est])
            pooled, se = reps.mean() / exact, 1.96 * reps.std(ddof=1) / math.sqrt(len(reps)) / exact
            low = np.mean([e.probability + e.ci < exact for e in est])
            high = np.mean([e.probability - e.ci > exact for e in est])
            print(f"| {exact:.4g} | {clones} | {pooled:.3f} ± {se:.3f} | {1 - low - high:.3f} | {low:.3f} / {high:.3f}"
                  f" | {reps.var(ddof=1) / reps.mean() ** 2:.3f} | {np.mean([e.cpu_time for e in est]):.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer clones and paths (a smoke run)")
    parser.add_argument("--coverage", type=int, nargs="?", const=100, default=0, metavar="CALLS",
                        help="instead, repeat the OU estimates over CALLS seeds (default 100) and count the coverage")
    parser.add_argument("--replicas", type=int, default=8, help="with --coverage: replicas per estimate")
    parser.add_argument("--clones", type=int, nargs="+", default=[200, 1000], help="with --coverage: clone counts")
    parser.add_argument("--first-seed", type=int, default=10_000, help="with --coverage: the first seed")
    args = parser.parse_args()
    scale = 4 if args.quick else 1
    warnings.simplefilter("always", RareEventWarning)
    # the OU level is read at step ends on purpose: the exact answer is that of the Euler chain, so dt's bias is moot
    warnings.simplefilter("ignore", StepSizeWarning)
    if args.coverage:
        coverage(args.coverage, args.replicas, tuple(args.clones), args.first_seed)
        return

    print("1. OU process, em, dt = 0.01, t_max = 1 (exact: the Euler chain by quadrature)")
    bf_p, (lo, hi), per_path = brute_force(ou(), "x < 3.25", dt=0.01, t_max=1.0, x0=(0.0,), paths=64, scheme="em")
    paths = 400_000 // scale
    bf_p, (lo, hi), per_path = brute_force(ou(), "x < 3.25", dt=0.01, t_max=1.0, x0=(0.0,), paths=paths, scheme="em")
    vrs = []
    for b, levels, clones in OU_LEVELS:
        exact = euler_ou_exceedance(b)
        replicas = 32
        est = splitting_probability(ou(), "x", b, levels=levels, t_max=1.0, x0=(0.0,), dt=0.01, clones=clones // scale,
                                    replicas=replicas, scheme="em", seed=9)
        measured = None
        if b == OU_LEVELS[0][0]:
            work = (1 - bf_p) / bf_p * per_path  # n paths: RE^2 = (1 - P)/(P n), cost n c_bf
            measured = (f"P = {bf_p:.4g} [{lo:.4g}, {hi:.4g}] ({paths} paths), (1-P)/P * c_bf = {work:.3g} CPU s; "
                        f"splitting RE^2 * C = {est.replica_relative_variance / replicas * est.cpu_time:.3g} CPU s")
        vrs.append(row(f"b = {b}", est, f"{exact:.5g} exact (estimate / exact = {est.probability / exact:.3f}; "
                                          f"within the interval: {abs(est.probability - exact) <= est.ci})",
                       per_path, measured))

    print("\n2. Example 1 from rest, splitting scheme, dt = 0.01, t_max = 10")
    model = DuffingImpact(restitution=Ma(0.4))
    brute_force(model, "H < 2.7", dt=0.01, t_max=10.0, x0=(0.0, 0.0), paths=64, scheme="splitting")
    paths = 400_000 // scale
    bf_p, (lo, hi), per_path = brute_force(model, "H < 2.7", dt=0.01, t_max=10.0, x0=(0.0, 0.0), paths=paths,
                                           scheme="splitting", seed=2)
    for H_c, levels, clones, replicas in EXAMPLE_LEVELS:
        first = H_c == EXAMPLE_LEVELS[0][0]
        est = splitting_probability(model, "H", H_c, levels=levels, t_max=10.0, x0=(0.0, 0.0), dt=0.01,
                                    clones=clones // scale, replicas=replicas, seed=3)
        if first:
            work = (1 - bf_p) / bf_p * per_path
            reference = (f"{bf_p:.4g} [{lo:.4g}, {hi:.4g}] brute force, {paths} paths (intervals overlap: "
                         f"{abs(est.probability - bf_p) <= est.ci + (hi - lo) / 2})")
            measured = (f"(1-P)/P * c_bf = {work:.3g} CPU s; splitting RE^2 * C = "
                        f"{est.replica_relative_variance / len(est.replicas) * est.cpu_time:.3g} CPU s")
        else:
            reference, measured = "none affordable (brute force cost extrapolated by the formula)", None
        row(f"H_c = {H_c}", est, reference, per_path, measured)


if __name__ == "__main__":
    main()
