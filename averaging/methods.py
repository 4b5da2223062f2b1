"""How impacts enter the averaged energy equation: the methods registry ``METHODS``.

* ``paper`` (eq. 13): a drift -dH/T with dH = (1 - e**4)(H - G(delta)), e = e(v), v = sqrt(2(H - G(delta))).
* ``exact-two-impact``: the same with dH = (1 - e1**2 e2**2)(H - G(delta)), e1 = e(v), e2 = e(e1 v): the free
  system's loss over two successive impacts (docs/paper-readings.md).
* ``jump``: no loss drift; every impact is a jump H -> G(delta) + e(v)**2 (H - G(delta)) at rate 2/T(H).
* ``chain``: the same jump, but at the end of each flight (duration T(H)/walls) instead of at Poisson times: the
  impact-to-impact chain of :mod:`averaging.chain`.

Other geometries (:meth:`ImpactMethod.cycle_loss`): a level H hits each wall whose energy G_w it exceeds, once per
quasi-period. One wall (a stop at an offset or at the equilibrium): every method loses (1 - e**2)(H - G_w) per
quasi-period, or jumps once per T(H). Two walls at different energies (asymmetric): between the levels only the
lower wall is hit; above both, the drift methods lose the two impacts in sequence (the second at the energy the
first left), averaged over which wall comes first; ``paper`` takes the second coefficient at the speed of the level
H itself, as eq. 13 does, ``exact-two-impact`` at the speed actually reached. Both reduce to the symmetric forms
when the levels coincide. ``jump`` jumps at each wall at its own rate 1/T(H) by that wall's own loss.

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
    reading = "exact"
    description = ""

    def loss(self, law, excess, walls: int = 2):
        """Energy lost per quasi-period as a drift term, given ``excess`` = H - G(delta) >= 0 (array).

        ``walls`` is the number of barriers a level above G(delta) hits per quasi-period: 2 for a symmetric gap,
        1 for a one-sided stop (then every method's loss is the single impact's (1 - e**2) excess).
        """
        return np.zeros_like(np.asarray(excess, dtype=float))

    def cycle_loss(self, law, H, wall_levels):
        """Energy lost per quasi-period by the level H for walls at energies ``wall_levels`` (one per wall).

        0 for the jump methods (their impacts are jumps). See the module docstring for the geometries.

        Examples
        --------
        >>> from models import Newton
        >>> m = PaperMethod()
        >>> float(m.cycle_loss(Newton(0.5), 1.5, (0.5, 0.5)))      # symmetric: eq. 13, (1 - e**4)(H - G)
        0.9375
        >>> float(m.cycle_loss(Newton(0.5), 1.5, (0.5, 2.0)))      # only the lower wall is hit
        0.75
        >>> float(m.cycle_loss(Newton(0.5), 1.5, (0.0,)))          # a wall at the equilibrium
        1.125
        """
        H = np.asarray(H, dtype=float)
        if self.jumps or not wall_levels:
            return np.zeros_like(H)
        if len(wall_levels) == 1:
            return law.impact_loss(np.maximum(H - wall_levels[0], 0.0)) + 0.0 * H
        a, b = wall_levels
        if a == b:
            return self.loss(law, np.maximum(H - a, 0.0), 2) + 0.0 * H
        return 0.5 * (self._sequence(law, H, a, b) + self._sequence(law, H, b, a))

    def _sequence(self, law, H, first, second):
        """Loss of an impact on the wall at level ``first`` followed by one on ``second``, in one quasi-period."""
        la = law.impact_loss(np.maximum(H - first, 0.0))
        left = np.maximum(H - la - second, 0.0)  # kinetic energy at the second wall after the first impact
        if self.reading == "paper":
            from models.restitution import _impact_speed

            e = np.asarray(law.coefficient(_impact_speed(np.maximum(H - second, 0.0))), dtype=float)
            return la + (1.0 - e * e) * left
        return la + law.impact_loss(left)

    def loss_breakpoints(self, law, wall_levels) -> list[float]:
        """Energies where :meth:`cycle_loss` (or a jump target) is not smooth: the kinks of the law at each wall,
        and where the first of two impacts leaves the level just at the second wall's energy (or a kink speed)."""
        out = set()
        levels = sorted(set(wall_levels))
        speeds = self.speed_breakpoints(law) if len(wall_levels) == 2 and len(levels) == 1 else \
            _law_breakpoints(law)
        for g in levels:
            out.update(g + 0.5 * v * v for v in speeds)
        if len(levels) == 2 and not self.jumps:
            for first, second in (levels, levels[::-1]):
                for v in [0.0] + _law_breakpoints(law):
                    def after(H, first=first):
                        return H - law.impact_loss(np.maximum(H - first, 0.0))
                    top = max(levels)
                    if after(top) >= second + 0.5 * v * v:
                        continue
                    h = _solve_increasing(after, second + 0.5 * v * v, lo=top, hi=top + 1.0)
                    if h is not None:
                        out.add(float(h))
        return _dedupe(out)

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
    reading = "paper"
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

    On other geometries each wall w the level reaches jumps on its own: H -> G_w + e(v_w)**2 (H - G_w) at rate
    1/T(H), v_w = sqrt(2 (H - G_w)).

    Examples
    --------
    >>> from models import Newton
    >>> float(JumpMethod().jump_target(Newton(0.5), 1.0))
    0.25
    """

    name = "jump"
    jumps = True
    description = "jump-diffusion: H -> G_w + e^2 (H - G_w) at rate 1/T(H) for each wall w the level reaches"


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
