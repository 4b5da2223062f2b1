"""The ``cuda`` scheduler: the generated Monte Carlo kernels on an NVIDIA GPU with numba-cuda, one thread per path.

The kernel is generated from the same pieces as the CPU kernel of :mod:`hybrid.stochastic._codegen`: the
:class:`~hybrid.stochastic._codegen.Emitter` prints the model (drift, noise, potential, restitution law) and the
scheme's ``step_code`` gives the step with its in-step impact location; only the loop around them, the random
numbers and the histograms differ:

* **Random numbers.** Philox-4x32-10 keyed by the seed, counter (step // 2, global path index), Box-Muller
  (:mod:`hybrid.stochastic._cuda_rng`). A path's normals do not depend on the block size, the grid or the launch
  boundaries, so every statistic is bitwise the same for any launch configuration.
* **Histograms.** Each block counts into ``cuda.shared.array`` histograms with shared-memory atomics (int32) and
  adds them once per launch into the global int64 histograms (integer atomics: order-independent).
* **Statistics rows.** Each thread keeps its path's counts and float sums in registers and stores them in one row
  per path; the host adds the rows of each chunk of ``chunk_paths`` paths (in path order), so the result is the
  same :class:`EnsembleStatistics`, with batch-means intervals over the same chunks as on the CPU.
* **Launches and checkpoints.** The steps are cut into launches of ``launch_steps``; the state of every path
  (x, y, the scheme's lane variables, its counts and sums) and the histograms stay on the device between launches
  and are written to ``mc_cuda_checkpoint.npz`` every ``checkpoint_every`` launches. ``resume`` continues from the
  saved step (the launches after the last checkpoint are run again); as the numbers are counter-based, a resumed
  run gives exactly the numbers of an uninterrupted one.
* **Precision.** Double by default. ``precision='f32'`` prints the model and every literal of the kernel as
  float32 (the state, the step and the normals in single precision); counts and the sums of moments stay int64 and
  float64.

Without numba-cuda or without a device, :class:`~hybrid.errors.CudaUnavailableError` says what to install. With
``NUMBA_ENABLE_CUDASIM=1`` (set before numba is imported) the kernel runs on numba's CUDA simulator, which is
how the tests run without a GPU.
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import json
import re
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy as sp

from hybrid.errors import CudaUnavailableError, ModelError, ParameterError
from hybrid.io import atomic_write

from . import _codegen, _cuda_rng
from ._auto_cuda import INSTALL_HINT, max_registers_from_env, require_cuda, simulator_enabled  # noqa: F401
from ._statistics import COUNTS, SUMS, EnsembleStatistics

TEMPLATE_VERSION = "4"
CUDA_CHECKPOINT_FILE = "mc_cuda_checkpoint.npz"
RNG = "philox4x32-10 box-muller"
PRECISIONS = ("f64", "f32")
SHARED_BYTES = 48 * 1024  # static shared memory of one block

# local variables of the CPU kernel's step code (hybrid.stochastic._codegen) behind each statistics column
COUNT_VARS = {"samples": "n_samples", "below": "n_below", "impacts_left": "n_il", "impacts_right": "n_ir",
              "h_over": "h_over", "xy_out": "xy_out", "v_over": "v_over", "violations": "viol", "stuck": "stuck",
              "nonfinite": "nonfinite", "h_under": "h_under", "v_under": "v_under", "bad_e": "bad_e"}
SUM_VARS = {"H": "s_h", "x2": "s_x2", "y2": "s_y2", "impact_speed": "s_iv", "bad_e_speed": "bad_v",
            "bad_e_value": "bad_ev"}
# per-chunk histograms of the CPU step code -> (block-shared histogram, its size, the overflow counter)
SHARED_HISTS = {"vh": ("sh_v", "VB", "v_over"), "hist": ("sh_h", "HB", "h_over")}


# ---------------------------------------------------------------------------------------------------- generation
class _F32Printer(_codegen._Printer):
    """Prints numbers as floats (so the f32 pass can type them) but keeps integer exponents (x**3 stays float32)."""

    def _print_Integer(self, expr):
        return repr(float(expr))

    def _print_Rational(self, expr):
        return repr(float(expr))

    def _print_Pow(self, expr, rational=False):
        if expr.exp.is_Integer and expr.exp > 0:
            return f"{self.parenthesize(expr.base, sp.printing.precedence.PRECEDENCE['Pow'])}**{int(expr.exp)}"
        return super()._print_Pow(expr, rational)


class _Float32Literals(ast.NodeTransformer):
    """Wraps every float literal in ``_fty(...)``, and every number of the restitution law (``_e = ...``).

    numba types a Python float literal as float64, which would promote the whole step to double; arguments of
    ``_dty(...)`` (the float64 accumulators) are left alone.
    """

    def __init__(self):
        self._law = False

    def visit_Call(self, node):
        if isinstance(node.func, ast.Name) and node.func.id == "_dty":
            return node
        return self.generic_visit(node)

    def visit_Assign(self, node):
        law = any(isinstance(t, ast.Name) and t.id == "_e" for t in node.targets)
        self._law = law
        self.generic_visit(node)
        self._law = False
        return node

    def visit_Constant(self, node):
        v = node.value
        if isinstance(v, float) or (self._law and isinstance(v, int) and not isinstance(v, bool)):
            return ast.copy_location(
                ast.Call(func=ast.Name(id="_fty", ctx=ast.Load()), args=[ast.Constant(float(v))], keywords=[]), node)
        return node


def _to_shared_atomics(code: str) -> str:
    """Turn the CPU step code's per-chunk histogram increments ``vh[k, i] += 1`` into shared-memory atomics."""
    pattern = re.compile(r"^(\s*)(\w+)\[k, (.+)\] \+= (\w+)\s*$")

    def repl(m):
        ind, name, idx, inc = m.groups()
        if name not in SHARED_HISTS:
            raise ModelError(f"the CUDA kernel has no shared histogram for {name!r} of the CPU step code")
        sh, size, over = SHARED_HISTS[name]
        # the device does not check bounds: an index outside the shared array is counted as overflow instead
        return (f"{ind}_bi = {idx}\n{ind}if _bi >= 0 and _bi < {size}:\n{ind}    cuda.atomic.add({sh}, _bi, {inc})\n"
                f"{ind}else:\n{ind}    {over} += {inc}")

    out = "\n".join(pattern.sub(repl, line) for line in code.splitlines())
    if re.search(r"\[k\b", out):
        raise ModelError("the CUDA translation of the step code left a per-chunk array access ([k, ...]); "
                         "hybrid/stochastic/_cuda.py must learn the new statement")
    return out


