"""Converged Monte Carlo reference for Example 1's mean first-passage time of the energy and its survival R(t).

Results in docs/results/first-passage-spectra.md; the reference is stored in
``benchmarks/data/first_passage_reference.json`` (``tests/test_first_passage_reference.py`` reads it).

Example 1 (Duffing a = 1, b = 0.2, c = 0.025, D = 0.05, walls at +-1, Ma V_C = 0.4) from rest; T = first time
H >= H_c. Event-exact Monte Carlo (``simulate_first_passage``, scheme ``splitting``): the walls and the level are
located inside the step (the level, a guard of the velocity, on states whose position and velocity belong to one
instant: ``ENGINE``), but the noise enters once per step, so H, which carries noise (dH has the diffusion
sqrt(2 D) |y| dW), is watched at the step ends only, and a path that crosses H_c and comes back inside one step is
missed: the passage comes late by O(sqrt(dt)) (2-4 % at dt = 0.002-0.01). The run therefore watches the moved level

    H + beta sqrt(2 D dt) |y| < H_c,        beta = -zeta(1/2) / sqrt(2 pi) = 0.5826,

the continuity correction of a discretely watched diffusion (Broadie, Glasserman and Kou 1997; the local noise
intensity of H at the crossing is sqrt(2 D) |y|), which leaves an O(dt) error in theory. Checks: at H_c = 0.25 the
uncorrected runs at three steps approach the corrected value as sqrt(dt) (``validate``), and at every level the
corrected runs at two steps are compared (``reference`` prints each step's difference from the finest with its CI):
where a difference exceeds its CI, the finest step alone is the reference.

Paths still inside at t_max are counted; the mean adds their tail R(t_max) / lambda, lambda the log-slope of the
Monte Carlo survival itself over its last decade (that term is printed; it is under 0.1 % of the mean).

    python benchmarks/first_passage_reference.py run H_c DT PATHS SEED [--uncorrected] [--scheme S]  # one run
    python benchmarks/first_passage_reference.py plan                                     # the runs of the file
    python benchmarks/first_passage_reference.py reference                                # combine -> json, table
    python benchmarks/first_passage_reference.py near H0 DT PATHS SEED [--uncorrected]     # R(t) from H0 < 2
    python benchmarks/first_passage_reference.py survival        # fpk R(t) against the Kaplan-Meier curves -> json
    python benchmarks/first_passage_reference.py compare         # fpk's default grid against the reference -> json
    python benchmarks/first_passage_reference.py oracle          # a guard of the velocity, noise-free: error, order
    python benchmarks/first_passage_reference.py trend           # the fit T0 + k dt of each level's runs

Each run appends one JSON line to ``benchmarks/data/first_passage_mc_runs.jsonl`` (paths, dt, seed, t_max, the
mean with its 95 % CI, censored paths, the tail term, R(t) at 200 times with Wilson intervals, CPU and wall s).
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
from hybrid.stochastic import simulate_first_passage
from models import DuffingImpact, Ma

DATA = Path(__file__).resolve().parent / "data"
RUNS = DATA / "first_passage_mc_runs.jsonl"
REFERENCE = DATA / "first_passage_reference.json"
SURVIVAL = DATA / "first_passage_survival.json"
NEAR = DATA / "first_passage_mc_near_level.jsonl"
COMPARE = DATA / "first_passage_fpk_vs_reference.json"
BETA = 0.5826  # -zeta(1/2)/sqrt(2 pi)
Z95 = 1.959963984540054  # a 95 % half-width in standard errors
LEVELS = (0.25, 0.5, 1.0, 1.5, 2.0)
T_MAX = {0.25: 60.0, 0.5: 120.0, 1.0: 300.0, 1.5: 450.0, 2.0: 800.0}  # R(t_max) below 1e-3 (fpk's decay rates)
SNAPSHOTS = 200
ENGINE = "consistent-velocity-guards"
"""The engine a run was made with: before this tag (runs without it) the splitting schemes read a guard of the
velocities, such as the level of H, on their half-kicked sub-step states, so exits fired early by O(dt) (about 1 %
at H_c = 2 and dt = 0.01). The reference uses the tagged runs only; the older ones stay in the runs file."""
# (H_c, dt, paths, seed): the runs behind the stored reference, all with ENGINE (seeds differ between every pair of
# runs; the replicate pairs, same level and step, test the CIs). The runs before ENGINE (seeds 101-509, 601) stay in
# the runs file: their level was read on half-kicked states.
PLAN = [(0.25, 0.01, 50_000, 131), (0.25, 0.01, 50_000, 133), (0.25, 0.005, 60_000, 132),
        (0.5, 0.01, 30_000, 231), (0.5, 0.01, 30_000, 233), (0.5, 0.005, 30_000, 232), (0.5, 0.005, 30_000, 234),
        (1.0, 0.01, 30_000, 331), (1.0, 0.01, 30_000, 333), (1.0, 0.005, 30_000, 332), (1.0, 0.005, 30_000, 334),
        (1.5, 0.01, 30_000, 432), (1.5, 0.01, 30_000, 434), (1.5, 0.005, 30_000, 431), (1.5, 0.005, 30_000, 433),
        (2.0, 0.02, 40_000, 521), (2.0, 0.01, 40_000, 522), (2.0, 0.02, 40_000, 523), (2.0, 0.01, 40_000, 524),
        (2.0, 0.02, 40_000, 525), (2.0, 0.01, 40_000, 526), (2.0, 0.02, 40_000, 527), (2.0, 0.01, 40_000, 528)]
# checks outside the reference: scheme baoab at H_c = 2 (run 2.0 0.005 20000 601 --scheme baoab), and R(t) from
# H = 1.9 at three steps, corrected and not (near 1.9 DT 100000 SEED [--uncorrected], seeds 701-706)
# the uncorrected level at H_c = 0.25 (the continuity correction's check): (dt, paths, seed)
VALIDATE = [(0.01, 30_000, 111), (0.005, 30_000, 112), (0.0025, 30_000, 113)]


def example1():
    """Example 1's automaton with two extra parameters, the level ``hc`` and the correction ``kb``: one kernel
    serves every level and step (parameters are runtime values)."""
    base = DuffingImpact(restitution=Ma(vc=0.4)).to_automaton()
    return HybridAutomaton(base.states, {**base.parameters, "hc": 1.0, "kb": 0.0}, base.modes, base.transitions,
                           base.initial_mode, base.observables, base.positive, base.nonnegative)


def tail_term(times, survival, paths):
    """R(t_max) / lambda with lambda the log-slope of R over its last decade (0 when nothing is left)."""
    r_end = survival[-1]
    if r_end <= 0:
        return 0.0, None
    top = min(1.0, 10 * r_end)
    pick = (survival <= top) & (survival > 0)
    t, r = times[pick], survival[pick]
    if len(t) < 3 or survival[-1] * paths < 5:  # too few survivors to fit: use the last two e-folds seen
        pick = (survival <= max(10 * r_end, 0.05)) & (survival > 0)
        t, r = times[pick], survival[pick]
    rate = -np.polyfit(t, np.log(r), 1)[0]
    return float(r_end / rate), float(rate)


def run(H_c, dt, paths, seed, corrected=True, chunk_paths=1000, scheme="splitting"):
    """One ensemble: the mean first-passage time (with the tail term) and R(t) at SNAPSHOTS times."""
    model = example1()
    kb = BETA * math.sqrt(2 * 0.05 * dt) if corrected else 0.0
    t_max = T_MAX[H_c]
    t0, c0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # censoring is counted below and its tail added
        r = simulate_first_passage(model, "H + kb*abs(y) < hc", scheme, dt=dt, paths=paths, t_max=t_max,
                                   x0=(0.0, 0.0), seed=seed, snapshots=SNAPSHOTS, time_bins=40_000,
                                   params={"hc": H_c, "kb": kb}, chunk_paths=chunk_paths)
        est = r.mean_time()
    tail, rate = tail_term(r.times, r.survival, r.paths)
    lo, hi = r.survival_interval()
    return {"H_c": H_c, "dt": dt, "paths": paths, "seed": seed, "corrected": corrected, "kb": kb, "t_max": t_max,
            "scheme": scheme, "engine": ENGINE, "mean_censored_at_t_max": est.value, "mean": est.value + tail,
            "ci95": est.ci,
            "tail": tail, "tail_rate": rate, "censored": r.censored, "times": r.times.tolist(),
            "R": r.survival.tolist(), "R_lo": lo.tolist(), "R_hi": hi.tolist(),
            "cpu_seconds": time.process_time() - c0, "wall_seconds": time.perf_counter() - t0}


def near_level(H0, dt, paths, seed, corrected=True, H_c=2.0, t_max=5.0, snapshots=100):
    """The correction's check at hard impacts: R(t) on [0, t_max] from (0, sqrt(2 H0)), just below the level,
    where most paths leave within a fraction of a period and the level's placement decides R directly."""
    model = example1()
    kb = BETA * math.sqrt(2 * 0.05 * dt) if corrected else 0.0
    c0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the paths still inside at t_max are the point of the check
        r = simulate_first_passage(model, "H + kb*abs(y) < hc", "splitting", dt=dt, paths=paths, t_max=t_max,
                                   x0=(0.0, math.sqrt(2 * H0)), seed=seed, snapshots=snapshots,
                                   time_bins=10 * snapshots, params={"hc": H_c, "kb": kb}, chunk_paths=1000)
    lo, hi = r.survival_interval()
    return {"H_c": H_c, "H0": H0, "dt": dt, "paths": paths, "seed": seed, "corrected": corrected, "kb": kb,
            "engine": ENGINE,
            "t_max": t_max, "times": r.times.tolist(), "R": r.survival.tolist(), "R_lo": lo.tolist(),
            "R_hi": hi.tolist(), "cpu_seconds": time.process_time() - c0}


