"""A hybrid automaton declared as plain data with sympy expressions.

A :class:`HybridAutomaton` holds state variables, named parameters with defaults, modes with flows (and optional
noise coefficients) and transitions. A transition fires when its guard expression crosses zero in the declared
direction; it then maps the state through its reset and switches mode. Simulators (``hybrid.deterministic``,
``hybrid.stochastic``) consume this data; nothing here integrates anything.
"""

from __future__ import annotations

import tokenize
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import sympy as sp

from .errors import ModelError, ParameterError

ResetMap = tuple[sp.Expr, ...] | Callable


def real_symbol(name: str) -> sp.Symbol:
    """The canonical symbol for ``name``: every expression in this package uses real symbols.

    Examples
    --------
    >>> real_symbol("x").is_real
    True
    """
    return sp.Symbol(name, real=True)


NUMPY_FUNCTIONS = frozenset({
    "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh",
    "exp", "log", "Abs", "sign", "Min", "Max", "Piecewise", "Heaviside", "floor", "ceiling", "re", "im",
})
"""sympy functions that numpy evaluates alone (lambdify's numpy printer); any other (erf, gamma, Bessel ...) needs
scipy.special."""


def lambdify_numeric(args, expr, **kwargs):
    """``sympy.lambdify`` for arrays: numpy alone where it suffices, scipy (its special functions) only where needed.

    Start-up matters on the command line: lambdify's ``"numpy"`` runs ``from numpy import *``, which loads numpy's
    lazy submodules (f2py, testing, random, ma: about 0.1 s), and ``"scipy"`` imports scipy.special (0.1-0.2 s).
    Passing the numpy module itself prints the same code without either.

    Parameters
    ----------
    args : sequence of sympy.Symbol
        The function's arguments, in order.
    expr : sympy expression, or a list or tuple of them
        What it evaluates.
    **kwargs
        Passed to ``sympy.lambdify``.

    Returns
    -------
    callable
        A function of ``args`` that takes arrays.

    Examples
    --------
    >>> x = real_symbol("x")
    >>> float(lambdify_numeric([x], sp.sin(x) + x**3)(1.0)) == float(sp.sin(1) + 1)
    True
    >>> round(float(lambdify_numeric([x], sp.erf(x))(1.0)), 6)
    0.842701
    """
    import numpy as np

    exprs = expr if isinstance(expr, (list, tuple)) else [expr]
    names = {type(f).__name__ for e in exprs for f in sp.sympify(e).atoms(sp.Function)}
    modules = [np] if names <= NUMPY_FUNCTIONS else ["scipy", "numpy"]
    return sp.lambdify(args, expr, modules=modules, **kwargs)


def canonical(expr: sp.Expr) -> sp.Expr:
    """Replace every free symbol by the real symbol of the same name, so that symbols compare by name."""
    return expr.xreplace({s: real_symbol(s.name) for s in expr.free_symbols if isinstance(s, sp.Symbol)})


def _as_expr(value, where: str) -> sp.Expr:
    try:
        expr = sp.sympify(value, locals=_LOCALS) if isinstance(value, str) else sp.sympify(value)
    except Exception as exc:  # sympify evaluates the text: any error is a bad expression, not a crash
        cause = getattr(exc, "base_exc", None) or exc
        reason = "invalid syntax" if isinstance(cause, (SyntaxError, tokenize.TokenError)) else type(cause).__name__
        raise ModelError(f"{where}: cannot read {value!r} as an expression ({reason}); write it in Python syntax "
                         "with the state and parameter names, e.g. 'a*x + b*x**3' or '1/(1 + v)'") from exc
    if not isinstance(expr, sp.Expr):
        raise ModelError(f"{where}: {value!r} is not an algebraic expression")
    if expr.has(sp.zoo, sp.nan, sp.I):
        raise ModelError(f"{where}: {value!r} is not a finite real expression (it contains {expr}); "
                         "use real, finite terms")
    _refuse_undefined_functions(expr, where)
    return canonical(expr)