_MODULE = '''\
# Generated by hybrid.stochastic._cuda (template {version}); scheme {scheme}; model {model}; precision {precision}.
# Do not edit: the file name hashes this text.
import math

import numpy as np
from numba import cuda, float32, float64, int32

from hybrid.stochastic._cuda_rng import device_normal_pair

normal_pair = device_normal_pair("{precision}")
_fty = {ftype}
_dty = float64
HB = {hbins}
VB = {vbins}
NXY = {nxy}


@cuda.jit({jit_options})  # cache: the compiled kernel is kept next to this file, like the CPU kernels
def advance(n0, n1, npath, n_burn, stride, k0, k1, dt, prm, rprm, wl, wr, h_scale, g_bar, xlo, x_scale, nx, ylo,
            y_scale, ny, do_xy, v_scale, xs, ys, lanes, cnt, sm, hist, xyh, vh):
    """Steps [n0, n1) of paths 0 .. npath-1 (one thread each); state, counts and sums in/out per path."""
    sh_h = cuda.shared.array(HB, int32)
    sh_v = cuda.shared.array(VB, int32)
    sh_xy = cuda.shared.array(NXY, int32)
    tid = cuda.threadIdx.x
    nthr = cuda.blockDim.x
    for _i in range(tid, HB, nthr):
        sh_h[_i] = 0
    for _i in range(tid, VB, nthr):
        sh_v[_i] = 0
    for _i in range(tid, NXY, nthr):
        sh_xy[_i] = 0
    cuda.syncthreads()
    p = cuda.grid(1)
    if p < npath:  # no early return: every thread reaches the barriers below
        sdt = math.sqrt(dt)
        hdt = 0.5 * dt
        vbins = VB
{unpack}
{preamble}
        x = xs[p]
        y = ys[p]
        if n0 == 0:
{init}
        else:
{load}
{load_counts}
        fnx = _fty(nx)  # compared with float bins: no int -> double conversion in f32
        fny = _fty(ny)
        xi = 0.0
        xi2 = 0.0
        _cs = (n0 - n_burn) % stride if n0 > n_burn else 0  # recorded steps since the last sample (no % per step)
        for _n in range(n0, n1):
            # one Philox call gives the normals of steps 2j and 2j+1; a launch may start on an odd step
            if _n == n0 or (_n & 1) == 0:
                xi, xi2 = normal_pair(k0, k1, p, _n >> 1)
                if (_n & 1) == 1:
                    xi = xi2
            else:
                xi = xi2
            rec = _n >= n_burn
{step}
            if not rec:
                continue
            _cs += 1
            if _cs < stride:
                continue
            _cs = 0
            yy = y * y
            xx = x * x
            H = 0.5 * yy + {potential}
            s_h += H
            s_x2 += xx
            s_y2 += yy
            n_samples += 1
            if H < g_bar:
                n_below += 1
            hb = H * h_scale
            if hb >= 0.0 and hb <= HB:  # the last bin is closed on the right, as on the CPU
                cuda.atomic.add(sh_h, min(int(hb), HB - 1), 1)
            elif hb < 0.0:
                h_under += 1
            else:
                h_over += 1
                if H != H:
                    nonfinite += 1
            if do_xy:
                bx = (x - xlo) * x_scale
                by = (y - ylo) * y_scale
                if bx >= 0.0 and bx < fnx and by >= 0.0 and by < fny:
                    cuda.atomic.add(sh_xy, int(by) * nx + int(bx), 1)
                else:
                    xy_out += 1
        xs[p] = x
        ys[p] = y
{store}
{store_counts}
    cuda.syncthreads()
    # flush the block's histograms once
    for _i in range(tid, HB, nthr):
        if sh_h[_i] != 0:
            cuda.atomic.add(hist, _i, sh_h[_i])
    for _i in range(tid, VB, nthr):
        if sh_v[_i] != 0:
            cuda.atomic.add(vh, _i, sh_v[_i])
    for _i in range(tid, NXY, nthr):
        if sh_xy[_i] != 0:
            cuda.atomic.add(xyh, _i, sh_xy[_i])
'''


