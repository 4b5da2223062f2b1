"""Restitution laws: the coefficient e(v) of an impact at speed v = |velocity before impact| > 0.

Each law gives the coefficient as a vectorised numpy function and as a sympy expression of the speed, so that
the same law feeds the deterministic backends, the compiled Monte Carlo kernels and the averaging. The velocity
after the impact is ``v_plus = -e(|v_minus|) * v_minus``.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Mapping

import numpy as np
import sympy as sp

from hybrid.automaton import _as_expr, lambdify_numeric, real_symbol
from hybrid.errors import ParameterError, RestitutionError

SPEED = real_symbol("v")
"""Symbol of the impact speed in restitution expressions."""

# Speeds at which a law's coefficient is checked to lie in (0, 1].
_CHECK_SPEEDS = np.concatenate([np.geomspace(1e-8, 1e4, 400), [0.4, 1.0]])


def _impact_speed(excess):
    """sqrt(2 excess), with 1 where there is no impact (the loss is multiplied by excess = 0 there): a law such as
    Ma's, (V_C / v)**(1/6), must not be evaluated at v = 0."""
    return np.where(excess > 0.0, np.sqrt(2.0 * excess), 1.0)
def _real(value, what: str, example: str) -> float:
    """``value`` as a float, or a one-line :class:`RestitutionError` (None, strings, complex, arrays)."""
    if isinstance(value, (bool, str)) or not isinstance(value, numbers.Real):
        raise RestitutionError(f"{what}={value!r} is not a real number; give e.g. {example}")
    return float(value)


class RestitutionLaw:
    """Base class. Subclasses set :attr:`name`, :attr:`parameters` and implement :meth:`expression`.

    Examples
    --------
    >>> Newton(0.8).coefficient(2.0)
    0.8
    """

    name = "law"

    def __init__(self, **parameters: float):
        self.parameters: Mapping[str, float] = dict(parameters)

    # symbolic form used by every backend
    def expression(self, speed: sp.Symbol = SPEED) -> sp.Expr:
        """e as a sympy expression of the impact speed, with parameter values substituted."""
        raise NotImplementedError

    def coefficient(self, speed):
        """e(speed) for a scalar or an array of impact speeds (absolute values are taken).

        Examples
        --------
        >>> Ma(0.4).coefficient([0.1, 1.0]).round(6).tolist()
        [1.0, 0.858374]
        """
        fn = self._numpy()
        try:
            arr = np.abs(np.asarray(speed, dtype=float))
        except (TypeError, ValueError) as exc:
            raise RestitutionError(f"impact speeds must be real numbers, got {speed!r}") from exc
        out = np.broadcast_to(np.asarray(fn(arr), dtype=float), arr.shape).copy()
        return float(out) if out.ndim == 0 else out

    def _numpy(self) -> Callable:
        cached = getattr(self, "_fn", None)
        if cached is None:
            cached = lambdify_numeric(SPEED, self.expression(SPEED))
            self._fn = cached
        return cached

    def validate(self) -> None:
        """Raise :class:`RestitutionError` unless 0 < e(v) <= 1 on speeds from 1e-8 to 1e4.

        Only a grid is checked; the orbit simulators also check the coefficient applied at every impact.
        """
        try:
            with np.errstate(all="ignore"):
                e = np.asarray(self.coefficient(_CHECK_SPEEDS), dtype=float)
        except RestitutionError:
            raise
        except Exception as exc:  # a user law that fails: report it in one line
            raise RestitutionError(f"restitution law {self!r} cannot be evaluated on speeds 1e-8..1e4 "
                                   f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}); "
                                   "it must return a coefficient for an array of speeds") from exc
        bad = ~np.isfinite(e) | (e <= 0.0) | (e > 1.0 + 1e-12)
        if bad.any():
            v = _CHECK_SPEEDS[bad][0]
            raise RestitutionError(
                f"restitution law {self!r} gives e({v:.3g}) = {e[bad][0]!r}, outside (0, 1]; "
                "a restitution coefficient must satisfy 0 < e <= 1"
            )

    # energy losses: the one implementation every engine and diagnostic uses
    def impact_loss(self, excess):
        """Energy lost by one impact at kinetic energy ``excess`` = H - G(wall): (1 - e(v)**2) excess, v**2 = 2 excess.

        Examples
        --------
        >>> Newton(0.5).impact_loss(1.0)
        0.75
        """
        excess = np.maximum(np.asarray(excess, dtype=float), 0.0)
        e = np.asarray(self.coefficient(_impact_speed(excess)), dtype=float)
        out = (1.0 - e * e) * excess
        return float(out) if out.ndim == 0 else out

    def two_impact_loss(self, excess, reading: str = "exact"):
        """Energy lost over two successive impacts of a free orbit (one quasi-period of a symmetric gap).

        ``'exact'``: (1 - e1**2 e2**2) excess with e1 = e(v), e2 = e(e1 v), the second impact at its own, slower
        speed. ``'paper'``: (1 - e(v)**4) excess, one coefficient for both impacts (the paper's drift form).

        Examples
        --------
        >>> Newton(0.5).two_impact_loss(1.0), Newton(0.5).two_impact_loss(1.0, "paper")
        (0.9375, 0.9375)
        >>> round(Ma(0.4).two_impact_loss(2.42 - 0.55), 12) < round(Ma(0.4).two_impact_loss(2.42 - 0.55, "paper"), 12)
        True
        """
        excess = np.maximum(np.asarray(excess, dtype=float), 0.0)
        v = _impact_speed(excess)
        e1 = np.asarray(self.coefficient(v), dtype=float)
        if reading == "paper":
            e2 = e1
        elif reading == "exact":
            e2 = np.asarray(self.coefficient(e1 * v), dtype=float)
        else:
            raise ParameterError(f"reading must be 'paper' or 'exact', got {reading!r}")
        out = (1.0 - e1 * e1 * e2 * e2) * excess
        return float(out) if out.ndim == 0 else out

    @property
    def is_elastic(self) -> bool:
        """True when e = 1 at every speed."""
        return False

    def elastic_below(self) -> float:
        """Largest speed below which e = 1 (0 if none); impacts slower than this lose no energy."""
        return 0.0

    def spec(self) -> str:
        """The command-line spelling, e.g. ``ma:vc=0.4``."""
        args = ",".join(f"{k}={v:g}" for k, v in self.parameters.items())
        return f"{self.name}:{args}" if args else self.name

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.parameters.items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and dict(self.parameters) == dict(other.parameters)

    def __hash__(self) -> int:
        return hash((type(self).__name__, tuple(sorted(self.parameters.items()))))


