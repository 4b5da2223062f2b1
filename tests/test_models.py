"""Models, restitution laws and the hybrid automaton: declarations, derived quantities, clear errors."""

import math

import numpy as np
import pytest
import sympy as sp
from problems import duffing_potential

from hybrid import HybridAutomaton, Mode, ModelError, ParameterError, RestitutionError, Transition
from models import (
    CustomRestitution,
    DuffingImpact,
    DuffingVanDerPolImpact,
    Elastic,
    ImpactOscillator,
    Ma,
    Newton,
    RayleighImpact,
    X,
    Y,
    make_model,
    parse_restitution,
)


def test_ma_law_matches_eqs_3_4():
    law = Ma(vc=0.4)
    v = np.array([0.1, 0.4, 0.41, 1.0, 25.6])
    expected = np.where(v <= 0.4, 1.0, 0.4 ** (1 / 6) * v ** (-1 / 6))
    np.testing.assert_allclose(law.coefficient(v), expected, rtol=1e-15)
    assert law.coefficient(-1.0) == law.coefficient(1.0)  # the speed |v-| enters
    assert law.omega == pytest.approx(0.4 ** (1 / 6))


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.5])
def test_newton_outside_unit_interval_is_refused(bad):
    with pytest.raises(RestitutionError, match=r"\(0, 1\]"):
        Newton(bad)


def test_custom_law_checked_and_symbolic():
    law = CustomRestitution("1/(1 + v)")
    assert law.coefficient(1.0) == pytest.approx(0.5)
    with pytest.raises(RestitutionError, match="outside"):
        CustomRestitution("1 + v")
    with pytest.raises(RestitutionError, match="only on the speed"):
        CustomRestitution("q*v")
    with pytest.raises(RestitutionError, match="symbolic"):
        CustomRestitution(lambda v: 0.9 + 0 * v).expression()


def test_parse_restitution_specs():
    assert parse_restitution("elastic") == Elastic()
    assert parse_restitution("newton:e=0.5") == Newton(0.5)
    assert parse_restitution("ma:vc=0.4") == Ma(0.4)
    with pytest.raises(ParameterError):
        parse_restitution("bogus")
    with pytest.raises(ParameterError):
        parse_restitution("ma:vc")


def test_duffing_potential_energy_and_amplitude():
    m = DuffingImpact(a=1.3, b=0.7)
    x = np.linspace(-1, 1, 11)
    np.testing.assert_allclose(m.potential(x), duffing_potential(x, 1.3, 0.7), rtol=1e-14)
    H = np.array([1e-9, 0.01, 0.3, 0.8])
    A = m.amplitude(H)
    np.testing.assert_allclose(duffing_potential(A, 1.3, 0.7), H, rtol=1e-12)
    # closed form and the generic root finder agree
    np.testing.assert_allclose(ImpactOscillator.amplitude(m, H), A, rtol=1e-12)
    lo, hi = m.turning_points(H)
    np.testing.assert_allclose(-lo, hi, rtol=1e-12)


def test_ito_coefficients_additive_and_multiplicative():
    m = DuffingImpact()
    a, b, c, D = sp.symbols("a b c D", real=True)
    assert sp.simplify(m.ito_drift - (-a * X - b * X**3 - c * Y)) == 0
    assert sp.simplify(m.diffusion_squared - 2 * D) == 0
    assert m.additive_noise
    # f = y: Wong-Zakai term D f df/dy = D y; sigma^2 = 2 D y^2
    mult = ImpactOscillator("x", "c*y", noise=("y",), parameters={"c": 0.1, "D": 0.01, "delta": 1.0})
    assert sp.simplify(mult.ito_drift - (-X - c * Y + D * Y)) == 0
    assert sp.simplify(mult.diffusion_squared - 2 * D * Y**2) == 0
    assert not mult.additive_noise


