"""Free-orbit formulas of the paper: loss per impact (eq. 11), per quasi-period (eq. 13), (quasi-)period (8, 14).

Used by ``vibro orbit`` to print measured against predicted values. The tests check the orbits against independent
oracles in ``tests/problems.py`` (mpmath), not against these.
"""

from __future__ import annotations

import math

from scipy import integrate, optimize

from hybrid.errors import ParameterError


def _turning_point(model, H: float, sign: float) -> float:
    """The s > 0 with G(sign * s) = H, ignoring the barriers (G increasing in s on a single well)."""
    G = lambda s: float(model.potential(sign * s))  # noqa: E731
    hi = 1.0
    for _ in range(200):
        if G(hi) >= H:
            break
        hi *= 2.0
    else:
        raise ParameterError(f"no turning point for H={H:g}: the potential does not confine")
    return optimize.brentq(lambda s: G(s) - H, 0.0, hi, xtol=1e-15, rtol=8.9e-16)


def quasi_period(model, H: float) -> float:
    """T(H) = 2 * int dx / sqrt(2H - 2G(x)) over the reachable part of the gap: eq. 8 below G(delta), eq. 14 above.

    The turning-point singularities are removed with x = A sin(theta).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> m = DuffingImpact(a=1.0, b=0.0, delta=10.0)
    >>> round(quasi_period(m, 0.5), 10)   # linear oscillator: 2 pi
    6.2831853072
    >>> round(quasi_period(DuffingImpact(a=1.0, b=0.0, delta=0.5), 0.5), 10)   # cut at x = +-A/2: 2 pi / 3
    2.0943951024
    """
    H = float(H)
    if not (H > 0 and math.isfinite(H)):
        raise ParameterError(f"energy H={H!r} must be positive and finite")
    left, right = model.barriers
    total = 0.0
    for sign, wall in ((1.0, right), (-1.0, left)):
        A = _turning_point(model, H, sign)
        top = math.pi / 2 if abs(wall) >= A else math.asin(abs(wall) / A)

        def f(theta, A=A, sign=sign):
            gap = 2.0 * (H - float(model.potential(sign * A * math.sin(theta))))
            return A * math.cos(theta) / math.sqrt(gap) if gap > 0 else 0.0

        total += integrate.quad(f, 0.0, top, epsabs=0.0, epsrel=1e-13, limit=200)[0]
    return 2.0 * total


def impact_loss(model, H_minus: float, e: float | None = None) -> float:
    """Eq. 11: (1 - e**2)(H_minus - G(delta)), with e = e(v) at the impact speed unless given.

    Examples
    --------
    >>> from models import DuffingImpact, Newton
    >>> round(impact_loss(DuffingImpact(restitution=Newton(0.5)), 1.55), 12)
    0.75
    """
    Gd = model.barrier_energy
    if e is None:
        e = float(model.restitution.coefficient(math.sqrt(max(2.0 * (H_minus - Gd), 0.0))))
    return (1.0 - e * e) * (H_minus - Gd)


def two_impact_loss(model, H_minus: float, reading: str = "exact") -> float:
    """Loss over a quasi-period (two impacts): ``'paper'`` (eq. 13, (1 - e**4)(H - G)) or ``'exact'``.

    ``'exact'`` uses the second impact's own speed: (1 - e1**2 e2**2)(H - G) with e2 = e(e1 v) (NOTES.md).

    Examples
    --------
    >>> from models import DuffingImpact, Newton
    >>> m = DuffingImpact(restitution=Newton(0.5))
    >>> two_impact_loss(m, 1.55, "paper") == two_impact_loss(m, 1.55, "exact")
    True
    """
    Gd = model.barrier_energy
    v = math.sqrt(max(2.0 * (H_minus - Gd), 0.0))
    e1 = float(model.restitution.coefficient(v))
    if reading == "paper":
        return (1.0 - e1**4) * (H_minus - Gd)
    if reading == "exact":
        e2 = float(model.restitution.coefficient(e1 * v))
        return (1.0 - e1 * e1 * e2 * e2) * (H_minus - Gd)
    raise ParameterError(f"reading must be 'paper' or 'exact', got {reading!r}")
