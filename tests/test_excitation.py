"""Coloured noise as filter states (models.excitation) against closed forms.

- The filter output's stationary variance: alpha D (Ornstein-Uhlenbeck), 2 zeta omega_f D (band-pass).
- Its spectrum, seen through a linear oscillator without barriers: Var x = int |H(iw)|^2 S_z(w) dw and
  Var x' = int w^2 |H(iw)|^2 S_z(w) dw (quadrature of the closed-form spectral densities), for three OU bandwidths
  and one band-pass filter. The splitting scheme's own bias is known exactly for a linear system (its one-step
  map is linear: a discrete Lyapunov equation), and it is the only allowance beyond the 95 % interval.
- As the bandwidth grows, the impact oscillator's mean energy tends to the exact Gibbs value of white noise
  (elastic impacts, linear damping: p proportional to exp(-c H / D) between the barriers).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy import integrate, linalg

from hybrid.errors import ModelError, ParameterError
from hybrid.stochastic import simulate_automaton
from models import DuffingImpact, Elastic, ImpactOscillator
from models.automata import impact_pair
from models.excitation import attach_filter, bandpass_filter, ou_filter

W0, C, D = 1.0, 0.5, 0.25  # x'' + C x' + W0^2 x = z


def linear(**extra):
    return ImpactOscillator("w2*x", "c*y", parameters={"w2": W0**2, "c": C, "D": D}, barriers=None, name="lin")


def spectrum(kind, w, alpha=None, zeta=None, omega_f=None):
    """Closed-form two-sided spectral density of the filter output (white limit: D / pi)."""
    if kind == "ou":
        return D / math.pi * alpha**2 / (alpha**2 + w**2)
    b = 2 * zeta * omega_f
    return D / math.pi * b**2 * w**2 / ((omega_f**2 - w**2) ** 2 + b**2 * w**2)


def response(kind, **fp):
    """(Var z, Var x, Var x') by quadrature of S and |H|^2 S over the real line."""
    def q(f):
        return 2 * integrate.quad(f, 0, np.inf, limit=400, epsabs=1e-13, epsrel=1e-11)[0]

    h2 = lambda w: 1.0 / ((W0**2 - w**2) ** 2 + (C * w) ** 2)  # noqa: E731
    return (q(lambda w: spectrum(kind, w, **fp)), q(lambda w: h2(w) * spectrum(kind, w, **fp)),
            q(lambda w: w**2 * h2(w) * spectrum(kind, w, **fp)))


def splitting_chain(dt, b, wf2):
    """Stationary covariance of [x, y, z_int, z] under the splitting scheme's exact linear one-step map:
    half kick of the velocities (y, z), free flight of the positions (x, z_int), noise on z, half kick."""
    A = np.array([[0, 1, 0, 0], [-W0**2, -C, 0, 1], [0, 0, 0, 1], [0, 0, -wf2, -b]], dtype=float)
    B = np.array([[0], [0], [0], [b * math.sqrt(2 * D)]])
    vel, pos = np.diag([0, 1, 0, 1]), np.diag([1, 0, 1, 0])
    K = np.eye(4) + 0.5 * dt * vel @ A
    F = np.eye(4) + dt * pos @ A
    M, N = K @ F @ K, K @ B
    if wf2 == 0.0:  # OU: z_int is a random walk that drives nothing; the rest is stationary
        keep = [0, 1, 3]
        P = np.zeros((4, 4))
        sub = np.ix_(keep, keep)
        P[sub] = linalg.solve_discrete_lyapunov(M[sub], (N @ N.T)[sub] * dt)
        return P
    return linalg.solve_discrete_lyapunov(M, N @ N.T * dt)


def run(A, dt, seed, t_end=1500.0):
    # the model's H first, then z2, x2, y2: the observables (and so the kernel) of the OU-filtered `vibro mc` run in
    # test_cli_automaton_mc.py
    return simulate_automaton(A, "splitting", dt=dt, paths=64, t_end=t_end, t_burn=30.0, x0=(0, 0, 0, 0),
                              seed=seed, chunk_paths=4,
                              observables={"H": A.observables["H"], "z2": "z**2", "x2": "x**2", "y2": "y**2"},
                              histograms={"H": (0, 1e3, 1), "z2": (0, 1e3, 1), "x2": (0, 1e3, 1), "y2": (0, 1e3, 1)})


def check(ens, exact, chain):
    for k, (name, i) in enumerate((("z2", 3), ("x2", 0), ("y2", 1))):
        est = ens.mean(name)
        bias = abs(chain[i, i] - exact[k])
        assert bias < 0.02 * exact[k], (name, chain[i, i], exact[k])  # the scheme's own bias is small here
        assert abs(est.value - exact[k]) <= 3 * est.ci + bias, (name, est, exact[k], bias)


def test_closed_form_spectra_integrate_to_the_stated_variances():
    # the module's normalisation: Var z = alpha D (OU), 2 zeta omega_f D (band-pass); white limit S = D / pi
    assert response("ou", alpha=3.0)[0] == pytest.approx(3.0 * D, rel=1e-9)
    assert response("bandpass", zeta=0.3, omega_f=2.0)[0] == pytest.approx(2 * 0.3 * 2.0 * D, rel=1e-9)
    assert spectrum("ou", 0.7, alpha=1e6) == pytest.approx(D / math.pi, rel=1e-9)
    assert spectrum("bandpass", 0.7, zeta=1e6, omega_f=1.0) == pytest.approx(D / math.pi, rel=1e-9)


@pytest.mark.parametrize("alpha", [0.5, 2.0, 8.0])
def test_ou_output_variance_and_oscillator_response_match_the_spectrum(alpha):
    dt = min(0.01, 0.04 / alpha)  # keeps the scheme's bias on Var z near 1 %
    exact = response("ou", alpha=alpha)
    ens = run(ou_filter(linear(), alpha=alpha), dt, seed=11)
    check(ens, exact, splitting_chain(dt, alpha, 0.0))
    # the spectrum's shape matters: white noise of the same intensity gives Var x = D / (c w0^2)
    white = D / (C * W0**2)
    if alpha < 4:
        assert abs(ens.mean("x2").value - white) > 10 * ens.mean("x2").ci


def test_bandpass_output_variance_and_oscillator_response_match_the_spectrum():
    dt, zeta, wf = 0.01, 0.25, 1.5
    exact = response("bandpass", zeta=zeta, omega_f=wf)
    ens = run(bandpass_filter(linear(), zeta=zeta, omega_f=wf), dt, seed=12)
    check(ens, exact, splitting_chain(dt, 2 * zeta * wf, wf**2))


def gibbs_linear_between_walls(c, d, delta, edges):
    """Exact white-noise stationary E[H] and bin masses of H: p(H) proportional to T(H) exp(-c H / D), T(H) the
    period of the linear oscillator x'' + x = 0 cut by elastic walls at +-delta."""
    theta = d / c

    def period(H):
        return 2 * math.pi if H <= delta**2 / 2 else 4 * math.asin(delta / math.sqrt(2 * H))

    def moment(k):
        return integrate.quad(lambda H: H**k * period(H) * math.exp(-H / theta), 0, 60 * theta,
                              points=[delta**2 / 2], limit=400)[0]

    masses = np.array([integrate.quad(lambda H: period(H) * math.exp(-H / theta), a, b)[0]
                       for a, b in zip(edges[:-1], edges[1:])]) / moment(0)
    return moment(1) / moment(0), masses


def test_impact_oscillator_tends_to_the_white_noise_gibbs_density_as_the_bandwidth_grows():
    # measured: the coloured-noise deficit of E[H] is first order in 1/alpha here (alpha * gap = -0.45 +- 0.03 at
    # alpha = 16, 32, 64), so the limit is checked by extrapolating a fit E = E_inf + a / alpha
    c, d, delta = 0.5, 0.25, 0.6
    model = ImpactOscillator("x", "c*y", parameters={"c": c, "D": d, "delta": delta}, restitution=Elastic())
    edges = np.linspace(0.0, 3.0, 31)
    gibbs, masses = gibbs_linear_between_walls(c, d, delta, edges)
    alphas, means, sigmas, l1 = [2.0, 16.0, 32.0, 64.0], [], [], []
    A = ou_filter(model, alpha=1.0)
    for alpha in alphas:
        ens = simulate_automaton(A, "splitting", dt=0.005, paths=64, t_end=1000.0, t_burn=20.0, x0=(0, 0, 0, 0),
                                 seed=5, chunk_paths=4, params={"alpha": alpha}, histograms={"H": (0.0, 3.0, 30)})
        est = ens.mean("H")
        means.append(est.value)
        sigmas.append(est.ci / 1.96)
        l1.append(float(np.abs(ens.counts["H"][1:-1] / ens.flags["samples"] - masses).sum()))
    gaps = [gibbs - m for m in means]
    assert gaps[0] > gaps[1] + 3 * (sigmas[0] + sigmas[1]), gaps
    assert l1[0] > l1[1] > l1[3], l1  # p(H) too: closer to the white-noise Gibbs density as alpha grows
    X = np.column_stack([np.ones(3), 1.0 / np.array(alphas[1:])])
    w = 1.0 / np.array(sigmas[1:]) ** 2
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    e_inf, slope = cov @ X.T @ (w * np.array(means[1:]))
    assert slope < -3 * math.sqrt(cov[1, 1]), (slope, cov, means)  # the deficit shrinks as 1 / alpha
    assert abs(e_inf - gibbs) <= 3 * math.sqrt(cov[0, 0]), (e_inf, math.sqrt(cov[0, 0]), gibbs, means)


@pytest.mark.slow
def test_impact_oscillator_with_band_pass_noise_tends_to_the_white_noise_gibbs_mean():
    # as for OU noise, the deficit is first order in the bandwidth b = 2 zeta omega_f (b * gap about -0.4)
    c, d, delta = 0.5, 0.25, 0.6
    model = ImpactOscillator("x", "c*y", parameters={"c": c, "D": d, "delta": delta}, restitution=Elastic())
    gibbs, _ = gibbs_linear_between_walls(c, d, delta, np.array([0.0, 1.0]))
    A = bandpass_filter(model, zeta=1.0, omega_f=1.0)
    zetas, means, sigmas = [8.0, 16.0, 32.0], [], []
    for zeta in zetas:
        est = simulate_automaton(A, "splitting", dt=0.005, paths=128, t_end=3000.0, t_burn=20.0, x0=(0, 0, 0, 0),
                                 seed=9, chunk_paths=8, params={"zeta": zeta}, histograms={"H": (0.0, 4.0, 40)}
                                 ).mean("H")
        means.append(est.value)
        sigmas.append(est.ci / 1.96)
    X = np.column_stack([np.ones(3), 1.0 / (2 * np.array(zetas))])
    w = 1.0 / np.array(sigmas) ** 2
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    e_inf, slope = cov @ X.T @ (w * np.array(means))
    assert slope < -3 * math.sqrt(cov[1, 1]), (slope, cov, means)
    assert abs(e_inf - gibbs) <= 3 * math.sqrt(cov[0, 0]), (e_inf, math.sqrt(cov[0, 0]), gibbs, means)


def test_each_noise_of_a_two_mass_model_gets_its_own_filter():
    # the impact pair with a clearance it never reaches: a linear 4-state system whose two standard white noises
    # (gains sqrt(2 c_i theta) / m_i) become two OU outputs z1, z2 (L = I: Var z_i = alpha / 2)
    alpha, dt = 2.0, 0.01
    A = ou_filter(impact_pair(gap=1e6), alpha=alpha)
    p = dict(A.parameters)
    k1, k2, m1, m2, c1, c2, th = (p[k] for k in ("k1", "k2", "m1", "m2", "c1", "c2", "theta"))
    g1, g2 = math.sqrt(2 * c1 * th) / m1, math.sqrt(2 * c2 * th) / m2
    # states x1, x2, v1, v2, z1, z2 (the filters' integrals drive nothing and are left out)
    M = np.zeros((6, 6))
    M[0, 2] = M[1, 3] = 1
    M[2, :] = [-k1 / m1, 0, -c1 / m1, 0, g1, 0]
    M[3, :] = [0, -k2 / m2, 0, -c2 / m2, 0, g2]
    M[4, 4] = M[5, 5] = -alpha
    B = np.zeros((6, 2))
    B[4, 0] = B[5, 1] = alpha
    exact = linalg.solve_continuous_lyapunov(M, -B @ B.T)
    # the splitting scheme's one-step map: half kick of v1, v2, z1, z2, free flight of x1, x2, noise, half kick
    K = np.eye(6) + 0.5 * dt * np.diag([0, 0, 1, 1, 1, 1]) @ M
    F = np.eye(6) + dt * np.diag([1, 1, 0, 0, 0, 0]) @ M
    chain = linalg.solve_discrete_lyapunov(K @ F @ K, K @ B @ B.T @ K.T * dt)
    obs = {"x1s": "x1**2", "x2s": "x2**2", "z1s": "z1**2", "z2s": "z2**2"}
    ens = simulate_automaton(A, "splitting", dt=dt, paths=64, t_end=1500.0, t_burn=30.0, x0=(0,) * 8, seed=13,
                             chunk_paths=4, observables=obs, histograms={k: (0, 1e3, 1) for k in obs})
    for name, i in (("x1s", 0), ("x2s", 1), ("z1s", 4), ("z2s", 5)):
        est, bias = ens.mean(name), abs(chain[i, i] - exact[i, i])
        assert bias < 0.02 * exact[i, i], (name, chain[i, i], exact[i, i])
        assert abs(est.value - exact[i, i]) <= 3 * est.ci + bias, (name, est, exact[i, i], bias)
    assert exact[4, 4] == pytest.approx(alpha / 2) and exact[0, 0] < th / k1  # coloured: below the Gibbs th/k1


def test_filters_extend_states_parameters_and_resets():
    A = ou_filter(DuffingImpact(), alpha=4.0)
    assert [s.name for s in A.states] == ["x", "y", "z_int", "z"]
    assert A.parameters["alpha"] == 4.0 and A.filter["kind"] == "ou"
    assert all(len(t.reset) == 4 for t in A.transitions)
    d, a = sp.Symbol("D", real=True), sp.Symbol("alpha", real=True)
    assert sp.simplify(A.modes[0].noise[3][0] - sp.sqrt(2 * d) * a) == 0  # sqrt(2 alpha^2 D)
    B = bandpass_filter(impact_pair(), zeta=0.2, omega_f=3.0)  # two noises: two filters
    assert [s.name for s in B.states][4:] == ["z1_int", "z1", "z2_int", "z2"]
    assert B.resolve_parameters({"zeta": 0.5})["zeta"] == 0.5
    renamed = ou_filter(linear(), alpha=2.0, state="u", names={"alpha": "a_f"})
    assert "a_f" in renamed.parameters and renamed.states[-1].name == "u"
    # correlated noises: the filters are driven by L dW with L L^T = 2 D (and a model parameter alpha is no clash
    # once the filter's is renamed)
    corr = ImpactOscillator("x", "c*y", noise=(1, "x"), intensity=[["D", "rho"], ["rho", "D"]],
                            parameters={"c": 0.1, "D": 0.1, "rho": 0.05, "alpha": 3.0}, barriers=None)
    C2 = ou_filter(corr, alpha=2.0, names={"alpha": "a_f"})
    a_f = sp.Symbol("a_f", real=True)
    L = sp.Matrix([C2.modes[0].noise[3], C2.modes[0].noise[5]]) / a_f
    assert sp.simplify(L * L.T - 2 * corr.intensity) == sp.zeros(2, 2)
    assert C2.modes[0].flow[1] == sp.sympify(corr.to_automaton().modes[0].flow[1]) + C2.states[3] + \
        C2.states[0] * C2.states[5]


@pytest.mark.parametrize("call, error", [
    (lambda: ou_filter(DuffingImpact(), alpha=0.0), ParameterError),
    (lambda: ou_filter(DuffingImpact(), alpha=-1.0), ParameterError),
    (lambda: ou_filter(DuffingImpact(), alpha=float("nan")), ParameterError),
    (lambda: bandpass_filter(DuffingImpact(), zeta=0.0), ParameterError),
    (lambda: bandpass_filter(DuffingImpact(), omega_f=float("nan")), ParameterError),
    (lambda: ou_filter(DuffingImpact()).resolve_parameters({"alpha": -2.0}), ParameterError),
    (lambda: bandpass_filter(DuffingImpact()).resolve_parameters({"omega_f": float("nan")}), ParameterError),
    (lambda: ou_filter(DuffingImpact()).resolve_parameters({"D": -1.0}), ParameterError),
    (lambda: attach_filter(DuffingImpact(), "pink"), ParameterError),
    (lambda: ou_filter("duffing"), ModelError),
    (lambda: ou_filter(DuffingImpact(D=0.0).with_params(), state="x"), ModelError),
    (lambda: ou_filter(ImpactOscillator("x", parameters={"D": 0.1, "alpha": 1.0}, barriers=None)), ModelError),
    (lambda: ou_filter(ImpactOscillator("x", noise=(0,), parameters={"D": 0.1}, barriers=None)), ModelError),
])
def test_bad_filters_are_refused_in_one_line(call, error):
    with pytest.raises(error) as info:
        call()
    assert "\n" not in str(info.value)


def test_a_negative_bandwidth_is_refused_by_the_engine_before_it_runs():
    with pytest.raises(ParameterError, match="alpha"):
        simulate_automaton(ou_filter(linear()), "em", dt=0.01, paths=1, t_end=1.0, x0=(0, 0, 0, 0), seed=1,
                           params={"alpha": -1.0}, histograms={})


@pytest.mark.slow  # the docs build in CI runs every example too, and stops on a failed self-check
def test_example_10_runs_headless_and_passes_its_checks():
    from examples_run import run_example

    res = run_example("10_coloured_noise.py", "--quick")
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.strip().splitlines()[-1] == "OK"