def test_correlated_two_noise_intensity_matrix():
    m = ImpactOscillator("x", 0, noise=("1", "x"), intensity=[["D1", "D12"], ["D12", "D2"]],
                         parameters={"D1": 1, "D2": 2, "D12": 0.5, "delta": 1.0}, nonnegative=("D1", "D2"))
    D1, D2, D12 = sp.symbols("D1 D2 D12", real=True)
    assert sp.simplify(m.diffusion_squared - 2 * (D1 + 2 * D12 * X + D2 * X**2)) == 0


def test_van_der_pol_reading_is_named():
    vdp = DuffingVanDerPolImpact()
    lit = DuffingVanDerPolImpact(reading="literal")
    c1, c2 = sp.symbols("c1 c2", real=True)
    assert sp.simplify(vdp.h - (c1 + c2 * X**2) * Y) == 0
    assert sp.simplify(lit.h - (c1 - c2 * X**2) * Y) == 0
    with pytest.raises(ModelError, match="reading"):
        DuffingVanDerPolImpact(reading="other")


@pytest.mark.parametrize(
    ("params", "match"),
    [({"delta": -1.0}, "delta"), ({"D": -0.1}, "noise intensity"), ({"zz": 1.0}, "unknown")],
)
def test_bad_parameters_are_refused(params, match):
    with pytest.raises(ParameterError, match=match):
        DuffingImpact().with_params(**params)


def test_unknown_symbol_in_declaration():
    with pytest.raises(ModelError, match="neither the states"):
        ImpactOscillator("k*x", parameters={"D": 0.1, "delta": 1.0})


def test_non_confining_and_double_well_potentials_are_refused():
    with pytest.raises(ModelError, match="single well"):
        DuffingImpact(a=-1.0).check_single_well()
    with pytest.raises(ModelError, match="does not confine the motion on the left: there is no wall"):
        ImpactOscillator("x - x**3/10", parameters={"D": 0.1}, barriers=None)  # refused when declared
    ImpactOscillator("x + x**3", parameters={"D": 0.1}, barriers=None).check_single_well()


def test_asymmetric_barriers_have_no_single_barrier_energy():
    m = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.1, "dl": 0.5, "dr": 1.0},
                         barriers=("-dl", "dr"), positive=("dl", "dr"))
    assert m.barriers == (-0.5, 1.0)
    assert not m.is_symmetric
    with pytest.raises(ModelError, match="G\\(left\\)"):
        _ = m.barrier_energy
    assert len(m.to_automaton().transitions) == 2


def test_potential_without_closed_form_falls_back_to_quadrature():
    m = ImpactOscillator("x*exp(sin(x))", parameters={"D": 0.1, "delta": 1.0})
    from scipy import integrate

    ref = integrate.quad(lambda s: s * math.exp(math.sin(s)), 0, 0.7, epsrel=1e-14)[0]
    assert m.potential_expr is None
    assert float(m.potential(0.7)) == pytest.approx(ref, rel=1e-12)


def test_automaton_from_model_and_validation():
    A = DuffingImpact().to_automaton()
    assert [t.name for t in A.transitions] == ["right", "left"]
    assert A.transitions[0].direction == 1 and A.transitions[1].direction == -1
    x, v = sp.symbols("x v")
    with pytest.raises(ModelError, match="must map every state"):
        HybridAutomaton(states=(x, v), parameters={}, modes=[Mode("m", (v, -x))],
                        transitions=[Transition("t", "m", "m", guard=x, reset=(x,))])
    with pytest.raises(ModelError, match="unknown symbols"):
        HybridAutomaton(states=(x, v), parameters={}, modes=[Mode("m", (v, -sp.Symbol("k") * x))])
    with pytest.raises(ModelError, match="unknown mode"):
        HybridAutomaton(states=(x, v), parameters={}, modes=[Mode("m", (v, -x))],
                        transitions=[Transition("t", "m", "nowhere", guard=x, reset=(x, v))])


def test_registry_and_user_model():
    assert make_model("duffing", {"delta": 0.8}).params["delta"] == 0.8
    assert RayleighImpact().with_restitution(Newton(0.9)).restitution == Newton(0.9)
    with pytest.raises(ParameterError, match="unknown model"):
        make_model("nope")
