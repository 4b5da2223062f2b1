"""Generate numba source for a model and a scheme, write it to a cache directory and import it.

The model's sympy expressions (Itô drift, sigma**2, its y-derivative, the potential G and the restitution law) are
printed as Python into one module together with the ensemble kernel of the chosen scheme. Parameter values are
*not* in the source: model parameters arrive as the array ``prm`` and the numbers in the restitution law (for example
V_C) as ``rprm``, so changing delta, c, D or V_C reuses the compiled kernel. The source is written to
``$VIBRO_CACHE_DIR`` (default ``~/.cache/vibro-impact``) under a name that hashes the source itself, and numba's
``cache=True`` keeps the machine code next to it, so a second process loads the kernel instead of compiling it.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import inspect
import logging
import os
import re
import sys
import textwrap
import time
import types
from dataclasses import dataclass, field
from pathlib import Path

import numba as nb
import numpy as np
import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from hybrid.automaton import real_symbol
from hybrid.errors import ModelError, RestitutionError

from . import _rng
from ._statistics import COUNTS, SUMS

TEMPLATE_VERSION = "7"
_X, _Y = real_symbol("x"), real_symbol("y")
_V = real_symbol("v")


def cache_dir() -> Path:
    """Directory of generated kernels: ``$VIBRO_CACHE_DIR`` or ``~/.cache/vibro-impact``.

    Examples
    --------
    >>> cache_dir().name in ("vibro-impact",) or "VIBRO_CACHE_DIR" in __import__("os").environ
    True
    """
    env = os.environ.get("VIBRO_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "vibro-impact"


class _Printer(PythonCodePrinter):
    """Python printer whose output numba compiles (math functions, conditional expressions)."""

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_Function(self, expr):
        # a restitution law given as a Python callable: the module binds the numba-compiled callable to this name
        if type(expr).__name__ == USER_LAW:
            return f"{USER_LAW}({', '.join(self._print(a) for a in expr.args)})"
        return super()._print_Function(expr)


USER_LAW = "_user_law"
"""The name under which a generated module calls a restitution law given as a Python callable (numba-compiled)."""


@dataclass
class Emitter:
    """Turns the model's expressions into code strings for the scheme templates.

    Parameters are renamed to ``_p0, _p1, ...`` (unpacked from ``prm`` once per kernel call), numbers of the
    restitution law to ``_r0, ...``. Sub-expressions free of ``x`` and ``y`` are hoisted out of the loops.
    """

    model: object
    param_names: tuple[str, ...]
    law_code: str
    preamble: list[str] = field(default_factory=list)
    _hoisted: dict = field(default_factory=dict)

    def __post_init__(self):
        self._subs = {real_symbol(k): real_symbol(f"_p{i}") for i, k in enumerate(self.param_names)}
        self._printer = _Printer({"standard": "python3"})

    def code(self, expr) -> str:
        """Code for a sympy expression of x, y and parameters (hoisted when constant)."""
        expr = sp.sympify(expr).xreplace(self._subs)
        text = self._printer.doprint(expr)
        if not (expr.free_symbols & {_X, _Y}) and not expr.is_Number:
            if text not in self._hoisted:
                name = f"_c{len(self._hoisted)}"
                self._hoisted[text] = name
                self.preamble.append(f"{name} = {text}")
            return self._hoisted[text]
        return f"({text})"

    def is_constant(self, expr) -> bool:
        """True when ``expr`` does not depend on the state."""
        return not (sp.sympify(expr).free_symbols & {_X, _Y})

    # ------------------------------------------------------------------ impacts
    def _impact(self, side: str, speed: str, record: bool) -> str:
        # e is checked at every impact (a callable law is only validated on a grid beforehand); the first bad value
        # is kept so that the runner can name the speed. NaN fails the test too.
        lines = [f"_v = {speed}", f"_e = {self.law_code}", "if not (_e > 0.0 and _e <= 1.0):",
                 "    if bad_e == 0:", "        bad_v = _v", "        bad_ev = _e", "    bad_e += 1"]
        if record:  # only after burn-in (the flag rec)
            # the crossing speed can be <= 0 with EM (the in-step velocity turned before the wall): underflow bin
            lines += [
                "if rec:",
                f"    n_i{side} += 1",
                "    s_iv += _v",
                "    _vb = _v * v_scale",
                "    if _vb >= 0.0 and _vb <= vbins:",
                "        vh[k, min(int(_vb), vbins - 1)] += 1",
                "    elif _vb < 0.0:",
                "        v_under += 1",
                "    else:",
                "        v_over += 1",
            ]
        return "\n".join(lines)

    def flight(self, tau: str, record: bool) -> str:
        """Free flight of x with the constant velocity y for time ``tau``, reflecting at the walls (loop)."""
        return _FLIGHT.format(
            tau=tau,
            imp_r=textwrap.indent(self._impact("r", "y", record), " " * 12),
            imp_l=textwrap.indent(self._impact("l", "-y", record), " " * 12),
        )

    def flight_em(self, inc: str, record: bool) -> str:
        """Euler-Maruyama step: x moves with the old velocity, y gains ``inc`` spread linearly over the step."""
        return _FLIGHT_EM.format(
            inc=inc,
            imp_r=textwrap.indent(self._impact("r", "_vm", record), " " * 12),
            imp_l=textwrap.indent(self._impact("l", "-_vm", record), " " * 12),
        )

    def clamp_flip(self, record: bool) -> str:
        """The naive rule: after the step, put x on the wall and flip y (impact time wrong by up to a step)."""
        return _CLAMP.format(
            imp_r=textwrap.indent(self._impact("r", "y", record), " " * 4),
            imp_l=textwrap.indent(self._impact("l", "-y", record), " " * 4),
        )


# Free flight with velocity y for time _tau. x <= wr and x >= wl hold before; the crossing time (wr - x)/y is on
# the straight segment, so the position stays C^1 up to the wall. Several impacts in one step are looped over.
# A position can only leave the gap through the impact path, so the violation counter is checked there.
_FLIGHT = """\
_tau = {tau}
_xn = x + y * _tau
if _xn <= wr and _xn >= wl:
    x = _xn
