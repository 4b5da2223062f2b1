"""A user's model file, as ``vibro ... --model docs/user_model/my_models.py:NAME`` loads it.

Two declarations: an impact oscillator (every command takes it) and a hybrid automaton built by a function
(``vibro mc`` takes it). The file is imported once per command; it must not run work or exit at import.
"""

import sympy as sp

from hybrid import HybridAutomaton, Mode, Transition, real_symbol
from models import ImpactOscillator, Newton


class SofteningStop(ImpactOscillator):
    """x'' + c x' + x - k3 x^3 = sqrt(2 D) xi(t) against walls at -delta and +delta, Newton impacts v+ = -r v-.

    Every parameter has a default, so the commands can build it without arguments; ``--param NAME=VALUE``
    overrides one, ``--restitution`` replaces the law.
    """

    name = "softening-stop"

    def __init__(self, restitution=None, **params):
        super().__init__(
            restoring="x - k3*x**3",                  # g(x)
            damping="c*y",                            # h(x, y), y = dx/dt
            noise=(1,),                               # f_k(x, y): one additive noise
            intensity="D",                            # D_kl: E[xi(t) xi(t + s)] = 2 D delta(s)
            parameters={"k3": 0.1, "c": 0.05, "D": 0.03, "delta": 1.2, **params},
            barriers="delta",                         # or (None, "delta"), (0, None), ("-a", "b"), None
            restitution=restitution if restitution is not None else Newton(0.8),
        )


def bouncing_mass(**parameters):
    """A damped mass on a spring above a rigid floor at x = -h, white noise on the velocity, Newton impacts.

    A function that returns a ``HybridAutomaton``; ``vibro mc`` calls it without arguments, so every parameter
    has a default (``--param NAME=VALUE`` overrides it). The observable ``H`` is histogrammed by ``--h-max`` and
    ``--bins``.
    """
    x, v, w, c, D, h, r = (real_symbol(n) for n in ("x", "v", "w", "c", "D", "h", "r"))
    defaults = {"w": 1.0, "c": 0.05, "D": 0.02, "h": 0.8, "r": 0.7}
    free = Mode("free", flow=(v, -w**2 * x - c * v), noise=(0, sp.sqrt(2 * D)))
    floor = Transition("floor", "free", "free", guard=-x - h, direction=+1, reset=(x, -r * v))
    return HybridAutomaton(
        states=(x, v), parameters={**defaults, **parameters}, modes=[free], transitions=[floor],
        observables={"H": (v**2 + w**2 * x**2) / 2},
        positive=("w", "h"), nonnegative=("c", "D", "r"),
    )
