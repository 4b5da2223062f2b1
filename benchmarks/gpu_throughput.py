"""GPU throughput of ``scheduler="cuda"`` against the CPU kernel, measured in the same run.

    python benchmarks/gpu_throughput.py                 # a GPU machine: 2**20 paths x 1e5 steps on the GPU
    python benchmarks/gpu_throughput.py --quick         # small sizes
    NUMBA_ENABLE_CUDASIM=1 python benchmarks/gpu_throughput.py --quick   # no GPU: numba's simulator (not a timing)

Example 1 (Fig. 2): Duffing a=1, b=0.2, c=0.025, D=0.05, barriers at |x| = delta = 1, Ma's law V_C = 0.4, dt=1e-3,
scheme ``milstein`` (with additive noise: semi-implicit Euler, the crossing located on the step and the law applied
there, the scheme of issue 13's table; ``--scheme splitting`` for BAOAB), a histogram of H (400 bins on [0, 4])
filled every step, normals drawn in the kernel. Prints path-steps/s of the CPU kernel (all numba threads of this
machine) and of the GPU kernel in double precision, their ratio, then the same GPU run in single precision and the
effect of f32 on p(H) (same seed, so the same Philox words drive both). Compilation is excluded on both sides
(each side's first call is a small warm-up run).

Without a GPU (and without the simulator) the GPU part is skipped with the reason; the CPU part still runs.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hybrid.errors import CudaUnavailableError  # noqa: E402
from hybrid.stochastic import _cuda, simulate_ensemble  # noqa: E402
from models import DuffingImpact, Ma  # noqa: E402

DT = 1e-3


def run(scheduler, paths, steps, scheme, seed=1, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # chattering / step warnings are not the point here
        return simulate_ensemble(DuffingImpact(restitution=Ma(vc=0.4), a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0),
                                 scheme, dt=DT, paths=paths, t_end=steps * DT, t_burn=0.0, seed=seed, h_max=4.0,
                                 bins=400, xy_bins=None, stride=1, scheduler=scheduler, **kw)


def describe_device() -> str:
    from numba import cuda

    if _cuda.simulator_enabled():
        return "numba CUDA simulator (timings are NOT GPU measurements)"
    dev = cuda.get_current_device()
    return f"{dev.name.decode() if isinstance(dev.name, bytes) else dev.name} (cc {dev.compute_capability})"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (seconds)")
    ap.add_argument("--scheme", default="milstein", choices=["milstein", "splitting", "em", "naive"])
    ap.add_argument("--paths", type=int, help="GPU paths (default 2**20; --quick 2**16, simulator 64)")
    ap.add_argument("--steps", type=int, help="GPU steps per path (default 1e5; --quick 2000, simulator 200)")
    ap.add_argument("--cpu-paths", type=int, help="CPU paths (default 1024; --quick 64)")
    ap.add_argument("--cpu-steps", type=int, help="CPU steps per path (default 2e5; --quick 2000)")
    ap.add_argument("--threads-per-block", default="128", help="comma list to sweep, e.g. 128,256")
    ap.add_argument("--max-registers", default="0",
                    help="comma list of register caps per thread to sweep (0: none), e.g. 0,96,64")
    ap.add_argument("--no-f32", action="store_true", help="skip the single-precision run")
    ap.add_argument("--json", type=Path, help="write the figures to this file")
    a = ap.parse_args(argv)
    import numba

    out = {"scheme": a.scheme, "dt": DT, "model": "Example 1, delta=1, Ma V_C=0.4",
           "histogram": "H, 400 bins, every step"}
    cpu_paths = a.cpu_paths or (64 if a.quick else 1024)
    cpu_steps = a.cpu_steps or (2000 if a.quick else 200_000)
    run(None, 8, 100, a.scheme)  # compile (or load) the CPU kernel
    cpu = run(None, cpu_paths, cpu_steps, a.scheme)
    out["cpu"] = {"threads": numba.get_num_threads(), "paths": cpu_paths, "steps": cpu_steps,
                  "path_steps_per_s": cpu.throughput, "wall_s": cpu.wall_time, "E_H": [cpu.mean_energy.value,
                                                                                       cpu.mean_energy.ci]}
    print(f"CPU kernel  ({numba.get_num_threads()} threads): {cpu_paths} paths x {cpu_steps} steps, "
          f"{cpu.throughput:.3g} path-steps/s  (E[H] = {cpu.mean_energy})")
    try:
        _cuda.require_cuda()
    except CudaUnavailableError as exc:
        print(f"GPU part skipped: {exc}")
        out["gpu"] = {"skipped": str(exc)}
        return _finish(out, a)
    sim = _cuda.simulator_enabled()
    paths = a.paths or (64 if sim else 2**16 if a.quick else 2**20)
    steps = a.steps or (200 if sim else 2000 if a.quick else 100_000)
    out["device"] = describe_device()
    print(f"device: {out['device']}")
    configs = [(int(t), int(r)) for t in a.threads_per_block.split(",") for r in a.max_registers.split(",")]
    if sim:
        configs = configs[:1]

    def timed(prec, tpb, maxreg):
        os.environ["VIBRO_CUDA_MAX_REGISTERS"] = str(maxreg)  # read when the kernel is generated
        warm = run("cuda", min(paths, 4 * tpb), 10, a.scheme, precision=prec, threads_per_block=tpb)
        g = run("cuda", paths, steps, a.scheme, precision=prec, threads_per_block=tpb)
        row = {"precision": prec, "threads_per_block": tpb, "max_registers": maxreg or None, "paths": paths,
               "steps": steps, "path_steps_per_s": g.throughput, "wall_s": g.wall_time,
               "compile_s": warm.compile_time, "E_H": [g.mean_energy.value, g.mean_energy.ci],
               "violations": g.violations, "impacts": g.impacts}
        print(f"GPU kernel  ({prec}, {tpb} threads/block, max registers {maxreg or '-'}): {paths} paths x {steps} "
              f"steps, {g.throughput:.3g} path-steps/s, wall {g.wall_time:.3g} s, compile {warm.compile_time:.3g} s"
              f"  (E[H] = {g.mean_energy}, violations {g.violations})")
        return g, row

    rows, runs = [], {}
    best = None
    for tpb, maxreg in configs:
        g, row = timed("f64", tpb, maxreg)
        rows.append(row)
        if best is None or g.throughput > best[0].throughput:
            best = (g, tpb, maxreg)
    runs["f64"] = best[0]
    out["gpu_f64"] = rows
    out["ratio_gpu_f64_to_cpu"] = best[0].throughput / cpu.throughput
    print(f"ratio GPU f64 / CPU: {out['ratio_gpu_f64_to_cpu']:.3g}  (best configuration: {best[1]} threads/block, "
          f"max registers {best[2] or '-'})")
    if not a.no_f32:
        runs["f32"], out["gpu_f32"] = timed("f32", best[1], best[2])
    if "f32" in runs:
        p64, p32 = runs["f64"].h_density(), runs["f32"].h_density()
        width = 4.0 / 400
        l1 = float(np.abs(p64 - p32).sum() * width)
        d_eh = runs["f32"].mean_energy.value - runs["f64"].mean_energy.value
        out["f32_effect"] = {"L1_pH": l1, "dE_H": d_eh, "E_H_ci_f64": runs["f64"].mean_energy.ci,
                             "speedup_f32": runs["f32"].throughput / runs["f64"].throughput}
        print(f"f32 vs f64 (same Philox words): L1 distance of p(H) {l1:.3g}, E[H] shift {d_eh:+.3g} "
              f"(f64 95% CI half-width {runs['f64'].mean_energy.ci:.3g}), "
              f"speed x{out['f32_effect']['speedup_f32']:.3g}")
    if sim:
        print("(simulator: the GPU figures above measure Python, not a GPU)")
    return _finish(out, a)


def _finish(out, a):
    if a.json:
        a.json.write_text(json.dumps(out, indent=2, default=lambda v: None if isinstance(v, float) and
                                     not math.isfinite(v) else v))
    return out


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"total {time.perf_counter() - t0:.1f} s")