def generate_cuda_source(model, scheme, hbins: int, vbins: int, nxy: int, precision: str = "f64",
                         max_registers: int | None = None):
    """The CUDA kernel module for ``model`` and ``scheme`` (histogram sizes are compile-time constants).

    ``max_registers`` caps the registers per thread (numba-cuda's ``max_registers``; not passed on the simulator,
    which does not take it): a tuning knob for occupancy, see :func:`max_registers_from_env`.

    Returns ``(source, law_values, lane_vars)``.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> from hybrid.stochastic import SCHEMES
    >>> src, law, lanes = generate_cuda_source(DuffingImpact(), SCHEMES["splitting"], 400, 200, 1)
    >>> "def advance" in src and "cuda.atomic.add(sh_v" in src, law[0], lanes
    (True, 0.4, ('_F',))
    """
    if precision not in PRECISIONS:
        raise ParameterError(f"precision={precision!r}; choose one of {PRECISIONS}")
    if model.potential_expr is None:
        raise ModelError(f"sympy cannot integrate g = {model.g} in closed form; the kernel needs G(x) for H")
    missing = [c for c in COUNTS if c not in COUNT_VARS] + [s for s in SUMS if s not in SUM_VARS]
    if missing:
        raise ModelError(f"the CUDA kernel does not fill the statistics columns {missing}; update _cuda.COUNT_VARS")
    scheme.check(model)
    law_code, law_values, user_law = _codegen._law_code(model.restitution)
    if user_law is not None:
        raise ModelError("scheduler='cuda' needs the restitution law as a sympy expression of v "
                         "(CustomRestitution('...')); a Python callable cannot be compiled for the device")
    names = tuple(model.params)
    em = _codegen.Emitter(model, names, law_code)
    if precision == "f32":
        em._printer = _F32Printer({"standard": "python3"})
    potential = em.code(model.potential_expr)
    init = scheme.init_code(em)
    step = _to_shared_atomics(scheme.step_code(em, record=True))
    lanes = tuple(scheme.lane_vars)
    unpack = [f"_p{i} = prm[{i}]" for i in range(len(names))] + [f"_r{i} = rprm[{i}]" for i in range(len(law_values))]
    ind = textwrap.indent
    counts = [(COUNT_VARS[c], j) for j, c in enumerate(COUNTS)]
    sums = [(SUM_VARS[s], j) for j, s in enumerate(SUMS)]
    src = _MODULE.format(
        version=TEMPLATE_VERSION, scheme=scheme.name, model=f"{model.name} {model.fingerprint()}",
        jit_options="cache=True" + (f", max_registers={int(max_registers)}" if max_registers else ""),
        precision=precision, ftype="float32" if precision == "f32" else "float64", hbins=int(hbins),
        vbins=int(vbins), nxy=int(nxy), unpack=ind("\n".join(unpack) or "pass", " " * 8),
        preamble=ind("\n".join(dict.fromkeys(em.preamble)) or "pass", " " * 8),
        init=ind(init or "pass", " " * 12),
        load=ind("\n".join(f"{v} = lanes[{i}, p]" for i, v in enumerate(lanes)) or "pass", " " * 12),
        load_counts=ind("\n".join([f"{v} = cnt[p, {j}]" for v, j in counts] + [f"{v} = sm[p, {j}]" for v, j in sums]),
                        " " * 8),
        step=ind(step, " " * 12), potential=potential,
        store=ind("\n".join(f"lanes[{i}, p] = {v}" for i, v in enumerate(lanes)) or "pass", " " * 8),
        store_counts=ind("\n".join([f"cnt[p, {j}] = {v}" for v, j in counts] + [f"sm[p, {j}] = {v}" for v, j in sums]),
                         " " * 8),
    )
    if precision == "f32":
        tree = _Float32Literals().visit(ast.parse(src))
        src = src.split("\n", 2)[0] + "\n" + ast.unparse(ast.fix_missing_locations(tree)) + "\n"
    return src, law_values, lanes


