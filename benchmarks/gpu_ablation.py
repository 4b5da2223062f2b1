"""What the pieces of the automaton CUDA kernel cost: variants of its generated source, timed in one process.

    python benchmarks/gpu_ablation.py                                  # Example 1, every variant, 2 rounds
    python benchmarks/gpu_ablation.py --models "impact pair" --variants norng,nobook,noevent
    python benchmarks/gpu_ablation.py --variants bake,base@64,bake@80   # register caps in the same process
    python benchmarks/gpu_ablation.py --ncu nostats  # one launch of 2**17 x 2000 steps of one variant, for ncu:
    ncu -k regex:advance --launch-count 1 --section SourceCounters -o nostats \
        python benchmarks/gpu_ablation.py --ncu nostats
    NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 python benchmarks/gpu_ablation.py --quick   # a check, not a timing

Each variant is the device module of ``simulate_automaton(..., scheduler="cuda")`` with one change made to its
text (or, for ``nobm``, to the normal generator it imports), compiled under its own module name. Two kinds:

* **ablations** cut a piece out, to price it; their numbers are wrong on purpose. ``norng``: uniforms of variance 1
  from a splitmix64 hash of (pair, path) in place of Philox and Box-Muller; ``nobm``: Philox's words as such
  uniforms, without Box-Muller. These two keep the noise's mean and variance, so E[observable] should stay close
  to the kernel's (printed, in the kernel's intervals). ``nostats``: no statistics at all; ``nohist``: no histogram
  increment; ``noevent``: the event code never called (a guard that fires is ignored: it prices the event code's
  place in the kernel, its registers most of all). ``nobook`` keeps only the bookkeeping this benchmark's runs need
  (no burn-in, every step a sample): its numbers are the kernel's on a model without phase sections.
* **rewrites** do the same arithmetic in another shape and must give the kernel's numbers exactly (checked: the
  observable's histogram and its mean to full precision): ``bake`` (Example 1 only: every launch argument but the
  state, the steps and the keys a literal of the source, as in a hand-written kernel), ``bakeparams`` (only the
  model's parameters and their loop invariants), ``bakeobs`` (only the histogram's range), ``extevent`` (the event
  code compiled on its own and linked, so that it is a call NVVM cannot inline).

  Earlier rewrites that paid are now the template's own (docs/gpu.md): the times computed only where the event
  code reads them, 32-bit bins straight into the shared cells, a 32-bit step counter, a toggled parity for the
  normals' pairs (H100, with the runner whose host work was cut: 1.06x together on Example 1, 1.12x on the impact
  pair), no phase or joint code in a run without them (1.08x, 1.07x; benchmarks/data/gpu_h100_ablation_runner.txt).
  Others did not: two steps per loop pass, the next pair drawn a pass early, the event code out of the hot loop in
  a loop of its own (gpu_h100_ablation_run4.log, gpu_h100_ablation_nested.txt).

A variant may name a register cap: ``bake@64`` is ``bake`` compiled under ``VIBRO_CUDA_MAX_REGISTERS=64``
(``@0``: no cap); a cap does not change the arithmetic, so ``base@64`` must give base's numbers too.

All variants of a model run in one process on one warm device, in rounds whose order alternates, with the
unchanged kernel (``base``) in every round: per variant it prints the path-steps/s of each timing (2**20 paths x
20,000 steps of dt = 1e-3 from rest, compilation excluded) and the mean over rounds of its ratio to base's median
in the same round (an even number of rounds, so that a steady drift cancels). Only such ratios compare: the
H100s lent to this project drifted by up to 15 % within one such run. The models are those of
``gpu_throughput.py --automata``. A rewrite assumes the text the current template generates; where it does not fit
(the template has changed, or the model has another number of noises), the variant is skipped with a line naming
the text it missed.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import math
import os
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from gpu_throughput import DT, automaton_models  # noqa: E402

from hybrid.stochastic import _auto_cuda, _cuda_rng, simulate_automaton  # noqa: E402


class TemplateChanged(SystemExit):
    """A rewrite did not find the text it changes (a SystemExit, so that no ``except Exception`` on the way out of
    ``simulate_automaton`` turns it into another error)."""


def _need(src: str, *pieces: str) -> None:
    for piece in pieces:
        if piece not in src:
            raise TemplateChanged(f"gpu_ablation: the generated source has no {piece.strip()[:60]!r}: the template "
                                  "changed; update the variant")


# the generated text the variants change (the kernel template of hybrid/stochastic/_auto_cuda.py)
_BOOK = """                phase_now = False
                sample = False
                if rec:
                    _cs += 1
                    if _cs >= stride:
                        _cs = 0
                        sample = True
