"""Cold compile time of the Monte Carlo kernels named in issue 22, each in a fresh process with empty caches.

    python benchmarks/compile_time.py            # the three kernels, 3 fresh processes each (a few minutes)
    python benchmarks/compile_time.py --reps 1 --functions   # and each numba function's own compile time
    python benchmarks/compile_time.py --baseline main        # and the same in a ``git archive`` of main, interleaved
    python benchmarks/compile_time.py --baseline main --throughput   # and path-steps per CPU s of each kernel
    python benchmarks/compile_time.py --baseline main --warm 4       # and 4 recompiles in each warm process

Kernels: Example 1 (``simulate_ensemble(DuffingImpact(Ma(0.4)), "milstein")``, the automaton kernel's symplectic
scheme), the impact pair with ``splitting`` and a forced linear oscillator with phase sections (``splitting``,
``phases=8``). Each run starts a new Python with an empty ``VIBRO_CACHE_DIR`` and ``NUMBA_CACHE_DIR``, so numba
compiles everything the kernel needs (the random-number helpers too), as on a user's first run. Printed per kernel:
the wall time and the process CPU time (``time.process_time``: on a shared machine the wall time also counts other
processes) of the first small run, which is almost all compile (8 paths x 300 to 1,100 steps), and of numba's
compiles alone (numba's ``numba:compile`` events of top-level functions), the part of it spent in LLVM (numba's
``numba:llvm_lock`` events: optimisation and machine code) and the size of the generated kernel source. The median
over repetitions is what issue 22 budgets (at most 2 s). With ``--baseline REF`` each kernel is also compiled by the
tree of the git revision REF (``git archive`` into a temporary folder), alternating with this tree, and the ratio of
the medians is printed: a before/after measured in the same run, under the same load. With ``--warm N`` each fresh
process then compiles its kernel N more times, under fresh module names (a new name is a new file, which neither
the loaded modules nor numba's disk cache hold): numba's own start-up is then paid, and what is timed is the
kernel's compile alone. On a shared machine whose speed drifts, the least of these is the steadiest figure for
comparing two generators.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, sys, time, warnings
warnings.simplefilter("ignore")
sys.path.insert(0, {tests!r})
from numba.core import event
import numpy as np
from hybrid.stochastic import simulate_automaton, simulate_ensemble
from models import DuffingImpact, ImpactOscillator, Ma, automata

compiles = []
llvm = []  # cpu s under numba's LLVM lock (outermost only)
stack = []  # per open compile: [start wall, start cpu, cpu of the compiles nested in it]
own = {{}}  # function name -> cpu s of its own compiles, without the functions compiled on the way


class Listener(event.Listener):
    def on_start(self, ev):
        stack.append([time.perf_counter(), time.process_time(), 0.0])

    def on_end(self, ev):
        w0, c0, nested = stack.pop()
        cpu = time.process_time() - c0
        name = ev.data["dispatcher"].py_func.__name__
        own[name] = own.get(name, 0.0) + cpu - nested
        if stack:
            stack[-1][2] += cpu
        else:
            compiles.append((name, time.perf_counter() - w0, cpu))


class LlvmListener(event.Listener):
    depth = 0

    def on_start(self, ev):
        if not self.depth:
            llvm.append(-time.process_time())
        self.depth += 1

    def on_end(self, ev):
        self.depth -= 1
        if not self.depth:
            llvm[-1] += time.process_time()


event.register("numba:compile", Listener())
event.register("numba:llvm_lock", LlvmListener())
case = {case!r}
small = dict(dt=0.01, paths=8, t_end=3.0, t_burn=1.0, seed=1)


def run(small):
    if case == "example1-milstein":
        simulate_ensemble(DuffingImpact(restitution=Ma(0.4), a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0), "milstein",
                          h_max=4.0, bins=400, **small)
    elif case == "impact-pair-splitting":
        simulate_automaton(automata.impact_pair(), "splitting", x0=(0.0, 0.0, 0.0, 0.0),
                           histograms={{"H": (0.0, 1.0, 50), "z": (-0.2, 0.2, 40)}}, **small)
    else:
        m = ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t + phi)",
                             parameters=dict(c=0.5, w0=1.0, W=1.3, A=0.4, phi=0.0, D=0.05), barriers=None)
        simulate_automaton(m.to_automaton(), "splitting", x0=(0.0, 0.0), observables={{"x": "x"}},
                           histograms={{"x": (-3.0, 3.0, 60)}}, phases=8, period=m.forcing_period,
                           **{{**small, "t_end": max(small["t_end"], 11.0)}})  # a forcing period (4.8) sampled


w0, c0 = time.perf_counter(), time.process_time()
run(small)
wall, cpu = time.perf_counter() - w0, time.process_time() - c0
rate = None
if {throughput!r}:  # path-steps per CPU second of a longer run, the kernel compiled above
    c1 = time.process_time()
    run(dict(dt=0.01, paths=64, t_end=2000.0, t_burn=0.0, seed=2, chunk_paths=8))
    rate = 64 * 200000 / (time.process_time() - c1)
import os, pathlib
kernels = [f for f in pathlib.Path(os.environ["VIBRO_CACHE_DIR"]).glob("*.py")]
result = dict(wall=wall, cpu=cpu, numba_wall=sum(c[1] for c in compiles), numba_cpu=sum(c[2] for c in compiles),
              llvm_cpu=sum(llvm), functions=[c[0] for c in compiles], own=own,
              source_lines=sum(len(f.read_text().splitlines()) for f in kernels), path_steps_per_cpu_s=rate, warm=[])
if {warm!r}:  # the same kernel compiled again in this (warm) process, under fresh module names
    from hybrid.stochastic import _kernel_modules
    load, fresh = _kernel_modules.load_source, [0]

    def load_fresh(name, src, *args, **kwargs):  # a new name is a new file: numba's disk cache has no entry for it
        return load(f"{{name}}w{{fresh[0]}}", src, *args, **kwargs)

    _kernel_modules.load_source = load_fresh
    for fresh[0] in range({warm!r}):
        c1 = time.process_time()
        run(small)
        result["warm"].append(time.process_time() - c1)
print(json.dumps(result))
"""