else:
    _it = 0
    while True:
        _xn = x + y * _tau
        if _xn > wr:
            _s = (wr - x) / y
{imp_r}
            y = -_e * y
            x = wr
            _tau = _tau - _s if _tau > _s else 0.0
        elif _xn < wl:
            _s = (wl - x) / y
{imp_l}
            y = -_e * y
            x = wl
            _tau = _tau - _s if _tau > _s else 0.0
        else:
            x = _xn
            break
        _it += 1
        if _it > 64:
            stuck += 1
            break
    if x > wr or x < wl:
        viol += 1
"""

# Euler-Maruyama with impacts: on the segment x moves with velocity u (y at the start of the step, or after the last
# impact), y = u + (fraction of the remaining step) * _inc. At a crossing the velocity reached so far is reset and the
# rest of the increment is applied after the impact.
_FLIGHT_EM = """\
_inc = {inc}
_tau = dt
_xn = x + y * _tau
if _xn <= wr and _xn >= wl:
    x = _xn
    y = y + _inc
else:
    _it = 0
    while True:
        _xn = x + y * _tau
        if _xn > wr:
            _s = (wr - x) / y
            _f = _s / _tau if _tau > 0.0 else 1.0
            _vm = y + _f * _inc
{imp_r}
            y = -_e * _vm
            _inc = _inc * (1.0 - _f)
            x = wr
            _tau = _tau - _s if _tau > _s else 0.0
        elif _xn < wl:
            _s = (wl - x) / y
            _f = _s / _tau if _tau > 0.0 else 1.0
            _vm = y + _f * _inc
{imp_l}
            y = -_e * _vm
            _inc = _inc * (1.0 - _f)
            x = wl
            _tau = _tau - _s if _tau > _s else 0.0
        else:
            x = _xn
            y = y + _inc
            break
        _it += 1
        if _it > 64:
            stuck += 1
            y = y + _inc
            break
    if x > wr or x < wl:
        viol += 1
