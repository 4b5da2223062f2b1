"""Monte Carlo throughput and time-to-accuracy against reference kernels, all measured in the same run.

    python benchmarks/mc_throughput.py                         # about two minutes on 2 cores
    python benchmarks/mc_throughput.py --quick                 # smaller sizes
    python benchmarks/mc_throughput.py --baseline PATH|none    # an outside baseline kernel (optional)

The reference that is always there is ``numpy_reference`` below: the same scheme as the classic semi-implicit
Euler kernel with the crossing located on the free-flight segment, vectorised over paths with numpy (no compiler),
written for this benchmark. An outside baseline (a module with ``run(npaths, nsteps, dt, a, b, c, D, delta, vc,
seed, nburn, hbins, hmax) -> histogram``) is added when ``--baseline`` or the environment variable
``VIBRO_MC_BASELINE`` names one; without either the benchmark runs against the numpy reference only.

1. Throughput on Example 1 with impacts (a=1, b=0.2, c=0.025, D=0.05, delta=1, Ma V_C=0.4, dt=1e-3), histogram of H
   with 400 bins up to 4, every kernel on the same dt and histogram, interleaved repetitions (the machine's speed
   drifts); prints M path-steps/s of each and the ratios. Compilation is excluded everywhere. The numpy reference
   runs more paths over fewer steps (a vectorised kernel needs wide arrays to be fair to it) and its p(H) is checked
   against ours, so the comparison is between kernels that simulate the same thing.
2. Compile time of our kernel: cold (empty cache directory, in a fresh process) and warm (second process).
3. Time-to-accuracy: elastic walls (e = 1, delta = 1, same parameters): rounds of 256 paths (new seeds, merged)
   until the L1 distance of p(H) (40 bins on [0, 4], both normalised there) to the exact density
   (tests/problems.py ElasticStationary.energy_density) is <= 0.01. Our splitting scheme at a large step, timed
   from nothing in a fresh process with an empty cache (compilation included) and with a warm cache; the baseline
   kernel at dt = 1e-3 (compilation excluded).
4. One declaration, two entry points, in the same run, interleaved, same dt, paths, chunks and histogram:
   ``simulate_ensemble(model, scheme)`` for each oscillator scheme (milstein, splitting, em, naive; milstein also
   with the default joint histogram) against ``simulate_automaton(model.to_automaton(), ...)`` with the automaton
   scheme it runs as (symplectic, baoab, em, naive). Both run kernels of the one generator (the front end's lifts
   the restitution law's numbers into parameters), so E[H] and the impact rate must agree to rounding; the ratio is
   the front end's cost (its statistics rows and the joint histogram).

"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BASELINE_ENV = "VIBRO_MC_BASELINE"
"""Environment variable naming an outside baseline kernel when no --baseline is given."""
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

PARAMS = dict(a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0)
L1_BINS, H_MAX, TARGET = 40, 4.0, 0.01


def resolve_baseline(arg):
    """The outside baseline's path: ``arg`` ('none' disables), else ``$VIBRO_MC_BASELINE``, else None."""
    if arg is None:
        arg = os.environ.get(BASELINE_ENV)
    if arg is None or arg.lower() == "none":
        return None
    path = Path(arg)
    if not path.is_file():
        sys.exit(f"--baseline {arg}: no such file (give a kernel module, or 'none')")
    return path


