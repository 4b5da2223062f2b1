"""Transient FPK and mean first-passage times against exact results for the averaged linear oscillator."""

import math

import numpy as np
import pytest
from scipy import integrate

from averaging import mean_first_passage_time, stationary_density, transient_density
from hybrid.errors import ParameterError
from models import DuffingImpact, ImpactOscillator

C, D = 0.1, 0.1


def _linear():
    return ImpactOscillator("x", "c*y", parameters={"c": C, "D": D}, barriers=None)


def test_linear_mean_energy_relaxes_exactly_exponentially():
    # averaged equation dH = (D - c H) dt + sqrt(2 D H) dW: E[H(t)] = D/c + (H0 - D/c) exp(-c t) exactly
    t = np.array([0.0, 1.0, 5.0, 10.0, 30.0])
    tr = transient_density(_linear(), 3.0, t, h_max=30.0, points=1000)
    exact = D / C + (3.0 - D / C) * np.exp(-C * t)
    np.testing.assert_allclose(tr.mean_energy, exact, rtol=1e-4)
    assert tr.p.min() >= 0.0
    np.testing.assert_allclose(tr.masses.sum(axis=1), 1.0, rtol=1e-13)


def test_implicit_euler_is_positive_conservative_and_first_order():
    t = np.array([0.0, 5.0, 10.0])
    exact = D / C + (3.0 - D / C) * np.exp(-C * t)
    errs = []
    for dt in (0.2, 0.1):
        tr = transient_density(_linear(), 3.0, t, h_max=30.0, points=400, scheme="implicit-euler", dt=dt)
        assert tr.masses.min() >= 0.0
        np.testing.assert_allclose(tr.masses.sum(axis=1), 1.0, rtol=1e-12)
        errs.append(abs(tr.mean_energy[-1] - exact[-1]))
    assert 1.6 < errs[0] / errs[1] < 2.4  # first order in time


@pytest.mark.parametrize("method", ["paper", "jump"])
def test_transient_relaxes_to_the_stationary_density(method):
    model = DuffingImpact()
    tr = transient_density(model, 1.0, [0.0, 1500.0], method=method, h_max=4.0, points=200)
    sd = stationary_density(model, method, h_max=4.0, points=200)
    assert np.trapezoid(np.abs(tr.p[-1] - sd.p), sd.H) < 1e-8
    np.testing.assert_allclose(tr.p[-1], sd.p, rtol=1e-6)


def test_mean_first_passage_time_matches_the_quadrature_formula():
    # MFPT(0 -> Hc) = int_0^Hc 2 / (s2(z) p_s(z)) int_0^z p_s(u) du dz with p_s = exp(-c z / D), s2 = 2 D z
    Hc = 4.0
    exact = integrate.quad(lambda z: math.expm1(C * z / D) / z, 0, Hc, epsabs=0, epsrel=1e-13)[0] / C
    got = mean_first_passage_time(_linear(), Hc, 0.0, points=1000)
    assert got == pytest.approx(exact, rel=2e-6)
    # from an intermediate level: int_H0^Hc of the same integrand
    exact_mid = integrate.quad(lambda z: math.expm1(C * z / D) / z, 1.0, Hc, epsabs=0, epsrel=1e-13)[0] / C
    assert mean_first_passage_time(_linear(), Hc, 1.0, points=1000) == pytest.approx(exact_mid, rel=2e-6)


def test_transient_bad_input():
    with pytest.raises(ParameterError, match="H0"):
        transient_density(_linear(), 50.0, [0.0, 1.0], h_max=30.0)
    with pytest.raises(ParameterError, match="scheme"):
        transient_density(_linear(), 1.0, [0.0, 1.0], h_max=30.0, scheme="rk4")
    with pytest.raises(ParameterError, match="increasing"):
        transient_density(_linear(), 1.0, [1.0, 0.0], h_max=30.0)
    with pytest.raises(ParameterError, match="finite"):
        transient_density(_linear(), 1.0, [0.0, math.nan], h_max=30.0)
    with pytest.raises(ParameterError, match="points"):
        transient_density(_linear(), 1.0, [0.0, 1.0], h_max=30.0, points=2)


def test_mfpt_bad_input_is_refused_not_truncated_or_nan():
    with pytest.raises(ParameterError, match="points"):
        mean_first_passage_time(_linear(), 1.0, points=2.5)
    with pytest.raises(ParameterError, match="points"):
        mean_first_passage_time(_linear(), 1.0, points=1)
    with pytest.raises(ParameterError, match="starting energies"):
        mean_first_passage_time(_linear(), 1.0, H0=math.nan, points=50)
    with pytest.raises(ParameterError, match="H_c"):
        mean_first_passage_time(_linear(), math.inf, points=50)


def test_mfpt_with_impacts_matches_the_quadrature_formula_on_direct_coefficients():
    # Duffing with Ma impacts, paper method: the backward-equation solve on the chain against the 1-D formula
    # MFPT = int_0^Hc 2/(s2 p_s) int_0^z p_s, evaluated on a fine grid from directly averaged coefficients
    from averaging import averaged_coefficients

    model = DuffingImpact()
    Hc = 1.5
    Gd = model.barrier_energy
    # below G(delta) integrate in H; above it in u = sqrt(H - G(delta)), where the coefficients are smooth
    z1 = np.linspace(0.0, Gd, 3001)[1:]
    u = np.linspace(0.0, math.sqrt(Hc - Gd), 3001)[1:]
    z2 = Gd + u * u

    def cumulative(g1, g2):
        """int_0^z g dH on z1 then z2 (first panels by the rectangle rule at the first node)."""
        a = integrate.cumulative_simpson(g1, x=z1, initial=0.0) + g1[0] * z1[0]
        b = a[-1] + integrate.cumulative_simpson(g2 * 2 * u, x=u, initial=0.0) + g2[0] * u[0] ** 2
        return a, b

    c1, c2 = averaged_coefficients(model, z1, "paper"), averaged_coefficients(model, z2, "paper")
    f1, f2 = 2 * c1.drift / c1.diffusion - 1 / z1, 2 * c2.drift / c2.diffusion - 1 / z2  # regular at 0
    phi1, phi2 = cumulative(f1, f2)
    ps1, ps2 = np.exp(phi1 + np.log(z1)) / c1.diffusion, np.exp(phi2 + np.log(z2)) / c2.diffusion
    in1, in2 = cumulative(ps1, ps2)
    out1, out2 = cumulative(2 * in1 / (c1.diffusion * ps1), 2 * in2 / (c2.diffusion * ps2))
    exact = out2[-1]
    got = mean_first_passage_time(model, Hc, 0.0, method="paper", points=1500)
    assert got == pytest.approx(exact, rel=1e-5)
