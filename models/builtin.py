"""The paper's two examples, a user-style example model, and the registry used by the command line."""

from __future__ import annotations

import numpy as np

from .oscillator import ImpactOscillator
from .restitution import Ma, RestitutionLaw


def _parameters(model: str, defaults: dict, given: dict) -> dict:
    """The defaults overridden by ``given``; an unknown name is refused in one line."""
    unknown = set(given) - set(defaults)
    if unknown:
        from hybrid.errors import ParameterError

        raise ParameterError(f"unknown parameters {sorted(unknown)} for {model}; known: {sorted(defaults)}")
    return {**defaults, **given}


_DUFFING = {"a": 1.0, "b": 0.2, "c": 0.025, "D": 0.05, "delta": 1.0}


class DuffingImpact(ImpactOscillator):
    """Example 1 (eq. 32): x'' + c x' + a x + b x**3 = xi(t), |x| < delta, Ma restitution law.

    Defaults are the Fig. 2 parameters with delta = 1.0.

    Examples
    --------
    >>> m = DuffingImpact(delta=0.8)
    >>> round(m.barrier_energy, 6)
    0.34048
    >>> round(float(m.amplitude(m.barrier_energy)), 12)
    0.8
    """

    name = "duffing"

    def __init__(self, restitution: RestitutionLaw | None = None, **params: float):
        parameters = _parameters("duffing", _DUFFING, params)
        super().__init__(
            restoring="a*x + b*x**3",
            damping="c*y",
            noise=(1,),
            intensity="D",
            parameters=parameters,
            restitution=restitution if restitution is not None else Ma(vc=0.4),
        )

    def amplitude(self, H):
        """Closed form A(H) = sqrt((sqrt(a**2 + 4 b H) - a) / b) (paper, after eq. 38); a*H/... when b = 0."""
        H = np.asarray(H, dtype=float)
        a, b = self.params["a"], self.params["b"]
        if b == 0.0:
            return np.sqrt(2.0 * H / a)
        # rationalised form: no cancellation for small b*H
        return np.sqrt(4.0 * H / (np.sqrt(a * a + 4.0 * b * H) + a))


class DuffingVanDerPolImpact(ImpactOscillator):
    """Example 2 (eq. 39), Duffing-van der Pol with impacts.

    ``reading='van-der-pol'`` (default; see docs/paper-readings.md) uses h = (c1 + c2 x**2) y with c1 = -0.01,
    c2 = 0.005: negative damping near the origin and a limit cycle of amplitude about 2.7. ``reading='literal'`` uses
    the printed h = (c1 - c2 x**2) y, which is negative everywhere and has no stationary density without barriers.

    Examples
    --------
    >>> DuffingVanDerPolImpact().h
    y*(c1 + c2*x**2)
    """

    name = "duffing-vdp"
    READINGS = {"van-der-pol": "(c1 + c2*x**2)*y", "literal": "(c1 - c2*x**2)*y"}

    def __init__(self, restitution: RestitutionLaw | None = None, reading: str = "van-der-pol", **params: float):
        if reading not in self.READINGS:
            from hybrid.errors import ModelError

            raise ModelError(f"reading must be one of {sorted(self.READINGS)}, got {reading!r}")
        self.reading = reading
        defaults = {"a": 1.0, "b": 0.2, "c1": -0.01, "c2": 0.005, "D": 0.01, "delta": 1.0}
        parameters = _parameters("duffing-vdp", defaults, params)
        super().__init__(
            restoring="a*x + b*x**3",
            damping=self.READINGS[reading],
            noise=(1,),
            intensity="D",
            parameters=parameters,
            restitution=restitution if restitution is not None else Ma(vc=0.4),
        )

    amplitude = DuffingImpact.amplitude


class RayleighImpact(ImpactOscillator):
    """A user-style model in a few lines: linear spring, Rayleigh damping c y + k3 y**3, noise on y.

    It is also the documented template for users: declare g, h, f, D, defaults and a restitution law.

    Examples
    --------
    >>> m = RayleighImpact()
    >>> m.h
    c*y + k3*y**3
    """

    name = "rayleigh"

    def __init__(self, restitution: RestitutionLaw | None = None, **params: float):
        super().__init__(
            restoring="w2*x",
            damping="c*y + k3*y**3",
            noise=(1,),
            intensity="D",
            parameters={"w2": 1.0, "c": 0.02, "k3": 0.01, "D": 0.05, "delta": 1.0, **params},
            restitution=restitution if restitution is not None else Ma(vc=0.4),
        )


class ForcedDuffingImpact(ImpactOscillator):
    """Example 1 with harmonic forcing: x'' + c x' + a x + b x**3 = A cos(Omega t + phi) + xi(t), |x| < delta.

    A forced model: orbits and Monte Carlo (through its automaton, with phase-resolved statistics) run; the
    averaging methods refuse it. ``vibro mc --model duffing-forced --param A=0.3 --param Omega=1.2 --phases 8``.

    Examples
    --------
    >>> m = ForcedDuffingImpact(Omega=2.0)
    >>> m.is_forced, round(m.forcing_period, 12)
    (True, 3.14159265359)
    """

    name = "duffing-forced"

    def __init__(self, restitution: RestitutionLaw | None = None, **params: float):
        parameters = _parameters("duffing-forced", {**_DUFFING, "A": 0.2, "Omega": 1.2, "phi": 0.0}, params)
        super().__init__(
            restoring="a*x + b*x**3",
            damping="c*y",
            noise=(1,),
            intensity="D",
            parameters=parameters,
            restitution=restitution if restitution is not None else Ma(vc=0.4),
            forcing="A*cos(Omega*t + phi)",
        )

    amplitude = DuffingImpact.amplitude


MODELS: dict[str, type[ImpactOscillator]] = {
    "duffing": DuffingImpact,
    "duffing-forced": ForcedDuffingImpact,
    "duffing-vdp": DuffingVanDerPolImpact,
    "rayleigh": RayleighImpact,
}


def make_model(name: str, params: dict | None = None, restitution: RestitutionLaw | None = None) -> ImpactOscillator:
    """Build a registered model by name with parameter overrides.

    Examples
    --------
    >>> make_model("duffing", {"delta": 1.2}).params["delta"]
    1.2
    """
    from hybrid.errors import ParameterError

    if name not in MODELS:
        raise ParameterError(f"unknown model {name!r}; choose one of {sorted(MODELS)}")
    model = MODELS[name](restitution=restitution)
    return model.with_params(**(params or {})) if params else model
