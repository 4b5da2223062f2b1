"""Energy-envelope averaging: symbolic derivation, quadrature, stationary densities, methods, errors.

Every reference here is independent of the averaging code: mpmath periods with high-precision turning points,
closed forms (linear oscillator, elastic barriers), hand derivations of the Wong-Zakai term, and a direct
scipy-quad implementation of the corrected eqs. 36-38.
"""

import math

import mpmath as mp
import numpy as np
import pytest
import sympy as sp
from problems import ElasticStationary, elastic_duffing, linear_oscillator_energy_density, period_mpmath
from scipy import integrate

from averaging import (
    METHODS,
    action,
    averaged_coefficients,
    averaging_equations,
    period,
    stationary_density,
)
from averaging.jump import EnergyChain
from averaging.stationary import energy_table
from hybrid.errors import NormalisationError, ParameterError
from models import DuffingImpact, Elastic, ImpactOscillator, Ma, Newton, X, Y

# ----------------------------------------------------------------------------- oracles


def _mp_turning(G, H):
    """Positive root of G(x) = H in 40-digit arithmetic."""
    with mp.workdps(40):
        H = mp.mpf(H)
        lo, hi = mp.mpf(0), mp.mpf(1)
        while G(hi) < H:
            hi *= 2
        return mp.findroot(lambda x: G(x) - H, (lo, hi), solver="anderson")


def _mp_period_action(G, H, delta):
    """(T, loop action) by mpmath: turning points in 40 digits, or the barriers above G(delta)."""
    with mp.workdps(40):
        A = _mp_turning(G, H)
        lim = A if A < delta else mp.mpf(delta)
        T = period_mpmath(G, H, -lim, lim, dps=40)

        def s(x):
            gap = 2 * mp.mpf(H) - 2 * G(x)
            return mp.sqrt(gap) if gap > 0 else mp.mpf(0)

        act = float(2 * mp.quad(s, [-lim, lim]))
    return T, act


def g_duffing(x):
    return x * x / 2 + mp.mpf("0.2") * x**4 / 4


def g_quintic(x):
    return x * x / 2 + x**6 / 6


QUINTIC = dict(restoring="x + x**5", damping="c*y", parameters={"c": 0.05, "D": 0.04, "delta": 0.9})

# ----------------------------------------------------------------------------- quadrature


@pytest.mark.parametrize("which", ["duffing", "quintic"])
def test_period_and_action_match_mpmath_to_1e9(which):
    if which == "duffing":
        model, G, delta = DuffingImpact(delta=1.0), g_duffing, 1.0
    else:
        model, G, delta = ImpactOscillator(**QUINTIC), g_quintic, 0.9
    Gd = model.barrier_energy
    levels = [1e-10, 1e-6, 0.05, 0.3, Gd * (1 - 1e-6), Gd * (1 + 1e-9), Gd * (1 + 1e-6), Gd * 1.01, 1.5, 4.0]
    for H in levels:
        T_ref, A_ref = _mp_period_action(G, H, delta)
        assert period(model, H)[0] == pytest.approx(T_ref, rel=1e-9, abs=0), H
        assert action(model, H)[0] == pytest.approx(A_ref, rel=1e-9, abs=0), H


def test_linear_oscillator_period_and_area_closed_form():
    lin = ImpactOscillator("w2*x", parameters={"w2": 4.0, "D": 0.0}, barriers=None)
    H = np.array([1e-8, 0.5, 30.0])
    np.testing.assert_allclose(period(lin, H), np.pi, rtol=1e-12)  # 2 pi / omega, omega = 2
    np.testing.assert_allclose(action(lin, H), 2 * np.pi * H / 2.0, rtol=1e-12)  # area pi A * (omega A)


# ----------------------------------------------------------------------------- symbolic


def test_wong_zakai_and_sigma2_by_hand():
    c, D, D1, D2, D12 = sp.symbols("c D D1 D2 D12", real=True)
    # f = y (velocity-parametric noise): Stratonovich correction D f df/dy = D y
    m = ImpactOscillator("x", "c*y", noise=("y",), parameters={"c": 0.1, "D": 0.01}, barriers=None)
    eq = averaging_equations(m)
    assert sp.simplify(eq.drift - (-X - c * Y + D * Y)) == 0
    assert sp.simplify(eq.diffusion_squared - 2 * D * Y**2) == 0
    # f = x: no correction
    m = ImpactOscillator("x", "c*y", noise=("x",), parameters={"c": 0.1, "D": 0.01}, barriers=None)
    eq = averaging_equations(m)
    assert sp.simplify(eq.drift - (-X - c * Y)) == 0
    assert sp.simplify(eq.diffusion_squared - 2 * D * X**2) == 0
    # two noises f = (1, y), D = [[D1, D12], [D12, D2]]: D_jk f_j df_k/dy = D12 * 1 + D2 * y
    m = ImpactOscillator("x", "c*y", noise=("1", "y"), intensity=[["D1", "D12"], ["D12", "D2"]],
                         parameters={"c": 0.1, "D1": 0.01, "D2": 0.02, "D12": 0.0}, barriers=None,
                         nonnegative=("D1", "D2"))
    eq = averaging_equations(m)
    assert sp.simplify(eq.drift - (-X - c * Y + D12 + D2 * Y)) == 0
    assert sp.simplify(eq.diffusion_squared - 2 * (D1 + 2 * D12 * Y + D2 * Y**2)) == 0


