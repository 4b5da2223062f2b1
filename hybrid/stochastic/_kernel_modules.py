"""The generated kernel modules: their printer, their cache on disk, loading, identity and compile notices.

This is the shared infrastructure of the one Monte Carlo code generator, :mod:`._auto_codegen` (CPU) and its CUDA
target :mod:`._auto_cuda`. The kernels are generated from a model's hybrid automaton and written to
``$VIBRO_CACHE_DIR`` (default ``~/.cache/vibro-impact``) under a name that hashes the source; numba's ``cache=True``
keeps the machine code next to it, so a second process loads the kernel instead of compiling it
(:func:`load_source`). A restitution law given as a Python callable is compiled by numba (:func:`_law_code`) and
bound in the kernel module (:func:`load_source`).
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
import types
from pathlib import Path

import numba as nb
import numpy as np
import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from hybrid.automaton import real_symbol
from hybrid.errors import ModelError, RestitutionError

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
    """``simulate_ensemble`` has no time: a forced model must go through its automaton (one-line ModelError)."""
    if getattr(model, "is_forced", False):
        raise ModelError(f"model {model.name!r} is forced (F = {model.forcing}): simulate_ensemble has no time; "
                         "run hybrid.stochastic.simulate_automaton(model.to_automaton(), ...) (phases=N for "
                         "Poincaré sections) or vibro mc, which does so")


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

COMPILE_ESTIMATE_S = {"vibro_auto": 8, "vibro_auto_cuda": None}
"""About how long a cold compile takes, by kernel family, the module name's prefix (the longest that matches): the
CPU kernels of the automaton generator take 5 - 9 CPU s on 2 cores (medians 6.0 - 8.3 in the last measurement,
docs/results/compile-time.md); only said to the user. Compiles of the CUDA kernels have not been measured (None: no
figure is claimed)."""


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
    families = [family for family in COMPILE_ESTIMATE_S if module.__name__.startswith(family + "_")]
    estimate = COMPILE_ESTIMATE_S[max(families, key=len)] if families else None
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


def load_source(name: str, src: str, user_law=None, label: str | None = None) -> tuple[types.ModuleType, Path | None]:
    """Import generated source ``src`` as module ``name`` from the cache directory (written atomically once).

    ``user_law``: a restitution law given as a Python callable, compiled by numba, which the module binds as
    :data:`USER_LAW`. Where ``name`` carries the law's :func:`callable_digest` (``..._law<digest>``), the kernel is
    cached on disk like any other: the digest covers the law's code, constants and the globals it reads, so another
    law gets another name. numba's cache entry refers to the module that defined the law, so another process loads
    it only where that module can be imported (a script's ``__main__`` always can); elsewhere the entry is compiled
    again. A law that reads an object that cannot be hashed has no digest: its module is built in memory and compiled
    in every process. ``label`` names the kernel in the :data:`COMPILE_LOG` record of a compile
    (default: from ``name``).
    """
    if name in _LOADED:
        return _LOADED[name], getattr(_LOADED[name], "__file__", None)
    bound = {}
    if user_law is not None:
        digest = callable_digest(getattr(user_law, "py_func", user_law))
        if digest is None or not name.endswith(f"_law{digest}"):
            module = types.ModuleType(name)
            module.__dict__[USER_LAW] = user_law
            exec(compile(src, f"<{name}>", "exec"), module.__dict__)
            _announce_compiles(module, label or _label(name))
            _LOADED[name] = module
            return module, None
        # the source was generated without numba's disk cache (CACHE = False) for the in-memory case
        src = src.replace("\nCACHE = False\n", "\nCACHE = True\n", 1)
        bound[USER_LAW] = user_law
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
    module.__dict__.update(bound)  # the callable law, before the module's functions are defined
    sys.modules[name] = module
    spec.loader.exec_module(module)
    _rebuild_on_corrupt_cache(module)
    _announce_compiles(module, label or _label(name))
    _LOADED[name] = module
    return module, path


def _rebuild_on_corrupt_cache(module) -> None:
    """Make a corrupt numba cache entry (index or machine code) a cache miss: compiled again and overwritten."""
    for obj in list(vars(module).values()):  # every kernel function of the module, not its imported helpers
        if getattr(getattr(obj, "py_func", None), "__module__", None) != module.__name__:
            continue
        cache = getattr(obj, "_cache", None)
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
