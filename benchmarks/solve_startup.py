"""CPU time of ``vibro solve`` (start-up included) against a baseline source tree, in the same run.

For each case and repetition, ``python -m vibro solve ... --tol TOL --out FILE.csv`` runs as a subprocess once
with ``PYTHONPATH`` at this tree and once at the baseline (alternating, so that both see the same load); the CPU
time is user + system of the subprocess (``resource.getrusage``). Prints per case the median over the repetitions
and the ratio current / baseline, and the medians over all cases. A third column times the imports alone
(``python -c "import vibro.solve, averaging.phase_plane"``).

The baseline is a source tree of another commit, e.g.
``git archive 5778cbf | tar -x -C /tmp/vibro-base``.

Run: ``nice -n 10 python benchmarks/solve_startup.py --baseline /tmp/vibro-base [--repeats 3] [--tol 0.02]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RESULT = ROOT / "benchmarks" / "data" / "solve_startup.json"
"""The last run's figures, which benchmarks/method_choice.py puts on docs/results/method-choice.md."""
CASES = ("f2_1", "f6_1", "f10_1", "f11_1", "f12_1", "f13_1", "f14_1", "OneSidedStop")
"""A sample of the acceptance cases of benchmarks/method_choice.py (one per figure, and the one-sided stop)."""


def cpu_of(cmd, tree: Path, cwd: Path) -> float:
    """CPU seconds (user + system) of one subprocess run with PYTHONPATH at ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, cwd=cwd, env=env, check=True, capture_output=True, timeout=600)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    ap.add_argument("--baseline", required=True, type=Path, help="source tree of the baseline commit")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tol", type=float, default=0.02)
    ap.add_argument("--baseline-name", default=None, help="what the baseline is, for the page (e.g. its commit)")
    args = ap.parse_args(argv)
    if not (args.baseline / "vibro" / "__main__.py").exists():
        sys.exit(f"solve_startup: {args.baseline} holds no vibro source tree")
    from benchmarks.method_choice import cases

    trees = {"current": ROOT, "baseline": args.baseline.resolve()}
    imports = [sys.executable, "-c", "import vibro.solve, averaging.phase_plane"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for tree in trees.values():  # warm the bytecode caches of both trees first
            cpu_of(imports, tree, tmp)
        for key, label, model_args, _ in cases():
            if key not in CASES:
                continue
            # a model file given by path is read relative to the working directory: run from the tree's root
            times = {name: [] for name in trees}
            for _ in range(args.repeats):
                for name, tree in trees.items():
                    cmd = [sys.executable, "-m", "vibro", "solve", *model_args, "--tol", str(args.tol),
                           "--no-progress", "--out", str(tmp / f"{key}.csv")]
                    times[name].append(cpu_of(cmd, tree, tree))
            med = {name: float(np.median(v)) for name, v in times.items()}
            rows.append((label, med["current"], med["baseline"]))
            print(f"{label:42s} current {med['current']:5.2f} s  baseline {med['baseline']:5.2f} s  ratio "
                  f"{med['current'] / med['baseline']:.2f}", flush=True)
        imp = {name: float(np.median([cpu_of(imports, tree, tmp) for _ in range(args.repeats)]))
               for name, tree in trees.items()}
    cur, base = np.median([r[1] for r in rows]), np.median([r[2] for r in rows])
    line = (f"median over {len(rows)} cases (tol {args.tol:g}): current {cur:.2f} s, baseline {base:.2f} s CPU, ratio "
            f"{cur / base:.2f}; imports alone: current {imp['current']:.2f} s, baseline {imp['baseline']:.2f} s; "
            f"load average {os.getloadavg()[0]:.1f}")
    print(line)
    baseline_name = args.baseline_name or args.baseline.name
    RESULT.write_text(json.dumps({"baseline": baseline_name, "tol": args.tol, "repeats": args.repeats,
                                  "rows": rows, "summary": line}, indent=1) + "\n")
    print(f"wrote {RESULT}")


if __name__ == "__main__":
    main()
