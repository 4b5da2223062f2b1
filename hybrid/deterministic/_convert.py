"""Translate sympy expressions into heyoka expressions and into fast numpy/math callables.

heyoka's ``pow`` has a NaN derivative at a zero base, so integer powers are expanded into products (and
negative integer powers into a quotient of products). Only the functions listed in ``_HEYOKA_FUNCTIONS`` are
translated; anything else raises :class:`~hybrid.errors.ModelError` and names the scipy backend as the fallback.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Mapping, Sequence

import numpy as np
import sympy as sp

from hybrid.automaton import HybridAutomaton
from hybrid.errors import ModelError


def _heyoka_functions():
    import heyoka as hy

    table = {
        sp.sin: hy.sin, sp.cos: hy.cos, sp.tan: hy.tan, sp.exp: hy.exp, sp.log: hy.log, sp.tanh: hy.tanh,
        sp.sinh: hy.sinh, sp.cosh: hy.cosh, sp.atan: hy.atan, sp.asin: hy.asin, sp.acos: hy.acos, sp.erf: hy.erf,
    }
    return table


def _int_power(base, n: int):
    """base**n for an integer n >= 1 by repeated squaring, as a product tree (no pow node)."""
    result = None
    square = base
    while n:
        if n & 1:
            result = square if result is None else result * square
        n >>= 1
        if n:
            square = square * square
    return result


def to_heyoka(expr: sp.Expr, symbols: Mapping[str, object]):
    """Convert a sympy expression into a heyoka expression.

    Parameters
    ----------
    expr : sympy expression
    symbols : mapping of symbol name to heyoka expression
        Usually state names to ``heyoka.make_vars(...)`` variables and parameter names to ``heyoka.par[i]``.

    Returns
    -------
    heyoka.expression

    Raises
    ------
    ModelError
        On a symbol missing from ``symbols`` or a function heyoka cannot differentiate here (Abs, Piecewise, ...).

    Examples
    --------
    >>> import heyoka as hy, sympy as sp
    >>> x = sp.Symbol("x")
    >>> hx = hy.make_vars("x")
    >>> str(to_heyoka(x**3 + 2, {"x": hx}))
    '(2.0000000000000000 + (x * (x * x)))'
    """
    import heyoka as hy

    functions = _heyoka_functions()

    def conv(e):
        if isinstance(e, sp.Symbol):
            if e.name not in symbols:
                raise ModelError(f"symbol {e.name!r} has no heyoka counterpart; known: {sorted(symbols)}")
            return symbols[e.name]
        if e.is_Number:
            if not e.is_real:
                raise ModelError(f"complex constant {e} in an expression for heyoka")
            return hy.expression(float(e))
        if e in (sp.pi, sp.E):
            return hy.expression(float(e))
        if isinstance(e, sp.Add):
            terms = [conv(a) for a in e.args]
            return hy.sum(terms) if len(terms) > 1 else terms[0]
        if isinstance(e, sp.Mul):
            factors = [conv(a) for a in e.args]
            out = factors[0]
            for f in factors[1:]:
                out = out * f
            return out
        if isinstance(e, sp.Pow):
            base, exponent = e.args
            if exponent.is_Integer:
                n = int(exponent)
                if n == 0:
                    return hy.expression(1.0)
                power = _int_power(conv(base), abs(n))
                return power if n > 0 else hy.expression(1.0) / power
            if exponent == sp.Rational(1, 2):
                return hy.sqrt(conv(base))
            if exponent == sp.Rational(-1, 2):
                return hy.expression(1.0) / hy.sqrt(conv(base))
            return conv(base) ** conv(exponent)
        for sym_fn, hy_fn in functions.items():
            if isinstance(e, sym_fn):
                return hy_fn(conv(e.args[0]))
        raise ModelError(
            f"cannot translate {type(e).__name__} ({e}) into heyoka; rewrite it with smooth functions "
            "or use backend='scipy'"
        )

    return conv(sp.sympify(expr))


def to_callable(exprs: Sequence[sp.Expr], states: Sequence[sp.Symbol], params: Sequence[str]):
    """A fast callable ``f(state_sequence, param_values) -> tuple`` for scalar evaluation of ``exprs``.

    Uses the ``math`` module (quicker than numpy on scalars) and falls back to numpy for functions math lacks.

    Examples
    --------
    >>> import sympy as sp
    >>> x, k = sp.symbols("x k")
    >>> f = to_callable([-k * x, x**2], [x], ["k"])
    >>> f([2.0], [3.0])
    (-6.0, 4.0)
    """
    return _to_callable(tuple(sp.sympify(e) for e in exprs), tuple(states), tuple(params))


@functools.lru_cache(maxsize=256)
def _to_callable(exprs: tuple, states: tuple, params: tuple):
    """Cached worker of :func:`to_callable`."""
    args = [sp.Symbol(s.name) for s in states] + [sp.Symbol(p) for p in params]
    plain = [sp.sympify(e).xreplace({s: sp.Symbol(s.name) for s in sp.sympify(e).free_symbols}) for e in exprs]
    try:
        fn = sp.lambdify(args, plain, modules=["math"], cse=True)
        n_state = len(states)
        probe = [0.5] * (n_state + len(params))
        fn(*probe)
    except (NameError, TypeError, KeyError):
        fn = sp.lambdify(args, plain, modules=["numpy"], cse=True)
    except (ValueError, ZeroDivisionError, OverflowError):
        pass  # the probe point is outside the domain; the math version is still fine

    def call(state, values):
        return tuple(float(v) for v in fn(*state, *values))

    return call


def automaton_fingerprint(automaton: HybridAutomaton) -> str:
    """Hash of the automaton's structure (states, parameter names, flows, guards, directions), not its values.

    Two automata with the same fingerprint compile to the same integrator; parameter values and resets may differ.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> A = DuffingImpact().to_automaton()
    >>> B = DuffingImpact(delta=2.0).to_automaton()
    >>> automaton_fingerprint(A) == automaton_fingerprint(B)
    True
    """
    parts = [",".join(s.name for s in automaton.states), ",".join(automaton.parameters)]
    for m in automaton.modes:
        parts.append(f"mode {m.name}: " + ";".join(sp.srepr(f) for f in m.flow))
    for t in automaton.transitions:
        parts.append(f"transition {t.name} {t.source}->{t.target} {t.direction}: {sp.srepr(t.guard)}")
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:20]


def finite_array(values, what: str) -> np.ndarray:
    """``values`` as a 1-D float array, with a clear error when it is not numeric or not finite."""
    from hybrid.errors import ParameterError

    try:
        arr = np.atleast_1d(np.asarray(values, dtype=float)).ravel()
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{what} must be numbers, got {values!r}") from exc
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{what} must be finite, got {values!r}")
    return arr