def test_duffing_integrands_reduce_to_corrected_eqs_36_38():
    eq = averaging_equations(DuffingImpact())
    s = sp.Symbol("s", positive=True)
    c, D = sp.symbols("c D", real=True)
    assert sp.simplify(eq.drift_integrand - (2 * D / s - 2 * c * s)) == 0  # (1/T) int -> D - (2c/T) int y dx
    assert sp.simplify(eq.diffusion_integrand - 4 * D * s) == 0
    text = str(eq)
    assert "m_bar" in text and "sqrt(2*H" in text
    latex = eq.latex()
    assert r"\bar{\sigma}^2" in latex and r"\int" in latex


def test_velocity_parametric_noise_averaged_by_hand():
    # x'' + c x' + x = y xi (Stratonovich): m_bar = (2D - c) H, sigma2_bar = 3 D H**2 (hand integration)
    c, D = 0.1, 0.02
    m = ImpactOscillator("x", "c*y", noise=("y",), parameters={"c": c, "D": D}, barriers=None)
    H = np.array([0.01, 0.7, 5.0])
    coef = averaged_coefficients(m, H)
    np.testing.assert_allclose(coef.drift, (2 * D - c) * H, rtol=1e-12)
    np.testing.assert_allclose(coef.diffusion, 3 * D * H**2, rtol=1e-12)


def test_sign_dependent_damping_averages_both_branches():
    # h = c y + d y**2: the force d y**2 has the same sign on both branches and does no net work per cycle, so
    # m_bar is that of d = 0. Doubling the +y branch (eq. 21 read literally) would add -(2d/T) int y**2 dx.
    base = ImpactOscillator("x + x**3", "c*y", parameters={"c": 0.05, "D": 0.02}, barriers=None)
    quad = ImpactOscillator("x + x**3", "c*y + d*y**2", parameters={"c": 0.05, "d": 0.3, "D": 0.02}, barriers=None)
    H = np.array([0.05, 0.5, 2.0])
    np.testing.assert_allclose(averaged_coefficients(quad, H).drift, averaged_coefficients(base, H).drift,
                               rtol=1e-13)


# ----------------------------------------------------------------------------- stationary: exact cases


@pytest.mark.parametrize("method", sorted(METHODS))
def test_elastic_duffing_exact_density_and_moments(method):
    model, ex = elastic_duffing(delta=1.0)
    sd = stationary_density(model, method, h_max=70.0, points=1401)
    H = np.array([1e-4, 0.1, 0.4, model.barrier_energy * (1 + 1e-6), 0.9, 2.0, 6.0])
    np.testing.assert_allclose(sd.density(H), ex.energy_density(H), rtol=1e-6)
    assert sd.mean_x2 == pytest.approx(ex.mean_x2(), rel=1e-8)
    assert sd.prob_below_barrier == pytest.approx(ex.probability_below(model.barrier_energy), rel=1e-8)
    assert sd.impact_rate == pytest.approx(2 * ex.impact_rate_per_wall(), rel=1e-8)


def test_elastic_quintic_potential_exact_density():
    model = ImpactOscillator(**QUINTIC, restitution=Elastic())
    ex = ElasticStationary(lambda x: x * x / 2 + x**6 / 6, 0.05, 0.04, 0.9)
    sd = stationary_density(model, "paper", h_max=40.0, points=801)
    H = np.array([1e-3, 0.2, model.barrier_energy * (1 - 1e-7), model.barrier_energy * (1 + 1e-7), 1.0, 3.0])
    np.testing.assert_allclose(sd.density(H), ex.energy_density(H, G_delta=model.barrier_energy), rtol=1e-6)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_linear_oscillator_without_barriers_exponential_density(method):
    c, D, h_max = 0.1, 0.05, 20.0
    lin = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    sd = stationary_density(lin, method, h_max=h_max, points=500)
    exact = linear_oscillator_energy_density(sd.H, c, D) / (1 - math.exp(-c * h_max / D))
    np.testing.assert_allclose(sd.p, exact, rtol=1e-9)
    assert sd.prob_below_barrier == 1.0 and sd.impact_rate == 0.0


