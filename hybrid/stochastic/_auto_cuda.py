"""The ``cuda`` scheduler of automaton ensembles: the automaton generator's own step code on an NVIDIA GPU.

The device module is printed by :func:`hybrid.stochastic._auto_codegen.generate_source` itself, from the same
pieces as the CPU kernel: the model's functions (drift, noise, guards, resets, observables), the event code
(``crosses``, ``locate``, ``event_step``, the velocity sub-steps) and the straight-line fast step of each mode, with
their decorators turned into ``cuda.jit(device=True)``. Only the loop around them differs (:data:`_KERNEL`):

* **One thread per path; counter-based normals.** Normal number q = step * M + k of path i (M noises) is half of
  the Philox-4x32-10 draw at counter (q // 2, i) under the seed's key, by Box-Muller
  (:mod:`hybrid.stochastic._cuda_rng`). Nothing depends on the block size, the grid or where a launch starts, so
  every number is bitwise the same for any launch configuration and across a checkpoint and resume; and the host
  can compute the same normals, to rounding (the tests drive the CPU kernel with them and find the same paths).
* **Launch arguments.** The Philox round keys, the model's parameters, the loop invariants of its expressions
  (evaluated on the host by the module's ``hoisted_values``) and the histograms' ranges are tuple arguments, read
  from the constant bank: as arrays they held registers across the whole step loop, or spilled.
* **Histograms.** Each block counts into one flat ``cuda.shared.array`` of int32 cells with shared atomics (the
  speeds at the firings, the observables, the joint histogram, the phase sections, in that order, as far as they
  fit in 48 KiB; the rest goes straight to global memory) and adds it once per launch into the global int64 cells.
  Integer atomics give the same sums in any order.
* **Per-path rows.** Each thread keeps its path's state, mode, counters and sums in registers and local memory and
  stores them in one row per path after each launch. The rows start on the device, and the device adds the rows of
  each chunk of ``chunk_paths`` paths in path order (:mod:`hybrid.stochastic._cuda_rows`), so that the ensemble has
  per-chunk rows, and batch-means intervals, as on the CPU, whatever the launch.
* **Launches and checkpoints.** The steps are cut into launches of ``launch_steps``; every ``checkpoint_every``
  launches the rows and histograms go to the automaton checkpoint file (checksummed, tied to the run's identity,
  which for CUDA also names the generator and the precision), and ``resume`` continues from the saved step.
* **Precision.** Double by default; ``precision='f32'`` types every float literal of the module as float32 (the
  state, the step and the normals in single precision); counters, the sums of observables and the speed sums stay
  int64 and float64.

With ``NUMBA_ENABLE_CUDASIM=1`` (set before numba is imported) the kernel runs on numba's CUDA simulator, which is
how the tests run without a GPU. Without numba-cuda or a device, :class:`~hybrid.errors.CudaUnavailableError` says
what to do in one line.
"""

from __future__ import annotations

import ast
import contextlib
import math
import re
import textwrap
import time
import types
from pathlib import Path

import numpy as np

from hybrid.errors import CudaUnavailableError, ModelError, ParameterError

from . import _auto_codegen, _auto_exec, _cuda_rng, _kernel_modules

RNG = "philox4x32-10 box-muller (angle by sincospi on the device), counter (step*M+k)//2, path"
PRECISIONS = ("f64", "f32")
SHARED_CELLS = 12 * 1024
"""int32 cells of a block's shared histograms (48 KiB, the static shared memory of one block)."""
INSTALL_HINT = 'pip install -e ".[cuda]"'


# ---------------------------------------------------------------------------------------------------- availability
def simulator_enabled() -> bool:
    """True when numba runs CUDA kernels on its simulator (``NUMBA_ENABLE_CUDASIM=1`` before numba's import)."""
    from numba.core import config

    return bool(config.ENABLE_CUDASIM)


def require_cuda():
    """``numba.cuda`` when a device (or the simulator) can run kernels, else :class:`CudaUnavailableError`.

    A real device needs the numba-cuda package (numba's own ``numba.cuda`` is deprecated); the simulator of either
    is accepted.

    Examples
    --------
    >>> try:
    ...     require_cuda()
    ... except CudaUnavailableError as e:
    ...     assert "\\n" not in str(e)
    """
    try:
        from numba import cuda
    except ImportError:
        raise CudaUnavailableError(
            f"scheduler='cuda' needs numba-cuda, which is not installed: {INSTALL_HINT}"
        ) from None
    if simulator_enabled():
        return cuda
    if getattr(cuda, "implementation", "") != "NVIDIA":
        raise CudaUnavailableError(
            f"scheduler='cuda' needs the numba-cuda package (numba's built-in CUDA target is not supported): "
            f"{INSTALL_HINT}"
        )
    try:
        ok = cuda.is_available()
    except Exception:  # a broken driver install raises instead of answering False
        ok = False
    if not ok:
        raise CudaUnavailableError(
            "scheduler='cuda': no CUDA device was found (numba.cuda.is_available() is False); run on a machine with "
            "an NVIDIA GPU and driver, or set NUMBA_ENABLE_CUDASIM=1 for numba's (slow) simulator"
        )
    return cuda


# ---------------------------------------------------------------------------------------------------- generation
_PRELUDE = '''\
# Generated for the device by hybrid.stochastic._auto_cuda from the automaton generator's own pieces
# (hybrid.stochastic._auto_codegen): precision {precision}. Do not edit: the file name hashes this text.
from numba import cuda, float32, float64, int32, int64

from hybrid.stochastic._cuda_rng import device_normal_pair

normal_pair = device_normal_pair("{precision}")
_fty = {ftype}
SH = {shared}  # cells of the block-shared copy of the histograms: a prefix of the layout below
VW = {vw}  # the layout of the flat histogram cells: speeds (transition, bin) first, then
H_OFF = {h_off}  # the observables (observable, bin),
WIDTH = {width}
J_OFF = {j_off}  # the joint histogram (y bin, x bin),
NX = {nx}
P_OFF = {p_off}  # the phase sections (section, observable, bin)
CELLS = {cells}
HOISTED_NAMES = {hoisted_names}  # loop invariants of the model's expressions: the launch argument hv
N_HOISTED = len(HOISTED_NAMES)  # (hoisted_values)
HOISTED_TEXTS = {hoisted_texts}  # the same in the model's names, for messages
'''