def load_runs():
    return [json.loads(line) for line in RUNS.read_text().splitlines() if line.strip()] if RUNS.exists() else []


def scatter_factor(runs):
    """sqrt(chi2 / dof) of the replicate runs (same level and step) about their pooled mean, at least 1.

    Replicates that scatter more than their CIs say would widen every CI of the reference by this factor (the
    Birge ratio). The weights are 1 / sigma^2 with sigma = ci95 / 1.96 (the runs before ENGINE were weighted by
    1 / ci95^2, which made chi2 3.84 times too small: their 6.6 on 7 degrees of freedom was 25.4)."""
    chi2, dof = 0.0, 0
    for key in {(r["H_c"], r["dt"]) for r in runs}:
        group = [r for r in runs if (r["H_c"], r["dt"]) == key]
        if len(group) < 2:
            continue
        w = np.array([(Z95 / r["ci95"]) ** 2 for r in group])
        m = np.array([r["mean"] for r in group])
        chi2 += float(np.sum(w * (m - np.sum(w * m) / np.sum(w)) ** 2))
        dof += len(group) - 1
    return max(1.0, math.sqrt(chi2 / dof)) if dof else 1.0, chi2, dof


def combine(runs, scatter=(1.0, 0.0, 0)):
    """Pool runs of one (level, dt) (paths-weighted; CIs in quadrature as independent means, widened by the
    replicates' scatter factor)."""
    n = sum(r["paths"] for r in runs)
    mean = sum(r["paths"] * r["mean"] for r in runs) / n
    ci = scatter[0] * math.sqrt(sum((r["paths"] / n * r["ci95"]) ** 2 for r in runs))
    R = sum(r["paths"] * np.array(r["R"]) for r in runs) / n
    return {"mean": mean, "ci95": ci, "paths": n, "seeds": [r["seed"] for r in runs],
            "censored": sum(r["censored"] for r in runs), "tail": sum(r["paths"] * r["tail"] for r in runs) / n,
            "cpu_seconds": sum(r["cpu_seconds"] for r in runs), "R": R, "times": np.array(runs[0]["times"])}