"""

_CLAMP = """\
x = x + y * dt
if x > wr:
{imp_r}
    x = wr
    y = -_e * y
elif x < wl:
{imp_l}
    x = wl
    y = -_e * y
"""

_MODULE = '''\
# Generated by hybrid.stochastic._codegen (template {version}); scheme {scheme}; model {model}.
# Do not edit: the file name hashes this text, and numba caches the machine code next to it.
import math

import numba as nb
import numpy as np

from hybrid.stochastic._rng import next_normal

CACHE = {cache}
LANES = 8


@nb.njit(nogil=True, cache=CACHE)
def run_chunks(states, npaths, n_burn, n_samp, stride, dt, x0, y0, prm, rprm, wl, wr, zx, zk, zf,
               h_scale, hbins, g_bar, xlo, x_scale, nx, ylo, y_scale, ny, do_xy, v_scale, vbins,
               hist, xyh, vh, cnt, sm):
    """Run every chunk (row of ``states``) of ``npaths[k]`` paths; statistics per chunk (one row each).

    Serial and ``nogil``: the runner calls it from several threads on disjoint chunks (compiles in about half the
    time of a ``prange`` kernel, and the result does not depend on the number of threads either way).
    """
    nc = states.shape[0]
    sdt = math.sqrt(dt)
    hdt = 0.5 * dt
{unpack}
{preamble}
    for k in range(nc):
        s0 = states[k, 0]
        s1 = states[k, 1]
        s2 = states[k, 2]
        s3 = states[k, 3]
        n_samples = 0
        n_below = 0
        n_il = 0
        n_ir = 0
        h_over = 0
        xy_out = 0
        v_over = 0
        viol = 0
        stuck = 0
        nonfinite = 0
        h_under = 0
        v_under = 0
        bad_e = 0
        bad_v = 0.0
        bad_ev = 0.0
        s_h = 0.0
        s_x2 = 0.0
        s_y2 = 0.0
        s_iv = 0.0
        xs = np.empty(LANES)
        ys = np.empty(LANES)
{alloc}
        # paths run in groups of LANES interleaved lanes: their independent dependency chains overlap in the CPU
        for _g in range(0, npaths[k], LANES):
            nl = min(LANES, npaths[k] - _g)
            for _l in range(nl):
                x = x0
                y = y0
{init}
                xs[_l] = x
                ys[_l] = y
{store}
            _cs = 0
            for _n in range(n_burn + n_samp * stride):
                rec = _n >= n_burn
                for _l in range(nl):
                    x = xs[_l]
                    y = ys[_l]
{load}
                    xi, s0, s1, s2, s3 = next_normal(s0, s1, s2, s3, zx, zk, zf)
{step_rec}
                    xs[_l] = x
                    ys[_l] = y
{store_b}
                if not rec:
                    continue
                _cs += 1
                if _cs < stride:
                    continue
                _cs = 0
                for _l in range(nl):
                    x = xs[_l]
                    y = ys[_l]
                    yy = y * y
                    xx = x * x
                    H = 0.5 * yy + {potential}
                    s_h += H
                    s_x2 += xx
                    s_y2 += yy
                    n_samples += 1
                    if H < g_bar:
                        n_below += 1
                    # every index is provably in range: 0 <= hb <= hbins, and the last bin is closed on the right
                    hb = H * h_scale
                    if hb >= 0.0 and hb <= hbins:
                        hist[k, min(int(hb), hbins - 1)] += 1
                    elif hb < 0.0:
                        h_under += 1
                    else:
                        h_over += 1
                        if H != H:
                            nonfinite += 1
                if do_xy:
                    for _l in range(nl):
                        bx = (xs[_l] - xlo) * x_scale
                        by = (ys[_l] - ylo) * y_scale
                        if bx >= 0.0 and bx <= nx and by >= 0.0 and by <= ny:
                            xyh[k, min(int(by), ny - 1), min(int(bx), nx - 1)] += 1
                        else:
                            xy_out += 1
        cnt[k, 0] = n_samples
        cnt[k, 1] = n_below
        cnt[k, 2] = n_il
        cnt[k, 3] = n_ir
        cnt[k, 4] = h_over
        cnt[k, 5] = xy_out
        cnt[k, 6] = v_over
        cnt[k, 7] = viol
        cnt[k, 8] = stuck
        cnt[k, 9] = nonfinite
        cnt[k, 10] = h_under
        cnt[k, 11] = v_under
        cnt[k, 12] = bad_e
        sm[k, 0] = s_h
        sm[k, 1] = s_x2
        sm[k, 2] = s_y2
        sm[k, 3] = s_iv
        sm[k, 4] = bad_v
        sm[k, 5] = bad_ev


@nb.njit(cache=CACHE)
def integrate_normals(x0, y0, xis, dt, prm, rprm, wl, wr, bad):
    """Paths driven by given standard normals ``xis`` (paths, steps): final (x, y) per path, no statistics.

    ``bad`` (3 floats) receives the number of impacts with e outside (0, 1], the first such speed and e.
    """
    npath = xis.shape[0]
    nstep = xis.shape[1]
    out = np.empty((npath, 2))
    sdt = math.sqrt(dt)
    hdt = 0.5 * dt
    stuck = 0
    viol = 0
    bad_e = 0
    bad_v = 0.0
    bad_ev = 0.0
{unpack}
{preamble}
    for _path in range(npath):
        x = x0[_path]
        y = y0[_path]
{init_i}
        for _n in range(nstep):
            xi = xis[_path, _n]
{step_i}
        out[_path, 0] = x
        out[_path, 1] = y
    bad[0] = bad_e
    bad[1] = bad_v
    bad[2] = bad_ev
    return out


@nb.njit(cache=CACHE)
def record_paths(state, npath, nstep, every, dt, x0, y0, prm, rprm, wl, wr, zx, zk, zf, bad):
    """A few stored paths: (x, y) every ``every`` steps, drawing from one RNG stream ``state`` (updated).

    ``bad`` (3 floats) receives the number of impacts with e outside (0, 1], the first such speed and e.
    """
    nrec = nstep // every + 1
    out = np.empty((npath, nrec, 2))
    sdt = math.sqrt(dt)
    hdt = 0.5 * dt
    stuck = 0
    viol = 0
    bad_e = 0
    bad_v = 0.0
    bad_ev = 0.0
    s0 = state[0]
    s1 = state[1]
    s2 = state[2]
    s3 = state[3]
{unpack}
{preamble}
    for _path in range(npath):
        x = x0
        y = y0
{init_i}
        out[_path, 0, 0] = x
        out[_path, 0, 1] = y
        for _n in range(1, nrec * every - every + 1):
            xi, s0, s1, s2, s3 = next_normal(s0, s1, s2, s3, zx, zk, zf)
{step_i}
            if _n % every == 0:
                out[_path, _n // every, 0] = x
                out[_path, _n // every, 1] = y
    state[0] = s0
    state[1] = s1
    state[2] = s2
    state[3] = s3
    bad[0] = bad_e
    bad[1] = bad_v
    bad[2] = bad_ev
    return out
'''


@dataclass
class Kernel:
    """A loaded kernel module: ``run_chunks``, ``integrate_normals``, the parameter order and compile time."""

    module: types.ModuleType
    path: Path | None
    param_names: tuple[str, ...]
    law_values: tuple[float, ...]
    scheme: str
    source: str
    compile_time: float = float("nan")
    identity: dict = field(default_factory=dict)

    @property
    def run_chunks(self):
        return self.module.run_chunks

    @property
    def record_paths(self):
        return self.module.record_paths

    @property
    def integrate_normals(self):
        return self.module.integrate_normals


def _law_code(law) -> tuple[str, tuple[float, ...], object | None]:
    """Code for e(_v), the law's numbers as runtime values, and a user callable to njit (or None)."""
    try:
        expr = sp.sympify(law.expression(_V))
    except RestitutionError:
        fn = getattr(law, "callable", None)
        if fn is None:
            raise
        try:
            jitted = nb.njit(fn)
            val = float(jitted(1.0))
        except Exception as exc:  # numba's errors are many types; report them in one line
            raise RestitutionError(
                f"the custom restitution callable {law!r} cannot be compiled by numba "
                f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}); "
                "declare the law as a sympy expression of v, e.g. CustomRestitution('1/(1 + v/10)')"
            ) from exc
        if not 0.0 < val <= 1.0:
            raise RestitutionError(f"the custom restitution callable gives e(1) = {val!r}, outside (0, 1]") from None
        return "_user_law(_v)", (), jitted
    values: list[float] = []
    subs = {}
    for atom in sp.preorder_traversal(expr):
        if isinstance(atom, sp.Float) and atom not in subs:
            subs[atom] = real_symbol(f"_r{len(values)}")
            values.append(float(atom))
    unknown = {s.name for s in expr.free_symbols} - {"v"}
    if unknown:
        raise RestitutionError(f"restitution law {law!r} depends on {sorted(unknown)}; it may depend on v only")
    expr = expr.xreplace(subs).xreplace({_V: real_symbol("_v")})
    return f"({_Printer({'standard': 'python3'}).doprint(expr)})", tuple(values), None


