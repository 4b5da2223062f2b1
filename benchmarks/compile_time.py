"""Cold compile time of the Monte Carlo kernels named in issue 22, each in a fresh process with empty caches.

    python benchmarks/compile_time.py            # the three kernels, 3 fresh processes each (a few minutes)
    python benchmarks/compile_time.py --reps 1 --functions   # and each numba function's own compile time
    python benchmarks/compile_time.py --baseline main        # and the same in a ``git archive`` of main, interleaved
    python benchmarks/compile_time.py --baseline main --throughput   # and path-steps per CPU s of each kernel
    python benchmarks/compile_time.py --baseline main --warm 4       # and 4 recompiles in each warm process
    python benchmarks/compile_time.py --reps 1 --stages              # and each stage's own CPU s (numba, LLVM)
    python benchmarks/compile_time.py --baseline main --ab 30        # and 30 alternating throughput rounds

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
comparing two generators. ``--stages`` times the stages of the first run by their own CPU time (the stages they
start subtracted): numba's other passes and its start, type inference, lowering to llvmlite's IR, LLVM's parse of
that IR as text, its function passes, its module optimisation, machine code, and what runs outside numba. ``--ab N``
(with ``--baseline``) keeps one process per tree alive after its first run and alternates N rounds of the
throughput run between them, one at a time: the two trees see the same load at a resolution of one run.
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
stages = {{}}  # stage -> own cpu s
if {stages!r}:
    from numba.core import codegen, dispatcher, lowering, typed_passes

    timers = []  # per open timed call: cpu s of the timed calls nested in it

    def timed(label, f):
        def g(*a, **k):
            c0 = time.process_time()
            timers.append(0.0)
            try:
                return f(*a, **k)
            finally:
                cpu, nested = time.process_time() - c0, timers.pop()
                stages[label] = stages.get(label, 0.0) + cpu - nested
                if timers:
                    timers[-1] += cpu
        return g

    typed_passes.type_inference_stage = timed("type inference", typed_passes.type_inference_stage)
    lowering.Lower.lower = timed("lowering to llvmlite IR", lowering.Lower.lower)
    lib = codegen.CPUCodeLibrary
    lib.add_ir_module = timed("LLVM: IR as text, parsed", lib.add_ir_module)
    lib._optimize_functions = timed("LLVM: function passes", lib._optimize_functions)
    lib._optimize_final_module = timed("LLVM: module O3", lib._optimize_final_module)
    lib._finalize_final_module = timed("LLVM: machine code", lib._finalize_final_module)
    dispatcher.Dispatcher._compile_for_args = timed("numba: other passes, start",
                                                    dispatcher.Dispatcher._compile_for_args)
case = {case!r}
small = dict(dt=0.01, paths=8, t_end=3.0, t_burn=1.0, seed=1)


def run(small):  # the run's first mean (E[H], or E[x] of the forced model)
    if case == "example1-milstein":
        return simulate_ensemble(DuffingImpact(restitution=Ma(0.4), a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0),
                                 "milstein", h_max=4.0, bins=400, **small).mean_energy.value
    if case == "impact-pair-splitting":
        return simulate_automaton(automata.impact_pair(), "splitting", x0=(0.0, 0.0, 0.0, 0.0),
                                  histograms={{"H": (0.0, 1.0, 50), "z": (-0.2, 0.2, 40)}}, **small).mean("H").value
    m = ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t + phi)",
                         parameters=dict(c=0.5, w0=1.0, W=1.3, A=0.4, phi=0.0, D=0.05), barriers=None)
    return simulate_automaton(m.to_automaton(), "splitting", x0=(0.0, 0.0), observables={{"x": "x"}},
                              histograms={{"x": (-3.0, 3.0, 60)}}, phases=8, period=m.forcing_period,
                              **{{**small, "t_end": max(small["t_end"], 11.0)}}).mean("x").value  # a period sampled


if {stages!r}:
    run = timed("outside numba (generation, runner)", run)
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
              llvm_cpu=sum(llvm), functions=[c[0] for c in compiles], own=own, stages=stages,
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
print(json.dumps(result), flush=True)
if {serve!r}:  # one throughput run per line on stdin (the parent alternates the trees): path-steps per cpu s, E
    for line in sys.stdin:
        c1 = time.process_time()
        est = run(dict(dt=0.01, paths=64, t_end=2000.0, t_burn=0.0, seed=2, chunk_paths=8))
        print(json.dumps(dict(rate=64 * 200000 / (time.process_time() - c1), value=est)), flush=True)
"""