def reference():
    """Per level: the corrected runs per step and each step's difference from the finest with its CI; the
    reference is their inverse-variance pool where every difference lies within its CI, else the finest step
    alone. R(t) of the same runs pooled, with its Wilson interval. Writes REFERENCE."""
    from hybrid.stochastic._passage import _wilson

    runs = [r for r in load_runs() if r["corrected"] and r.get("scheme", "splitting") == "splitting"
            and r.get("engine") == ENGINE]
    scatter = scatter_factor(runs)
    out = {"model": "Example 1: DuffingImpact a=1 b=0.2 c=0.025 D=0.05 walls +-1, Ma(vc=0.4); start (0, 0)",
           "quantity": "mean first time with H >= H_c",
           "method": "simulate_first_passage, scheme splitting, level moved to H + 0.5826 sqrt(2 D dt)|y| < H_c "
                     "(continuity correction), tail beyond t_max added as R(t_max)/lambda",
           "script": "benchmarks/first_passage_reference.py",
           "scatter_factor": {"factor": scatter[0], "chi2": scatter[1], "dof": scatter[2],
                              "note": "replicate runs (same level and step) scatter this much more than their "
                                      "CIs; every CI here is widened by it"},
           "levels": {}}
    for H_c in LEVELS:
        per_dt = {}
        for dt in sorted({r["dt"] for r in runs if r["H_c"] == H_c}, reverse=True):
            per_dt[dt] = combine([r for r in runs if r["H_c"] == H_c and r["dt"] == dt], scatter)
        if not per_dt:
            continue
        steps = sorted(per_dt, reverse=True)
        fine = per_dt[steps[-1]]
        differences = {f"{dt:g}-{steps[-1]:g}": [per_dt[dt]["mean"] - fine["mean"],
                                                 math.hypot(per_dt[dt]["ci95"], fine["ci95"])] for dt in steps[:-1]}
        # an O(dt) residual of the correction shows as a step difference beyond its CI: then the finest step alone
        pooled = len(steps) >= 2 and all(abs(d) <= ci for d, ci in differences.values())
        if pooled:
            w = {dt: 1 / v["ci95"] ** 2 for dt, v in per_dt.items()}
            mean = sum(w[dt] * v["mean"] for dt, v in per_dt.items()) / sum(w.values())
            ci = 1 / math.sqrt(sum(w.values()))
        else:
            mean, ci = fine["mean"], fine["ci95"]
        row = {"mean": mean, "ci95": ci, "relative_ci95": ci / mean, "pooled_over_steps": pooled,
               "reference_steps": [float(dt) for dt in (steps if pooled else steps[-1:])],
               "step_differences": differences,
               "steps": {str(dt): {k: v for k, v in c.items() if k not in ("R", "times")}
                         for dt, c in per_dt.items()}}
        # R(t): the runs of the reference's steps pooled (Kaplan-Meier = empirical survival: censoring at t_max only)
        used = [per_dt[dt] for dt in (steps if pooled else steps[-1:])]
        n = sum(c["paths"] for c in used)
        R = sum(c["paths"] * c["R"] for c in used) / n
        lo, hi = _wilson(np.round(R * n), n)
        row["survival"] = {"t": used[0]["times"].tolist(), "R": R.tolist(), "R_lo": lo.tolist(), "R_hi": hi.tolist(),
                           "paths": n, "max_half_width": float(np.max(hi - lo) / 2)}
        out["levels"][str(H_c)] = row
        print(json.dumps({"H_c": H_c, **{k: v for k, v in row.items() if k != "survival"}}), flush=True)
    REFERENCE.write_text(json.dumps(out, indent=1) + "\n")