_KERNEL = '''\
@cuda.jit(device=True, inline=True)
def count(sh, gh, i):
    # one histogram cell: in the block's shared copy when it lies there, else straight into the global cells
    if i < SH:
        cuda.atomic.add(sh, i, 1)
    else:
        cuda.atomic.add(gh, i, 1)


@cuda.jit({jit_options})
def advance(n0, n1, npath, n_burn, stride, rk, dt, t0, p, hv, obs_lo, obs_scale, obs_bins, jx, jy, j_lo, j_scale,
            j_bins, v_scale, v_bins, track, n_phase, phase_steps, XS, MS, CNT, SM, PSM, IWS, FWS, elogs, gh):
    """Steps [n0, n1) of paths 0 .. npath-1, one thread each; every path's row in XS .. FWS in and out."""
    sh = cuda.shared.array(SH, int32)
    tid = cuda.threadIdx.x
    nthr = cuda.blockDim.x
    for _i in range(tid, SH, nthr):
        sh[_i] = 0
    cuda.syncthreads()
    ip = cuda.grid(1)
    sdt = math.sqrt(dt)
    hdt = _fty(0.5) * dt
{unpack_args}
    if ip < npath:  # no early return: every thread reaches the barriers
        x = cuda.local.array(N, _fty)
        ws = cuda.local.array(WORK, _fty)
        dw = cuda.local.array(M, _fty)
        ob = cuda.local.array(N_OBS, _fty)
        iw = cuda.local.array(IW, int64)
        fw = cuda.local.array(FW, float64)
        counts = cuda.local.array(6, int64)
        for _i in range(IW):
            iw[_i] = IWS[ip, _i]
        for _i in range(FW):
            fw[_i] = FWS[ip, _i]
        for _i in range(6):
            counts[_i] = CNT[ip, _i]
        elog = elogs[ip]
        mode = MS[ip]
{rows_in}
        _cs = (n0 - n_burn) % stride if n0 > n_burn else 0  # recorded steps since the last sample
        _nsamp = np.int64(0)  # samples of this launch: a scalar, counts[] lives in local memory
{draw_init}
        for _k in range(np.int32(n1 - n0)):  # a 32-bit counter (n1 - n0 < 2**31: max_launch_steps)
                step = n0 + np.int64(_k)  # the body indented as the CPU lane loop, for its pieces
@@HEAD@@{normals}
{fast}
                if _slow:  # a guard may have fired: the step again through the general event loop
{to_array}
{dw_store}
                    mode = event_step(mode, x, t, _t1, dt, dw, p, rec, sh, v_scale, v_bins, track, iw, fw, ws, elog)
{from_array}
                    if sample and FAST_CHECKS_SET and outside(mode, x, _t1, p):
                        counts[2] += 1
@@STATS@@{rows_out}
        MS[ip] = mode
        for _i in range(IW):
            IWS[ip, _i] = iw[_i]
        for _i in range(FW):
            FWS[ip, _i] = fw[_i]
        counts[0] += _nsamp
        for _i in range(6):
            CNT[ip, _i] = counts[_i]
    cuda.syncthreads()
    for _i in range(tid, SH, nthr):  # the block's shared cells into the global ones, once per launch
        if sh[_i] != 0:
            cuda.atomic.add(gh, _i, sh[_i])


{hoisted_function}'''

_PHASES = """\
                if phase_now:
{to_ob}
                    kp = ((step + 1) // phase_steps) % n_phase
                    for o in range(N_OBS):
                        v = ob[o]
                        if v != v:
                            continue
                        PSM[ip, kp, o] += v
                        b = (v - obs_lo[o]) * obs_scale[o]
                        if b < 0.0:
                            cell = 0
                        elif b >= _fty(obs_bins[o]):
                            cell = obs_bins[o] + 1
                        else:
                            cell = int(b) + 1
                        count(sh, gh, P_OFF + (kp * N_OBS + o) * WIDTH + cell)
"""
_JOINT = """\
                    bx = (ob[jx] - j_lo[0]) * j_scale[0]
                    by = (ob[jy] - j_lo[1]) * j_scale[1]
                    if bx >= 0.0 and bx < _fty(j_bins[0]) and by >= 0.0 and by < _fty(j_bins[1]):
                        count(sh, gh, J_OFF + int(by) * NX + int(bx))
                    else:
                        counts[4] += 1
"""
_RECORD_SIGNATURE = ("elogs, gh):\n", "elogs, gh, ip0, REC):\n")
_RECORD_AT = "                _nsamp += 1\n"


def _cuda_template(phases: bool, joint: bool, record: bool) -> str:
    """The device module's template: the generator's header (constants, the model's functions), its event code and
    its admissible set test, around the kernel above, which holds only what the run uses: the phase sections'
    statistics where it has sections (``phases``), the joint histogram's where it has one (``joint``). Dropping them
    ran Example 1 1.08x and the impact pair 1.07x as fast on an H100 (benchmarks/data/gpu_h100_ablation_runner.txt,
    variant ``unused``).

    ``record``: the recording variant (``generate_cuda_source(record=True)``, for the Monte Carlo spectrum): the
    same kernel with two more arguments, the first path's index ``ip0`` (its Philox counter: the same normals for
    any batch of paths) and ``REC`` (paths, samples, N), which receives the state of every sample.
    """
    stats = ("                if not (phase_now or sample):\n" if phases else "                if not sample:\n")
    stats += "                    continue\n{observe}\n" + (_PHASES if phases else "")
    if phases:
        stats += "                if not sample:\n                    continue\n"
    stats += _RECORD_AT + _auto_codegen.SAMPLE_GUARD + (_auto_codegen.JOINT_START + _JOINT if joint else "")
    kernel = (_KERNEL.replace("@@HEAD@@", _auto_codegen.step_head(16, "_cs", "_fty(step)", "_fty(step + 1)",
                                                                   phases=phases))
              .replace("@@STATS@@", stats))
    if record:
        assert kernel.count(_RECORD_AT) == 1
        kernel = kernel.replace(*_RECORD_SIGNATURE).replace(_RECORD_AT, _RECORD_AT + "{record_rows}\n")
    return (_PRELUDE + _auto_codegen._TEMPLATE_HEAD + _auto_codegen._TEMPLATE_EVENTS + _auto_codegen._TEMPLATE_OUTSIDE
            + kernel)


assert _KERNEL.count(_RECORD_SIGNATURE[0]) == 1 and _KERNEL.count("@@STATS@@") == 1

_DECORATOR = re.compile(r"^@nb\.njit\([^)]*\)$", re.M)
_HIST = re.compile(r"^(\s*)hist\[(\d+), (.+)\] \+= 1$", re.M)
_VHIST = re.compile(r"^(\s*)vhist\[best, (.+)\] \+= 1$", re.M)
_BIN_COUNT = re.compile(r"\b_b < _nb(\d+)\b")