def refuse_forced(model) -> None:
    """The oscillator kernels have no time: a forced model must go through its automaton (one-line ModelError)."""
    if getattr(model, "is_forced", False):
        raise ModelError(f"model {model.name!r} is forced (F = {model.forcing}): the oscillator kernels have no time; "
                         "run hybrid.stochastic.simulate_automaton(model.to_automaton(), ...) (phases=N for "
                         "Poincaré sections) or vibro mc, which does so")


def generate_source(model, scheme, cache: bool = True) -> tuple[str, tuple[float, ...], object | None]:
    """The kernel module source for ``model`` and ``scheme`` (a Scheme instance).

    Returns ``(source, law_values, user_law)``; ``user_law`` is a numba-compiled callable law or None.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> from hybrid.stochastic import SCHEMES
    >>> src, law_values, _ = generate_source(DuffingImpact(), SCHEMES["milstein"])
    >>> "def run_chunks" in src, law_values[0]
    (True, 0.4)
    """
    refuse_forced(model)
    if model.potential_expr is None:
        raise ModelError(
            f"sympy cannot integrate g = {model.g} in closed form, and the Monte Carlo kernel needs the potential G(x) "
            "for the energy H; declare a restoring force with an elementary antiderivative"
        )
    scheme.check(model)
    law_code, law_values, user_law = _law_code(model.restitution)
    names = tuple(model.params)
    em = Emitter(model, names, law_code)
    potential = em.code(model.potential_expr)
    init = scheme.init_code(em)
    step_free = scheme.step_code(em, record=False)
    step_rec = scheme.step_code(em, record=True)
    lane = tuple(scheme.lane_vars)
    unpack = "\n".join(f"_p{i} = prm[{i}]" for i in range(len(names)))
    unpack += "\n" + "\n".join(f"_r{i} = rprm[{i}]" for i in range(len(law_values)))
    ind = textwrap.indent
    src = _MODULE.format(
        version=TEMPLATE_VERSION, scheme=scheme.name, model=f"{model.name} {model.fingerprint()}",
        cache="True" if cache and user_law is None else "False",
        unpack=ind(unpack.strip(), " " * 4), preamble=ind("\n".join(dict.fromkeys(em.preamble)), " " * 4),
        init=ind(init or "pass", " " * 16), step_rec=ind(step_rec, " " * 20),
        alloc=ind("\n".join(f"ls{v} = np.empty(LANES)" for v in lane), " " * 8),
        load=ind("\n".join(f"{v} = ls{v}[_l]" for v in lane), " " * 20),
        store=ind("\n".join(f"ls{v}[_l] = {v}" for v in lane), " " * 16),
        store_b=ind("\n".join(f"ls{v}[_l] = {v}" for v in lane), " " * 20),

        potential=potential, init_i=ind(init or "pass", " " * 8), step_i=ind(step_free, " " * 12),
    )
    return src, law_values, user_law