def survival(grids=((60, 64), (120, 128)), steps=2000):
    """fpk's R(t) against the stored Kaplan-Meier curves at every level: sup |R_fpk - R_mc|, where, the largest
    excess over the Monte Carlo's 95 % half-width, that half-width, and fpk's CPU seconds. Writes SURVIVAL."""
    from averaging.phase_plane import first_passage_fpk

    model = DuffingImpact(restitution=Ma(vc=0.4))
    levels = json.loads(REFERENCE.read_text())["levels"]
    out = {"script": "benchmarks/first_passage_reference.py survival", "steps": steps, "levels": {}}
    for H_c in LEVELS:
        sv = levels[str(H_c)]["survival"]
        t, R, lo, hi = (np.array(sv[k]) for k in ("t", "R", "R_lo", "R_hi"))
        half = (hi - lo) / 2
        row = {"paths": sv["paths"], "mc_max_half_width": float(half.max()), "grids": {}}
        for grid in grids:
            c0 = time.process_time()
            r = first_passage_fpk(model, f"H < {H_c}", grid=grid, check=False, t_max=float(t[-1]), steps=steps)
            cpu = time.process_time() - c0
            gap = np.abs(r.survival(t) - R)
            k = int(np.argmax(gap))
            row["grids"][f"{grid[0]}x{grid[1]}"] = {
                "sup_gap": float(gap[k]), "at_t": float(t[k]), "R_there": float(R[k]),
                "half_width_there": float(half[k]), "max_excess_over_half_width": float(np.max(gap - half)),
                "cpu_seconds": cpu}
        out["levels"][str(H_c)] = row
        print(json.dumps({str(H_c): row}), flush=True)
    SURVIVAL.write_text(json.dumps(out, indent=1) + "\n")