def _to_device(src: str, shared_observables: bool = False) -> str:
    """The CPU statements of the generated pieces that the device does otherwise: ``@nb.njit`` -> device functions,
    per-chunk histogram increments -> atomics on the flat cells (shared where they fit), comparisons with an
    integer bin count -> with the count in the kernel's float type.

    ``shared_observables``: every observable's cells lie in the block's shared copy, so an increment goes there
    without :func:`count`'s test, its bin a 32-bit integer (as in a hand-written kernel)."""
    if re.search(r"\b_user_law\b", src):
        raise ModelError("scheduler='cuda' needs the restitution law as a sympy expression of v "
                         "(CustomRestitution('...')); a Python callable cannot be compiled for the device")
    src = _DECORATOR.sub("@cuda.jit(device=True)", src)
    if shared_observables:
        src = _HIST.sub(lambda m: f"{m[1]}cuda.atomic.add(sh, H_OFF + {m[2]} * WIDTH + "
                                  f"{m[3].replace('np.int64(', 'np.int32(')}, 1)", src)
    src = _HIST.sub(lambda m: f"{m[1]}count(sh, gh, H_OFF + {m[2]} * WIDTH + {m[3]})", src)
    # the speeds' cells come first in the layout and always fit in the shared copy (event_step gets it as vhist)
    src = _VHIST.sub(lambda m: f"{m[1]}cuda.atomic.add(vhist, best * VW + {m[2]}, 1)", src)
    # the bin coordinate against the bin count in the kernel's float type (_nbf, bound by the kernel's unpacking):
    # float32 < int64 compares in double, which consumer GPUs run at a small fraction of the single-precision rate
    src = _BIN_COUNT.sub(r"_b < _nbf\1", src)
    left = [line.strip() for line in src.splitlines()
            if re.search(r"\b(nb\.|hist\[|vhist\[|jhist\[|phist\[|np\.empty|np\.zeros)|< _nb\d", line)]
    if left:
        raise ModelError(f"the CUDA translation of the automaton kernel left CPU statements {left[:3]}; "
                         "hybrid/stochastic/_auto_cuda.py must learn them")
    return src


class _Float32(ast.NodeTransformer):
    """Types every float literal (and ``float(...)``) of the module as float32: numba types a Python float as
    float64, which would promote the whole step to double. Integer literals stay integers (indices, exponents)."""

    def visit_Call(self, node):
        self.generic_visit(node)
        if isinstance(node.func, ast.Name) and node.func.id == "float":
            node.func = ast.Name(id="_fty", ctx=ast.Load())
        return node

    def visit_BinOp(self, node):
        self.generic_visit(node)
        ints = [isinstance(v, ast.Constant) and type(v.value) is int for v in (node.left, node.right)]
        if isinstance(node.op, ast.Div) and all(ints):  # a printed Rational, (1/2): a float64 in numba
            return ast.copy_location(ast.Call(func=ast.Name(id="_fty", ctx=ast.Load()),
                                              args=[ast.Constant(node.left.value / node.right.value)], keywords=[]),
                                     node)
        return node

    def visit_Constant(self, node):
        if isinstance(node.value, float):
            return ast.copy_location(ast.Call(func=ast.Name(id="_fty", ctx=ast.Load()),
                                              args=[ast.Constant(node.value)], keywords=[]), node)
        return node


def layout(n_obs: int, width: int, n_trans: int, v_bins: int, joint_bins: tuple, n_phases: int) -> dict:
    """Offsets of the flat histogram cells and how many of them a block keeps in shared memory.

    Examples
    --------
    >>> lay = layout(1, 42, 2, 100, (1, 1), 1)
    >>> lay["h_off"], lay["cells"], lay["shared"] == lay["cells"]
    (202, 287, True)
    """
    vw = int(v_bins) + 1
    h_off = max(n_trans, 1) * vw
    j_off = h_off + n_obs * width
    nx, ny = int(joint_bins[0]), int(joint_bins[1])
    p_off = j_off + nx * ny
    cells = p_off + n_phases * n_obs * width
    if h_off > SHARED_CELLS:
        raise ParameterError(f"scheduler='cuda': the speed histograms ({h_off} cells: transitions x (bins + 1)) do not "
                             f"fit in a block's {SHARED_CELLS} shared cells; use fewer speed bins (speed_range)")
    shared = max(b for b in (h_off, j_off, p_off, cells) if b <= SHARED_CELLS)
    return dict(vw=vw, h_off=h_off, width=width, j_off=j_off, nx=nx, p_off=p_off, cells=cells, shared=shared)


def generate_cuda_source(automaton, scheme: str, observables: dict, convention: str = "stratonovich", *,
                         summed=(), phases: bool = False, joint: bool = False, lay: dict, precision: str = "f64",
                         cache: bool = True, max_registers: int | None = None, record: bool = False):
    """The device module of ``scheme`` for ``automaton``, generated by the automaton generator; ``(source, st)``.

    ``lay``: the histogram layout (:func:`layout`), compile-time constants of the module. ``phases``, ``joint``:
    whether the run has phase sections and a joint histogram (the kernel holds their code only then). ``record``:
    the recording variant (:func:`_cuda_template`), whose ``advance`` also stores every sample's state in ``REC``.

    Examples
    --------
    >>> from models.automata import impact_pair
    >>> lay = layout(1, 42, 2, 100, (1, 1), 1)
    >>> src, st = generate_cuda_source(impact_pair(), "splitting", {"H": impact_pair().observables["H"]}, lay=lay)
    >>> "def advance" in src and "def event_step" in src and "@nb.njit" not in src
    True
    """
    if precision not in PRECISIONS:
        raise ParameterError(f"precision={precision!r}; choose one of {PRECISIONS}")
    n = len(automaton.states)
    m_noise = _auto_codegen.analyse(automaton, convention).n_noise
    n_obs = max(len(observables), 1)
    ind = _indent
    draw, draw_init = _draws(m_noise, "ip0 + ip" if record else "ip")
    jit_options = "cache=True" if cache else ""
    if max_registers:
        jit_options += f", max_registers={int(max_registers)}"
    fields = dict(
        precision=precision, ftype="float32" if precision == "f32" else "float64", **lay,
        jit_options=jit_options.strip(", "),
        rows_in=ind([f"_x{i} = XS[ip, {i}]" for i in range(n)] + [f"_sum{o} = SM[ip, {o}]" for o in range(n_obs)], 8),
        rows_out=ind([f"XS[ip, {i}] = _x{i}" for i in range(n)] + [f"SM[ip, {o}] = _sum{o}" for o in range(n_obs)],
                     8),
        normals=ind(draw, 16), draw_init=ind(draw_init, 8),
        dw_store=ind([f"dw[{k}] = _w{k}" for k in range(m_noise)], 20),
        from_array=ind([f"_x{i} = x[{i}]" for i in range(n)], 20),
    )
    if record:  # sample k (k = 1, 2, ... after the burn-in) into row k - 1
        fields["record_rows"] = ind(["_r = (step + 1 - n_burn) // stride - 1"]
                                    + [f"REC[ip, _r, {i}] = _x{i}" for i in range(n)], 16)
    src, st = _auto_codegen.generate_source(automaton, scheme, observables, convention, cache=cache, summed=summed,
                                            phases=phases, template=_cuda_template(phases, joint, record),
                                            fields=fields)
    src = _lazy_times(_to_device(src, shared_observables=lay["shared"] >= lay["j_off"]))
    if precision == "f32":
        tree = _Float32().visit(ast.parse(src))
        src = "\n".join(src.splitlines()[:2]) + "\n" + ast.unparse(ast.fix_missing_locations(tree)) + "\n"
    return src, st


