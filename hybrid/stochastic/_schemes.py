"""Time-stepping schemes of oscillator ensembles: a registry of small classes that declare their orders.

Every scheme advances (x, y) over one step dt with one standard normal ``xi`` and handles the barriers inside the
step. It declares its orders for smooth problems (no barriers): ``strong_order`` and ``weak_order``, and
``weak_order_barriers``, the weak order it keeps with impacts. The tests fit these orders from convergence slopes.

Every ensemble runs on the kernel generated from ``model.to_automaton()`` (:mod:`._auto_codegen`), with the
automaton scheme :data:`~hybrid.stochastic._front.AUTOMATON_SCHEME_OF` names for each of these; a scheme here
declares its orders and refuses (:meth:`Scheme.check`) the models it cannot integrate.
"""

from __future__ import annotations

import sympy as sp

from hybrid.automaton import real_symbol
from hybrid.errors import ModelError, ParameterError

_X, _Y = real_symbol("x"), real_symbol("y")


class Scheme:
    """Base class of the kernel schemes.

    Examples
    --------
    >>> SCHEMES["splitting"].weak_order
    2.0
    """

    name = "scheme"
    strong_order = 0.5
    weak_order = 1.0
    weak_order_barriers = 1.0
    description = ""

    def check(self, model) -> None:
        """Raise :class:`ModelError` when the scheme cannot integrate ``model``."""

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(strong_order={self.strong_order}, weak_order={self.weak_order}, "
                f"weak_order_barriers={self.weak_order_barriers})")


class EulerMaruyama(Scheme):
    """Explicit Euler-Maruyama: x += y dt, y += m(x, y) dt + sigma(x, y) dB, all evaluated at the step start.

    Impacts: on the free-flight segment x + y s the crossing time s is exact; the velocity reached at s (y plus the
    fraction s/dt of the increment) is reset by the restitution law, and the rest of the increment is added after
    the impact. Known pitfall: on a lightly damped oscillator the explicit update pumps energy at the rate
    dt * omega**2, so E[y**2] = D / (c - omega**2 dt): c = 0.025, dt = 1e-3 biases the temperature by about 4 %
    (4.17 % from the exact stationary covariance of the recursion, tests/test_montecarlo.py). Kept for comparison.

    Examples
    --------
    >>> EulerMaruyama().strong_order, EulerMaruyama().weak_order
    (0.5, 1.0)
    """

    name = "em"
    strong_order = 0.5
    weak_order = 1.0
    weak_order_barriers = 1.0
    description = "explicit Euler-Maruyama with in-step impact location"


class Milstein(Scheme):
    """Itô Milstein in the velocity, symplectic (semi-implicit) ordering: the new y first, then x with the new y.

    y_new = y + m(x, y) dt + sigma dB + 1/2 sigma dsigma/dy (dB**2 - dt), computed as 1/4 d(sigma**2)/dy (dB**2 - dt)
    from ``model.diffusion_squared`` (no division by sigma), with m the Itô drift including the Wong-Zakai term.
    Then x moves with the constant velocity y_new for dt (symplectic Euler for the conservative part: no energy
    pumping, the energy error stays O(dt) and bounded); the crossing of a wall on that segment is located exactly
    and the law is applied at the crossing, as often as needed. With additive noise the correction vanishes and
    the scheme is the symplectic Euler-Maruyama.

    Examples
    --------
    >>> Milstein().strong_order
    1.0
    """

    name = "milstein"
    strong_order = 1.0
    weak_order = 1.0
    weak_order_barriers = 1.0
    description = "Itô Milstein, symplectic ordering, in-step impact location"


class Splitting(Scheme):
    """BAOAB splitting with exact collisions (weak order 2; Leimkuhler, Sharma & Tretyakov 2024 for elastic walls).

    The drift must be m(x, y) = F(x) - k(x) y and the noise sigma(x) must not depend on y. One step:

    * B: y += F(x) dt/2;
    * A: free flight x += y dt/2 with every wall crossing located exactly and the restitution law applied;
    * O: exact Ornstein-Uhlenbeck step at fixed x: y = exp(-k dt) y + sigma sqrt((1 - exp(-2 k dt)) / (2 k)) xi;
    * A: as above; B: y += F(x) dt/2 (F kept for the next step's first B).

    Models with other damping (e.g. Rayleigh c y + k3 y**3) or noise depending on y are refused.

    Examples
    --------
    >>> Splitting().weak_order_barriers
    2.0
    """

    name = "splitting"
    strong_order = 1.0
    weak_order = 2.0
    weak_order_barriers = 2.0
    description = "BAOAB splitting: exact free flight with collisions, exact OU step"

    def _parts(self, model):
        m = sp.expand(model.ito_drift)
        if sp.diff(model.diffusion_squared, _Y) != 0:
            raise ModelError(
                f"scheme 'splitting' needs noise independent of y, but sigma**2 = {model.diffusion_squared}; "
                "use scheme='milstein'"
            )
        if sp.simplify(sp.diff(m, _Y, 2)) != 0:
            raise ModelError(
                f"scheme 'splitting' needs damping linear in y (h = k(x) y), but h = {model.h}; use scheme='milstein'"
            )
        k = sp.simplify(-sp.diff(m, _Y))
        F = sp.simplify(m.subs(_Y, 0))
        return F, k

    def check(self, model):
        self._parts(model)


class NaiveFlip(Scheme):
    """The naive scheme, for charts only: symplectic Euler-Maruyama, then if x left the gap put it on the wall and
    flip y with the law. The impact time is wrong by up to one step (the anti-pattern of design.md).

    Examples
    --------
    >>> NaiveFlip().name
    'naive'
    """

    name = "naive"
    strong_order = 0.5
    weak_order = 1.0
    weak_order_barriers = 1.0  # measured slope 1.0 for E[x^2], but a bias ~15x that of Milstein at the same dt
    description = "baseline only: velocity flipped at the end of the step, x clamped to the wall"


SCHEMES: dict[str, Scheme] = {
    s.name: s for s in (EulerMaruyama(), Milstein(), Splitting(), NaiveFlip())
}
"""Registry: scheme name -> scheme instance (``em``, ``milstein``, ``splitting``, ``naive``)."""


def get_scheme(scheme) -> Scheme:
    """A scheme from its name or a :class:`Scheme` instance.

    Examples
    --------
    >>> get_scheme("milstein").name
    'milstein'
    """
    if isinstance(scheme, Scheme):
        return scheme
    if isinstance(scheme, type) and issubclass(scheme, Scheme):
        return scheme()
    if scheme not in SCHEMES:
        raise ParameterError(f"unknown scheme {scheme!r}; choose one of {sorted(SCHEMES)}")
    return SCHEMES[scheme]