def test_joint_density_and_marginals_elastic_exact():
    model, ex = elastic_duffing(delta=1.0)
    sd = stationary_density(model, "paper", h_max=70.0, points=301)
    x = np.array([-0.99, -0.5, 0.0, 0.3, 0.8])
    np.testing.assert_allclose(sd.marginal_x(x), ex.marginal_x(x), rtol=1e-7)
    y = np.array([0.0, 0.7, -1.5, 3.0])
    var = ex.D / ex.c
    np.testing.assert_allclose(sd.marginal_y(y), np.exp(-y * y / (2 * var)) / np.sqrt(2 * np.pi * var), rtol=1e-7)
    # eq. 31 directly: p(x, y) = exp(-c H / D) / Z on the strip
    xx, yy = np.array([0.0, 0.5, 1.2]), np.array([0.3, -1.0])
    H = 0.5 * yy[:, None] ** 2 + model.potential(xx)[None, :]
    Z = ex._z() * math.sqrt(2 * math.pi * var)
    expected = np.where(np.abs(xx)[None, :] <= 1.0, np.exp(-ex.beta * H) / Z, 0.0)
    np.testing.assert_allclose(sd.joint(xx, yy), expected, rtol=1e-7)


# ----------------------------------------------------------------------------- paper method vs direct eqs. 36-38


def _eqs_36_38_log_density(H_values, a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0, vc=0.4):
    """log p(H) (up to a constant) by plain scipy quad of the corrected eqs. 36-38 and eq. 30 (independent)."""
    def G(x):
        return 0.5 * a * x * x + 0.25 * b * x**4

    Gd = G(delta)

    def e(v):
        return 1.0 if v <= vc else (vc / v) ** (1 / 6)

    def coeffs(h):
        if h < Gd:
            A = math.sqrt((math.sqrt(a * a + 4 * b * h) - a) / b)
            # x = A sin(t): 2H - 2G(x) = cos(t)**2 (a A**2 + b A**4 (1 + sin(t)**2) / 2), so dx / y is smooth
            q = lambda t: math.sqrt(a * A * A + 0.5 * b * A**4 * (1 + math.sin(t) ** 2))  # noqa: E731
            T = 2 * 2 * integrate.quad(lambda t: A / q(t), 0, math.pi / 2, epsabs=0, epsrel=1e-13)[0]
            I = 2 * integrate.quad(lambda t: A * math.cos(t) ** 2 * q(t), 0, math.pi / 2, epsabs=0, epsrel=1e-13)[0]
            loss = 0.0
        else:
            y = lambda x: math.sqrt(2 * h - 2 * G(x))  # noqa: E731
            T = 2 * 2 * integrate.quad(lambda x: 1 / y(x), 0, delta, epsabs=0, epsrel=1e-13, limit=200)[0]
            I = 2 * integrate.quad(y, 0, delta, epsabs=0, epsrel=1e-13, limit=200)[0]
            v = math.sqrt(2 * (h - Gd))
            loss = (1 - e(v) ** 4) * (h - Gd)
        m = D - 2 * c * I / T - loss / T
        s2 = 4 * D * I / T
        return m, s2

    def f(h):
        m, s2 = coeffs(h)
        return 2 * m / s2 - 1 / h

    out, acc, prev = [], 0.0, 0.0
    for h in H_values:
        pts = [p for p in (Gd, Gd + vc * vc / 2) if prev < p < h]
        acc += integrate.quad(f, prev, h, points=pts or None, epsabs=1e-11, epsrel=1e-11, limit=200)[0]
        prev = h
        out.append(acc + math.log(h) - math.log(coeffs(h)[1]))
    return np.array(out)


def test_paper_method_equals_direct_eqs_36_38():
    model = DuffingImpact()
    sd = stationary_density(model, "paper", h_max=4.0, points=401)
    H = np.array([0.2, 0.5, 0.56, 0.7, 1.1, 2.0, 3.5])
    ref = _eqs_36_38_log_density(H)
    ours = np.log(sd.density(H))
    diff = ours - ref
    assert np.ptp(diff) < 1e-7