_TIMES = "                t = t0 + _fty(step) * dt\n                _t1 = t0 + _fty(step + 1) * dt\n"
_SLOW = "                if _slow:  # a guard may have fired: the step again through the general event loop\n"
_GUARD = "                if not FAST_CHECKS_SET:  # splitting's or baoab's kicks after the flight can move a guard\n"


def _lazy_times(src: str) -> str:
    """The step's start and end times computed only where code reads them (the event code, the admissible set test)
    when nothing else in the step loop does (a forced model's step, an observable of the time): two
    integer-to-double conversions fewer per step."""
    if src.count(_TIMES) != 1 or src.count(_SLOW) != 1:  # the kernel template's own text: a change must show here
        raise ModelError("the CUDA kernel template changed: _lazy_times must learn it")
    lines = src.split(_TIMES)[1].splitlines()
    body = lines[:next(i for i, line in enumerate(lines) if line.strip() and len(line) - len(line.lstrip()) <= 8)]
    # the lines that will receive the times: the event code's call and the admissible-set tests
    rest = [line for line in body if "event_step(" not in line and "outside(mode, x, _t1, p)" not in line]
    if re.search(r"\bt\b|\b_t1\b", "\n".join(rest)):
        return src
    times = textwrap.indent(_TIMES, "    ")
    return src.replace(_TIMES, "").replace(_SLOW, _SLOW + times).replace(_GUARD, _GUARD + times)


def _draws(m_noise: int, path: str) -> tuple[list, list]:
    """The step's normals ``_w0 .. _w{M-1}`` (lines of the loop body) and what they need before the loop.

    Normal q = step * M + k of a path is half of its Philox draw q // 2 (:mod:`hybrid.stochastic._cuda_rng`). One
    noise: the draw of an even step serves the odd step after it, a parity toggled each step tells them apart (the
    first step of a launch may be odd: the loop starts with its pair); two noises: one draw per step; more: each
    normal's draw made when it differs from the last one's. ``path``: the path's Philox index.
    """
    if m_noise == 1:
        return (["if _odd == 0:  # an even step: the pair of this step and the next",
                 f"    _za, _zb = normal_pair(rk, {path}, np.uint64(step) >> np.uint64(1))",
                 "    _w0 = sdt * _za",
                 "else:",
                 "    _w0 = sdt * _zb",
                 "_odd ^= 1", "_slow = False"],
                ["_za = _fty(0.0)", "_zb = _fty(0.0)",
                 "_odd = np.int32(n0 & 1)",
                 "if _odd == 1:",
                 f"    _za, _zb = normal_pair(rk, {path}, np.uint64(n0) >> np.uint64(1))"])
    if m_noise == 2:
        return ([f"_za, _zb = normal_pair(rk, {path}, np.uint64(step))", "_w0 = sdt * _za", "_w1 = sdt * _zb",
                 "_slow = False"], ["pass"])
    draw = []
    for k in range(m_noise):
        draw += [f"_q = np.uint64(step) * np.uint64({m_noise}) + np.uint64({k})",
                 "if (_q >> np.uint64(1)) != _zp:",
                 "    _zp = _q >> np.uint64(1)",
                 f"    _za, _zb = normal_pair(rk, {path}, _zp)",
                 f"_w{k} = sdt * (_za if (_q & np.uint64(1)) == np.uint64(0) else _zb)"]
    return draw + ["_slow = False"], ["_zp = np.uint64(0xFFFFFFFFFFFFFFFF)  # the Philox draw in _za, _zb (none yet)",
                                      "_za = _fty(0.0)", "_zb = _fty(0.0)"]


def _indent(lines: list, spaces: int) -> str:
    return "\n".join(" " * spaces + line for line in lines) or " " * spaces + "pass"