"""
_DRAW = re.compile(r"_za, _zb = normal_pair\(rk, ip, (.+)\)$", re.M)
_HIST_CELL = "cuda.atomic.add(sh, H_OFF + 0 * WIDTH + np.int32(_b) + 1, 1)"


def norng(src):
    # splitmix64's finaliser of (pair, path): two independent-looking 32-bit halves, as uniforms of variance 1
    if not _DRAW.search(src):
        raise TemplateChanged("gpu_ablation: norng: the generated source draws no normal_pair(rk, ip, ...)")

    def cheap(m):
        ind = "\n" + " " * (len(m.string[:m.start()].rsplit("\n", 1)[-1]))
        return ind.join([
            f"_hh = np.uint64({m[1]}) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(ip) * np.uint64(0xD1B54A32D192ED03)",
            "_hh = (_hh ^ (_hh >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)",
            "_hh = (_hh ^ (_hh >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)",
            "_hh = _hh ^ (_hh >> np.uint64(31))",
            "_za = _fty(_hh >> np.uint64(32)) * _fty(8.065872858567445e-10) - _fty(1.7320508075688772)",
            "_zb = _fty(_hh & np.uint64(0xFFFFFFFF)) * _fty(8.065872858567445e-10) - _fty(1.7320508075688772)"])

    return _DRAW.sub(cheap, src)


def nobm(src):
    # the source is unchanged but for this line: its own module and cache entry, tied to the generator that run()
    # swaps in (numba's disk cache would not see an edit of _philox_uniforms)
    digest = hashlib.sha256(inspect.getsource(_philox_uniforms).encode()).hexdigest()[:16]
    return src + f"\n# gpu_ablation variant nobm: Philox without Box-Muller ({digest})\n"


def nostats(src):
    cut = "                if not sample:\n                    continue\n"
    _need(src, cut)
    return src.replace(cut, "                continue\n", 1)


def nohist(src):
    _need(src, _HIST_CELL)
    return src.replace(_HIST_CELL, "_nsamp += 0", 1)


def nobook(src):
    _need(src, _BOOK)
    return src.replace(_BOOK, "                phase_now = False\n                sample = True\n")


def noevent(src):
    cut = "mode = event_step(mode, x, t, _t1, dt, dw, p, rec, sh, v_scale, v_bins, track, iw, fw, ws, elog)"
    _need(src, cut)
    return src.replace(cut, "mode = mode + 0")


_ADVANCE_DOC = ('    """Steps [n0, n1) of paths 0 .. npath-1, one thread each; every path\'s row in XS .. FWS in and '
                'out."""\n')
_EXAMPLE1_HOISTED = ("HOISTED_TEXTS = ('_inv0 = -a', '_inv1 = -b', '_inv2 = -c', '_inv3 = sqrt(2)*sqrt(D)', "
                     "'_inv4 = -delta', '_inv5 = a/2', '_inv6 = b/4')")
_EXAMPLE1_P = "p = (1.0, 0.2, 0.025, 0.05, 1.0)"
_EXAMPLE1_HV = f"hv = {(-1.0, -0.2, -0.025, math.sqrt(2) * math.sqrt(0.05), -1.0, 0.5, 0.05)!r}"
_EXAMPLE1_OBS = ("obs_lo = (0.0,)", "obs_scale = (100.0,)", "obs_bins = (400,)")


def _literals(*lines):
    """A rewrite that sets launch arguments to literals at the kernel's top: Example 1's values in gpu_throughput's
    runs (its histogram of H and hoisted invariants are checked first)."""
    def rewrite(src):  # f64: the literals are doubles; gpu_throughput's DT is the 1e-3 baked in
        _need(src, _ADVANCE_DOC, _EXAMPLE1_HOISTED, "\nN_OBS = 1\n", "precision f64.")
        return src.replace(_ADVANCE_DOC, _ADVANCE_DOC + "".join(f"    {ln}\n" for ln in lines))
    return rewrite


