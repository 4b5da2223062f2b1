"""How impacts enter the averaged energy equation: the methods registry ``METHODS``.

* ``paper`` (eq. 13): a drift -dH/T with dH = (1 - e**4)(H - G(delta)), e = e(v), v = sqrt(2(H - G(delta))).
* ``exact-two-impact``: the same with dH = (1 - e1**2 e2**2)(H - G(delta)), e1 = e(v), e2 = e(e1 v): the free
  system's loss over two successive impacts (docs/paper-readings.md).
* ``jump``: no loss drift; every impact is a jump H -> G(delta) + e(v)**2 (H - G(delta)) at rate 2/T(H).
* ``chain``: the same jump, but at the end of each flight (duration T(H)/walls) instead of at Poisson times: the
  impact-to-impact chain of :mod:`averaging.chain`.

Each method is a small class; ``METHODS[name]`` gives an instance. New methods subclass :class:`ImpactMethod` and
call :func:`register`.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import ParameterError


class ImpactMethod:
    """Base class: a named treatment of the impact losses.

    Examples
    --------
    >>> sorted(METHODS)
    ['chain', 'exact-two-impact', 'jump', 'paper']
    """

    name = "base"
    jumps = False
    flights = False
    """True when impacts come at the end of flights (the impact-to-impact chain), not at Poisson times."""
    description = ""

    def loss(self, law, excess, walls: int = 2):
        """Energy lost per quasi-period as a drift term, given ``excess`` = H - G(delta) >= 0 (array).

        ``walls`` is the number of barriers a level above G(delta) hits per quasi-period: 2 for a symmetric gap,
        1 for a one-sided stop (then every method's loss is the single impact's (1 - e**2) excess).
        """
        return np.zeros_like(np.asarray(excess, dtype=float))

    def jump_target(self, law, excess):
        """Post-impact excess energy e(v)**2 (H - G(delta)) of a single impact (used by jump methods)."""
        excess = np.asarray(excess, dtype=float)
        return excess - law.impact_loss(excess)

    def speed_breakpoints(self, law) -> list[float]:
        """Impact speeds where the loss is not smooth (kinks of the restitution law)."""
        return _law_breakpoints(law)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class PaperMethod(ImpactMethod):
    """Eq. 13 as printed: dH = (1 - e**4)(H - G(delta)), one e for both impacts.

    Examples
    --------
    >>> from models import Newton
    >>> float(PaperMethod().loss(Newton(0.5), 1.0))
    0.9375
    """

    name = "paper"
    description = "eq. 13: drift -(1 - e^4)(H - G(delta))/T"

    def loss(self, law, excess, walls: int = 2):
        if walls == 1:
            return law.impact_loss(excess)
        return law.two_impact_loss(excess, reading="paper")


class ExactTwoImpactMethod(ImpactMethod):
    """Free-orbit loss of two successive impacts: (1 - e1**2 e2**2)(H - G(delta)), e2 = e(e1 v).

    Examples
    --------
    >>> from models import Newton
    >>> float(ExactTwoImpactMethod().loss(Newton(0.5), 1.0))
    0.9375
    """

    name = "exact-two-impact"
    description = "drift -(1 - e1^2 e2^2)(H - G(delta))/T, e2 = e(e1 v)"

    def loss(self, law, excess, walls: int = 2):
        if walls == 1:
            return law.impact_loss(excess)
        return law.two_impact_loss(excess, reading="exact")

    def speed_breakpoints(self, law) -> list[float]:
        out = set(_law_breakpoints(law))
        for b in list(out):  # second impact at e(v) v = b
            v = _solve_increasing(lambda v: law.coefficient(v) * v, b)
            if v is not None:
                out.add(v)
        return _dedupe(out)


class JumpMethod(ImpactMethod):
    """Impacts as jumps of the averaged energy: H -> G(delta) + e(v)**2 (H - G(delta)) at rate 2/T(H).

    Examples
    --------
    >>> from models import Newton
    >>> float(JumpMethod().jump_target(Newton(0.5), 1.0))
    0.25
    """

    name = "jump"
    jumps = True
    description = "jump-diffusion: H -> G + e^2 (H - G) at rate 2/T(H)"


class ChainMethod(JumpMethod):
    """The jump of :class:`JumpMethod` applied once per flight of duration T(H)/walls (:mod:`averaging.chain`).

    ``phases`` clock phases per flight, Richardson-extrapolated with phases / 2
    (:func:`averaging.chain.chain_density`).

    Examples
    --------
    >>> from models import Newton
    >>> m = ChainMethod()
    >>> m.flights, float(m.jump_target(Newton(0.5), 1.0))
    (True, 0.25)
    """

    name = "chain"
    flights = True
    phases = 8
    description = "impact-to-impact chain: H -> G + e^2 (H - G) at the end of each flight T(H)/walls"


METHODS: dict[str, ImpactMethod] = {}
"""Registry: method name -> instance."""


def register(method: ImpactMethod) -> ImpactMethod:
    """Add a method instance to :data:`METHODS` under its ``name``.

    Examples
    --------
    >>> get_method("jump").name
    'jump'
    """
    METHODS[method.name] = method
    return method


for _m in (PaperMethod(), ExactTwoImpactMethod(), JumpMethod(), ChainMethod()):
    register(_m)


def get_method(method) -> ImpactMethod:
    """The method instance for a name or an instance; clear error for unknown names."""
    if isinstance(method, ImpactMethod):
        return method
    if not isinstance(method, str) or method not in METHODS:
        raise ParameterError(f"unknown averaging method {method!r}; choose one of {sorted(METHODS)}")
    return METHODS[method]


def _dedupe(values, rel: float = 1e-9) -> list[float]:
    out: list[float] = []
    for v in sorted(values):
        if not out or v > out[-1] * (1.0 + rel):
            out.append(v)
    return out


def _law_breakpoints(law) -> list[float]:
    import sympy as sp

    from models import SPEED

    out = set()
    vc = law.elastic_below()
    if 0.0 < vc < np.inf:
        out.add(float(vc))
    try:
        expr = law.expression(SPEED)
    except Exception:  # callable laws: no symbolic kinks known
        return _dedupe(out)
    for pw in expr.atoms(sp.Piecewise):
        for _, cond in pw.args:
            for rel in cond.atoms(sp.core.relational.Relational):
                for side in (rel.lhs, rel.rhs):
                    if side.is_number and float(side) > 0:
                        out.add(float(side))
    return _dedupe(out)


def _solve_increasing(fun, target, lo=0.0, hi=1.0):
    """Root of fun(v) = target for an increasing fun (None when not bracketed)."""
    for _ in range(200):
        if fun(hi) >= target:
            break
        lo, hi = hi, hi * 2.0
    else:
        return None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if fun(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