# ---------------------------------------------------------------------------------------------------- runner
def default_launch_steps(paths: int, threads_per_block: int) -> int:
    """Steps per launch: about 1e10 path-steps (a fraction of a second on a large GPU), at least 1000, and at most
    :func:`max_launch_steps`.

    Examples
    --------
    >>> default_launch_steps(10**6, 128), default_launch_steps(8, 128)
    (10000, 262143)
    """
    return int(min(max_launch_steps(threads_per_block), max(1000, 10**10 // max(paths, 1))))


def max_launch_steps(threads_per_block: int) -> int:
    """The most steps one launch may take so that no int32 shared cell can overflow: a block adds at most one
    sample per thread and step to a cell of the observables, and at most ``MAX_EVENTS`` firings to a speed cell.

    Examples
    --------
    >>> max_launch_steps(128)
    262143
    """
    return (2**31 - 1) // (int(threads_per_block) * _auto_codegen.MAX_EVENTS)


def _after_launch(n_done: int) -> None:
    """Called after each launch has finished (a test interrupts a run here)."""


def _plain_device_functions(module) -> None:
    """On numba's simulator: each device function of the device module replaced by the Python function it wraps.

    At every call of a device function the simulator takes two locks, to count the calls that need the name
    ``cuda`` swapped in the function's globals. The kernel's launch has swapped it already for the whole module,
    whose functions share its globals, so those calls only take the locks. With 32 threads contending for them, a
    run sometimes crawled (1 s became up to 150 s). The same functions run, so the numbers do not change.
    """
    for name, obj in list(vars(module).items()):
        if getattr(obj, "_device", False) is True and callable(getattr(obj, "fn", None)):
            setattr(module, name, obj.fn)


class CudaRun:
    """The device module of one automaton run and the per-path state it advances (one row per path).

    Built by :func:`hybrid.stochastic.simulate_automaton` (``scheduler='cuda'``) from its job
    (:class:`~hybrid.stochastic._auto_exec.AutomatonJob`: the run's arguments and per-chunk shapes).
    """

    ORDER = ("XS", "MS", "CNT", "SM", "PSM", "IWS", "FWS", "elogs", "gh")
    RECORD = False  # the recording variant of the kernel (CudaRecorder)

    def __init__(self, job, automaton, scheme: str, observables: dict, convention: str, *, summed, phases: int,
                 n_trans: int, seed: int, precision: str = "f64", threads_per_block: int = 128):
        if precision not in PRECISIONS:
            raise ParameterError(f"precision={precision!r}; choose one of {PRECISIONS}")
        tpb = threads_per_block
        if isinstance(tpb, bool) or not isinstance(tpb, (int, np.integer)) or not (32 <= tpb <= 1024 and tpb % 32 == 0):
            raise ParameterError(f"threads_per_block={tpb!r} must be a multiple of 32 in [32, 1024]")
        self.cuda = require_cuda()
        self.job, self.tpb, self.precision = job, int(tpb), precision
        self.ft = np.float32 if precision == "f32" else np.float64
        a, shapes = job.args, job.shapes
        self.n_obs, self.width = shapes["hist"][0]
        self.n_trans, self.phases = n_trans, phases
        ny, nx = shapes["jhist"][0]
        self.lay = layout(self.n_obs, self.width, n_trans, a["v_bins"], (nx, ny), phases)
        sim = simulator_enabled()
        self.max_registers = None if sim else max_registers_from_env(precision)
        src, st = generate_cuda_source(automaton, scheme, observables, convention, summed=summed, phases=phases > 0,
                                       joint=a["jx"] >= 0, lay=self.lay, precision=precision, cache=not sim,
                                       max_registers=self.max_registers, record=self.RECORD)
        self.source, self.n = src, len(st.states)
        where = ("sim" if sim else "dev") + ("_rec" if self.RECORD else "")
        self.name = f"vibro_auto_cuda_{scheme}_{precision}_{where}_{_auto_codegen.kernel_key(src)}"
        self.module, _ = _kernel_modules.load_source(self.name, src, label=f"automaton/{scheme} (CUDA, {precision})")
        if sim:
            _plain_device_functions(self.module)
        self.key = _cuda_rng.seed_key(seed)
        self.round_keys = _cuda_rng.round_keys(*self.key)  # launch arguments: read from the constant bank
        ft = self.ft
        # the parameters and the histograms' ranges as tuples: launch arguments, which the device reads from its
        # constant bank (arrays are loaded once into registers that the whole step loop holds); one unused value
        # when a model has no parameters
        def floats(v):
            return tuple(ft(w) for w in v)

        def ints(v):
            return tuple(np.int64(w) for w in v)

        params = floats(a["p"]) or (ft(0.0),)
        hoisted = hoisted_values(self.module, a["p"], a["dt"], ft)
        self.scalars = (ft(a["dt"]), ft(0.0), params, hoisted, floats(a["obs_lo"]), floats(a["obs_scale"]),
                        ints(a["obs_bins"]), np.int64(a["jx"]), np.int64(a["jy"]), floats(a["j_lo"]),
                        floats(a["j_scale"]), ints(a["j_bins"]), ft(a["v_scale"]), np.int64(a["v_bins"]))
        self._check_memory(int(job.npaths.sum()))  # before any compile or launch

    REDUCED = ("counts", "sums", "psums", "events", "vsum", "gstat", "fbad")
    """The runner's per-chunk rows that :meth:`chunk_rows` sums on the device, in ``reduce_chunks``' order."""

    def row_shapes(self, paths: int) -> dict:
        """Shape and dtype of each per-path row array of ``paths`` paths (:data:`ORDER` but the histogram cells):
        one layout for the host's rows, the device's and the memory estimate."""
        mod = self.module
        return {"XS": ((paths, self.n), self.ft), "MS": ((paths,), np.int64), "CNT": ((paths, 6), np.int64),
                "SM": ((paths, self.n_obs), np.float64), "PSM": ((paths, max(self.phases, 1), self.n_obs), np.float64),
                "IWS": ((paths, mod.IW), np.int64), "FWS": ((paths, mod.FW), np.float64),
                "elogs": ((paths, self.job.shapes["elog"][0][1], 3), np.float64)}

    def fresh(self, paths: int) -> dict:
        """The host arrays of ``paths`` paths at t = 0."""
        a, mod = self.job.args, self.module
        host = {k: np.zeros(shape, dtype) for k, (shape, dtype) in self.row_shapes(paths).items()}
        host["XS"][:] = a["x0"].astype(self.ft)
        host["MS"][:] = a["mode0"]
        for j in range(self.n_trans):  # [sum, count, min, max] of the guard changes: the extremes start empty
            host["FWS"][:, mod.FW_GSTAT + 4 * j + 2], host["FWS"][:, mod.FW_GSTAT + 4 * j + 3] = np.inf, -np.inf
        host["elogs"][:] = np.nan
        host["gh"] = np.zeros(self.lay["cells"], np.int64)
        return host

    def advance(self, dev: dict, paths: int, n0: int, n1: int, n_burn: int, track: bool) -> None:
        """Launch the kernel on the device arrays ``dev`` for steps [n0, n1) and wait for it."""
        a = self.job.args
        blocks = max(1, -(-paths // self.tpb))
        dt, t0, *rest = self.scalars
        self.module.advance[blocks, self.tpb](
            np.int64(n0), np.int64(n1), np.int64(paths), np.int64(n_burn), np.int64(a["stride"]), self.round_keys,
            dt, t0, *rest, bool(track), np.int64(a["phases"]), np.int64(a["phase_steps"]),
            *(dev[k] for k in self.ORDER))
        self.cuda.synchronize()

    def pilot(self, steps: int) -> np.ndarray:
        """The step rule's guard statistics (transitions, 4) of chunk 0's paths over ``steps`` steps of burn-in,
        every step through ``event_step`` (as the CPU pilot)."""
        paths = int(self.job.npaths[0])
        dev = self.device_fresh(paths)
        done = 0
        while done < steps:
            n1 = min(steps, done + max_launch_steps(self.tpb))
            self.advance(dev, paths, done, n1, steps, True)
            done = n1
        fw = dev["FWS"].copy_to_host()
        g0 = self.module.FW_GSTAT
        out = np.zeros((max(self.n_trans, 1), 4))
        for j in range(self.n_trans):
            gs = g0 + 4 * j
            out[j] = fw[:, gs].sum(), fw[:, gs + 1].sum(), fw[:, gs + 2].min(), fw[:, gs + 3].max()
        return out

    def _launch_steps(self, launch_steps, paths: int) -> int:
        """``launch_steps`` checked (an integer in [1, :func:`max_launch_steps`]), or the default for ``paths``."""
        cap = max_launch_steps(self.tpb)
        if launch_steps is None:
            return default_launch_steps(paths, self.tpb)
        if isinstance(launch_steps, bool) or not isinstance(launch_steps, (int, np.integer)) or \
                not 1 <= launch_steps <= cap:
            raise ParameterError(f"launch_steps={launch_steps!r} must be an integer in [1, {cap}] (int32 shared "
                                 f"cells of {self.tpb} threads per block)")
        return int(launch_steps)

    def run(self, rows: dict, *, run_id: str, checkpoint=None, resume=False, checkpoint_every=4,
            launch_steps=None) -> dict:
        """Advance every path over the run's steps and fill the runner's per-chunk ``rows``; the run's settings.

        Launches of ``launch_steps`` steps (default :func:`default_launch_steps`); every ``checkpoint_every``
        launches, and at the end, the state goes to the checkpoint directory; ``resume`` continues from it.
        """
        a = self.job.args
        paths = int(self.job.npaths.sum())
        total = a["n_burn"] + a["n_samp"] * a["stride"]
        launch_steps = self._launch_steps(launch_steps, paths)
        ckdir = Path(checkpoint) if checkpoint is not None else None
        n, dev = 0, None
        if ckdir is not None and resume:
            host = self.fresh(paths)
            host["n_done"] = np.zeros(1, np.int64)
            if _auto_exec.load(ckdir, run_id, host) is not None:  # fills host in place
                n = int(host["n_done"][0])
                dev = {k: self.cuda.to_device(host[k]) for k in self.ORDER}
            del host
        if dev is None:  # from t = 0: the rows start on the device
            dev = self.device_fresh(paths)
        launches = 0

        def save(n_done):
            state = {k: dev[k].copy_to_host() for k in self.ORDER}
            state["n_done"] = np.array([n_done], np.int64)
            _auto_exec.write(ckdir, run_id, np.zeros(0, bool), state)

        t_start = time.perf_counter()
        while n < total:
            n1 = min(total, n + int(launch_steps))
            self.advance(dev, paths, n, n1, a["n_burn"], False)
            n = n1
            launches += 1
            _after_launch(n)
            if ckdir is not None and launches % checkpoint_every == 0 and n < total:
                save(n)
        if ckdir is not None:
            save(n)
        self._fill(rows, self.chunk_rows(dev, rows), total)
        return {"scheduler": "cuda", "precision": self.precision, "rng": RNG, "threads_per_block": self.tpb,
                "launch_steps": int(launch_steps), "device_seconds": time.perf_counter() - t_start,
                "cuda_kernel": self.name, "max_registers": self.max_registers}

    def device_fresh(self, paths: int) -> dict:
        """The device arrays of ``paths`` paths at t = 0 (:meth:`fresh`'s values), filled on the device."""
        from . import _cuda_rows

        a, mod, cuda = self.job.args, self.module, self.cuda
        dev = {k: cuda.device_array(shape, dtype) for k, (shape, dtype) in self.row_shapes(paths).items()}
        dev["gh"] = cuda.to_device(np.zeros(self.lay["cells"], np.int64))
        blocks = max(1, -(-paths // self.tpb))
        _cuda_rows.init_rows[blocks, self.tpb](
            cuda.to_device(np.asarray(a["x0"], self.ft)), np.int64(a["mode0"]), np.int64(mod.FW_GSTAT),
            np.int64(self.n_trans), *(dev[k] for k in self.ORDER[:-1]))
        cuda.synchronize()
        return dev

    def chunk_rows(self, dev: dict, rows: dict) -> dict:
        """The per-chunk sums of the device rows ``dev`` (``rows``: the runner's arrays, for their shapes), computed
        on the device (:func:`hybrid.stochastic._cuda_rows.reduce_chunks`) and copied back, with the histogram
        cells; the event logs and their counts only where the run keeps a log."""
        from . import _cuda_rows

        cuda, mod = self.cuda, self.module
        cp = int(self.job.shapes["elog"][0][0])
        n_chunks = rows["counts"].shape[0]
        # the runner's own shapes, zeros where the kernel writes nothing (no transition, no phase section)
        red = {k: cuda.to_device(np.zeros_like(rows[k])) for k in self.REDUCED}
        _cuda_rows.reduce_chunks[max(1, -(-n_chunks // 128)), 128](
            np.int64(cp), np.int64(mod.IW_EVENTS), np.int64(mod.FW_GSTAT), np.int64(mod.FW_FBAD),
            np.int64(self.n_trans), dev["CNT"], dev["SM"], dev["PSM"], dev["IWS"], dev["FWS"],
            *(red[k] for k in self.REDUCED))
        cuda.synchronize()
        host = {k: v.copy_to_host() for k, v in red.items()}
        host["gh"] = dev["gh"].copy_to_host()
        if rows["elog"].shape[2]:  # a run that keeps event logs: every path's log and its count
            host["elogs"] = dev["elogs"].copy_to_host()
            host["nlog"] = dev["IWS"].copy_to_host()[:, mod.IW_NLOG]
        return host

    def _check_memory(self, paths: int) -> None:
        """Refuse, with the estimate, per-path rows that do not fit in the device's memory (the simulator: 4 GB)."""
        from hybrid.sizes import check_size

        row = sum(math.prod(shape) * np.dtype(dtype).itemsize for shape, dtype in self.row_shapes(1).values())
        if simulator_enabled():
            limit = 4e9
        else:
            limit = 0.8 * self.cuda.current_context().get_memory_info()[0]
        check_size(f"scheduler='cuda' with {paths} paths", memory=float(paths) * row, max_memory=limit,
                   detail=f"{row} bytes of state, counters and sums per path, against 80 % of the device's free "
                          "memory", fix="run fewer paths per call and merge the ensembles")

    def _fill(self, rows: dict, r: dict, total: int) -> None:
        """The runner's per-chunk ``rows`` from :meth:`chunk_rows`' sums ``r``; the histograms into chunk 0's row."""
        a, lay = self.job.args, self.lay
        cp = self.job.shapes["elog"][0][0]
        paths = int(self.job.npaths.sum())
        starts = np.arange(0, paths, cp)
        for k in self.REDUCED:
            rows[k][:] = r[k]
        if "elogs" in r:
            n_log = rows["elog"].shape[2]
            padded = np.full((len(starts) * cp, n_log, 3), np.nan)
            padded[:paths] = r["elogs"]
            rows["elog"][:] = padded.reshape(len(starts), cp, n_log, 3)
            nlog = np.zeros(len(starts) * cp, np.int64)
            nlog[:paths] = r["nlog"]
            rows["nlog"][:] = nlog.reshape(len(starts), cp)
        gh = r["gh"]
        nv = max(self.n_trans, 1)
        rows["vhist"][0] = gh[:nv * lay["vw"]].reshape(nv, lay["vw"])
        rows["hist"][0] = gh[lay["h_off"]:lay["j_off"]].reshape(self.n_obs, self.width)
        rows["jhist"][0] = gh[lay["j_off"]:lay["p_off"]].reshape(rows["jhist"].shape[1:])
        if self.phases:
            rows["phist"][0] = gh[lay["p_off"]:].reshape(self.phases, self.n_obs, self.width)
            # every path samples section k at the same steps: (step + 1) a multiple of phase_steps, after burn-in
            ends = np.arange(a["n_burn"] + 1, total + 1)
            ends = ends[ends % a["phase_steps"] == 0]
            per_path = np.bincount((ends // a["phase_steps"]) % self.phases, minlength=self.phases)
            rows["pcount"][:] = np.minimum(cp, paths - starts)[:, None] * per_path[None, :]


class CudaRecorder(CudaRun):
    """:class:`CudaRun` with the recording kernel: the state of every sample of a batch of paths, for the Monte
    Carlo spectrum (:func:`hybrid.stochastic._welch.welch_spectrum` with ``scheduler='cuda'``).

    The job's ``n_burn`` and ``stride`` place the samples (after steps n_burn + k * stride, k = 1 .. n_samp). Path
    i of the run draws the Philox normals of path i whatever batch it runs in, so the recorded states depend on
    neither the batches nor the launch configuration.
    """

    RECORD = True

    def record(self, lo: int, hi: int, launch_steps=None) -> tuple[np.ndarray, np.ndarray, dict]:
        """Paths lo .. hi-1 of the run from t = 0: ``(start, rec, rows)``, the states after the burn-in (hi - lo, N),
        every sample's state (hi - lo, n_samp, N) and the paths' final rows (``CNT``, ``IWS``, ``FWS``)."""
        a = self.job.args
        paths = int(hi - lo)
        n_burn, total = int(a["n_burn"]), int(a["n_burn"] + a["n_samp"] * a["stride"])
        launch_steps = self._launch_steps(launch_steps, paths)
        dev = self.device_fresh(paths)
        rec = self.cuda.to_device(np.zeros((paths, int(a["n_samp"]), self.n), self.ft))
        start = None
        n = 0
        for stop in (n_burn, total):  # the burn-in's end is a launch boundary: its states are sample 0
            while n < stop:
                n1 = min(stop, n + int(launch_steps))
                self._launch(dev, rec, lo, paths, n, n1)
                n = n1
            if start is None:
                start = dev["XS"].copy_to_host()
        rows = {k: dev[k].copy_to_host() for k in ("CNT", "IWS", "FWS")}
        return start, rec.copy_to_host(), rows

    def _launch(self, dev: dict, rec, lo: int, paths: int, n0: int, n1: int) -> None:
        a = self.job.args
        blocks = max(1, -(-paths // self.tpb))
        dt, t0, *rest = self.scalars
        self.module.advance[blocks, self.tpb](
            np.int64(n0), np.int64(n1), np.int64(paths), np.int64(a["n_burn"]), np.int64(a["stride"]),
            self.round_keys, dt, t0, *rest, False, np.int64(0), np.int64(1), *(dev[k] for k in self.ORDER),
            np.int64(lo), rec)
        self.cuda.synchronize()


DEFAULT_MAX_REGISTERS = {"f64": 96, "f32": 64}
"""The register cap per thread when ``VIBRO_CUDA_MAX_REGISTERS`` is unset. Measured on an H100 (2**20 paths x
20,000 steps, benchmarks/gpu_throughput.py and docs/gpu.md): Example 1 in f64 ran at 3.3-3.6e10 path-steps/s with
the compiler's 160 registers and 4.4-4.6e10 capped at 96; the impact pair 2.1e10 with 210 and 2.6-2.7e10 at 96; f32
Example 1 3.8-4.5e10 with 138 and 4.8-4.9e10 at 64. The spills the caps cause cost less than the occupancy gained.
With the launch arguments (2026-11-27, first machine, one timing per cap, six at 96): Example 1 3.6e10 uncapped
(130 registers), 4.3e10 at 128, 4.6-4.9e10 at 96, 3.8-4.1e10 at 80-64; the impact pair 2.4e10 uncapped, 2.9-3.2e10
at 128-80 (those timings held 0.22 s of host work per run). Later, Example 1 at 64 ran 0.86x its speed at 96 (with
the host work; benchmarks/data/gpu_h100_ablation_nested.txt) and at 80 0.98x (without it, with its values as
literals; gpu_h100_ablation_runner.txt), while the impact pair at 64 ran 1.05x (with the host work): not measured
again on the final kernel, so 96 stays."""


def max_registers_from_env(precision: str = "f64") -> int | None:
    """The register cap of the device kernel: ``VIBRO_CUDA_MAX_REGISTERS`` as an int (0: no cap, the compiler
    chooses), or :data:`DEFAULT_MAX_REGISTERS` of ``precision`` when the variable is unset or empty.

    Examples
    --------
    >>> import os; os.environ.pop("VIBRO_CUDA_MAX_REGISTERS", None) and None
    >>> max_registers_from_env("f64"), max_registers_from_env("f32")
    (96, 64)
    """
    import os

    if precision not in PRECISIONS:
        raise ParameterError(f"precision={precision!r}; choose one of {PRECISIONS}")
    raw = os.environ.get("VIBRO_CUDA_MAX_REGISTERS", "").strip()
    if not raw:
        return DEFAULT_MAX_REGISTERS[precision]
    if raw == "0":
        return None
    try:
        n = int(raw)
    except ValueError:
        n = -1
    if not 16 <= n <= 255:
        raise ParameterError(f"VIBRO_CUDA_MAX_REGISTERS={raw!r} must be an integer in [16, 255] (or 0: no cap)")
    return n


def kernel_resources(settings: dict) -> dict:
    """Registers and local memory per thread, shared memory per block and the occupancy they allow, of the kernel
    that ran an ensemble (its ``settings``), on the current device. Needs a real GPU (the simulator compiles nothing).

    Occupancy: resident warps per SM over the most an SM holds, from the limits on threads, registers (allocated
    per warp in units of 256), shared memory and 32 blocks per SM (the CUDA occupancy calculator's rule).
    """
    require_cuda()
    if simulator_enabled():
        raise CudaUnavailableError("kernel_resources needs a GPU: the simulator compiles no kernel")
    module = _kernel_modules._LOADED.get(settings.get("cuda_kernel"))
    if module is None:
        raise ParameterError("kernel_resources: the ensemble's CUDA kernel was not run in this process")
    return compiled_resources(module.advance, int(settings["threads_per_block"]))


def compiled_resources(kernel, tpb: int) -> dict:
    """:func:`kernel_resources` of any numba-cuda kernel that has run once, at ``tpb`` threads per block
    (``benchmarks/gpu_ceiling.py`` prices its hand-written kernels with it). Needs a real GPU."""
    cuda = require_cuda()

    def one(value):  # a kernel compiled at its first launch answers per signature: it has one
        return int(next(iter(value.values())) if isinstance(value, dict) else value)

    regs = one(kernel.get_regs_per_thread())
    local = one(kernel.get_local_mem_per_thread())
    shared = one(kernel.get_shared_mem_per_block())
    dev = cuda.get_current_device()
    warps = -(-tpb // 32)
    per_warp = -(-regs * 32 // 256) * 256
    blocks = min(int(dev.MAX_THREADS_PER_MULTIPROCESSOR) // tpb,
                 int(dev.MAX_REGISTERS_PER_MULTIPROCESSOR) // max(per_warp * warps, 1),
                 int(dev.MAX_SHARED_MEMORY_PER_MULTIPROCESSOR) // max(shared, 1), 32)
    occupancy = blocks * warps * 32 / int(dev.MAX_THREADS_PER_MULTIPROCESSOR)
    return {"registers_per_thread": regs, "local_bytes_per_thread": local, "shared_bytes_per_block": shared,
            "blocks_per_sm": blocks, "occupancy": occupancy}


class _IeeeMath:
    """``math`` as the device computes it: Python's function (the C library's, as the CPU kernel's), and numpy's
    where Python's raises instead of giving inf or NaN (an overflow of exp, a logarithm of 0, a square root of a
    negative number); a function numpy lacks still raises."""

    def __getattr__(self, name):
        exact = getattr(math, name)
        ieee = getattr(np, name, None)
        if not callable(exact) or ieee is None:
            return exact

        def evaluate(*args):
            try:
                return exact(*args)
            except (OverflowError, ValueError):
                return ieee(*(np.float64(a) for a in args))

        return evaluate


_IEEE_MATH = _IeeeMath()


def hoisted_values(module, p, dt, ftype) -> tuple:
    """The loop invariants of the model's expressions (``module.hoisted_values``), evaluated on the host and given
    to the kernel as a launch argument (a tuple of ``ftype``); one unused value where there are none.

    They are evaluated in double precision with IEEE semantics, as the device did before (an intermediate may
    overflow to inf, as in 1 / (1 + exp(800)) = 0), then rounded to ``ftype``; where an f32 module types a literal
    as float32 the product is still made in double. An invariant that is NaN (a square root of a negative D, a
    negative number to a fractional power) is a one-line :class:`~hybrid.errors.ParameterError`: the CPU kernel
    would run such a model into NaN states.
    """
    fn = module.hoisted_values
    ieee = types.FunctionType(fn.__code__, {**fn.__globals__, "math": _IEEE_MATH}, fn.__name__)
    params = tuple(np.float64(v) for v in p)
    try:
        with np.errstate(all="ignore"):
            values = [np.float64(v) for v in ieee(params, np.float64(dt))]
    except (ArithmeticError, ValueError, TypeError) as exc:  # a function numpy lacks, on a bad argument
        raise ParameterError(f"the model's parameters {tuple(float(v) for v in p)} make a loop invariant of its "
                             f"expressions undefined ({type(exc).__name__}: {exc})") from None
    bad = [k for k, v in enumerate(values) if v != v]
    if bad:
        raise ParameterError(f"the model's parameters {tuple(float(v) for v in p)} make {module.HOISTED_TEXTS[bad[0]]} "
                             "NaN, a value of its expressions that the device needs (a square root of a negative "
                             "number, a negative number to a fractional power, ...)")
    return tuple(ftype(v) for v in values) or (ftype(0.0),)


def kernel_signature(precision: str = "f64", record: bool = False, n_params: int = 1, n_obs: int = 1,
                     n_hoisted: int = 1) -> tuple:
    """numba types of the arguments of ``advance``, in the order :meth:`CudaRun.advance` passes them (``record``:
    the recording variant's, as :meth:`CudaRecorder._launch` passes them), for a model of ``n_params``
    parameters, ``n_obs`` observables and ``n_hoisted`` loop invariants (``N_HOISTED`` of its module)."""
    from numba import types as t

    f = t.float32 if precision == "f32" else t.float64
    i, d = t.int64, t.float64

    def arr(dtype, ndim):
        return t.Array(dtype, ndim, "C")

    no = max(n_obs, 1)
    return (i, i, i, i, i, t.UniTuple(t.uint32, 20), f, f, t.UniTuple(f, max(n_params, 1)),
            t.UniTuple(f, max(n_hoisted, 1)), t.UniTuple(f, no),
            t.UniTuple(f, no), t.UniTuple(i, no), i, i, t.UniTuple(f, 2), t.UniTuple(f, 2), t.UniTuple(i, 2), f, i,
            t.boolean, i, i, arr(f, 2), arr(i, 1), arr(i, 2), arr(d, 2), arr(d, 3),
            arr(i, 2), arr(d, 2), arr(d, 3), arr(i, 1)) + ((i, arr(f, 3)) if record else ())


def compile_ptx(automaton, scheme: str, observables: dict, *, histograms_width: int = 42, v_bins: int = 100,
                phases: int = 0, precision: str = "f64", cc=(9, 0), record: bool = False, joint: bool = False) -> str:
    """PTX of the automaton kernel (``record``: its recording variant; ``joint``: with a joint histogram) for
    compute capability ``cc`` (default sm_90, the H100), without a GPU.

    The real numba-cuda pipeline (typing, lowering, NVVM), which the simulator skips. Needs numba-cuda and the NVVM
    and NVRTC libraries (the ``nvidia-cuda-nvcc-cu12`` and ``nvidia-cuda-nvrtc-cu12`` wheels or a CUDA toolkit),
    not a driver; ``NUMBA_ENABLE_CUDASIM`` must be unset.
    """
    from numba import cuda

    if getattr(cuda, "implementation", "") != "NVIDIA" or simulator_enabled():
        raise CudaUnavailableError(f"compile_ptx needs numba-cuda ({INSTALL_HINT}) and NUMBA_ENABLE_CUDASIM unset")
    lay = layout(max(len(observables), 1), histograms_width, len(automaton.transitions), v_bins, (1, 1), phases)
    src, st = generate_cuda_source(automaton, scheme, observables, lay=lay, phases=phases > 0, joint=joint,
                                   precision=precision, cache=False, max_registers=max_registers_from_env(precision),
                                   record=record)
    name = f"vibro_auto_cuda_ptx_{scheme}_{precision}_{_auto_codegen.kernel_key(src)}"
    module, _ = _kernel_modules.load_source(name, src)
    with assumed_device(cc):
        signature = kernel_signature(precision, record, len(st.params), len(observables), module.N_HOISTED)
        ptx, _ = cuda.compile_ptx(module.advance.py_func, signature, cc=cc)
    return ptx


@contextlib.contextmanager
def assumed_device(cc=(9, 0)):
    """Within the block, numba-cuda's current device is one of compute capability ``cc``: it compiles a kernel's
    device functions for the current device, and without a GPU there is none (a PTX compile on a machine without
    one: :func:`compile_ptx`, ``benchmarks/gpu_ceiling.py --registers``).

    Examples
    --------
    >>> from numba.cuda import dispatcher
    >>> with assumed_device((8, 0)):
    ...     dispatcher.get_current_device().compute_capability
    (8, 0)
    """
    from numba.cuda import dispatcher

    current = dispatcher.get_current_device
    dispatcher.get_current_device = lambda: types.SimpleNamespace(compute_capability=tuple(cc))
    try:
        yield
    finally:
        dispatcher.get_current_device = current