@dataclass
class CudaKernel:
    """A loaded CUDA kernel module (``advance``) and what the host needs to call it."""

    module: object
    source: str
    param_names: tuple[str, ...]
    law_values: tuple[float, ...]
    lane_vars: tuple[str, ...]
    precision: str

    @property
    def advance(self):
        return self.module.advance


_RNG_HASH = hashlib.sha256(inspect.getsource(_cuda_rng).encode()).hexdigest()[:8]


def build_cuda_kernel(model, scheme, hbins, vbins, nxy, precision="f64") -> CudaKernel:
    """Generate and import the CUDA kernel module (written to the kernel cache directory, like the CPU kernels).

    numba-cuda compiles ``advance`` at its first launch.
    """
    import numba as nb

    sim = simulator_enabled()
    maxreg = None if sim else max_registers_from_env()
    src, law_values, lanes = generate_cuda_source(model, scheme, hbins, vbins, nxy, precision, maxreg)
    sim = "sim" if sim else "dev"
    h = hashlib.sha256((src + _RNG_HASH + nb.__version__ + np.__version__ + sim).encode()).hexdigest()[:16]
    name = f"vibro_cuda_{scheme.name}_{model.fingerprint()}_{h}"
    module, _ = _codegen.load_source(name, src, label=f"{model.name}/{scheme.name} (CUDA, {precision})")
    return CudaKernel(module, src, tuple(model.params), law_values, lanes, precision)