CASES = ("example1-milstein", "impact-pair-splitting", "forced-phases")


def _child(case: str, tree: Path, throughput: bool, warm: int, stages: bool, serve: bool, tmp: str):
    env = {**os.environ, "VIBRO_CACHE_DIR": str(Path(tmp) / "vibro"), "NUMBA_CACHE_DIR": str(Path(tmp) / "numba"),
           "PYTHONPATH": str(tree)}
    code = _CHILD.format(tests=str(tree / "tests"), case=case, throughput=throughput, warm=warm, stages=stages,
                         serve=serve)
    return subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=tree)


def cold(case: str, tree: Path = ROOT, throughput: bool = False, warm: int = 0, stages: bool = False) -> dict:
    """One cold first run of ``case`` by the source ``tree`` in a fresh process with empty kernel and numba caches
    (``throughput``: then the path-steps per CPU second of 64 paths x 200,000 steps with the kernel compiled)."""
    with tempfile.TemporaryDirectory() as tmp:
        out, err = _child(case, tree, throughput, warm, stages, False, tmp).communicate()
        lines = out.strip().splitlines()
        if not lines:
            sys.exit(err)
        return json.loads(lines[-1])


def alternate(case: str, trees: dict, rounds: int) -> dict:
    """Throughput rounds of ``case`` alternating between one live process per tree (each compiled cold first):
    {tree label: [(path-steps per cpu s, first mean), ...]}."""
    out: dict = {label: [] for label in trees}
    with tempfile.TemporaryDirectory() as tmp:
        procs = {}
        for i, (label, tree) in enumerate(trees.items()):
            procs[label] = _child(case, tree, False, 0, False, True, f"{tmp}/{i}")
            if not procs[label].stdout.readline():
                sys.exit(procs[label].stderr.read())
        try:
            for r in range(rounds):
                for label in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
                    procs[label].stdin.write("go\n")
                    procs[label].stdin.flush()
                    got = json.loads(procs[label].stdout.readline())
                    out[label].append((got["rate"], got["value"]))
        finally:
            for proc in procs.values():
                proc.stdin.close()
                proc.wait()
    return out


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
    ap.add_argument("--stages", action="store_true", help="also each compile stage's own CPU s (first run)")
    ap.add_argument("--ab", type=int, default=0, metavar="N",
                    help="with --baseline: also N throughput rounds alternating between a live process per tree")
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
                runs.append(cold(case, throughput=args.throughput, warm=args.warm, stages=args.stages))
                if args.baseline:
                    before.append(cold(case, Path(base), throughput=args.throughput, warm=args.warm,
                                       stages=args.stages))
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
            if args.stages:  # each stage's own cpu s, medians over the runs
                for label, group in (("this tree", runs), (args.baseline, before)):
                    if group:
                        names = sorted(group[0]["stages"], key=lambda k: -group[0]["stages"][k])
                        print(f"{'':34s} stages, {label} (own cpu s): " + ", ".join(
                            f"{k} {statistics.median(r['stages'].get(k, 0.0) for r in group):.2f}" for k in names))
            if args.ab and args.baseline:  # alternating rounds between a live process per tree
                got = alternate(case, {"new": ROOT, "old": Path(base)}, args.ab)
                ratios_ab = [n[0] / o[0] for n, o in zip(got["new"], got["old"])]
                print(f"{'':34s} {args.ab} alternating rounds (64 x 200,000 steps, M path-steps/cpu s, medians): "
                      f"{statistics.median(r[0] for r in got['new']) / 1e6:.1f} against "
                      f"{statistics.median(r[0] for r in got['old']) / 1e6:.1f} for {args.baseline}; per-round "
                      f"after / before median {statistics.median(ratios_ab):.3f} (least {min(ratios_ab):.3f}, most "
                      f"{max(ratios_ab):.3f}); same first mean: {got['new'][-1][1] == got['old'][-1][1]} "
                      f"({got['new'][-1][1]!r}, {got['old'][-1][1]!r})")
            if args.functions:  # each function's own compile, without those it compiles on the way (first run)
                own = sorted(runs[0]["own"].items(), key=lambda kv: -kv[1])
                print(f"{'':34s} own cpu s: " + ", ".join(f"{name} {sec:.2f}" for name, sec in own if sec >= 0.05))
        print(f"median over kernels of the median first-run cpu time: {statistics.median(medians):.2f} s (budget 2 s)"
              + (f"; after / before: {', '.join(f'{r:.2f}' for r in ratios)}" if ratios else ""))
        print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
