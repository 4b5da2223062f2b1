"""The example geometries of ``benchmarks/method_choice.py`` as user classes, for ``vibro solve --model FILE:CLASS``.

* ``AsymmetricGap``: examples/09_asymmetric_gap.py (x + 0.5 x**3, c = D = 0.05, walls at -0.6 and 1.0, Newton 0.8).
* ``OneSidedStop``: benchmarks/geometry_averaging.py (x + 0.5 x**3, c = D = 0.05, one wall at 0.8, Newton 0.7).
* ``EquilibriumStop``: examples/06_equilibrium_stop.py (linear, c = D = 0.05, a stop at x = 0, Newton r = 0.6).
"""

from __future__ import annotations

from models import ImpactOscillator, Newton


class AsymmetricGap(ImpactOscillator):
    """Hardening spring between walls at -0.6 and 1.0 (examples/09_asymmetric_gap.py)."""

    name = "asymmetric-gap"

    def __init__(self, restitution=None, **params):
        super().__init__("x + b*x**3", "c*y", parameters={"b": 0.5, "c": 0.05, "D": 0.05, **params},
                         barriers=(-0.6, 1.0), restitution=restitution or Newton(0.8))


class OneSidedStop(ImpactOscillator):
    """Hardening spring with one wall at x = 0.8 (benchmarks/geometry_averaging.py)."""

    name = "one-sided-stop"

    def __init__(self, restitution=None, **params):
        super().__init__("x + b*x**3", "c*y", parameters={"b": 0.5, "c": 0.05, "D": 0.05, **params},
                         barriers=(None, 0.8), restitution=restitution or Newton(0.7))


class EquilibriumStop(ImpactOscillator):
    """Linear oscillator with a stop at its equilibrium (examples/06_equilibrium_stop.py)."""

    name = "equilibrium-stop"

    def __init__(self, restitution=None, **params):
        super().__init__("x", "c*y", parameters={"c": 0.05, "D": 0.05, **params}, barriers=(0, None),
                         restitution=restitution or Newton(0.6))