def compare():
    """fpk on its default grid (120 x 128) with its error estimate against the stored reference at every level:
    the error, the estimate, whether the gap is within estimate + CI and within 1 %, and fpk's CPU s. Writes
    COMPARE."""
    from averaging.phase_plane import first_passage_fpk

    model = DuffingImpact(restitution=Ma(vc=0.4))
    levels = json.loads(REFERENCE.read_text())["levels"]
    out = {"script": "benchmarks/first_passage_reference.py compare", "grid": "default (120 x 128), check=True",
           "levels": {}}
    for H_c in LEVELS:
        ref = levels[str(H_c)]
        c0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the estimate's size is in the row
            r = first_passage_fpk(model, f"H < {H_c}", check=True, survival=False)
        cpu = time.process_time() - c0
        gap = r.mean_time - ref["mean"]
        row = {"fpk": r.mean_time, "error_estimate": r.error_estimate, "reference": ref["mean"],
               "reference_ci95": ref["ci95"], "error": gap, "relative_error": gap / ref["mean"],
               "within_estimate_and_ci": abs(gap) <= r.error_estimate + ref["ci95"],
               "within_1_percent": abs(gap) <= 0.01 * ref["mean"], "cpu_seconds": cpu}
        out["levels"][str(H_c)] = row
        print(json.dumps({str(H_c): row}), flush=True)
    COMPARE.write_text(json.dumps(out, indent=1) + "\n")


def oracle(dts=(0.04, 0.02, 0.01, 0.005), x0=-0.8, speed=0.5):
    """The reading of a guard of the velocity inside the step, noise-free: the reference runs' guard
    H + kb |y| < h_c with kb = 1 on the free linear oscillator (b = 0, c = 0, D = 0, walls at +-10) from (x0, 0),
    H = x0^2 / 2 constant, so it fires where `|y|` = h_c - H = speed: at arcsin(speed / `|x0|`) exactly. Prints each
    scheme's error per step and the log-log slope of `|error|` against dt (its order)."""
    from hybrid.stochastic import simulate_first_passage

    exact = math.asin(speed / abs(x0))
    for scheme in ("splitting", "baoab", "symplectic"):
        errors = []
        for dt in dts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = simulate_first_passage(example1(), "H + kb*abs(y) < hc", scheme, dt=dt, paths=1, t_max=2.0,
                                           x0=(x0, 0.0), seed=1, check_dt=False, snapshots=10, time_bins=100,
                                           chunk_paths=1, params={"hc": x0 * x0 / 2 + speed, "kb": 1.0, "c": 0.0,
                                                                  "D": 0.0, "b": 0.0, "delta": 10.0})
            errors.append(r.ensemble.mean("exit_time").value - exact)  # the parked mark: the located time
        slope = np.polyfit(np.log(dts), np.log(np.abs(errors)), 1)[0]
        print(json.dumps({"scheme": scheme, "dt": list(dts), "error": errors, "order": slope}), flush=True)


