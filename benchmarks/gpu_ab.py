"""GPU path-steps/s of the automaton kernel, this tree against a git revision, in interleaved processes.

    python benchmarks/gpu_ab.py --baseline 716ff86              # Example 1 and the impact pair, 4 rounds
    python benchmarks/gpu_ab.py --baseline main --rounds 4 --models "Example 1" --precision f32
    NUMBA_ENABLE_CUDASIM=1 python benchmarks/gpu_ab.py --baseline main --paths 32 --steps 20   # a check, not a timing

Each round runs one process per tree. The order alternates between rounds, because the first process after a
pause was seen to run slower, so an even number of rounds lets each tree go first as often. Each process compiles
(or loads) the kernels of the models named, then times ``--timings`` runs of ``--paths`` x ``--steps`` steps
(default 2**20 x 20,000, dt = 1e-3, from rest, the H histogram filled every step; compilation excluded; a model
with phase sections runs at least one period) through ``simulate_automaton(..., scheduler="cuda")``. Printed: each
process's timings, registers per thread, local memory and occupancy, E[H] (the same seed: the two trees' means
should agree to the digits their normals share), and per model the median over rounds of the paired ratio this
tree / baseline, whose spread is the honest error bar. The processes of one round run on the same warm device,
back to back: on the H100s lent to this project the same code ran up to a fifth faster on one machine than on
another, so only ratios measured in one run compare.

The models are those of ``gpu_throughput.py --automata`` (issue 22, item 2).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def worker(args) -> None:
    """Time the models in the tree on sys.path[0]; one JSON line per model on stdout."""
    sys.path.insert(0, str(Path(args.tree) / "benchmarks"))
    sys.path.insert(0, str(args.tree))
    from gpu_throughput import DT, automaton_models

    from hybrid.stochastic import _auto_cuda, simulate_automaton

    table = automaton_models()

    # its own run helper, not gpu_throughput's: a baseline tree's gpu_throughput.py is only sure to have
    # automaton_models and DT
    def ens(name, paths, steps):
        automaton, scheme, kw = table[name]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return simulate_automaton(automaton, scheme, dt=DT, paths=paths, t_end=steps * DT, t_burn=0.0, seed=1,
                                      check_dt=False, scheduler="cuda", threads_per_block=128,
                                      precision=args.precision, **kw)

    for name in args.models.split(";"):
        period = table[name][2].get("period")
        n_min = math.ceil(period / DT) + 1 if period else 10  # a model with phase sections: at least one period
        steps = max(args.steps, n_min)
        t0 = time.perf_counter()
        ens(name, 128, n_min)  # compile or load
        first = time.perf_counter() - t0
        rates = []
        for _ in range(args.timings):
            g = ens(name, args.paths, steps)
            rates.append(args.paths * steps / g.settings["device_seconds"])
        row = {"model": name, "rates": rates, "first_call_s": first, "mean": str(g.mean(g.names[0]))}
        if not _auto_cuda.simulator_enabled():
            row.update(_auto_cuda.kernel_resources(g.settings))
        print(json.dumps(row), flush=True)


def run_tree(tree: Path, args) -> dict:
    cmd = [sys.executable, __file__, "--worker", str(tree), "--models", args.models, "--precision", args.precision,
           "--paths", str(args.paths), "--steps", str(args.steps), "--timings", str(args.timings)]
    env = dict(os.environ, PYTHONPATH=str(tree))
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=args.timeout)
    if r.returncode != 0:
        raise SystemExit(f"gpu_ab: the run in {tree} failed: {(r.stderr.strip().splitlines() or ['?'])[-1]}")
    rows = (json.loads(line) for line in r.stdout.splitlines() if line.startswith("{"))
    return {row["model"]: row for row in rows}


def _show(label: str, row: dict) -> None:
    res = (f"; {row['registers_per_thread']} registers, local {row['local_bytes_per_thread']} B, occupancy "
           f"{row['occupancy']:.0%}" if "occupancy" in row else "")
    print(f"  {label:<10} {row['model']:<24} {' '.join(f'{r:.3g}' for r in row['rates'])} path-steps/s{res}; "
          f"E[.] = {row['mean']}", flush=True)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    ap.add_argument("--baseline", metavar="REF", help="git revision to compare with (its `git archive`)")
    ap.add_argument("--models", default="Example 1;impact pair",
                    help="separated by ';' (the names of gpu_throughput.py's automaton_models)")
    ap.add_argument("--precision", default="f64", choices=("f64", "f32"))
    ap.add_argument("--rounds", type=int, default=4, help="an even number lets each tree go first equally often")
    ap.add_argument("--timings", type=int, default=4, help="timed runs per process and model")
    ap.add_argument("--paths", type=int, default=2**20)
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per process")
    ap.add_argument("--json", metavar="FILE", help="write every process's rows")
    ap.add_argument("--worker", metavar="TREE", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        args.tree = args.worker
        worker(args)
        return {}
    if not args.baseline:
        ap.error("--baseline REF is required")
    out = {"baseline": args.baseline, "rounds": []}
    with tempfile.TemporaryDirectory() as base:
        archive = subprocess.run(["git", "archive", args.baseline], cwd=ROOT, capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", base], input=archive.stdout, check=True)
        trees = {"this tree": ROOT, args.baseline: Path(base)}
        for k in range(args.rounds):
            order = list(trees) if k % 2 else list(trees)[::-1]  # the baseline first in the first round
            rows = {}
            print(f"round {k + 1}:", flush=True)
            for label in order:
                rows[label] = run_tree(trees[label], args)
                for row in rows[label].values():
                    _show(label, row)
            out["rounds"].append(rows)
    print(f"this tree / {args.baseline}, paired medians of each round (spread over rounds):")
    for name in args.models.split(";"):
        ratios = [statistics.median(r["this tree"][name]["rates"]) / statistics.median(r[args.baseline][name]["rates"])
                  for r in out["rounds"]]
        print(f"  {name:<24} {statistics.median(ratios):.2f}  (rounds: {', '.join(f'{x:.2f}' for x in ratios)})")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