def kernel_signature(precision: str = "f64") -> tuple:
    """numba types of the arguments of ``advance``, in the order :func:`run_ensemble` passes them."""
    from numba import types as t

    f = t.float32 if precision == "f32" else t.float64
    i = t.int64

    def a1(d):
        return t.Array(d, 1, "C")

    def a2(d):
        return t.Array(d, 2, "C")

    return (i, i, i, i, i, t.uint64, t.uint64, f, a1(f), a1(f), f, f, f, f, f, f, i, f, f, i, t.boolean, f,
            a1(f), a1(f), a2(f), a2(i), a2(t.float64), a1(i), a1(i), a1(i))


def compile_ptx(model, scheme, precision="f64", hbins=400, vbins=200, nxy=1, cc=(9, 0)) -> str:
    """PTX of the kernel for compute capability ``cc`` (default sm_90, the H100), compiled without a GPU.

    Needs numba-cuda and the NVVM and NVRTC libraries (for example the ``nvidia-nvvm`` and ``nvidia-cuda-nvrtc``
    wheels), not a driver; ``NUMBA_ENABLE_CUDASIM`` must be unset. A check of the real compiler's typing and
    lowering, which the simulator does not do.
    """
    from numba import cuda

    if getattr(cuda, "implementation", "") != "NVIDIA" or simulator_enabled():
        raise CudaUnavailableError(f"compile_ptx needs numba-cuda ({INSTALL_HINT}) and NUMBA_ENABLE_CUDASIM unset")
    kern = build_cuda_kernel(model, scheme, hbins, vbins, nxy, precision)
    ptx, _ = cuda.compile_ptx(kern.advance.py_func, kernel_signature(precision), cc=cc)
    return ptx


# ---------------------------------------------------------------------------------------------------- checkpoints
def _resume_keys():
    from ._runner import _RESUME_KEYS

    return (*_RESUME_KEYS, "precision", "rng")


def _cpu_checkpoint_name() -> str:
    from ._runner import CHECKPOINT_FILE

    return CHECKPOINT_FILE


def _write_state(directory: Path, settings: dict, n_done: int, host: dict, wall: float) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    arrays = {"settings": np.array(json.dumps(settings, sort_keys=True)), "n_done": np.array(n_done),
              "wall_time": np.array(wall), **host}
    atomic_write(directory / CUDA_CHECKPOINT_FILE, lambda tmp: np.savez(tmp, **arrays))


def _read_state(directory: Path, settings: dict):
    path = directory / CUDA_CHECKPOINT_FILE
    if not path.exists():
        return None
    with np.load(path) as d:
        old = json.loads(str(d["settings"]))
        keys = _resume_keys()
        a = json.loads(json.dumps({k: old.get(k) for k in keys}))
        b = json.loads(json.dumps({k: settings.get(k) for k in keys}))
        diff = [k for k in keys if a[k] != b[k]]
        if diff:
            raise ParameterError(
                f"checkpoint {path} was made with other settings ({', '.join(diff)} differ); resume with the same "
                "arguments or use another --checkpoint directory"
            )
        return int(d["n_done"]), float(d["wall_time"]), {k: d[k].copy() for k in d.files
                                                          if k not in ("settings", "n_done", "wall_time")}