def load_baseline(path):
    """Import the outside baseline kernel from ``path`` (run, not copied); None when there is none."""
    if path is None:
        return None
    spec = importlib.util.spec_from_file_location("mc_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def numpy_reference(paths, nsteps, dt, vc, seed, nburn, hbins=400, hmax=H_MAX, block=250):
    """Reference kernel, vectorised over paths with numpy: symplectic Euler, crossing on the free-flight segment.

    Example 1 (Duffing, c*y damping, additive noise) between barriers at +-delta with Ma's law; H is histogrammed
    every step after ``nburn``. Normals and histogram indices are handled ``block`` steps at a time, so the Python
    loop costs little once ``paths`` is in the thousands.

    Examples
    --------
    >>> h = numpy_reference(64, 200, 1e-2, 0.4, seed=1, nburn=100)
    >>> int(h.sum())
    6400
    """
    a, b, c, D, delta = (PARAMS[k] for k in ("a", "b", "c", "D", "delta"))
    rng = np.random.default_rng(seed)
    x, v = np.zeros(paths), np.zeros(paths)
    hist = np.zeros(hbins, np.int64)
    sq, w = np.sqrt(2.0 * D * dt), vc ** (1.0 / 6.0)
    keep = []
    for n0 in range(0, nsteps, block):
        g = rng.standard_normal((min(block, nsteps - n0), paths)) * sq
        for n, gn in enumerate(g, n0):
            vn = v + (-c * v - a * x - b * x * x * x) * dt + gn
            xn = x + vn * dt
            hit = np.nonzero(np.abs(xn) >= delta)[0]
            if hit.size:
                xo, xh, vh = x[hit], xn[hit], vn[hit]
                sg = np.sign(xh)
                th = (sg * delta - xo) / (xh - xo)  # fraction of the step before the wall
                av = np.abs(vh)
                e = np.where(av <= vc, 1.0, w * av ** (-1.0 / 6.0))
                vn[hit] = -e * vh
                xn[hit] = sg * delta + vn[hit] * (1.0 - th) * dt
            x, v = xn, vn
            if n >= nburn:
                keep.append(0.5 * v * v + 0.5 * a * x * x + 0.25 * b * x ** 4)
        if keep:
            k = (np.concatenate(keep) * (hbins / hmax)).astype(np.int64)
            hist += np.bincount(k[k < hbins], minlength=hbins)
            keep = []
    return hist


def exact_bins():
    """Exact P(H in bin), 40 bins on [0, 4], Simpson per bin, renormalised on [0, 4]."""
    from problems import elastic_duffing

    model, exact = elastic_duffing(**PARAMS)
    e = np.linspace(0.0, H_MAX, L1_BINS + 1)
    lo, hi = e[:-1], e[1:]
    pts = np.maximum(np.concatenate([lo, 0.5 * (lo + hi), hi]), 1e-9)
    d = exact.energy_density(pts, model.barrier_energy)
    n = L1_BINS
    q = (hi - lo) / 6 * (d[:n] + 4 * d[n:2 * n] + d[2 * n:])
    return q / q.sum()


def l1(counts, q):
    c = np.asarray(counts, dtype=float).reshape(L1_BINS, -1).sum(axis=1)
    return float(np.abs(c / c.sum() - q).sum())


# ------------------------------------------------------------------------------------------------ 1. throughput
def throughput(paths, t_end, reps, mb, ref_paths, ref_t):
    import numba

    from hybrid.stochastic import simulate_ensemble
    from models import DuffingImpact, Ma

    model = DuffingImpact(restitution=Ma(0.4), **PARAMS)
    dt, t_burn = 1e-3, 100.0
    n, nburn = int(round(t_end / dt)), int(round(t_burn / dt))
    n_ref = int(round(ref_t / dt))
    if mb is not None:
        mb.run(2, 10, dt, 1.0, 0.2, 0.025, 0.05, 1.0, 0.4, 1, 1, 10, 4.0)  # compile the baseline
    kw = dict(dt=dt, paths=paths, t_end=t_end, t_burn=t_burn, h_max=H_MAX, bins=400, xy_bins=None, seed=1)
    simulate_ensemble(model, "milstein", **{**kw, "paths": 8, "t_end": 2.0, "t_burn": 1.0})  # compile/load ours
    simulate_ensemble(model, "splitting", **{**kw, "paths": 8, "t_end": 2.0, "t_burn": 1.0})
    ref_label = "numpy reference"
    rows = {ref_label: [], **({"outside baseline": []} if mb is not None else {}),
            "milstein": [], "splitting": [], "milstein stride 4": []}
    ref_hist = None
    for rep in range(reps):
        t0 = time.perf_counter()
        # the reference starts in equilibrium's neighbourhood only after a burn-in, like ours: t_burn = ref_t / 2
        h = numpy_reference(ref_paths, n_ref, dt, 0.4, 7 + rep, n_ref // 2)
        rows[ref_label].append(ref_paths * n_ref / (time.perf_counter() - t0) / 1e6)
        ref_hist = h if ref_hist is None else ref_hist + h
        if mb is not None:
            t0 = time.perf_counter()
            mb.run(paths, n, dt, 1.0, 0.2, 0.025, 0.05, 1.0, 0.4, 1, nburn, 400, H_MAX)
            rows["outside baseline"].append(paths * n / (time.perf_counter() - t0) / 1e6)
        for label, scheme, stride in (("milstein", "milstein", 1), ("splitting", "splitting", 1),
                                      ("milstein stride 4", "milstein", 4)):
            s = simulate_ensemble(model, scheme, stride=stride, **kw)
            assert s.violations == 0
            rows[label].append(s.throughput / 1e6)
    print(f"\n1. Throughput, Example 1 with Ma impacts, dt=1e-3, 400 H bins, {numba.get_num_threads()} threads, "
          f"best of {reps} interleaved runs (M path-steps/s); compiled kernels: {paths} paths x {n} steps; numpy "
          f"reference (written for this benchmark, vectorised over paths, no compiler): {ref_paths} paths x "
          f"{n_ref} steps")
    if mb is None:
        print("   outside baseline: none (give --baseline PATH to add one)")
    for label, vals in rows.items():
        ratio = ""
        for ref in [ref_label] + (["outside baseline"] if mb is not None and label != "outside baseline" else []):
            if label != ref and label in ("milstein", "splitting", "milstein stride 4", "outside baseline"):
                ratio += f"   {max(vals) / max(rows[ref]):.1f}x {ref} (median of runs " \
                         f"{np.median(np.array(vals) / np.array(rows[ref])):.1f}x)"
        print(f"   {label:18s} {max(vals):7.1f}  (runs: {', '.join(f'{v:.1f}' for v in vals)}){ratio}")
    # same start (rest), same window: the short reference runs are not yet stationary, so compare like with like
    ours = simulate_ensemble(model, "milstein", **{**kw, "paths": ref_paths, "t_end": ref_t, "t_burn": ref_t / 2})
    agree = float(np.abs(_bins(ours.h_counts) - _bins(ref_hist)).sum())
    print(f"   same physics: L1 of p(H) on {L1_BINS} bins over the same window from rest, numpy reference vs our "
          f"milstein = {agree:.3f} (sampling noise of both included)")
    return rows


def _bins(counts):
    c = np.asarray(counts, dtype=float).reshape(L1_BINS, -1).sum(axis=1)
    return c / c.sum()


# ------------------------------------------------------------------------------------------------ 2./3. fresh process
_CHILD = r"""
import json, sys, time, warnings
t_start = time.perf_counter()
import numpy as np
sys.path.insert(0, {tests!r})
from hybrid.stochastic import simulate_ensemble
from models import DuffingImpact, Elastic
t_import = time.perf_counter()
q = np.array({q!r})
model = DuffingImpact(restitution=Elastic(), **{params!r})
merged, rounds, t0 = None, 0, time.perf_counter()
while True:
    s = simulate_ensemble(model, {scheme!r}, dt={dt!r}, paths=256, t_end=1100.0, t_burn=100.0, h_max=4.0, bins=400,
                          xy_bins=None, seed=1000 + rounds)
    if rounds == 0:
        compile_time = s.compile_time
    merged = s if merged is None else merged.merge(s)
    rounds += 1
    c = merged.h_counts.reshape({bins}, -1).sum(axis=1)
    dist = float(np.abs(c / c.sum() - q).sum())
    if dist <= {target} or rounds >= 16:
        break
print(json.dumps(dict(import_s=t_import - t_start, compile_s=compile_time, total_s=time.perf_counter() - t0,
                      rounds=rounds, l1=dist, path_steps=merged.path_steps)))
"""


def fresh_process(scheme, dt, q, cache):
    code = _CHILD.format(tests=str(ROOT / "tests"), q=q.tolist(), params=PARAMS, scheme=scheme, dt=dt,
                         bins=L1_BINS, target=TARGET)
    env = {**os.environ, "VIBRO_CACHE_DIR": cache}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)
    if out.returncode:
        sys.exit(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def baseline_time_to_accuracy(q, paths, mb):
    dt, t_end, t_burn = 1e-3, 1100.0, 100.0
    n, nburn = int(round(t_end / dt)), int(round(t_burn / dt))
    mb.run(2, 10, dt, 1.0, 0.2, 0.025, 0.05, 1.0, 1e300, 1, 1, 10, 4.0)
    total, counts, rounds, t0 = 0, np.zeros(400), 0, time.perf_counter()
    while True:  # vc = 1e300: e = 1 at every speed (elastic walls)
        counts += mb.run(paths, n, dt, 1.0, 0.2, 0.025, 0.05, 1.0, 1e300, 1000 + rounds, nburn, 400, H_MAX)
        rounds += 1
        total += paths * n
        dist = l1(counts, q)
        if dist <= TARGET or rounds >= 8:
            return dict(total_s=time.perf_counter() - t0, rounds=rounds, l1=dist, path_steps=total)


def general_against_specialised(paths, t_end, reps):
    from hybrid.stochastic import AUTOMATON_SCHEME_OF, simulate_automaton, simulate_ensemble
    from models import DuffingImpact, Ma

    model = DuffingImpact(restitution=Ma(0.4), **PARAMS)
    auto = model.to_automaton()
    dt, t_burn, chunk = 2e-3, 100.0, 8
    common = dict(dt=dt, paths=paths, t_end=t_end, t_burn=t_burn, seed=1, chunk_paths=chunk)
    n = paths * t_end / dt
    print(f"\n4. Same model, two entry points: Example 1 (Ma 0.4), dt={dt:g}, {paths} paths x {t_end:g}, chunks of "
          f"{chunk}, interleaved, M path-steps/s (set-up included)")

    def front(scheme, xy=None, **kw):
        return simulate_ensemble(model, scheme, xy_bins=xy, bins=400, h_max=H_MAX, **kw)

    def automaton(scheme, xy=None, **kw):
        return simulate_automaton(auto, scheme, x0=(0.0, 0.0), histograms={"H": (0.0, H_MAX, 400)}, **kw)

    def mean_and_rate(r):
        if hasattr(r, "mean_energy"):
            return r.mean_energy.value, r.mean_energy.ci, r.impact_rate.value
        return r.mean("H").value, r.mean("H").ci, sum(r.rate(t) for t in r.transitions)

    cases = [(s, AUTOMATON_SCHEME_OF[s], f"simulate_ensemble {s} against simulate_automaton {AUTOMATON_SCHEME_OF[s]}")
             for s in ("milstein", "splitting", "em", "naive")]
    cases.insert(1, ("milstein", "symplectic", "the same with the default joint (x, y) histogram, 80 x 80 bins",
                     (80, 80)))
    for scheme, auto_scheme, label, *xy in cases:
        common["xy"] = xy[0] if xy else None
        warm = {**common, "paths": chunk, "t_end": t_burn + 1.0}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # em's temperature bias, one chunk in the warm-up
            front(scheme, **warm)
            automaton(auto_scheme, **{k: v for k, v in warm.items() if k != "xy"})
            special, general = [], []
            for _ in range(reps):
                t0 = time.perf_counter()
                s = front(scheme, **common)
                special.append(n / (time.perf_counter() - t0) / 1e6)
                t0 = time.perf_counter()
                e = automaton(auto_scheme, **{k: v for k, v in common.items() if k != "xy"})
                general.append(n / (time.perf_counter() - t0) / 1e6)
        ratio = np.array(special) / np.array(general)
        (sv, sc, sr), (gv, gc, gr) = mean_and_rate(s), mean_and_rate(e)
        print(f"   {label}\n      front end {max(special):6.1f} (runs {', '.join(f'{v:.1f}' for v in special)})"
              f"   automaton {max(general):6.1f} (runs {', '.join(f'{v:.1f}' for v in general)})   "
              f"front end / automaton: median {np.median(ratio):.2f}")
        print(f"      E[H] {sv:.6f} +- {sc:.4f} against {gv:.6f} +- {gc:.4f}; impact rate {sr:.5f} against {gr:.5f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    ap.add_argument("--baseline", default=None, metavar="PATH|none",
                    help=f"outside baseline kernel module (default: ${BASELINE_ENV} if set, else none)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    path = resolve_baseline(args.baseline)
    print(f"outside baseline: {path if path is not None else 'none'}; in-run reference: numpy_reference "
          "(this file)")
    mb = load_baseline(path)
    paths, t_end, reps = (64, 600.0, 2) if args.quick else (256, 1100.0, 3)
    ref_paths, ref_t = (2048, 20.0) if args.quick else (4096, 40.0)
    throughput(paths, t_end, reps, mb, ref_paths, ref_t)
    general_against_specialised(32 if args.quick else 64, 600.0 if args.quick else 1200.0, reps)

    q = exact_bins()
    with tempfile.TemporaryDirectory() as cold:
        first = fresh_process("splitting", 0.035, q, cold)
        second = fresh_process("splitting", 0.035, q, cold)
        mil = fresh_process("milstein", 0.01, q, cold)
    print("\n2. Compile time of the splitting kernel (generation + numba), fresh process:")
    print(f"   cold (empty cache dir) {first['compile_s']:.2f} s   warm (on-disk cache) {second['compile_s']:.2f} s   "
          f"(imports {first['import_s']:.2f} s)")
    print(f"\n3. Time to L1(p(H)) <= {TARGET} on {L1_BINS} bins, elastic walls, against the exact density:")
    for label, r in (("splitting dt=0.035, cold cache", first), ("splitting dt=0.035, warm cache", second),
                     ("milstein dt=0.01, cold cache", mil)):
        print(f"   ours {label:32s} {r['total_s']:6.2f} s incl. compile  ({r['rounds']} x 256 paths, "
              f"L1 = {r['l1']:.4f}, {r['path_steps']:.3g} path-steps)")
    print(f"   ratio milstein dt=0.01 / splitting dt=0.035 (both cold)  {mil['total_s'] / first['total_s']:.1f}x")
    if mb is None:
        print("   outside baseline: none given, so no baseline time-to-accuracy")
        return
    b = baseline_time_to_accuracy(q, 256, mb)
    print(f"   baseline dt=1e-3 (compile excluded)    {b['total_s']:6.2f} s  ({b['rounds']} x 256 paths, "
          f"L1 = {b['l1']:.4f}, {b['path_steps']:.3g} path-steps)")
    print(f"   ratio baseline / ours (warm cache)      {b['total_s'] / second['total_s']:.1f}x")


if __name__ == "__main__":
    main()
