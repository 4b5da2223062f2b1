"""Where a CUDA run's time goes outside the kernel: the rows' start, the launches, the per-chunk sums, the runner.

    python benchmarks/gpu_run_costs.py                      # Example 1, 2**20 paths, 2 and 20,000 steps, 3 runs each
    python benchmarks/gpu_run_costs.py --paths 65536 --steps 2,2000
    NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 python benchmarks/gpu_run_costs.py --paths 64 --steps 2,10   # a check

Runs Example 1 (gpu_throughput.py's values, the H histogram) through ``simulate_automaton(..., scheduler="cuda")``
and times the pieces of :class:`hybrid.stochastic._auto_cuda.CudaRun` by wrapping its methods: ``device_fresh``
(the per-path rows at t = 0, filled on the device), ``advance`` (the launches, each waited for), ``chunk_rows`` (the
per-chunk sums on the device and their copy to the host) and ``_fill`` (the runner's per-chunk rows from them). It
prints those, the run's ``device_seconds`` (launches, sums and fill) and the call's wall time. The first run of a
size includes compilation. ``benchmarks/data/gpu_h100_fixed_cost.txt`` holds the H100 figures before and after the
rows moved to the device (its first part from a probe of the host-side runner that this script replaced).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from gpu_throughput import DT, automaton_models  # noqa: E402

from hybrid.stochastic import _auto_cuda, simulate_automaton  # noqa: E402

PIECES = ("device_fresh", "advance", "chunk_rows", "_fill")


def timed_pieces() -> dict:
    """Wrap the runner's pieces so that each call adds its seconds to the returned dict (cleared by the caller)."""
    seconds: dict = {}

    def wrap(name):
        original = getattr(_auto_cuda.CudaRun, name)

        def timed(self, *args, **kwargs):
            t0 = time.perf_counter()
            try:
                return original(self, *args, **kwargs)
            finally:
                seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - t0

        setattr(_auto_cuda.CudaRun, name, timed)

    for name in PIECES:
        wrap(name)
    return seconds


def main(argv=None) -> list:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    ap.add_argument("--paths", type=int, default=2**20)
    ap.add_argument("--steps", default="2,20000", help="steps per path, separated by ','")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    try:
        steps_list = [int(s) for s in a.steps.split(",")]
    except ValueError:
        ap.error(f"--steps {a.steps!r}: integers separated by ','")
    if a.paths < 1 or a.repeats < 1 or any(s < 1 for s in steps_list):
        ap.error("--paths, --repeats and every --steps must be positive")
    try:
        _auto_cuda.require_cuda()
        if not _auto_cuda.simulator_enabled():
            from numba import cuda

            cuda.get_current_device()
    except Exception as exc:  # no GPU (CudaUnavailableError, a driver's error): one line
        print(f"gpu_run_costs: no GPU: {str(exc).splitlines()[0]}", file=sys.stderr)
        raise SystemExit(2) from None
    seconds = timed_pieces()
    automaton, scheme, kw = automaton_models()["Example 1"]
    rows = []
    for steps in steps_list:
        for _ in range(a.repeats):
            seconds.clear()
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                g = simulate_automaton(automaton, scheme, dt=DT, paths=a.paths, t_end=steps * DT, t_burn=0.0, seed=1,
                                       check_dt=False, scheduler="cuda", **kw)
            row = {"paths": a.paths, "steps": steps, "chunk_paths": g.settings["chunk_paths"],
                   "wall": time.perf_counter() - t0, "device_seconds": g.settings["device_seconds"], **seconds}
            rows.append(row)
            print(f"{a.paths} paths x {steps} steps (chunk_paths {row['chunk_paths']}): wall {row['wall']:.3f} s, "
                  f"device_seconds {row['device_seconds']:.3f}, "
                  + ", ".join(f"{k} {seconds.get(k, 0.0):.3f}" for k in PIECES) + f"; E[H] = {g.mean('H')}",
                  flush=True)
    return rows


if __name__ == "__main__":
    main()
