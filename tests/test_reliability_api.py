"""Issue 9: every bad input to the public API is a one-line VibroError, never a traceback from the internals."""

from __future__ import annotations

import numpy as np
import pytest

from averaging import stationary_density
from hybrid.deterministic import simulate_orbit
from hybrid.errors import ModelError, ParameterError, RestitutionError, VibroError
from models import CustomRestitution, DuffingImpact, ImpactOscillator, Ma, Newton, parse_restitution


def _one_line(exc_info):
    text = str(exc_info.value)
    assert text and "\n" not in text
    assert "Traceback" not in text and "parse_expr" not in text and "Sympify of expression" not in text
    return text


# regression: custom:zoo gave KeyError 'ComplexInfinity'; 'ma' leaked Ma.__init__(); custom:1/(1+ leaked sympy's
# parser message; np.float64 leaked an AttributeError
@pytest.mark.parametrize("spec,cls,words", [
    ("custom:zoo", ModelError, "not a finite real expression"),
    ("custom:nan", ModelError, "not a finite real expression"),
    ("custom:1/(1+", ModelError, "invalid syntax"),
    ("custom:v**", ModelError, "invalid syntax"),
    ("custom:np.float64(1)", ModelError, "cannot read"),
    ("custom:I*v", RestitutionError, "may depend only on the speed v"),
    ("ma", ParameterError, "needs vc=VALUE"),
    ("newton", ParameterError, "needs e=VALUE"),
    ("ma:vc=0.4,e=1", ParameterError, "takes no e"),
    ("elastic:e=1", ParameterError, "takes no e"),
    ("ma:vc=abc", ParameterError, "not a number"),
])
def test_bad_restitution_specs(spec, cls, words):
    with pytest.raises(cls) as info:
        parse_restitution(spec)
    assert words in _one_line(info)


@pytest.mark.parametrize("make", [lambda: Newton(None), lambda: Newton("0.8"), lambda: Newton(1j),
                                  lambda: Newton([0.5]), lambda: Ma(None), lambda: Ma(True)])
def test_law_parameters_must_be_real_numbers(make):
    with pytest.raises(RestitutionError, match="not a real number") as info:
        make()
    _one_line(info)


def test_callable_law_that_fails_is_a_restitution_error():
    with pytest.raises(RestitutionError, match="cannot be evaluated") as info:
        CustomRestitution(lambda: 1.0)
    _one_line(info)


def test_law_that_raises_at_an_impact_is_a_model_error():
    def law(v):
        if np.ndim(v) == 0:
            raise RuntimeError("boom")
        return 0.9 + 0 * v

    m = DuffingImpact(c=0.0, D=0.0, restitution=CustomRestitution(law))
    with pytest.raises(ModelError, match="reset of transition 'right' failed.*RuntimeError: boom") as info:
        simulate_orbit(m, (0.0, 2.2), 5.0)
    _one_line(info)


# regression: barriers=(None, 'delta') raised AttributeError; it is now a one-sided stop (tests/test_geometries.py)
@pytest.mark.parametrize("barriers,words", [(3, "use 'delta'"), (("a", "b", "c"), "use 'delta'"),
                                            (("delta", "a"), "enclose or touch")])
def test_bad_barriers_are_model_errors(barriers, words):
    with pytest.raises(ModelError, match=words) as info:
        ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.05, "delta": 1.0, "a": -1, "b": 1},
                         barriers=barriers)
    _one_line(info)


# regression: a non positive semi-definite intensity matrix was accepted by averaging; a complex one too
@pytest.mark.parametrize("intensity,cls,words", [
    ([[0.05, 1.0], [1.0, 0.05]], ParameterError, "not positive semi-definite"),
    ([[-0.05, 0.0], [0.0, 0.05]], ParameterError, "not positive semi-definite"),
    ([["I*D", 0], [0, "D"]], ModelError, "neither the states"),
    ([[1j, 0], [0, 1]], ModelError, "not a finite real expression"),
])
def test_bad_intensity_matrices_are_refused(intensity, cls, words):
    with pytest.raises(cls, match=words) as info:
        ImpactOscillator("x", "c*y", noise=(1, "x"), intensity=intensity,
                         parameters={"c": 0.1, "D": 0.05, "delta": 1.0})
    _one_line(info)


def test_negative_scalar_intensity_expression_is_refused_and_psd_is_rechecked_on_new_parameters():
    with pytest.raises(ParameterError, match="not positive semi-definite"):
        ImpactOscillator("x", "c*y", intensity="-D", parameters={"c": 0.1, "D": 0.05, "delta": 1.0})
    m = ImpactOscillator("x", "c*y", noise=(1, "x"), intensity=[["D", "K"], ["K", "D"]],
                         parameters={"c": 0.1, "D": 0.05, "K": 0.0, "delta": 1.0})
    with pytest.raises(ParameterError, match="not positive semi-definite"):
        m.with_params(K=1.0)
    with pytest.raises(ParameterError, match="not a number"):
        stationary_density(DuffingImpact().with_params(D=1j))


@pytest.mark.parametrize("kwargs,words", [(dict(noise=3), "sequence of coefficients"),
                                          (dict(parameters=[1]), "mapping of names")])
def test_declaration_type_confusion_is_a_model_error(kwargs, words):
    with pytest.raises(ModelError, match=words):
        ImpactOscillator("x", **kwargs)


def test_every_error_class_is_a_vibro_error():
    for cls in (ModelError, ParameterError, RestitutionError):
        assert issubclass(cls, VibroError)