def _feed(obj, parts: list, depth: int, seen: set) -> bool:
    """Append a stable description of ``obj`` to ``parts``; False when it holds something that cannot be described."""
    if depth > 8:
        return False
    if obj is None or isinstance(obj, (bool, int, str, bytes)):
        parts.append(repr(obj))
        return True
    if isinstance(obj, float):
        parts.append(float.hex(obj))
        return True
    if isinstance(obj, complex):
        parts.append(f"{obj.real.hex()}+{obj.imag.hex()}j")
        return True
    if isinstance(obj, np.generic):
        return _feed(obj.item(), parts, depth + 1, seen)
    if isinstance(obj, np.ndarray):  # numba freezes global arrays into the machine code
        parts.append(f"{obj.dtype.str}{obj.shape}{hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest()}")
        return True
    if isinstance(obj, tuple):
        parts.append(f"tuple{len(obj)}")
        return all(_feed(o, parts, depth + 1, seen) for o in obj)
    if isinstance(obj, types.ModuleType):
        parts.append(f"module {obj.__name__}")
        return True
    if isinstance(obj, types.BuiltinFunctionType):
        parts.append(f"builtin {getattr(obj, '__module__', '')}.{obj.__qualname__}")
        return True
    if isinstance(obj, types.CodeType):
        parts += [obj.co_code.hex(), repr(obj.co_names), repr(obj.co_varnames)]
        return all(_feed(c, parts, depth + 1, seen) for c in obj.co_consts)
    obj = getattr(obj, "py_func", obj)  # a numba dispatcher: its Python function
    if isinstance(obj, types.FunctionType):
        if id(obj) in seen:
            parts.append(f"recursive {obj.__qualname__}")
            return True
        seen.add(id(obj))
        if not _feed(obj.__code__, parts, depth + 1, seen) or not _feed(obj.__defaults__, parts, depth + 1, seen):
            return False
        for cell in obj.__closure__ or ():
            if not _feed(cell.cell_contents, parts, depth + 1, seen):
                return False
        names, stack = set(), [obj.__code__]
        while stack:  # global names used by the function and its nested code (comprehensions, lambdas)
            code = stack.pop()
            names.update(code.co_names)
            stack += [c for c in code.co_consts if isinstance(c, types.CodeType)]
        for name in sorted(names):
            if name in obj.__globals__:
                parts.append(f"global {name}")
                if not _feed(obj.__globals__[name], parts, depth + 1, seen):
                    return False
        return True
    return False