def _refuse_undefined_functions(expr, where: str) -> None:
    """An undeclared name called as a function, q(x), is no symbol: refuse it here, not as a NameError at run time."""
    from sympy.core.function import AppliedUndef

    calls = sorted({str(f.func) for f in expr.atoms(AppliedUndef)})
    if calls:
        raise ModelError(f"{where} calls {', '.join(f'{c}(...)' for c in calls)}, which is no known function; use "
                         "sympy's functions (sqrt, exp, sin, Abs, sign, ...) or declare a parameter and multiply by it")


class _RealSymbols(dict):
    """sympify locals that turn every unknown name into a real symbol (keeps functions such as sqrt, Abs)."""

    def __missing__(self, key):
        if hasattr(sp, key) and key not in ("E", "I", "S", "N", "O", "Q", "beta", "gamma", "zeta", "pi"):
            raise KeyError(key)
        return real_symbol(key)


_LOCALS = _RealSymbols()


@dataclass(frozen=True)
class Mode:
    """A continuous mode: ``d state / dt = flow`` (plus ``noise`` times white noise, if given).

    Parameters
    ----------
    name : str
        Mode name, unique within the automaton.
    flow : sequence of sympy expressions
        Time derivative of each state variable, in the automaton's state order.
    noise : sequence, optional
        Per state variable, the coefficient of one white noise (a sequence of expressions), or a row of
        coefficients of m independent white noises (a sequence of m-tuples: the n x m noise matrix). Zero where
        absent. ``hybrid.stochastic.simulate_automaton`` reads it as Stratonovich (physical) noise by default.

    Examples
    --------
    >>> import sympy as sp
    >>> x, y = sp.symbols("x y")
    >>> Mode("free", (y, -x)).name
    'free'
    """

    name: str
    flow: tuple[sp.Expr, ...]
    noise: tuple[sp.Expr, ...] | None = None

    def __post_init__(self):
        object.__setattr__(self, "flow", tuple(_as_expr(f, f"flow of mode {self.name!r}") for f in self.flow))
        if self.noise is not None:
            def entry(f):
                if isinstance(f, (tuple, list)):
                    return tuple(_as_expr(v, f"noise of mode {self.name!r}") for v in f)
                return _as_expr(f, f"noise of mode {self.name!r}")

            object.__setattr__(self, "noise", tuple(entry(f) for f in self.noise))


@dataclass(frozen=True)
class Transition:
    """A guarded jump between modes.

    Parameters
    ----------
    name : str
        Transition name (used in impact logs).
    source, target : str
        Mode names.
    guard : sympy expression
        The transition fires when ``guard`` crosses zero.
    direction : int
        +1: only upward crossings (guard goes from negative to positive); -1: only downward; 0: both.
    reset : tuple of sympy expressions or callable
        New state, as expressions of the pre-jump state and parameters, or a callable
        ``reset(state: numpy array, params: dict) -> numpy array``.
    priority : int
        When several guards fire at the same instant, the lowest priority number wins.
    check : sympy relational or boolean, optional
        A condition on the pre-jump state that must hold when the transition fires (for an impact, the
        restitution coefficient in (0, 1]). Monte Carlo counts the firings where it fails (``bad_reset``) and
        warns; the oscillator front end refuses the run.

    Examples
    --------
    >>> import sympy as sp
    >>> x, y = sp.symbols("x y")
    >>> t = Transition("floor", "air", "air", guard=-x, direction=1, reset=(x, -y / 2))
    >>> t.direction
    1
    """

    name: str
    source: str
    target: str
    guard: sp.Expr
    direction: int = 0
    reset: ResetMap = ()
    priority: int = 0
    check: object = None

    def __post_init__(self):
        object.__setattr__(self, "guard", _as_expr(self.guard, f"guard of transition {self.name!r}"))
        if self.check is not None:
            check = sp.sympify(self.check)
            if not isinstance(check, (sp.logic.boolalg.Boolean, sp.core.relational.Relational)):
                raise ModelError(f"transition {self.name!r}: check must be a condition (e.g. e <= 1), got {check!r}")
            object.__setattr__(self, "check", canonical(check))
        if self.direction not in (-1, 0, 1):
            raise ModelError(
                f"transition {self.name!r}: direction must be -1, 0 or +1, got {self.direction!r}"
            )
        if not callable(self.reset):
            object.__setattr__(
                self, "reset", tuple(_as_expr(r, f"reset of transition {self.name!r}") for r in self.reset)
            )

    @property
    def symbolic_reset(self) -> bool:
        """True when the reset is a tuple of sympy expressions (it can be compiled)."""
        return not callable(self.reset)