# ---------------------------------------------------------------------------------------------------- runner
def default_launch_steps(paths: int, threads_per_block: int) -> int:
    """Steps per launch: about 1e10 path-steps (a fraction of a second on a large GPU), at least 1000, and few
    enough that no block's int32 shared counter can overflow (at most 2**30 increments per bin and launch).

    Examples
    --------
    >>> default_launch_steps(10**6, 128), default_launch_steps(8, 128)
    (10000, 8388608)
    """
    cap = 2**30 // threads_per_block
    return int(min(cap, max(1000, 10**10 // max(paths, 1))))


def run_ensemble(model, scheme, settings: dict, *, checkpoint=None, resume=False, checkpoint_every=4,
                 progress=False, precision="f64", threads_per_block=128, launch_steps=None) -> EnsembleStatistics:
    """Run the ensemble described by ``settings`` (from the runner) on the GPU; returns its statistics.

    Parameters
    ----------
    model, scheme
        The model and a :class:`~hybrid.stochastic.Scheme` instance.
    settings : dict
        The runner's settings (paths, steps, histograms, seed, chunk_paths, ...); ``precision`` and ``rng`` are
        added.
    checkpoint, resume, checkpoint_every
        Directory of ``mc_cuda_checkpoint.npz``, written every ``checkpoint_every`` launches and at the end;
        ``resume`` continues from it.
    progress : bool
        tqdm bar over the launches.
    precision : {'f64', 'f32'}
    threads_per_block : int
        Block size (a multiple of 32); does not change any number.
    launch_steps : int or None
        Steps per launch (default :func:`default_launch_steps`); does not change any number either.

    Returns
    -------
    EnsembleStatistics
    """
    if precision not in PRECISIONS:
        raise ParameterError(f"precision={precision!r}; choose one of {PRECISIONS}")
    tpb = int(threads_per_block)
    if tpb != threads_per_block or tpb < 32 or tpb > 1024 or tpb % 32:
        raise ParameterError(f"threads_per_block={threads_per_block!r} must be a multiple of 32 in [32, 1024]")
    cuda = require_cuda()
    s = settings
    paths, total = s["paths"], s["steps_per_path"]
    if launch_steps is None:
        launch_steps = default_launch_steps(paths, tpb)
    elif not (isinstance(launch_steps, (int, np.integer)) and 0 < launch_steps <= 2**30 // tpb):
        raise ParameterError(f"launch_steps={launch_steps!r} must be an integer in [1, {2**30 // tpb}]")
    hbins, vbins = s["bins"], s["v_bins"]
    xy = s["xy_bins"]
    nx, ny = xy if xy is not None else (1, 1)
    need = 4 * (hbins + vbins + nx * ny)
    if need > SHARED_BYTES:
        raise ParameterError(
            f"the block-shared histograms need {need} bytes (bins={hbins}, v_bins={vbins}, xy_bins={xy}), more than "
            f"{SHARED_BYTES}; lower xy_bins (or pass xy_bins=None) for scheduler='cuda'"
        )
    s["precision"] = precision
    s["rng"] = RNG
    s["threads_per_block"] = tpb
    t0 = time.perf_counter()
    kern = build_cuda_kernel(model, scheme, hbins, vbins, nx * ny, precision)
    ft = np.float32 if precision == "f32" else np.float64
    left, right = model.barriers
    (xlo, xhi), (ylo, yhi) = s["xy_range"] if xy is not None else ((0.0, 1.0), (0.0, 1.0))
    k0, k1 = _cuda_rng.seed_key(s["seed"])
    prm = np.array([model.params[k] for k in kern.param_names], dtype=ft)
    rprm = np.array(kern.law_values if kern.law_values else (0.0,), dtype=ft)
    scal = (np.int64(s["n_burn"]), np.int64(s["stride"]), k0, k1, ft(s["dt"]))
    geo = (ft(left), ft(right), ft(hbins / s["h_max"]), ft(s["g_barrier"]), ft(xlo), ft(nx / (xhi - xlo)),
           np.int64(nx), ft(ylo), ft(ny / (yhi - ylo)), np.int64(ny), bool(xy is not None),
           ft(vbins / s["v_max"]))

    ckdir = Path(checkpoint) if checkpoint is not None else None
    saved = None
    if ckdir is not None and resume:
        saved = _read_state(ckdir, s)
        if saved is None and (ckdir / _cpu_checkpoint_name()).exists():
            raise ParameterError(f"{ckdir} holds a checkpoint of the CPU scheduler, whose random streams differ; "
                                 "resume it without --scheduler cuda, or use another --checkpoint directory")
    elif ckdir is not None and (ckdir / CUDA_CHECKPOINT_FILE).exists():
        raise ParameterError(f"{ckdir / CUDA_CHECKPOINT_FILE} exists; pass resume=True (--resume) or another directory")
    if saved is None:
        n_done, wall0 = 0, 0.0
        host = {"xs": np.full(paths, s["x0"][0], ft), "ys": np.full(paths, s["x0"][1], ft),
                "lanes": np.zeros((max(len(kern.lane_vars), 1), paths), ft),
                "cnt": np.zeros((paths, len(COUNTS)), np.int64), "sm": np.zeros((paths, len(SUMS))),
                "hist": np.zeros(hbins, np.int64), "xyh": np.zeros(nx * ny, np.int64),
                "vh": np.zeros(vbins, np.int64)}
    else:
        n_done, wall0, host = saved
    order = ("xs", "ys", "lanes", "cnt", "sm", "hist", "xyh", "vh")
    dev = {k: cuda.to_device(host[k]) for k in order}
    blocks = -(-paths // tpb)

    def launch(n0, n1, npath=paths):
        kern.advance[blocks, tpb](np.int64(n0), np.int64(n1), np.int64(npath), *scal, prm, rprm, *geo,
                                  *(dev[k] for k in order))

    launch(0, 0, 0)  # compiles (numba-cuda compiles at the first launch); no path is touched
    cuda.synchronize()
    compile_time = time.perf_counter() - t0

    def to_host():
        return {k: dev[k].copy_to_host() for k in order}

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, initial=n_done, unit="step", desc=f"mc {scheme.name} cuda")
    t_start = time.perf_counter()
    launches = 0
    n = n_done
    try:
        while n < total:
            n1 = min(total, n + launch_steps)
            launch(n, n1)
            cuda.synchronize()
            n = n1
            launches += 1
            if bar is not None:
                bar.update(n1 - bar.n)
            if ckdir is not None and launches % checkpoint_every == 0 and n < total:
                _write_state(ckdir, s, n, to_host(), wall0 + time.perf_counter() - t_start)
    finally:
        if bar is not None:
            bar.close()
    host = to_host()
    wall = wall0 + time.perf_counter() - t_start
    if ckdir is not None:
        _write_state(ckdir, s, n, host, wall)
    return _statistics(s, host, nx, ny, wall, compile_time)


def _statistics(s: dict, host: dict, nx: int, ny: int, wall: float, compile_time: float) -> EnsembleStatistics:
    """Per-path rows -> one row per chunk of ``chunk_paths`` paths (summed in path order), histograms as they are."""
    paths, cp = s["paths"], s["chunk_paths"]
    starts = np.arange(0, paths, cp)
    ids = np.arange(len(starts), dtype=np.int64)
    npaths = np.minimum(cp, paths - starts).astype(np.int64)
    cnt = np.add.reduceat(host["cnt"], starts, axis=0)
    sm = np.add.reduceat(host["sm"], starts, axis=0)
    stats = EnsembleStatistics.empty(s)
    stats.add_chunks(ids, npaths, host["hist"][None], host["xyh"].reshape(1, ny, nx), host["vh"][None], cnt, sm)
    stats.wall_time = wall
    stats.compile_time = compile_time
    return stats

