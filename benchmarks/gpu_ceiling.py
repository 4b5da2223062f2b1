"""How fast Example 1 can run on this GPU: a hand-written numba-cuda kernel beside the generated one, timed in one run.

    python benchmarks/gpu_ceiling.py                       # every variant, 2 rounds, 2**20 paths x 20,000 steps
    python benchmarks/gpu_ceiling.py --variants r10-f64,r10-f32 --rounds 4
    python benchmarks/gpu_ceiling.py --registers           # registers and spills of each variant (ptxas, no GPU)
    NUMBA_ENABLE_CUDASIM=1 python benchmarks/gpu_ceiling.py --quick   # a check on the simulator, not a timing

The generated kernel (``simulate_automaton(..., scheduler="cuda")``, hybrid/stochastic/_auto_cuda.py) carries what
every automaton needs: modes, located events, phase sections, samples at a stride, counters. This benchmark prices
that generality. Its hand-written kernel does only what Example 1's run needs: the semi-implicit Euler step of the
Duffing oscillator (a=1, b=0.2, c=0.025, D=0.05), the H histogram (400 bins on [0, 4]) in block-shared int32 cells
every step, and, where the step leaves |x| < 1, Ma's law (V_C = 0.4) applied at the step's end with the overshoot
reflected (not the located crossing: its E[H] differs from the generated kernel's by that, and that path is rare).

Its variants change one thing each, so that each piece's price is the ratio of two rows:

* ``r10-f64``: Philox-4x32-10 and Box-Muller in double precision, the normals of the generated kernel (the same
  numbers: :func:`hybrid.stochastic._cuda_rng.device_normal_pair`);
* ``r10-f32``: the same 53-bit uniforms, Box-Muller's logarithm, square root and ``sincospi`` in single precision
  (normals to about 1e-7 relative, tails to 8.6 sigma as before);
* ``r7-f64``, ``r7-f32``: Philox with 7 rounds (the fewest with which Salmon et al. 2011 found it passes BigCrush);
* ``nohist``: ``r10-f64`` without the histogram's increment (the sum of H stays);
* ``cheap``: a xorshift32 uniform of variance 1 per step in place of the normals (a price, not a method);
* ``x2``: ``r10-f64`` with two paths per thread, stepped together (twice the work per thread, half the threads);
* ``cap64``: ``r10-f64`` compiled under ``max_registers=64``.

Each timing is a whole run as the runner does it: launches of 10,000 steps, then the paths' state and the histogram
copied to the host. In the same rounds it times the generated kernel (``generated``; its ``device_seconds``), the
same with the ``r10-f32`` normals swapped in (``generated-f32bm``), and the generated kernel's fixed cost (2 steps
of every path: allocation, launches and copies), so that its per-step rate can be told from its overhead. Rounds
alternate their order and the ratios are to ``r10-f64`` of the same round: only ratios from one run compare (the
H100s lent to this project drifted by up to 15 % within one run).
"""

from __future__ import annotations

import argparse
import json
import math
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

try:  # module globals: numba's simulator swaps the name ``cuda`` in a kernel's globals, not in its closure
    from numba import cuda, int32, uint32
except ImportError:  # no numba-cuda: main() says so in one line
    cuda = int32 = uint32 = None

A, B, C, D, DELTA, VC = 1.0, 0.2, 0.025, 0.05, 1.0, 0.4
H_LO, H_HI, H_BINS = 0.0, 4.0, 400
LAUNCH = 10_000
HAND = ("r10-f64", "r10-f32", "r7-f64", "r7-f32", "nohist", "cheap", "x2", "cap64")
GENERATED = ("generated", "generated-f32bm")
VARIANTS = HAND + GENERATED


def _options(variant: str) -> dict:
    opt = {"rounds": 10, "bm": "f64", "hist": True, "per_thread": 1, "cap": None}
    if variant.startswith("r7"):
        opt["rounds"] = 7
    if variant.endswith("f32"):
        opt["bm"] = "f32"
    opt["hist"] = variant != "nohist"
    if variant == "cheap":
        opt["bm"] = "none"
    if variant == "x2":
        opt["per_thread"] = 2
    if variant == "cap64":
        opt["cap"] = 64
    return opt


def fast_normal_pair(device, philox):
    """``normal_pair(rk, path, pair)`` with the 53-bit uniforms of the f64 generator and Box-Muller in float32."""
    sim = _auto_cuda.simulator_enabled()
    if sim:
        sincos = _cuda_rng._sincos_2pi_f32
    else:
        from numba.cuda import libdevice

        sincospif, two_f = libdevice.sincospif, np.float32(2.0)
        sincos = device(lambda u: sincospif(two_f * u))
    return device(_cuda_rng._make_normal_pair(philox, False, sincos, f32_transform=True))


