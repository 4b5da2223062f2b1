"""Issue 24, property-based: model declarations drawn from a grammar of expressions.

Restoring forces, damping laws and automaton guards, resets, noises and observables are built from terms that a
user might write, good ones (``a*x``, ``b*x**3``, ``c*y``) and bad ones (``sqrt(x)``, ``1/x``, ``log(x)``, an
undeclared symbol ``q``, an undefined function ``f(x)``). A declaration is either refused where it is made, in one
line, or it gives a model whose density is finite and normalised (or is refused there, in one line). Nothing may
escape as another exception, and no number may come out NaN. Bounded: about 10 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from averaging import stationary_density
from hybrid import HybridAutomaton, Mode, Transition
from hybrid.errors import VibroError
from hybrid.stochastic._auto_codegen import generate_source
from models import ImpactOscillator

GOOD = ["a*x", "b*x**3", "x", "x + x**3", "a*x + b*x**3", "sinh(x)", "x*exp(x**2)"]
BAD = ["sqrt(x)", "1/x", "log(x)", "q*x", "f(x)", "x**0.5", "-x", "x**2", "0", "nan*x", "zoo*x", "exp(-x**2)*x",
       "a*x/(x - 0.5)", "atan(x)"]
DAMPING = ["c*y", "c*y + x**2*y", "c*y**3", "-c*y", "c*q*y", "c*y/x", "c*abs(y)", "f(y)", "c*sqrt(y)", "0"]

SETTINGS = settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck),
                    phases=(Phase.explicit, Phase.generate))


def _one_line(fn):
    """fn() -> its result, or None when it raised a one-line VibroError; any other exception fails the test."""
    try:
        return fn()
    except VibroError as exc:
        assert "\n" not in str(exc) and str(exc), repr(exc)
        return None


@SETTINGS
@given(restoring=st.sampled_from(GOOD + BAD), damping=st.sampled_from(DAMPING),
       delta=st.sampled_from([1.0, 0.3, math.inf]))
def test_oscillator_declarations_are_refused_or_give_a_normalised_density(restoring, damping, delta):
    params = {"a": 1.0, "b": 0.2, "c": 0.05, "D": 0.05, "delta": delta}
    model = _one_line(lambda: ImpactOscillator(restoring, damping, intensity="D", parameters=params))
    if model is None:
        return
    sd = _one_line(lambda: stationary_density(model, "jump", h_max=4.0, points=300))
    if sd is None:
        return
    assert np.all(np.isfinite(sd.p)) and np.all(sd.p >= 0)
    assert math.isfinite(sd.mean_energy) and sd.mean_energy >= 0
    assert float(np.trapezoid(sd.p, sd.H)) == pytest.approx(1.0, abs=0.01)


TERMS = ["x", "v", "x - 1", "v**2/2 + x**2/2 - 0.25", "q", "f(x)", "k*x", "1/x", "sqrt(v)", "t", "r*v"]


@SETTINGS
@given(guard=st.sampled_from(TERMS), reset=st.sampled_from(TERMS), noise=st.sampled_from(TERMS + ["s"]),
       observable=st.sampled_from(TERMS), scheme=st.sampled_from(["em", "splitting", "baoab"]))
def test_automaton_declarations_are_refused_where_made_or_generate_a_kernel(guard, reset, noise, observable, scheme):
    x, v = sp.symbols("x v")
    params = {"k": 1.0, "r": 0.8, "s": 0.1}

    def build():
        return HybridAutomaton(
            states=(x, v), parameters=params,
            modes=[Mode("free", (v, -sp.Symbol("k") * x), noise=(0, sp.sympify(noise)))],
            transitions=[Transition("wall", "free", "free", guard=sp.sympify(guard), direction=1,
                                    reset=(x, sp.sympify(reset)))],
            observables={"H": sp.sympify(observable)})

    automaton = _one_line(build)
    if automaton is None:
        return
    # a declaration that was accepted must generate its kernel source (no compile here): no NameError, no
    # printer error at run time
    _one_line(lambda: generate_source(automaton, scheme, {"H": automaton.observables["H"]}))
    assert not {"q", "f"} & {str(s) for s in automaton.observables["H"].free_symbols}


def test_the_cases_that_found_defects():
    params = {"c": 0.05, "D": 0.05, "delta": 0.3}
    # a damping singular at x = 0 has no stochastic differential equation: refused where it is declared
    with pytest.raises(VibroError, match=r"damping h\(x, y\) = c\*y/x is not a finite real number"):
        ImpactOscillator("x", "c*y/x", intensity="D", parameters=params)
    with pytest.raises(VibroError, match="noise coefficient f_1"):
        ImpactOscillator("x", "c*y", noise=("sqrt(y)",), intensity="D", parameters=params)
    # a quadratic minimum whose exponent nu is fitted as 3e-7 gave p(0) = 0 (the limit is 4.26): the CSV lost 3.5 %
    sd = stationary_density(ImpactOscillator("atan(x)", "c*y", intensity="D", parameters=params), "jump",
                            h_max=4.0, points=300)
    assert sd.p[0] == pytest.approx(sd.p[1], rel=0.02)
    assert float(np.trapezoid(sd.p, sd.H)) == pytest.approx(1.0, abs=1e-3)


def test_parameter_names_that_the_generated_code_uses_too():
    # the averaging's orbit variable is a sympy symbol 's': a parameter named s was a SyntaxError (duplicate
    # argument) in its numpy kernels; every name gives the answer of the same model with another name
    answers = set()
    for name in ("k", "s", "p", "dt", "np"):
        model = ImpactOscillator(f"{name}*x", "c*y", intensity="D",
                                 parameters={name: 1.0, "c": 0.05, "D": 0.05, "delta": 1.0})
        answers.add(round(stationary_density(model, "jump", points=300).mean_energy, 12))
    assert len(answers) == 1