def callable_digest(fn) -> str | None:
    """A hash of a restitution callable: bytecode, constants, defaults, closure and the globals it reads.

    None when it reads something that cannot be hashed reliably (an arbitrary object whose state may change):
    such a law cannot identify a checkpoint.

    Examples
    --------
    >>> callable_digest(lambda v: 0.9) == callable_digest(lambda v: 0.9), callable_digest(lambda v: 0.8) is None
    (True, False)
    """
    parts: list = []
    if not _feed(fn, parts, 0, set()):
        return None
    return hashlib.sha256("\x00".join(parts).encode()).hexdigest()[:32]


_LOADED: dict[str, types.ModuleType] = {}

COMPILE_LOG = logging.getLogger("hybrid.stochastic.compile")
"""An INFO record each time a Monte Carlo kernel is compiled rather than loaded from numba's disk cache, before the
compilation starts (``extra``: ``kernel``, e.g. ``duffing/milstein``, and ``estimate_s``). The library prints nothing
by itself; the command line turns the record into one line on stderr, so a first run's wait is not a silent one."""

COMPILE_ESTIMATE_S = {"vibro_mc": 10, "vibro_auto": 20}
"""About how long a cold compile takes, by kernel family (measured on 2 busy cores: oscillator ~7-10 s, automaton
~15-20 s); only said to the user. The CUDA kernels (``vibro_cuda``) are not measured here: no estimate is said."""