def make_kernel(variant: str):
    """The hand-written kernel ``kernel(n0, n1, rk, XS, SM, gh)`` of ``variant`` (steps [n0, n1), n0 and n1 even)."""
    opt = _options(variant)
    sim = _auto_cuda.simulator_enabled()
    device = (lambda f: f) if sim else cuda.jit(device=True, inline=True)
    rnd = device(_cuda_rng._philox_round)
    philox = device(_cuda_rng._make_philox(rnd, opt["rounds"]))
    if opt["bm"] == "f64":
        pair = device(_cuda_rng._make_normal_pair(philox, False, _cuda_rng._sincos_2pi)) if sim else None
        if pair is None:
            from numba.cuda import libdevice

            sincos = device(lambda u: libdevice.sincospi(2.0 * u))
            pair = device(_cuda_rng._make_normal_pair(philox, False, sincos))
    elif opt["bm"] == "f32":
        pair = fast_normal_pair(device, philox)
    else:
        root12 = math.sqrt(12.0) / 2**32

        def pair(rk, path, q):  # a xorshift32 of (pair, path) twice: a price of "no generator", not a generator
            s = uint32((q * 2654435761 + path * 40503 + 1) & 0xFFFFFFFF) | uint32(1)
            s ^= uint32(s << 13)
            s ^= uint32(s >> 17)
            s ^= uint32(s << 5)
            a = s
            s ^= uint32(s << 13)
            s ^= uint32(s >> 17)
            s ^= uint32(s << 5)
            return (a * root12 - 1.7320508075688772), (s * root12 - 1.7320508075688772)

        pair = device(pair)
    sig = math.sqrt(2.0 * D) * math.sqrt(DT)
    omega = VC ** (1.0 / 6.0)
    scale = H_BINS / (H_HI - H_LO)
    hist = opt["hist"]
    cells = H_BINS + 2

    def step(x, y, w, s, sh):
        y1 = y + sig * w + DT * (-A * x - B * x * x * x - C * y)
        x1 = x + DT * y1
        if x1 >= DELTA or x1 <= -DELTA:  # Ma's law at the step's end, the overshoot reflected
            sgn = 1.0 if x1 > 0.0 else -1.0
            v = abs(y1)
            e = 1.0 if v <= VC else omega * v ** (-1.0 / 6.0)
            x1 = sgn * DELTA - e * (x1 - sgn * DELTA)
            if abs(x1) >= DELTA:
                x1 = sgn * DELTA * 0.999999
            y1 = -e * y1
        h = 0.5 * A * x1 * x1 + 0.25 * B * x1 * x1 * x1 * x1 + 0.5 * y1 * y1
        if hist:
            b = (h - H_LO) * scale
            cell = int32(b) + 1 if b < H_BINS else H_BINS + 1
            cuda.atomic.add(sh, cell, 1)
        return x1, y1, s + h

    step = device(step)
    jit = (lambda f: cuda.jit(f, max_registers=opt["cap"])) if opt["cap"] and not sim else cuda.jit

    if opt["per_thread"] == 1:
        def kernel(n0, n1, rk, XS, SM, gh):
            sh = cuda.shared.array(cells, int32)
            for i in range(cuda.threadIdx.x, cells, cuda.blockDim.x):
                sh[i] = 0
            cuda.syncthreads()
            ip = cuda.grid(1)
            if ip < XS.shape[0]:
                x = XS[ip, 0]
                y = XS[ip, 1]
                s = SM[ip]
                for q in range(n0 // 2, n1 // 2):
                    za, zb = pair(rk, ip, q)
                    x, y, s = step(x, y, za, s, sh)
                    x, y, s = step(x, y, zb, s, sh)
                XS[ip, 0] = x
                XS[ip, 1] = y
                SM[ip] = s
            cuda.syncthreads()
            for i in range(cuda.threadIdx.x, cells, cuda.blockDim.x):
                if sh[i] != 0:
                    cuda.atomic.add(gh, i, sh[i])
    else:
        def kernel(n0, n1, rk, XS, SM, gh):
            sh = cuda.shared.array(cells, int32)
            for i in range(cuda.threadIdx.x, cells, cuda.blockDim.x):
                sh[i] = 0
            cuda.syncthreads()
            ia = 2 * cuda.grid(1)
            if ia + 1 < XS.shape[0]:
                xa = XS[ia, 0]
                ya = XS[ia, 1]
                sa = SM[ia]
                xb = XS[ia + 1, 0]
                yb = XS[ia + 1, 1]
                sb = SM[ia + 1]
                for q in range(n0 // 2, n1 // 2):
                    za, zb = pair(rk, ia, q)
                    wa, wb = pair(rk, ia + 1, q)
                    xa, ya, sa = step(xa, ya, za, sa, sh)
                    xb, yb, sb = step(xb, yb, wa, sb, sh)
                    xa, ya, sa = step(xa, ya, zb, sa, sh)
                    xb, yb, sb = step(xb, yb, wb, sb, sh)
                XS[ia, 0] = xa
                XS[ia, 1] = ya
                SM[ia] = sa
                XS[ia + 1, 0] = xb
                XS[ia + 1, 1] = yb
                SM[ia + 1] = sb
            cuda.syncthreads()
            for i in range(cuda.threadIdx.x, cells, cuda.blockDim.x):
                if sh[i] != 0:
                    cuda.atomic.add(gh, i, sh[i])

    return jit(kernel), opt


def run_hand(kernel, opt, paths: int, steps: int, tpb: int, rk) -> tuple[float, float]:
    """One whole run of a hand-written kernel: (path-steps/s, E[H])."""
    per = opt["per_thread"]
    t0 = time.perf_counter()
    XS = cuda.to_device(np.zeros((paths, 2)))
    SM = cuda.to_device(np.zeros(paths))
    gh = cuda.to_device(np.zeros(H_BINS + 2, np.int64))
    blocks = -(-paths // (per * tpb))
    for n0 in range(0, steps, LAUNCH):
        kernel[blocks, tpb](n0, min(steps, n0 + LAUNCH), rk, XS, SM, gh)
    cuda.synchronize()
    sums = SM.copy_to_host()
    XS.copy_to_host()
    counts = gh.copy_to_host()
    seconds = time.perf_counter() - t0
    if int(counts.sum()) != (paths * steps if opt["hist"] else 0):
        raise SystemExit(f"gpu_ceiling: the histogram holds {int(counts.sum())} samples, not {paths * steps}")
    return paths * steps / seconds, float(sums.sum() / (paths * steps))


def registers(names) -> dict:
    """Registers and spills of each hand-written variant for sm_90 (``ptxas -v`` on its PTX), without a GPU.

    Needs numba-cuda with NVVM (a CUDA toolkit, or the nvidia-cuda-nvcc wheel's library on LD_LIBRARY_PATH) and
    ``ptxas`` (gpu_throughput.find_ptxas); NUMBA_ENABLE_CUDASIM unset.
    """
    from gpu_throughput import find_ptxas, ptxas_usage
    from numba import types

    if _auto_cuda.simulator_enabled():
        raise SystemExit("gpu_ceiling --registers: NUMBA_ENABLE_CUDASIM must be unset")
    try:
        ptxas = find_ptxas()
    except ImportError:
        raise SystemExit("gpu_ceiling --registers: needs ptxas (on PATH or from the nvidia-cuda-nvcc wheel)") from None
    sig = (types.int64, types.int64, types.UniTuple(types.uint32, 20), types.float64[:, ::1], types.float64[::1],
           types.int64[::1])
    out = {}
    with _auto_cuda.assumed_device((9, 0)):  # no device: the compute capability of an H100
        for v in names:
            if v not in HAND:
                continue
            kernel, opt = make_kernel(v)
            ptx, _ = cuda.compile_ptx(kernel.py_func, sig, cc=(9, 0))
            out[v] = ptxas_usage(ptxas, ptx, opt["cap"])
            capped = f" -maxrregcount={opt['cap']}" if opt["cap"] else ""
            print(f"{v:<10} {out[v]['registers']} registers/thread, spill stores {out[v]['spill_stores']} B "
                  f"(sm_90, ptxas{capped})", flush=True)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    ap.add_argument("--variants", default=",".join(VARIANTS), help=f"from: {', '.join(VARIANTS)}")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--timings", type=int, default=2, help="timed runs per variant and round")
    ap.add_argument("--paths", type=int, default=2**20)
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--threads-per-block", type=int, default=128)
    ap.add_argument("--quick", action="store_true", help="64 paths x 40 steps (the simulator)")
    ap.add_argument("--registers", action="store_true", help="registers of the hand-written variants (no GPU)")
    ap.add_argument("--json", metavar="FILE")
    a = ap.parse_args(argv)
    names = [v.strip() for v in a.variants.split(",") if v.strip()]
    bad = [v for v in names if v not in VARIANTS]
    if bad or a.steps % 2 or a.steps < 2 or a.paths % 2:
        ap.error(f"unknown variants {bad}" if bad else "--steps and --paths must be even (x2: two paths per thread), "
                 "--steps at least 2")
    if a.quick:
        a.paths, a.steps, a.threads_per_block = 64, 40, 32
    if "r10-f64" not in names:
        names.insert(0, "r10-f64")
    if a.registers:
        return registers(names)
    try:
        _auto_cuda.require_cuda()
        if not _auto_cuda.simulator_enabled():
            cuda.get_current_device()
    except Exception as exc:  # no GPU: one line
        print(f"gpu_ceiling: no GPU: {str(exc).splitlines()[0]}", file=sys.stderr)
        raise SystemExit(2) from None
    sim = _auto_cuda.simulator_enabled()
    rk = _cuda_rng.round_keys(*_cuda_rng.seed_key(1))
    automaton, scheme, kw = automaton_models()["Example 1"]
    original_pair = _cuda_rng.device_normal_pair("f64")

    original_source = _auto_cuda.generate_cuda_source
    fast_pair = []

    def generated(paths, steps, f32bm):
        if f32bm:
            if not fast_pair:
                device = (lambda f: f) if sim else cuda.jit(device=True, inline=True)
                fast_pair.append(fast_normal_pair(device, device(_cuda_rng._make_philox(
                    device(_cuda_rng._philox_round)))))
            _cuda_rng._DEVICE["f64"] = fast_pair[0]

            def marked(*args, **kwargs):  # a module (and a disk cache entry) of its own for the swapped generator
                src, st = original_source(*args, **kwargs)
                return src + "\n# gpu_ceiling: Box-Muller in float32\n", st

            _auto_cuda.generate_cuda_source = marked
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                g = simulate_automaton(automaton, scheme, dt=DT, paths=paths, t_end=steps * DT, t_burn=0.0, seed=1,
                                       check_dt=False, scheduler="cuda", threads_per_block=a.threads_per_block,
                                       launch_steps=LAUNCH, **kw)
        finally:
            _cuda_rng._DEVICE["f64"] = original_pair
            _auto_cuda.generate_cuda_source = original_source
        return g

    if any(v in GENERATED for v in names):  # the fixed cost: 2 steps of every path
        generated(a.paths, 2, False)
        fixed = statistics.median(generated(a.paths, 2, False).settings["device_seconds"] for _ in range(3))
        print(f"generated kernel's fixed cost ({a.paths} paths, 2 steps): {fixed:.3g} s", flush=True)
    rows = {v: {"rates": [], "round_medians": []} for v in names}
    kernels = {}
    for r in range(a.rounds):
        for v in names if r % 2 == 0 else names[::-1]:
            row = rows[v]
            if v in GENERATED and "compile_s" not in row:
                t0 = time.perf_counter()
                generated(128, 10, v == "generated-f32bm")
                row["compile_s"] = time.perf_counter() - t0
            if v in HAND and v not in kernels:
                t0 = time.perf_counter()
                kernels[v] = make_kernel(v)
                run_hand(*kernels[v], 128, 10, a.threads_per_block, rk)
                row["compile_s"] = time.perf_counter() - t0
                if not sim:
                    row.update(_auto_cuda.compiled_resources(kernels[v][0], a.threads_per_block))
            rates = []
            for _ in range(a.timings):
                if v in HAND:
                    rate, eh = run_hand(*kernels[v], a.paths, a.steps, a.threads_per_block, rk)
                else:
                    g = generated(a.paths, a.steps, v == "generated-f32bm")
                    rate, eh = a.paths * a.steps / g.settings["device_seconds"], float(g.mean("H").value)
                    if not sim and "registers_per_thread" not in row:
                        row.update(_auto_cuda.kernel_resources(g.settings))
                rates.append(rate)
            row["rates"] += rates
            row["round_medians"].append(statistics.median(rates))
            row["E_H"] = eh
            print(f"round {r + 1} {v:<16} {' '.join(f'{x:.3g}' for x in rates)} path-steps/s; E[H] = {eh:.6f}",
                  flush=True)
    print(f"\nExample 1, f64, {a.paths} paths x {a.steps} steps, {a.threads_per_block} threads per block"
          + (" (the simulator: not a timing)" if sim else ""))
    print(f"{'variant':<16} {'median /s':>10} {'/ r10-f64':>9}  {'registers':>9} {'local':>5} {'occupancy':>9}"
          f"  {'E[H]':>9}  compile s")
    base = rows["r10-f64"]["round_medians"]
    for v in names:
        row = rows[v]
        row["ratio"] = statistics.mean(m / b for m, b in zip(row["round_medians"], base))
        occ = row.get("occupancy")
        print(f"{v:<16} {statistics.median(row['rates']):10.3g} {row['ratio']:9.2f}  "
              f"{row.get('registers_per_thread', '-'):>9} {row.get('local_bytes_per_thread', '-'):>5} "
              f"{f'{occ:.0%}' if occ is not None else '-':>9}  {row['E_H']:.6f}  {row.get('compile_s', 0):.1f}")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1, default=str))
    return rows


if __name__ == "__main__":
    main()
