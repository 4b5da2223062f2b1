"""How steadily numba's CUDA simulator runs the automaton kernel: one small model, many times, one process.

    NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 python benchmarks/cuda_simulator_speed.py            # 40 runs
    NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 python benchmarks/cuda_simulator_speed.py --runs 150 --model ou

The runs are those of the suite's simulator checks (``tests/auto_cuda_sim_runs.py``: 32 paths x 200-300 steps,
32 threads per block). Prints each run's seconds, their median, and how many took over ``--slow`` seconds.
numba's simulator takes two locks at every device function's call. Before the device module's functions ran as
plain Python on the simulator (``hybrid/stochastic/_auto_cuda._plain_device_functions``), its threads sometimes
queued on them: 6 of 94 runs of the stop at the equilibrium took 6-150 s instead of about 1 s (docs/gpu.md).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import auto_cuda_sim_runs  # noqa: E402

from hybrid.stochastic import _auto_cuda, simulate_automaton  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    table = auto_cuda_sim_runs.models()
    ap.add_argument("--model", default="stop", choices=sorted(table))
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--slow", type=float, default=3.0, help="seconds over which a run counts as slow")
    args = ap.parse_args(argv)
    if not _auto_cuda.simulator_enabled():
        print("cuda_simulator_speed: set NUMBA_ENABLE_CUDASIM=1 (and NUMBA_DISABLE_JIT=1, as the suite does)",
              file=sys.stderr)
        raise SystemExit(2)
    automaton, scheme, kw = table[args.model]
    seconds = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(args.runs):
            t0 = time.perf_counter()
            simulate_automaton(automaton, scheme, **kw)
            seconds.append(time.perf_counter() - t0)
            print(f"{seconds[-1]:.2f}", end=" ", flush=True)
    slow = sum(s > args.slow for s in seconds)
    print(f"\n{args.model}: {len(seconds)} runs, median {statistics.median(seconds):.2f} s, max {max(seconds):.1f} s, "
          f"{slow} over {args.slow:g} s")
    return {"seconds": seconds, "slow": slow}


if __name__ == "__main__":
    main()