def _label(name: str) -> str:
    """``duffing/milstein``-like words for a kernel module without a model name: the family and the scheme."""
    parts = name.split("_")
    if name.startswith("vibro_auto_") and len(parts) > 3:
        return f"automaton/{'_'.join(parts[2:-1])}"
    return name


def _announce_compiles(module, label: str) -> None:
    """Log one :data:`COMPILE_LOG` record when one of ``module``'s kernels misses numba's cache (it is then compiled).

    numba asks its cache (``load_overload``) just before it compiles a signature; a miss means a compile follows.
    Only the module's own dispatchers are watched (helpers imported from elsewhere keep theirs).
    """
    announced = []
    estimate = next((s for family, s in COMPILE_ESTIMATE_S.items() if module.__name__.startswith(family + "_")), None)
    when = "first run only" if estimate is None else f"first run only, ~{estimate} s"
    for obj in list(vars(module).values()):
        cache = getattr(obj, "_cache", None)
        load = getattr(cache, "load_overload", None)
        if load is None or getattr(getattr(obj, "py_func", None), "__module__", None) != module.__name__:
            continue

        def announcing(sig, target_context, _load=load):
            result = _load(sig, target_context)
            if result is None and not announced:
                announced.append(True)
                COMPILE_LOG.info("compiling the Monte Carlo kernel for %s (%s)", label, when,
                                 extra={"kernel": label, "estimate_s": estimate})
            return result

        cache.load_overload = announcing
_USER_LAWS: dict[int, object] = {}  # keeps user callables alive, so the id in a kernel name is never reused
_IMPORTED = re.compile(r"^\s*(?:from|import)\s+(hybrid(?:\.\w+)+)", re.MULTILINE)


@functools.cache
def _module_source_hash(module_name: str) -> str:
    return hashlib.sha256(inspect.getsource(importlib.import_module(module_name)).encode()).hexdigest()


def dependency_hash(src: str) -> str:
    """Hash of the source of every project module that the generated source ``src`` imports (the random-number
    generator, shared helpers).

    numba's disk cache checks the generated file only, not what it imports, so a kernel's cache key must carry
    these too: a changed generator must not load a kernel compiled with the old one.

    Examples
    --------
    >>> dependency_hash("from hybrid.stochastic._rng import next_normal") != dependency_hash("import math")
    True
    """
    parts = [name + _module_source_hash(name) for name in sorted(set(_IMPORTED.findall(src)))]
    return hashlib.sha256("\x00".join(parts).encode()).hexdigest()[:16]


def _module_name(model, scheme, src: str) -> str:
    h = hashlib.sha256((src + dependency_hash(src) + nb.__version__ + np.__version__).encode()).hexdigest()[:16]
    return f"vibro_mc_{scheme.name}_{model.fingerprint()}_{h}"