CASES = ("example1-milstein", "impact-pair-splitting", "forced-phases")


def cold(case: str, tree: Path = ROOT, throughput: bool = False, warm: int = 0) -> dict:
    """One cold first run of ``case`` by the source ``tree`` in a fresh process with empty kernel and numba caches
    (``throughput``: then the path-steps per CPU second of 64 paths x 200,000 steps with the kernel compiled)."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "VIBRO_CACHE_DIR": str(Path(tmp) / "vibro"), "NUMBA_CACHE_DIR": str(Path(tmp) / "numba"),
               "PYTHONPATH": str(tree)}
        code = _CHILD.format(tests=str(tree / "tests"), case=case, throughput=throughput, warm=warm)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tree)
        if out.returncode:
            sys.exit(out.stderr)
        return json.loads(out.stdout.strip().splitlines()[-1])


def _line(label: str, runs: list) -> float:
    med = {k: statistics.median(r[k] for r in runs) for k in ("wall", "cpu", "numba_cpu", "llvm_cpu", "source_lines")}
    cpus = ", ".join(f"{r['cpu']:.2f}" for r in runs)
    print(f"{label:34s} {med['wall']:6.2f} / {med['cpu']:6.2f}   numba {med['numba_cpu']:6.2f}   LLVM "
          f"{med['llvm_cpu']:5.2f}   source {int(med['source_lines']):5d} lines   runs (cpu): {cpus}")
    return med["cpu"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3, help="fresh processes per kernel (default 3)")
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=CASES)
    ap.add_argument("--functions", action="store_true", help="also each numba function's own compile time")
    ap.add_argument("--baseline", metavar="REF", help="also compile with the tree of git revision REF, interleaved")
    ap.add_argument("--throughput", action="store_true",
                    help="also path-steps per CPU second of each kernel after its compile (64 x 200,000 steps)")
    ap.add_argument("--warm", type=int, default=0, metavar="N",
                    help="also compile each kernel N more times in the same process, under fresh module names")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as base:
        if args.baseline:
            archive = subprocess.run(["git", "archive", args.baseline], cwd=ROOT, capture_output=True, check=True)
            subprocess.run(["tar", "-x", "-C", base], input=archive.stdout, check=True)
        print(f"load average at the start: {os.getloadavg()[0]:.1f} (2-core machine: wall times include others' work)")
        print("kernel (tree)                      first run wall / cpu (s), numba's compiles and LLVM (cpu s)")
        medians, ratios = [], []
        for case in args.cases:
            runs, before = [], []
            for _ in range(args.reps):  # interleaved: both trees see the same load
                runs.append(cold(case, throughput=args.throughput, warm=args.warm))
                if args.baseline:
                    before.append(cold(case, Path(base), throughput=args.throughput, warm=args.warm))
            if args.baseline:
                old = _line(f"{case} ({args.baseline})", before)
            medians.append(_line(f"{case} (this tree)", runs))
            if args.baseline:
                ratios.append(medians[-1] / old)
                print(f"{'':34s} compile after / before: {ratios[-1]:.2f}")
            if args.throughput:  # M path-steps per CPU second, compile excluded
                new = [r["path_steps_per_cpu_s"] / 1e6 for r in runs]
                line = f"{'':34s} throughput {statistics.median(new):6.1f} M path-steps/cpu s"
                if args.baseline:
                    old = [r["path_steps_per_cpu_s"] / 1e6 for r in before]
                    line += (f" against {statistics.median(old):6.1f} for {args.baseline}: after / before "
                             f"{statistics.median(new) / statistics.median(old):.3f} (runs "
                             + ", ".join(f"{a:.1f}/{b:.1f}" for a, b in zip(new, old)) + ")")
                print(line)
            if args.warm:  # numba warm: only the kernel's own compile, the least of all runs is the least disturbed
                new = [t for r in runs for t in r["warm"]]
                line = f"{'':34s} warm compile least / median {min(new):5.2f} / {statistics.median(new):5.2f} cpu s"
                if args.baseline:
                    old = [t for r in before for t in r["warm"]]
                    line += (f" against {min(old):5.2f} / {statistics.median(old):5.2f}: after / before "
                             f"{min(new) / min(old):.2f} / {statistics.median(new) / statistics.median(old):.2f}")
                print(line)
            if args.functions:  # each function's own compile, without those it compiles on the way (first run)
                own = sorted(runs[0]["own"].items(), key=lambda kv: -kv[1])
                print(f"{'':34s} own cpu s: " + ", ".join(f"{name} {sec:.2f}" for name, sec in own if sec >= 0.05))
        print(f"median over kernels of the median first-run cpu time: {statistics.median(medians):.2f} s (budget 2 s)"
              + (f"; after / before: {', '.join(f'{r:.2f}' for r in ratios)}" if ratios else ""))
        print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