bakeparams = _literals(_EXAMPLE1_P, _EXAMPLE1_HV)
bakeobs = _literals(*_EXAMPLE1_OBS)
bake = _literals(_EXAMPLE1_P, _EXAMPLE1_HV, *_EXAMPLE1_OBS, "jx = -1", "jy = -1", "j_lo = (0.0, 0.0)",
                 "j_scale = (1.0, 1.0)", "j_bins = (1, 1)", "n_phase = 0", "phase_steps = 1", "stride = 1",
                 "dt = 0.001", "t0 = 0.0")

_EVENT_CALL = "mode = event_step(mode, x, t, _t1, dt, dw, p, rec, sh, v_scale, v_bins, track, iw, fw, ws, elog)"
_COUNT_DEF = "\n@cuda.jit(device=True, inline=True)\ndef count("
_EXTERN = """
# gpu_ablation extevent: event_step compiled on its own (C ABI) and linked, so that NVVM cannot inline it
from numba import types as _nt  # noqa: E402

_F1 = _nt.Array(_fty, 1, "C")
_EV_SIG = _nt.int64(_nt.int64, _F1, _fty, _fty, _fty, _F1, _nt.UniTuple(_fty, {n_p}), _nt.boolean,
                    _nt.Array(int32, 1, "C"), _fty, _nt.int64, _nt.boolean, _nt.Array(int64, 1, "C"),
                    _nt.Array(float64, 1, "C"), _F1, _nt.Array(float64, 2, "C"))


def _event_ptx():
    import os
    from pathlib import Path
    try:
        cc = cuda.get_current_device().compute_capability
    except Exception:  # no device (a PTX compile on a machine without a GPU): the H100's
        cc = (9, 0)
    ptx, _ = cuda.compile_ptx(event_step.py_func, _EV_SIG.args, device=True, abi="c",
                              abi_info={{"abi_name": "vibro_event_step"}}, cc=cc)
    path = Path(__file__).with_suffix(".event.ptx") if "__file__" in globals() else Path(f"/tmp/ev{{os.getpid()}}.ptx")
    path.write_text(ptx)
    return str(path)


event_step_ext = cuda.declare_device("vibro_event_step", _EV_SIG, link=[_event_ptx()], abi="c")
"""


def extevent(src):
    # the event code as a call that NVVM cannot inline: its registers its own, a register cap's spills on the rare
    # path. Measured on an H100: slower (0.77x; 1.03x with bake under a cap of 64)
    _need(src, _EVENT_CALL, _COUNT_DEF, "@cuda.jit(cache=True")
    n_p = 1 + max((int(k) for k in re.findall(r"^    _p\d+ = p\[(\d+)\]$", src, re.M)), default=0)
    return (src.replace(_COUNT_DEF, _EXTERN.format(n_p=n_p) + "\n" + _COUNT_DEF, 1)
            .replace(_EVENT_CALL, _EVENT_CALL.replace("event_step(", "event_step_ext("))
            .replace("@cuda.jit(cache=True", "@cuda.jit(cache=False"))  # numba caches no kernel with links


VARIANTS = {"base": lambda src: src, "norng": norng, "nobm": nobm, "nostats": nostats, "nohist": nohist,
            "nobook": nobook, "noevent": noevent, "bake": bake, "bakeparams": bakeparams, "bakeobs": bakeobs,
            "extevent": extevent}
EXACT = ("nobook", "bake", "bakeparams", "bakeobs", "extevent")
"""The variants that must give the unchanged kernel's numbers (nobook: on these runs, without phase sections)."""
NEAR = ("norng", "nobm")
"""Ablations that keep the noise's mean and variance: E[observable] near the kernel's (not checked, printed)."""