@dataclass(frozen=True)
class HybridAutomaton:
    """Hybrid automaton: states, parameters, modes with flows, guarded transitions with resets.

    Parameters
    ----------
    states : sequence of sympy symbols
        State variables, in order.
    parameters : mapping of str to float
        Named parameters with their default values. Expressions may use them as symbols of the same name.
    modes : sequence of Mode
    transitions : sequence of Transition
    initial_mode : str, optional
        Defaults to the first mode.
    observables : mapping of str to sympy expression, optional
        Quantities logged before and after each jump (for example the energy ``H``).
    positive, nonnegative : sequence of str, optional
        Parameters that must be > 0 (a gap, a mass) or >= 0 (a damping, a noise temperature); defaults and every
        override (:meth:`resolve_parameters`) are checked, so a bad value is refused by name before anything runs.

    Raises
    ------
    ModelError
        On unknown symbols, duplicate names, unknown modes, or a reset that does not map every state.

    Examples
    --------
    A bouncing ball over a floor at x = 0 with restitution r:

    >>> import sympy as sp
    >>> x, v = sp.symbols("x v")
    >>> ball = HybridAutomaton(
    ...     states=(x, v), parameters={"g": 9.81, "r": 0.8},
    ...     modes=[Mode("air", (v, -sp.Symbol("g")))],
    ...     transitions=[Transition("floor", "air", "air", guard=x, direction=-1,
    ...                             reset=(x, -sp.Symbol("r") * v))])
    >>> ball.mode("air").flow[1]
    -g
    """

    states: tuple[sp.Symbol, ...]
    parameters: Mapping[str, float]
    modes: tuple[Mode, ...]
    transitions: tuple[Transition, ...] = ()
    initial_mode: str | None = None
    observables: Mapping[str, sp.Expr] = field(default_factory=dict)
    positive: tuple[str, ...] = ()
    nonnegative: tuple[str, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "positive", tuple(self.positive))
        object.__setattr__(self, "nonnegative", tuple(self.nonnegative))
        object.__setattr__(self, "states", tuple(canonical(sp.sympify(s)) for s in self.states))
        object.__setattr__(self, "modes", tuple(self.modes))
        object.__setattr__(self, "transitions", tuple(self.transitions))
        object.__setattr__(self, "parameters", MappingProxyType({k: float(v) for k, v in self.parameters.items()}))
        object.__setattr__(
            self,
            "observables",
            MappingProxyType({k: _as_expr(v, f"observable {k!r}") for k, v in self.observables.items()}),
        )
        if self.initial_mode is None:
            if not self.modes:
                raise ModelError("an automaton needs at least one mode")
            object.__setattr__(self, "initial_mode", self.modes[0].name)
        self.validate()

    # ------------------------------------------------------------------ validation
    def validate(self) -> None:
        """Check names, symbols, dimensions; raise :class:`ModelError` with the first problem found."""
        if len(self.states) == 0:
            raise ModelError("an automaton needs at least one state variable")
        for s in self.states:
            if not isinstance(s, sp.Symbol):
                raise ModelError(f"state variables must be sympy Symbols, got {s!r}")
        names = [s.name for s in self.states]
        if len(set(names)) != len(names):
            raise ModelError(f"duplicate state variable names: {names}")
        clash = set(names) & set(self.parameters)
        if clash:
            raise ModelError(f"names used both as state and parameter: {sorted(clash)}")
        mode_names = [m.name for m in self.modes]
        if len(set(mode_names)) != len(mode_names):
            raise ModelError(f"duplicate mode names: {mode_names}")
        if self.initial_mode not in mode_names:
            raise ModelError(f"initial mode {self.initial_mode!r} is not one of {mode_names}")
        if "t" in names or "t" in self.parameters:
            raise ModelError("the name 't' is reserved for time; rename that state or parameter")
        known = set(names) | set(self.parameters) | {"t"}  # t: time, for forcing and moving barriers
        n = len(self.states)

        def check(expr: sp.Expr, where: str) -> None:
            _refuse_undefined_functions(expr, where)
            unknown = {str(s) for s in expr.free_symbols} - known
            if unknown:
                raise ModelError(
                    f"{where} uses unknown symbols {sorted(unknown)}; declare them as states {names} "
                    f"or parameters {sorted(self.parameters)}"
                )

        for m in self.modes:
            if len(m.flow) != n:
                raise ModelError(f"mode {m.name!r} has {len(m.flow)} flow components for {n} states {names}")
            for f in m.flow:
                check(f, f"flow of mode {m.name!r}")
            if m.noise is not None:
                if len(m.noise) != n:
                    raise ModelError(f"mode {m.name!r} has {len(m.noise)} noise components for {n} states")
                for f in m.noise:
                    for v in (f if isinstance(f, tuple) else (f,)):
                        check(v, f"noise of mode {m.name!r}")
        tnames = [t.name for t in self.transitions]
        if len(set(tnames)) != len(tnames):
            raise ModelError(f"duplicate transition names: {tnames}")
        for t in self.transitions:
            for end in (t.source, t.target):
                if end not in mode_names:
                    raise ModelError(f"transition {t.name!r} refers to unknown mode {end!r}; modes: {mode_names}")
            check(t.guard, f"guard of transition {t.name!r}")
            if t.check is not None:
                check(t.check, f"check of transition {t.name!r}")
            if t.symbolic_reset:
                if len(t.reset) != n:
                    raise ModelError(
                        f"reset of transition {t.name!r} gives {len(t.reset)} values for {n} states {names}; "
                        "a reset must map every state variable (repeat a state to keep it)"
                    )
                for r in t.reset:
                    check(r, f"reset of transition {t.name!r}")
        for k, v in self.observables.items():
            check(v, f"observable {k!r}")
        undeclared = sorted(set(self.positive + self.nonnegative) - set(self.parameters))
        if undeclared:
            raise ModelError(f"positive/nonnegative name {undeclared}, which are not parameters "
                             f"{sorted(self.parameters)}")
        self._check_signs(self.parameters)

    def _check_signs(self, values: Mapping[str, float]) -> None:
        """Refuse a declared-positive parameter <= 0 or a declared-nonnegative one < 0 (NaN included)."""
        for k in self.positive:
            if not values[k] > 0:
                raise ParameterError(f"{k}={values[k]:g} must be > 0 (declared positive by the automaton); give a "
                                     "positive value")
        for k in self.nonnegative:
            if not values[k] >= 0:
                raise ParameterError(f"{k}={values[k]:g} must be >= 0 (declared nonnegative by the automaton); give "
                                     "a value >= 0")

    # ------------------------------------------------------------------ access
    def mode(self, name: str) -> Mode:
        """Return the mode called ``name``."""
        for m in self.modes:
            if m.name == name:
                return m
        raise ModelError(f"unknown mode {name!r}; modes: {[m.name for m in self.modes]}")

    def transitions_from(self, mode: str) -> list[Transition]:
        """Transitions leaving ``mode``, sorted by priority."""
        return sorted((t for t in self.transitions if t.source == mode), key=lambda t: t.priority)

    @property
    def parameter_symbols(self) -> tuple[sp.Symbol, ...]:
        """Parameter symbols in declaration order."""
        return tuple(real_symbol(k) for k in self.parameters)

    def resolve_parameters(self, overrides: Mapping[str, float] | None = None) -> dict[str, float]:
        """Defaults updated with ``overrides``; unknown names raise :class:`ModelError`.

        Examples
        --------
        >>> import sympy as sp
        >>> x = sp.Symbol("x")
        >>> A = HybridAutomaton(states=(x,), parameters={"k": 1.0}, modes=[Mode("m", (-sp.Symbol("k") * x,))])
        >>> A.resolve_parameters({"k": 2})
        {'k': 2.0}
        """
        values = dict(self.parameters)
        for k, v in (overrides or {}).items():
            if k not in values:
                raise ModelError(f"unknown parameter {k!r}; known: {sorted(values)}")
            values[k] = float(v)
        self._check_signs(values)
        return values


def free_symbols_by_name(exprs: Sequence[sp.Expr]) -> set[str]:
    """Names of the free symbols of several expressions (symbols compare by name across assumptions)."""
    out: set[str] = set()
    for e in exprs:
        out |= {str(s) for s in sp.sympify(e).free_symbols}
    return out