def trend():
    """Per level, the weighted fit T0 + k dt through the reference's runs at their steps (ENGINE): k, the
    first-order step error left, with its 95 % CI."""
    runs = [r for r in load_runs() if r["corrected"] and r.get("scheme", "splitting") == "splitting"
            and r.get("engine") == ENGINE]
    for H_c in LEVELS:
        rows = [r for r in runs if r["H_c"] == H_c]
        if len({r["dt"] for r in rows}) < 2:
            continue
        dt = np.array([r["dt"] for r in rows])
        m = np.array([r["mean"] for r in rows])
        w = (Z95 / np.array([r["ci95"] for r in rows])) ** 2
        A = np.vstack([np.ones_like(dt), dt]).T
        cov = np.linalg.inv(A.T @ (w[:, None] * A))
        T0, k = cov @ (A.T @ (w * m))
        print(json.dumps({"H_c": H_c, "T0": T0, "T0_ci95": Z95 * math.sqrt(cov[0, 0]), "k": k,
                          "k_ci95": Z95 * math.sqrt(cov[1, 1]), "k_dt_relative_at_0.01": k * 0.01 / T0}), flush=True)


def main(argv):
    if not argv or argv[0] not in ("run", "plan", "reference", "validate", "survival", "near", "compare",
                                        "oracle", "trend"):
        print(__doc__)
        return 2
    if argv[0] == "plan":
        for H_c, dt, paths, seed in PLAN:
            print(f"run {H_c} {dt} {paths} {seed}")
        for dt, paths, seed in VALIDATE:
            print(f"run 0.25 {dt} {paths} {seed} --uncorrected")
        return 0
    reports = {"reference": reference, "survival": survival, "compare": compare, "oracle": oracle, "trend": trend}
    if argv[0] in reports:  # the commands that take no arguments
        reports[argv[0]]()
        return 0
    if argv[0] == "validate":
        rows = [r for r in load_runs() if r["H_c"] == 0.25]
        for r in sorted(rows, key=lambda r: (r["corrected"], -r["dt"])):
            print(f"corrected={r['corrected']!s:5} dt={r['dt']:<8g} paths={r['paths']:>7} "
                  f"mean={r['mean']:.4f} +- {r['ci95']:.4f}")
        return 0
    if argv[0] == "near":
        out = near_level(float(argv[1]), float(argv[2]), int(argv[3]), int(argv[4]), "--uncorrected" not in argv)
        with open(NEAR, "a") as fh:
            fh.write(json.dumps(out) + "\n")
        print(json.dumps({k: out[k] for k in ("H0", "dt", "paths", "seed", "corrected", "cpu_seconds")}),
              "R at t = 1, 5:", out["R"][19], out["R"][-1], flush=True)
        return 0
    H_c, dt, paths, seed = float(argv[1]), float(argv[2]), int(argv[3]), int(argv[4])
    scheme = argv[argv.index("--scheme") + 1] if "--scheme" in argv else "splitting"
    out = run(H_c, dt, paths, seed, corrected="--uncorrected" not in argv, scheme=scheme)
    with open(RUNS, "a") as fh:
        fh.write(json.dumps(out) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k not in ("times", "R", "R_lo", "R_hi")}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