def load_source(name: str, src: str, user_law=None, label: str | None = None) -> tuple[types.ModuleType, Path | None]:
    """Import generated source ``src`` as module ``name`` from the cache directory (written atomically once).

    A user-callable restitution law cannot be cached on disk: that module is built in memory. ``label`` names the
    kernel in the :data:`COMPILE_LOG` record of a compile (default: from ``name``).
    """
    if name in _LOADED:
        return _LOADED[name], getattr(_LOADED[name], "__file__", None)
    if user_law is not None:
        module = types.ModuleType(name)
        module.__dict__["_user_law"] = user_law
        exec(compile(src, f"<{name}>", "exec"), module.__dict__)
        _announce_compiles(module, label or _label(name))
        _LOADED[name] = module
        return module, None
    directory = cache_dir()
    try:
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"{name}.py"
        try:
            current = path.read_text() if path.exists() else None
        except (OSError, ValueError):  # unreadable or not UTF-8: a corrupt entry is rewritten
            current = None
        if current != src:
            tmp = path.with_suffix(f".tmp{os.getpid()}")
            tmp.write_text(src)
            os.replace(tmp, path)
    except OSError as exc:
        raise ModelError(
            f"cannot write the kernel cache in {directory} ({exc}); set VIBRO_CACHE_DIR to a writable directory"
        ) from exc
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    _rebuild_on_corrupt_cache(module)
    _announce_compiles(module, label or _label(name))
    _LOADED[name] = module
    return module, path


def _rebuild_on_corrupt_cache(module) -> None:
    """Make a corrupt numba cache entry (index or machine code) a cache miss: compiled again and overwritten."""
    for fname in ("run_chunks", "integrate_normals", "record_paths"):
        cache = getattr(getattr(module, fname, None), "_cache", None)
        load = getattr(cache, "load_overload", None)
        if load is None or not hasattr(cache, "flush"):
            continue

        def safe(sig, target_context, _load=load, _cache=cache):
            try:
                return _load(sig, target_context)
            except Exception:  # unpickling garbage raises many types
                _cache.flush()  # an empty index: numba compiles and saves a fresh entry
                return None

        cache.load_overload = safe


def build_kernel(model, scheme, cache: bool = True, warm: bool = True) -> Kernel:
    """Generate, load and compile (or load from the numba cache) the kernel for ``model`` and ``scheme``.

    ``Kernel.compile_time`` is the wall time of this call (generation, import, compile or cache load).
    ``warm=False`` skips compiling ``run_chunks`` (numba compiles lazily at the first call).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> from hybrid.stochastic import SCHEMES
    >>> k = build_kernel(DuffingImpact(), SCHEMES["splitting"])  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    src, law_values, user_law = generate_source(model, scheme, cache)
    name = _module_name(model, scheme, src)
    if user_law is not None:
        # the source only calls _user_law(_v): the in-memory module belongs to this very callable
        fn = model.restitution.callable
        _USER_LAWS.setdefault(id(fn), fn)
        name += f"_law{id(fn):x}"
    module, path = load_source(name, src, user_law, label=f"{model.name}/{scheme.name}")
    # what identifies the computation (for checkpoints): the source (not the numba version: a resume after an
    # upgrade is allowed), the law's numbers in full precision, and a callable law's code
    identity = {
        "kernel": hashlib.sha256((src + dependency_hash(src)).encode()).hexdigest()[:32],
        "law": [float.hex(v) for v in law_values] if user_law is None
        else callable_digest(model.restitution.callable),
    }
    kern = Kernel(module, path, tuple(model.params), law_values, scheme.name, src, identity=identity)
    if warm:
        warm_up(kern, model)
    kern.compile_time = time.perf_counter() - t0
    return kern


def warm_up(kern: Kernel, model) -> None:
    """Compile (or load) ``run_chunks`` for the argument types the runner uses, by a call on zero chunks."""
    zx, zk, zf = _rng.ziggurat_tables()
    prm = np.array([model.params[k] for k in kern.param_names], dtype=float)
    rprm = np.array(kern.law_values, dtype=float)
    z2 = np.zeros((0, 1), dtype=np.int64)
    kern.run_chunks(
        np.zeros((0, 4), np.uint64), np.zeros(0, np.int64), 0, 0, 1, 1e-3, 0.0, 0.0, prm, rprm, -1.0, 1.0,
        zx, zk, zf, 1.0, 1, 1.0, 0.0, 1.0, 1, 0.0, 1.0, 1, False, 1.0, 1,
        z2, np.zeros((0, 1, 1), np.int64), z2, np.zeros((0, len(COUNTS)), np.int64), np.zeros((0, len(SUMS))),
    )