class Elastic(RestitutionLaw):
    """e = 1: perfectly elastic barriers.

    Examples
    --------
    >>> Elastic().coefficient(3.0)
    1.0
    """

    name = "elastic"

    def __init__(self):
        super().__init__()

    def expression(self, speed=SPEED):
        return sp.Integer(1)

    @property
    def is_elastic(self) -> bool:
        return True

    def elastic_below(self) -> float:
        return float("inf")


class Newton(RestitutionLaw):
    """Constant (Newton) coefficient 0 < e <= 1.

    Examples
    --------
    >>> Newton(0.5).coefficient(10.0)
    0.5
    """

    name = "newton"

    def __init__(self, e: float):
        e = _real(e, "Newton restitution e", "0.8")
        if not (0.0 < e <= 1.0):
            raise RestitutionError(f"Newton restitution e={e!r} is outside (0, 1]; choose 0 < e <= 1")
        super().__init__(e=e)

    def expression(self, speed=SPEED):
        return sp.Float(self.parameters["e"])

    @property
    def is_elastic(self) -> bool:
        return self.parameters["e"] == 1.0

    def elastic_below(self) -> float:
        return float("inf") if self.is_elastic else 0.0


class Ma(RestitutionLaw):
    """The paper's law (eqs. 3-4): e = 1 for v <= V_C, e = omega * v**(-1/6) above, omega = V_C**(1/6).

    Continuous at V_C and 0 < e < 1 above it.

    Examples
    --------
    >>> law = Ma(vc=0.4)
    >>> round(law.coefficient(0.4), 12), round(law.coefficient(0.4 * 64), 12)
    (1.0, 0.5)
    """

    name = "ma"

    def __init__(self, vc: float):
        vc = _real(vc, "Ma restitution vc", "0.4")
        if not (vc > 0.0) or not np.isfinite(vc):
            raise RestitutionError(f"Ma restitution needs a critical velocity vc > 0, got {vc!r}")
        super().__init__(vc=vc)

    @property
    def omega(self) -> float:
        """omega = V_C**(1/6)."""
        return self.parameters["vc"] ** (1.0 / 6.0)

    def expression(self, speed=SPEED):
        vc = sp.Float(self.parameters["vc"])
        return sp.Piecewise((sp.Integer(1), speed <= vc), ((vc / speed) ** sp.Rational(1, 6), True))

    def elastic_below(self) -> float:
        return self.parameters["vc"]