def test_exact_two_impact_loss_formula():
    law = Ma(vc=0.4)
    excess = np.array([0.01, 0.5, 2.0])
    v = np.sqrt(2 * excess)
    e1 = np.where(v <= 0.4, 1.0, (0.4 / v) ** (1 / 6))
    v2 = e1 * v
    e2 = np.where(v2 <= 0.4, 1.0, (0.4 / v2) ** (1 / 6))
    np.testing.assert_allclose(METHODS["exact-two-impact"].loss(law, excess), (1 - e1**2 * e2**2) * excess,
                               rtol=1e-14)
    np.testing.assert_allclose(METHODS["paper"].loss(law, excess), (1 - e1**4) * excess, rtol=1e-14)


# ----------------------------------------------------------------------------- jump method


def test_jump_equals_eq30_without_jumps():
    model, _ = elastic_duffing(delta=1.0)
    a = stationary_density(model, "jump", h_max=4.0, points=2000)
    b = stationary_density(model, "paper", h_max=4.0, points=2000)
    np.testing.assert_allclose(a.p, b.p, rtol=1e-12)
    # Ma law with a critical speed above every impact speed on the grid: all impacts elastic, no jumps
    fast = DuffingImpact(restitution=Ma(vc=10.0))
    np.testing.assert_allclose(stationary_density(fast, "jump", points=500).p,
                               stationary_density(fast, "paper", points=500).p, rtol=1e-12)


def test_jump_tends_to_drift_methods_as_impacts_become_elastic():
    # e = 1 - eps: jumps become small and the jump process tends to the drift-loss equation (difference O(eps))
    dist = []
    for eps in (1e-2, 1e-3):
        m = DuffingImpact(restitution=Newton(1 - eps))
        pj = stationary_density(m, "jump", points=2000)
        pp = stationary_density(m, "exact-two-impact", points=2000)
        dist.append(np.trapezoid(np.abs(pj.p - pp.p), pj.H))
    assert dist[1] < dist[0] / 5
    assert dist[1] < 2e-3


def test_chain_sweep_solves_the_sparse_stationary_equation():
    from scipy.sparse.linalg import spsolve

    model = DuffingImpact(delta=0.8)
    grid = np.linspace(0, 4.0, 600)
    chain = EnergyChain(energy_table(model, 4.0), grid, METHODS["jump"], model.restitution)
    pi = chain.stationary_masses()
    A = chain.generator().T.tolil()
    A[0, :] = 1.0  # replace one balance equation by the normalisation
    rhs = np.zeros(len(grid))
    rhs[0] = 1.0
    ref = spsolve(A.tocsc(), rhs)
    np.testing.assert_allclose(pi, ref, rtol=1e-8, atol=1e-14)
    assert np.all(pi > 0)


def test_jump_tail_does_not_depend_on_where_the_grid_stops():
    # p(H) at fixed H must not feel h_max: a reflecting top made d(p/p0)/dH = 0 there and the tail 50 % too heavy
    model = DuffingImpact()
    H = np.array([3.0, 3.5, 3.9])
    short = stationary_density(model, "jump", h_max=4.0, points=400)
    long = stationary_density(model, "jump", h_max=8.0, points=800)
    ratio_short = short.density(H) / short.density(1.0)
    ratio_long = long.density(H) / long.density(1.0)
    np.testing.assert_allclose(ratio_short, ratio_long, rtol=0.03)


def test_jump_method_statistics_are_consistent():
    sd = stationary_density(DuffingImpact(), "jump", points=2000)
    assert sd.total_mass == pytest.approx(1.0, abs=1e-12)
    assert np.trapezoid(sd.p * sd.H, sd.H) == pytest.approx(sd.mean_energy, rel=1e-5)
    paper = stationary_density(DuffingImpact(), "paper", points=2000)
    # impacts as jumps: more probability below the impact level and a lower mean energy than eq. 13 as a drift
    assert sd.mean_energy < paper.mean_energy
    assert sd.prob_below_barrier > paper.prob_below_barrier


# ----------------------------------------------------------------------------- errors


def test_negative_damping_without_barrier_cannot_be_normalised():
    m = ImpactOscillator("x", "c*y", parameters={"c": -0.01, "D": 0.01}, barriers=None)
    with pytest.raises(NormalisationError, match="drifts to infinity"):
        stationary_density(m, "paper")


def test_double_well_is_refused():
    m = ImpactOscillator("-x + x**3", "c*y", parameters={"c": 0.1, "D": 0.01, "delta": 2.0})
    with pytest.raises(NormalisationError, match="single well"):
        stationary_density(m, "paper")