def _philox_uniforms(precision):
    """A device ``normal_pair`` that returns two Philox words as uniforms of variance 1 (no Box-Muller)."""
    from numba import cuda

    # on the simulator plain functions, as _cuda_rng's own (device functions take a lock at every call there)
    device = (lambda f: f) if _auto_cuda.simulator_enabled() else cuda.jit(device=True, inline=True)
    philox = device(_cuda_rng._make_philox(device(_cuda_rng._philox_round)))
    mask, s32 = _cuda_rng._MASK, _cuda_rng._S32
    ft = np.float32 if precision == "f32" else np.float64
    scale, shift = ft(2.0 * 3.0**0.5 / 2**32), ft(3.0**0.5)

    def pair(rk, path, q):
        pr = np.uint64(q)
        pa = np.uint64(path)
        a, b, c, d = philox(pr & mask, pr >> s32, pa & mask, pa >> s32, rk)
        return ft(a) * scale - shift, ft(c) * scale - shift

    return device(pair)


def run(args) -> dict:
    automaton, scheme, kw = automaton_models()[args.models]
    original_source = _auto_cuda.generate_cuda_source
    original_pair = _cuda_rng.device_normal_pair(args.precision)
    sim = _auto_cuda.simulator_enabled()

    cap_env = os.environ.get("VIBRO_CUDA_MAX_REGISTERS")

    def use(variant):
        name, _, cap = variant.partition("@")  # "nested@64": the variant under a register cap of 64 (0: none)

        def generate(*a, **k):
            src, st = original_source(*a, **k)
            return VARIANTS[name](src), st

        _auto_cuda.generate_cuda_source = generate
        _cuda_rng._DEVICE[args.precision] = _philox_uniforms(args.precision) if name == "nobm" else original_pair
        if cap:  # read when the source is generated
            os.environ["VIBRO_CUDA_MAX_REGISTERS"] = cap
        elif cap_env is None:
            os.environ.pop("VIBRO_CUDA_MAX_REGISTERS", None)
        else:
            os.environ["VIBRO_CUDA_MAX_REGISTERS"] = cap_env

    def ensemble(paths, steps):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return simulate_automaton(automaton, scheme, dt=DT, paths=paths, t_end=steps * DT, t_burn=0.0, seed=1,
                                      check_dt=False, scheduler="cuda", threads_per_block=args.threads_per_block,
                                      launch_steps=args.launch_steps, precision=args.precision, **kw)

    def numbers(g):  # what a rewrite must leave unchanged: the first observable's histogram and mean, all bits
        name = g.names[0]
        return repr(float(g.mean(name).value)), np.asarray(g.counts[name]).tobytes()

    if args.ncu:
        use(args.ncu)
        g = ensemble(2**17, 2000)
        print(f"{args.ncu}: one launch, {g.settings['device_seconds']:.3f} s")
        return {}
    exact = tuple(v for v in EXACT if not (v == "nobook" and kw.get("phases"))) + ("base",)
    names = ["base"] + [v for v in args.variants.split(",") if v != "base"]
    unknown = [v for v in names if v.partition("@")[0] not in VARIANTS or not v.partition("@")[2].isdigit()
               and "@" in v]
    if unknown:
        raise SystemExit(f"gpu_ablation: unknown variants {unknown}; choose from {', '.join(VARIANTS)}")
    rows = {v: {"rates": [], "round_medians": []} for v in names}
    skipped: dict = {}
    try:
        for r in range(args.rounds):
            for v in names if r % 2 == 0 else names[::-1]:
                if v in skipped:
                    continue
                use(v)
                row = rows[v]
                if "compile_s" not in row:
                    t0 = time.perf_counter()
                    try:
                        ensemble(128, 10)
                    except TemplateChanged as exc:  # a rewrite that does not fit this model's source
                        skipped[v] = str(exc)
                        print(f"{v}: skipped ({exc})", flush=True)
                        continue
                    row["compile_s"] = time.perf_counter() - t0
                rates = []
                for _ in range(args.timings):
                    g = ensemble(args.paths, args.steps)
                    rates.append(args.paths * args.steps / g.settings["device_seconds"])
                row["rates"] += rates
                row["round_medians"].append(statistics.median(rates))
                row["mean"] = str(g.mean(g.names[0]))
                row["estimate"] = g.mean(g.names[0])
                row["numbers"] = numbers(g)
                if not sim:
                    row.update(_auto_cuda.kernel_resources(g.settings))
                print(f"round {r + 1} {v:<8} {' '.join(f'{x:.3g}' for x in rates)} path-steps/s; "
                      f"E[{g.names[0]}] = {row['mean']}", flush=True)
    finally:
        _auto_cuda.generate_cuda_source = original_source
        _cuda_rng._DEVICE[args.precision] = original_pair
        if cap_env is None:
            os.environ.pop("VIBRO_CUDA_MAX_REGISTERS", None)
        else:
            os.environ["VIBRO_CUDA_MAX_REGISTERS"] = cap_env
    print(f"\n{args.models}, {args.precision}, {args.paths} paths x {args.steps} steps, "
          f"{args.threads_per_block} threads per block"
          + (" (the simulator: not a timing)" if sim else ""))
    print(f"{'variant':<9} {'median /s':>10} {'/ base':>7}  rounds' ratios        registers local  numbers")
    base = rows["base"]
    names = [v for v in names if v not in skipped]
    for v in names:
        row = rows[v]
        ratios = [a / b for a, b in zip(row["round_medians"], base["round_medians"])]
        row["ratio"] = statistics.mean(ratios)
        if v.partition("@")[0] in exact and v != "base":
            same = "same" if row["numbers"] == base["numbers"] else "CHANGED"
        elif v.partition("@")[0] in NEAR:
            e, b = row["estimate"], base["estimate"]
            width = math.hypot(e.ci, b.ci)
            k = abs(e.value - b.value) / width if math.isfinite(width) and width > 0 else math.inf
            same = f"E {k:.2f} CIs off"
        else:
            same = "-"
        res = f"{row.get('registers_per_thread', '-'):>9} {row.get('local_bytes_per_thread', '-'):>5}"
        print(f"{v:<9} {statistics.median(row['rates']):10.3g} {row['ratio']:7.2f}  "
              f"{' '.join(f'{x:.2f}' for x in ratios):<21} {res}  {same}")
    bad = [v for v in names if v.partition("@")[0] in exact and rows[v]["numbers"] != base["numbers"]]
    if bad:
        raise SystemExit(f"gpu_ablation: the rewrites {bad} changed the numbers")
    for v, why in skipped.items():
        rows[v] = {"skipped": why}
    for row in rows.values():  # for --json
        row.pop("numbers", None)
        row.pop("estimate", None)
    return rows


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    ap.add_argument("--models", default="Example 1", help="one model of gpu_throughput.py's automaton_models")
    ap.add_argument("--variants", default=",".join(VARIANTS), help=f"separated by ',' from: {', '.join(VARIANTS)}")
    ap.add_argument("--precision", default="f64", choices=("f64", "f32"))
    ap.add_argument("--rounds", type=int, default=2, help="an even number: a steady drift cancels in the mean")
    ap.add_argument("--timings", type=int, default=1, help="timed runs per variant and round")
    ap.add_argument("--paths", type=int, default=2**20)
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--threads-per-block", type=int, default=128)
    ap.add_argument("--launch-steps", type=int, help="steps per launch (default: the scheduler's)")
    ap.add_argument("--quick", action="store_true",
                    help="64 paths x 51 steps in launches of 7, 32 threads per block, 2 rounds (for the simulator)")
    ap.add_argument("--ncu", metavar="VARIANT", help="one launch of one variant, nothing timed (run it under ncu)")
    ap.add_argument("--json", metavar="FILE", help="write the rows")
    args = ap.parse_args(argv)
    if args.quick:
        args.paths, args.steps, args.rounds, args.threads_per_block, args.launch_steps = 64, 51, 2, 32, 7
    if args.rounds % 2:
        print(f"gpu_ablation: {args.rounds} rounds: a steady drift does not cancel in an odd number", file=sys.stderr)
    if args.ncu and args.ncu not in VARIANTS:
        ap.error(f"--ncu {args.ncu}: choose one of {', '.join(VARIANTS)}")
    if not _auto_cuda.simulator_enabled():
        try:
            _auto_cuda.require_cuda()
            from numba import cuda

            cuda.get_current_device()
        except Exception as exc:  # no GPU: one line
            print(f"gpu_ablation: no GPU: {str(exc).splitlines()[0]} (NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 "
                  "runs it on the simulator)", file=sys.stderr)
            raise SystemExit(2) from None
    rows = run(args)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    return rows


if __name__ == "__main__":
    main()