class CustomRestitution(RestitutionLaw):
    """A user law, as a sympy expression of the speed ``v`` (a string is parsed) or a numpy callable.

    A callable cannot be compiled into the Monte Carlo kernels unless numba can compile it; an expression always can.

    Examples
    --------
    >>> law = CustomRestitution("1/(1 + v/10)")
    >>> round(law.coefficient(10.0), 12)
    0.5
    >>> CustomRestitution(lambda v: 0.9 + 0 * v).coefficient(1.0)
    0.9
    """

    name = "custom"

    def __init__(self, law, label: str = "custom"):
        super().__init__()
        self.label = label
        if callable(law) and not isinstance(law, sp.Basic):
            self._callable = law
            self._expr = None
            self._fn = lambda v: law(v)
        else:
            expr = _as_expr(law, "custom restitution law")
            unknown = {s.name for s in expr.free_symbols} - {"v"}
            if unknown:
                raise RestitutionError(
                    f"custom restitution law {law!r} uses {sorted(unknown)}; it may depend only on the speed v"
                )
            self._callable = None
            self._expr = expr.xreplace({real_symbol("v"): SPEED})
        self.validate()

    def expression(self, speed=SPEED):
        if self._expr is None:
            raise RestitutionError(
                f"the custom law {self.label!r} is a Python callable and has no symbolic form; "
                "declare it as a sympy expression of v to use it in compiled kernels or averaging"
            )
        return self._expr.xreplace({SPEED: speed})

    @property
    def callable(self):
        """The user's callable, or None for an expression law."""
        return self._callable

    def spec(self) -> str:
        return f"custom:{self._expr}" if self._expr is not None else f"custom:{self.label}"

    def __repr__(self) -> str:
        return f"CustomRestitution({str(self._expr) if self._expr is not None else self.label!r})"

    def __eq__(self, other) -> bool:
        if not isinstance(other, CustomRestitution):
            return False
        if self._expr is not None:
            return other._expr is not None and sp.simplify(self._expr - other._expr) == 0
        return self._callable is other._callable

    def __hash__(self) -> int:
        return hash(("custom", str(self._expr) if self._expr is not None else id(self._callable)))


def parse_restitution(spec: str) -> RestitutionLaw:
    """Read a command-line restitution spec.

    ``elastic``, ``newton:e=0.8``, ``ma:vc=0.4`` or ``custom:<expression in v>``.

    Examples
    --------
    >>> parse_restitution("ma:vc=0.4")
    Ma(vc=0.4)
    >>> parse_restitution("newton:e=0.7")
    Newton(e=0.7)
    """
    name, _, rest = spec.partition(":")
    name = name.strip().lower()
    if name == "custom":
        if not rest:
            raise ParameterError("custom restitution needs an expression in v, e.g. custom:'1/(1+v)'")
        return CustomRestitution(rest)
    kwargs: dict[str, float] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        if not eq:
            raise ParameterError(f"restitution argument {item!r} must read NAME=VALUE, e.g. ma:vc=0.4")
        try:
            kwargs[key.strip()] = float(value)
        except ValueError as exc:
            raise ParameterError(f"restitution argument {item!r}: {value!r} is not a number") from exc
    laws = {"elastic": (Elastic, ()), "newton": (Newton, ("e",)), "ma": (Ma, ("vc",))}
    if name not in laws:
        raise ParameterError(f"unknown restitution law {name!r}; use one of elastic, newton:e=.., ma:vc=.., custom:..")
    law, needed = laws[name]
    example = {"elastic": "elastic", "newton": "newton:e=0.8", "ma": "ma:vc=0.4"}[name]
    if set(kwargs) != set(needed):
        extra, missing = sorted(set(kwargs) - set(needed)), sorted(set(needed) - set(kwargs))
        what = f"needs {', '.join(missing)}=VALUE" if missing else f"takes no {', '.join(extra)}"
        raise ParameterError(f"restitution {spec!r} {what}; write e.g. {example}")
    return law(**kwargs)