def test_bad_inputs_have_clear_errors():
    with pytest.raises(ParameterError, match="unknown averaging method"):
        stationary_density(DuffingImpact(), "nope")
    with pytest.raises(ParameterError, match="h_max"):
        stationary_density(DuffingImpact(), "paper", h_max=-1.0)
    with pytest.raises(ParameterError, match="points"):
        stationary_density(DuffingImpact(), "paper", points=2)
    with pytest.raises(NormalisationError, match="noise"):
        stationary_density(DuffingImpact(D=0.0), "paper")
    with pytest.raises(ParameterError, match="H > 0"):
        averaged_coefficients(DuffingImpact(), [0.0])


def test_pandas_output():
    sd = stationary_density(DuffingImpact(), "exact-two-impact", points=50)
    df = sd.to_pandas()
    assert list(df.columns) == ["H", "p"] and len(df) == 50
    assert df.attrs["method"] == "exact-two-impact"
    coef = averaged_coefficients(DuffingImpact(), [0.3, 0.9], "jump").to_pandas()
    assert coef["jump_rate"].iloc[0] == 0.0 and coef["jump_rate"].iloc[1] > 0


def test_exact_two_impact_with_coincident_kinks_is_normalised():
    # for the Ma law the second-impact kink e(v) v = vc falls on v = vc itself (regression: a zero-width piece)
    m = DuffingImpact(restitution=Ma(vc=0.05)).with_params(delta=0.6, D=0.01)
    a = stationary_density(m, "exact-two-impact", points=400)
    b = stationary_density(m, "paper", points=400)
    assert a.total_mass == pytest.approx(1.0, abs=1e-12)
    assert a.mean_energy == pytest.approx(b.mean_energy, rel=0.05)
    assert np.all(np.isfinite(a.p))


def test_jump_chain_converges_at_second_order_in_the_grid():
    m = DuffingImpact()
    Hf = np.linspace(0, 4, 2001)
    ref = stationary_density(m, "jump", points=4001).density(Hf)
    err = [np.trapezoid(np.abs(stationary_density(m, "jump", points=n).density(Hf) - ref), Hf)
           for n in (251, 501, 1001)]
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert np.all(orders > 1.8), orders
    assert err[-1] < 1e-5


def test_potential_without_closed_form_elastic_exact():
    # sympy cannot integrate g = x + atan(x)**3: the averaging builds G numerically; elastic barriers stay exact
    model = ImpactOscillator("x + atan(x)**3", "c*y", parameters={"c": 0.05, "D": 0.05, "delta": 1.0},
                             restitution=Elastic())
    assert model.potential_expr is None

    def G(x):
        return mp.quad(lambda s: s + mp.atan(s) ** 3, [0, x])

    ex = ElasticStationary(lambda x: float(G(x)), 0.05, 0.05, 1.0)
    sd = stationary_density(model, "jump", h_max=40.0, points=801)
    Gd = float(G(1.0))
    assert sd.barrier_energy == pytest.approx(Gd, rel=1e-14)
    H = np.array([0.3, 2.0])
    np.testing.assert_allclose(sd.density(H), ex.energy_density(H, G_delta=Gd), rtol=1e-6)


def test_custom_restitution_laws_are_kept_apart_and_kinks_found():
    m = DuffingImpact()
    a = stationary_density(m.with_restitution(Newton(0.9)), "paper", points=200)
    b = stationary_density(m.with_restitution(Newton(0.5)), "paper", points=200)
    assert a.mean_energy > b.mean_energy  # more dissipation, lower energy (a shared table must not mix laws)
    # the Ma law written by hand as a custom Piecewise expression gives the same density (kink at v = 0.4 found)
    from models import CustomRestitution

    c = stationary_density(m.with_restitution(CustomRestitution("Piecewise((1, v <= 0.4), ((0.4/v)**(1/6), True))")),
                           "paper", points=200)
    np.testing.assert_allclose(c.p, stationary_density(m, "paper", points=200).p, rtol=1e-12)


def test_asymmetric_well_period_matches_mpmath():
    # G = x^2/2 + 0.1 x^3 + x^4/4 (g = x + 0.3 x^2 + x^3): different turning points on each side
    model = ImpactOscillator("x + 0.3*x**2 + x**3", parameters={"D": 0.0}, barriers=None)

    def G(x):
        return x * x / 2 + mp.mpf("0.1") * x**3 + x**4 / 4

    for H in (1e-6, 0.2, 3.0):
        with mp.workdps(40):
            hi = mp.findroot(lambda x, H=H: G(x) - H, (mp.mpf(0), mp.mpf(4)), solver="anderson")
            lo = mp.findroot(lambda x, H=H: G(x) - H, (mp.mpf(-4), mp.mpf(0)), solver="anderson")
            T_ref = period_mpmath(G, H, lo, hi, dps=40)
        assert period(model, H)[0] == pytest.approx(T_ref, rel=1e-9)
