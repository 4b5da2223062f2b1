"""GPU throughput of ``scheduler="cuda"`` against the CPU kernel, measured in the same run.

    python benchmarks/gpu_throughput.py                 # a GPU machine: 2**20 paths x 1e5 steps on the GPU
    python benchmarks/gpu_throughput.py --quick         # small sizes
    NUMBA_ENABLE_CUDASIM=1 python benchmarks/gpu_throughput.py --quick   # no GPU: numba's simulator (not a timing)

Example 1 (Fig. 2): Duffing a=1, b=0.2, c=0.025, D=0.05, barriers at |x| = delta = 1, Ma's law V_C = 0.4, dt=1e-3,
scheme ``milstein`` (with additive noise: semi-implicit Euler, the crossing located on the step and the law applied
there, the scheme of issue 13's table; ``--scheme splitting`` for BAOAB), a histogram of H (400 bins on [0, 4])
filled every step, normals drawn in the kernel, through ``simulate_ensemble`` on both sides: the CPU route and the
GPU route (the automaton's CUDA target on ``model.to_automaton()``, hybrid/stochastic/_auto_cuda.py). Prints
path-steps/s of the CPU kernel (all numba threads of this machine) and of the GPU kernel in double precision, their
ratio, the GPU kernel's registers per thread and occupancy, then the same GPU run in single precision and the
effect of f32 on p(H) (same seed, so the same Philox words drive both). Compilation is excluded on both sides
(each side's first call is a small warm-up run).

Without a GPU (and without the simulator) the GPU part is skipped with the reason; the CPU part still runs.

    python benchmarks/gpu_throughput.py --automata [--quick]   # the automaton kernel, per model

``--automata``: the CUDA kernel generated from the automaton code generator (``simulate_automaton(...,
scheduler="cuda")``) on every model of issue 22, item 2: Example 1 (symplectic, H histogram of 400 bins), the stop
at the equilibrium, the impact pair, the vibrating table, the forced Example 1 with 8 phase sections and Example 1
driven by OU noise, each at dt = 1e-3. Per model it prints the CPU kernel's path-steps/s (all threads of this
machine, wall time of a warm run), the GPU's (launch loop only, warm), their ratio, and the compiled kernel's
registers per thread, local memory, shared memory and the occupancy they allow. Without a GPU it stops at once
with one line (exit 2); with ``NUMBA_ENABLE_CUDASIM=1`` it runs tiny sizes on the simulator (a check, not a
timing).
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
from hybrid.stochastic import _auto_cuda, simulate_ensemble  # noqa: E402
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

    if _auto_cuda.simulator_enabled():
        return "numba CUDA simulator (timings are NOT GPU measurements)"
    dev = cuda.get_current_device()
    return f"{dev.name.decode() if isinstance(dev.name, bytes) else dev.name} (cc {dev.compute_capability})"


def automaton_models() -> dict:
    """name -> (automaton, scheme, keywords of simulate_automaton) of the models of issue 22, item 2."""
    from models import ForcedDuffingImpact, ImpactOscillator, Newton
    from models.automata import impact_pair, vibrating_table
    from models.excitation import ou_filter

    duffing = DuffingImpact(restitution=Ma(vc=0.4), a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0)
    stop = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=(0, None), restitution=Newton(0.8),
                            name="linear")
    forced = ForcedDuffingImpact(A=0.3, Omega=1.2)
    h = {"H": (0.0, 4.0, 400)}
    return {
        "Example 1": (duffing.to_automaton(), "symplectic", dict(x0=(0.0, 0.0), histograms=h)),
        "stop at the equilibrium": (stop.to_automaton(), "splitting", dict(x0=(0.5, 0.0), histograms=h)),
        "impact pair": (impact_pair(), "splitting",
                        dict(x0=(0.0,) * 4, histograms={"H": (0.0, 0.5, 100), "z": (-0.2, 0.2, 40)})),
        "vibrating table": (vibrating_table(D=0.02, A=0.1), "splitting",
                            dict(x0=(0.3, 0.0), histograms={"height": (0.0, 1.0, 100), "H": (0.0, 2.0, 100)})),
        "forced, 8 phases": (forced.to_automaton(), "symplectic",
                             dict(x0=(0.0, 0.0), histograms=h, phases=8, period=forced.forcing_period)),
        "OU-filtered": (ou_filter(duffing, alpha=4.0), "splitting", dict(x0=(0.0,) * 4, histograms=h)),
    }


def automata(a) -> dict:
    """Path-steps/s of the automaton kernel per model: CPU threads and the GPU in the same run; registers."""
    from hybrid.stochastic import _auto_cuda, simulate_automaton

    try:
        _auto_cuda.require_cuda()
    except CudaUnavailableError as exc:
        print(f"gpu_throughput --automata: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    import numba

    sim = _auto_cuda.simulator_enabled()
    paths = a.paths or (32 if sim else 2**16 if a.quick else 2**20)
    steps = a.steps or (100 if sim else 2000 if a.quick else 20_000)
    cpu_paths = a.cpu_paths or (32 if sim else 64 if a.quick else 1024)
    cpu_steps = a.cpu_steps or (100 if sim else 2000 if a.quick else 20_000)
    tpb = int(a.threads_per_block.split(",")[0])
    out = {"device": describe_device(), "dt": DT, "cpu_threads": numba.get_num_threads(), "models": {}}
    print(f"device: {out['device']}; CPU: {numba.get_num_threads()} threads; dt = {DT}")

    def ens(automaton, scheme, kw, n_paths, n_steps, **extra):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return simulate_automaton(automaton, scheme, dt=DT, paths=n_paths, t_end=n_steps * DT, t_burn=0.0, seed=1,
                                      check_dt=False, **kw, **extra)

    for name, (automaton, scheme, kw) in automaton_models().items():
        if kw.get("phases"):  # at least one period
            n_min = math.ceil(kw["period"] / DT) + 1
            c_steps, g_steps = max(cpu_steps, n_min), max(steps, n_min)
        else:
            c_steps, g_steps = cpu_steps, steps
        ens(automaton, scheme, kw, 8, min(c_steps, 100) if not kw.get("phases") else c_steps)  # compile or load
        cpu = ens(automaton, scheme, kw, cpu_paths, c_steps)
        cpu_rate = cpu_paths * c_steps / cpu.wall_time
        ens(automaton, scheme, kw, tpb, 10 if not kw.get("phases") else g_steps, scheduler="cuda",
            threads_per_block=tpb)  # compile
        gpu = ens(automaton, scheme, kw, paths, g_steps, scheduler="cuda", threads_per_block=tpb)
        gpu_rate = paths * g_steps / gpu.settings["device_seconds"]
        row = {"scheme": scheme, "cpu_paths": cpu_paths, "cpu_steps": c_steps, "cpu_path_steps_per_s": cpu_rate,
               "gpu_paths": paths, "gpu_steps": g_steps, "gpu_path_steps_per_s": gpu_rate,
               "ratio_gpu_to_cpu": gpu_rate / cpu_rate, "threads_per_block": tpb}
        first = gpu.names[0]
        line = (f"{name:<24} {scheme:<10} CPU {cpu_rate:9.3g}  GPU {gpu_rate:9.3g} path-steps/s  ratio "
                f"{gpu_rate / cpu_rate:8.3g}   E[{first}] GPU {gpu.mean(first)} CPU {cpu.mean(first)}")
        if not sim:
            res = _auto_cuda.kernel_resources(gpu.settings)
            row.update(res)
            row["max_registers"] = gpu.settings.get("max_registers")
            line += (f"   {res['registers_per_thread']} registers/thread (cap {row['max_registers']}), "
                     f"local {res['local_bytes_per_thread']} B, "
                     f"shared {res['shared_bytes_per_block']} B/block, occupancy {res['occupancy']:.0%}")
        print(line, flush=True)
        out["models"][name] = row
    if sim:
        print("(simulator: the GPU figures above measure Python, not a GPU; no registers without a GPU)")
    return out


def find_ptxas() -> str:
    """The ``ptxas`` on PATH, else the one the nvidia-cuda-nvcc wheel ships (ImportError without either)."""
    import shutil

    ptxas = shutil.which("ptxas")
    if ptxas is None:
        import nvidia.cuda_nvcc as wheel  # noqa: F401  (the nvidia-cuda-nvcc-cu12 wheel ships ptxas)

        ptxas = str(Path(list(wheel.__path__)[0]) / "bin" / "ptxas")
    return ptxas


def ptxas_usage(ptxas: str, ptx: str, cap: int | None = None) -> dict:
    """Registers, stack frame and spills (bytes) of the first function of ``ptx`` (the kernel: ptxas reports it
    first) for sm_90, from ``ptxas -v`` (``cap``: ``-maxrregcount``); None where the report lacks a figure."""
    import re
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "k.ptx"
        path.write_text(ptx)
        extra = [f"-maxrregcount={cap}"] if cap else []
        info = subprocess.run([ptxas, "-arch=sm_90", "-v", *extra, str(path), "-o", str(Path(tmp) / "k.cubin")],
                              capture_output=True, text=True).stderr
    regs = re.search(r"Used (\d+) registers", info)
    stack = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", info)
    return {"registers": int(regs.group(1)) if regs else None,
            "stack_bytes": int(stack.group(1)) if stack else None,
            "spill_stores": int(stack.group(2)) if stack else None,
            "spill_loads": int(stack.group(3)) if stack else None}


def registers(a) -> dict:
    """Registers per thread of each model's automaton kernel for sm_90 from its PTX (``ptxas -v``), without a GPU.

    Needs numba-cuda, NVVM and NVRTC (the ``nvidia-cuda-nvcc-cu12`` and ``nvidia-cuda-nvrtc-cu12`` wheels, their
    library folders on LD_LIBRARY_PATH) and ``ptxas`` (on PATH, or the one in the nvcc wheel).
    """
    from hybrid.stochastic import _auto_cuda

    ptxas = find_ptxas()
    out = {}
    for name, (automaton, scheme, kw) in automaton_models().items():
        obs = dict(automaton.observables) if "observables" not in kw else kw["observables"]
        obs = {k: v for k, v in obs.items() if k in kw["histograms"]}
        width = max(b for _, _, b in kw["histograms"].values()) + 2
        for prec in ("f64", "f32") if name == "Example 1" else ("f64",):
            t0 = time.perf_counter()
            ptx = _auto_cuda.compile_ptx(automaton, scheme, obs, histograms_width=width, phases=kw.get("phases", 0),
                                         precision=prec)
            cap = _auto_cuda.DEFAULT_MAX_REGISTERS[prec]
            rows = [ptxas_usage(ptxas, ptx), ptxas_usage(ptxas, ptx, cap)]
            row = dict(rows[0], capped={"cap": cap, **rows[1]}, compile_s=time.perf_counter() - t0)
            out[f"{name} {prec}"] = row
            print(f"{name:<24} {scheme:<10} {prec}: {row['registers']} registers/thread, stack {row['stack_bytes']} "
                  f"B, spill stores {row['spill_stores']} B; at the default cap of {cap}: spill stores "
                  f"{rows[1]['spill_stores']} B, loads {rows[1]['spill_loads']} B (sm_90, ptxas; PTX compile "
                  f"{row['compile_s']:.0f} s)", flush=True)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--automata", action="store_true",
                    help="the automaton kernel on the models of issue 22 (CPU and GPU per model, registers)")
    ap.add_argument("--registers", action="store_true",
                    help="registers per thread of the automaton kernels for sm_90 from PTX (ptxas -v; no GPU needed)")
    ap.add_argument("--quick", action="store_true", help="small sizes (seconds)")
    ap.add_argument("--scheme", default="milstein", choices=["milstein", "splitting", "em", "naive"])
    ap.add_argument("--paths", type=int, help="GPU paths (default 2**20; --quick 2**16, simulator 64)")
    ap.add_argument("--steps", type=int, help="GPU steps per path (default 1e5; --quick 2000, simulator 200)")
    ap.add_argument("--cpu-paths", type=int, help="CPU paths (default 1024; --quick 64)")
    ap.add_argument("--cpu-steps", type=int, help="CPU steps per path (default 2e5; --quick 2000)")
    ap.add_argument("--threads-per-block", default="128", help="comma list to sweep, e.g. 128,256")
    ap.add_argument("--max-registers", default="default",
                    help="comma list of register caps per thread to sweep (0: none; default: the library's, "
                         "hybrid.stochastic._auto_cuda.DEFAULT_MAX_REGISTERS), e.g. default,0,128,64")
    ap.add_argument("--no-f32", action="store_true", help="skip the single-precision run")
    ap.add_argument("--json", type=Path, help="write the figures to this file")
    a = ap.parse_args(argv)
    if a.automata:
        return _finish(automata(a), a)
    if a.registers:
        return _finish(registers(a), a)
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
        _auto_cuda.require_cuda()
    except CudaUnavailableError as exc:
        print(f"GPU part skipped: {exc}")
        out["gpu"] = {"skipped": str(exc)}
        return _finish(out, a)
    sim = _auto_cuda.simulator_enabled()
    paths = a.paths or (64 if sim else 2**16 if a.quick else 2**20)
    steps = a.steps or (200 if sim else 2000 if a.quick else 100_000)
    out["device"] = describe_device()
    print(f"device: {out['device']}")
    configs = [(int(t), r.strip()) for t in a.threads_per_block.split(",") for r in a.max_registers.split(",")]
    if sim:
        configs = configs[:1]

    def timed(prec, tpb, maxreg):
        if maxreg == "default":  # read when the kernel is generated
            os.environ.pop("VIBRO_CUDA_MAX_REGISTERS", None)
        else:
            os.environ["VIBRO_CUDA_MAX_REGISTERS"] = str(int(maxreg))
        warm = run("cuda", min(paths, 4 * tpb), 10, a.scheme, precision=prec, threads_per_block=tpb)
        g = run("cuda", paths, steps, a.scheme, precision=prec, threads_per_block=tpb)
        # the warm-up's generation and load plus its launches (numba-cuda compiles at the first launch)
        compile_s = warm.compile_time + warm.wall_time
        cap = g.settings.get("max_registers")
        row = {"precision": prec, "threads_per_block": tpb, "max_registers": cap, "paths": paths,
               "steps": steps, "path_steps_per_s": g.throughput, "wall_s": g.wall_time,
               "compile_s": compile_s, "E_H": [g.mean_energy.value, g.mean_energy.ci],
               "violations": g.violations, "impacts": g.impacts}
        regs = ""
        if not sim:
            row["resources"] = _auto_cuda.kernel_resources(g.settings)
            regs = (f", {row['resources']['registers_per_thread']} registers/thread, occupancy "
                    f"{row['resources']['occupancy']:.0%}")
        print(f"GPU kernel  ({prec}, {tpb} threads/block, max registers {cap or '-'}): {paths} paths x {steps} "
              f"steps, {g.throughput:.3g} path-steps/s, wall {g.wall_time:.3g} s, compile {compile_s:.3g} s{regs}"
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
          f"max registers {best[2]})")
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
