"""Energy-envelope averaging for every single-degree-of-freedom wall geometry: asymmetric walls (two impact levels)
and a wall at the equilibrium (every orbit hits it at its highest speed).

Oracles, each independent of the averaging code:

- elastic walls, linear damping c, additive noise D (E[xi xi] = 2 D delta): the Gibbs density p(x, y) ~ exp(-c H/D)
  (fluctuation-dissipation), so p(H) ~ T(H) exp(-c H / D) with T from scipy quadrature of the cut orbit, E[H] =
  D/(2c) + <G>_x from a 1-D integral, and the impact rate from Rice's formula at each wall;
- a linear oscillator against a stop at its equilibrium: the averaged equation has E[H] = D/(c + omega (1 - r**2)/pi)
  in closed form, which agrees with the asymptotic D/(c + (4 omega/pi)(1 - r)/(1 + r)) to first order in 1 - r;
- the free orbit (deterministic engine) for the loss of two impacts on walls at different energies;
- Monte Carlo (the project's engine) with its CI: slow tests, and examples/09 in the default suite.
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np
import pytest
from scipy import integrate, optimize

from averaging import averaged_coefficients, stationary_density
from averaging.methods import METHODS
from averaging.quadrature import geometry
from models import Elastic, ImpactOscillator, Ma, Newton

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
C, D, B = 0.1, 0.08, 0.3

GEOMETRIES = {
    "asymmetric": (-0.6, 1.0),
    "equilibrium-left": (0.0, None),
    "equilibrium-right": (None, 0.0),
    "equilibrium-and-wall": (0.0, 0.8),
    "two-walls-one-far": (-0.3, 2.5),
}


def duffing(barriers, law=None, c=C, d=D, b=B):
    return ImpactOscillator("x + b*x**3", "c*y", parameters={"b": b, "c": c, "D": d}, barriers=barriers,
                            restitution=law or Elastic())


def G(x, b=B):
    return 0.5 * x * x + 0.25 * b * x**4


def span(barriers):
    left, right = barriers
    return (-math.inf if left is None else float(left)), (math.inf if right is None else float(right))


def period_by_quad(H, barriers):
    """T(H) = int 2 dx / sqrt(2 (H - G)) over the part of the level inside the walls (scipy, no averaging code)."""
    left, right = span(barriers)
    lo = optimize.brentq(lambda x: G(x) - H, -50.0, 0.0)
    hi = optimize.brentq(lambda x: G(x) - H, 0.0, 50.0)
    a, b = max(lo, left), min(hi, right)
    return integrate.quad(lambda x: 2.0 / math.sqrt(2.0 * (H - G(x))), a, b, limit=200, epsabs=0, epsrel=1e-10)[0]


@pytest.mark.parametrize("method", ["paper", "jump"])
@pytest.mark.parametrize("name", sorted(GEOMETRIES))
def test_elastic_walls_give_the_gibbs_density_for_every_geometry(name, method):
    barriers = GEOMETRIES[name]
    sd = stationary_density(duffing(barriers), method, h_max=30.0)  # exp(-c H / D) below 1e-16 there
    # shape: p(H) / (T(H) exp(-c H / D)) is one constant
    Hs = np.array([0.03, 0.1, 0.3, 0.5, 0.9, 1.5, 3.0])
    ratio = sd.density(Hs) / np.array([period_by_quad(h, barriers) * math.exp(-C * h / D) for h in Hs])
    assert np.ptp(ratio) / ratio.mean() < 1e-8
    # E[H] = D / (2 c) + <G(x)> under exp(-c G / D) on the allowed x range
    left, right = span(barriers)
    a, b = max(left, -12.0), min(right, 12.0)
    z = integrate.quad(lambda x: math.exp(-C * G(x) / D), a, b, epsabs=0, epsrel=1e-12)[0]
    mean_G = integrate.quad(lambda x: G(x) * math.exp(-C * G(x) / D), a, b, epsabs=0, epsrel=1e-12)[0] / z
    assert sd.mean_energy == pytest.approx(D / (2 * C) + mean_G, rel=1e-7)
    # Rice at each wall: p_x(w) E[y+] = p_x(w) sqrt(D / (2 pi c))
    rate = sum(math.exp(-C * G(w) / D) / z * math.sqrt(D / (2 * math.pi * C)) for w in (left, right)
               if math.isfinite(w))
    assert sd.impact_rate == pytest.approx(rate, rel=1e-7)


@pytest.mark.parametrize("name", ["asymmetric", "equilibrium-and-wall"])
def test_elastic_marginals_are_the_gibbs_marginals(name):
    # p(x) ~ exp(-c G(x) / D) on the walls' span, p(y) Gaussian of variance D / c
    barriers = GEOMETRIES[name]
    sd = stationary_density(duffing(barriers), "paper", h_max=30.0)
    left, right = span(barriers)
    z = integrate.quad(lambda x: math.exp(-C * G(x) / D), left, right, epsabs=0, epsrel=1e-12)[0]
    x = np.linspace(left, right, 7)[1:-1]
    np.testing.assert_allclose(sd.marginal_x(x), np.exp(-C * G(x) / D) / z, rtol=1e-7)
    y = np.array([0.0, 0.4, 1.1])
    np.testing.assert_allclose(sd.marginal_y(y), np.exp(-C * y**2 / (2 * D)) / math.sqrt(2 * math.pi * D / C),
                               rtol=1e-7)


def test_levels_and_walls_hit():
    geo = geometry(duffing((-0.6, 1.0)))
    assert geo.levels == pytest.approx((G(-0.6), G(1.0)), rel=1e-14)
    assert geo.G_delta == pytest.approx(G(-0.6), rel=1e-14)
    assert geo.hits([0.1, 0.3, 1.0]).tolist() == [0, 1, 2]
    eq = geometry(duffing((0.0, None)))
    assert eq.levels == (0.0,) and eq.hits([1e-9, 5.0]).tolist() == [1, 1]


@pytest.mark.parametrize("method", ["paper", "exact-two-impact"])
def test_asymmetric_loss_per_quasi_period(method):
    m = METHODS[method]
    law = Ma(0.4)
    gl, gr = G(-0.6), G(1.0)
    H = np.array([0.5 * (gl + gr), gr + 0.7])
    loss = m.cycle_loss(law, H, (gl, gr))
    assert loss[0] == pytest.approx(law.impact_loss(H[0] - gl), rel=1e-14)  # the lower wall only
    # above both: the two impacts in sequence, averaged over which wall comes first
    assert gl < H[1] - loss[1] < H[1]
    # walls at one level: the symmetric forms of eq. 13 (paper) and of the exact two-impact loss
    sym = m.cycle_loss(law, H, (gl, gl + 1e-13))
    assert sym[1] == pytest.approx(m.loss(law, H[1] - gl, 2), rel=1e-9)
    assert np.all(m.cycle_loss(Elastic(), H, (gl, gr)) == 0.0)


def test_two_impacts_on_asymmetric_walls_lose_what_the_free_orbit_loses():
    from hybrid.deterministic import simulate_orbit

    law = Ma(0.4)
    m = duffing((-0.6, 1.0), law, c=0.0, d=0.0)
    gl, gr = G(-0.6), G(1.0)
    H0 = gr + 1.2
    df = simulate_orbit(m, (0.0, math.sqrt(2 * H0)), 30.0).to_pandas()  # moves right: the right wall first
    assert df.barrier.iloc[0] == "right" and df.barrier.iloc[1] == "left"
    after_two = df.H_plus.iloc[1]
    exact = METHODS["exact-two-impact"]._sequence(law, np.array([H0]), gr, gl)[0]
    assert H0 - after_two == pytest.approx(exact, rel=1e-8)


def test_jump_rates_count_the_walls_hit():
    m = duffing((-0.6, 1.0), Newton(0.7))
    H = np.array([0.1, 0.5 * (G(-0.6) + G(1.0)), G(1.0) + 0.5])
    c = averaged_coefficients(m, H, "jump")
    assert c.jump_rate.tolist() == pytest.approx([0.0, 1.0 / c.period[1], 2.0 / c.period[2]], rel=1e-12)
    assert np.all(c.loss == 0.0)


def equilibrium_stop(r, c=0.05, d=0.05, k=1.0):
    return ImpactOscillator("k*x", "c*y", parameters={"k": k, "c": c, "D": d}, barriers=(0, None),
                            restitution=Newton(r))


@pytest.mark.parametrize("k", [1.0, 4.0])
@pytest.mark.parametrize("r", [0.95, 0.8, 0.6])
def test_equilibrium_stop_mean_energy_solves_the_averaged_equation(r, k):
    # dE[H]/dt = D - c E[H] - (1 - r**2) E[H] / T, T = pi / omega: E[H] = D / (c + omega (1 - r**2) / pi) for the
    # drift (paper) and the Poisson-jump (jump) forms alike, since both are linear in H
    c, d, omega = 0.05, 0.05, math.sqrt(k)
    expected = d / (c + omega * (1 - r * r) / math.pi)
    paper = stationary_density(equilibrium_stop(r, c, d, k), "paper", h_max=40.0)
    assert paper.mean_energy == pytest.approx(expected, rel=1e-9)
    assert paper.impact_rate == pytest.approx(omega / math.pi, rel=1e-9)  # once per half period, at every level
    jump = stationary_density(equilibrium_stop(r, c, d, k), "jump", h_max=40.0, points=20001)
    assert jump.mean_energy == pytest.approx(expected, rel=2e-4)  # the chain's grid error: 8e-5 at worst here


def test_jump_chain_error_on_the_equilibrium_stop_shrinks_with_the_grid():
    expected = 0.05 / (0.05 + 2 * 0.64 / math.pi)
    errs = [abs(stationary_density(equilibrium_stop(0.6, k=4.0), "jump", h_max=40.0, points=n).mean_energy
                / expected - 1) for n in (8001, 32001)]
    order = math.log(errs[0] / errs[1]) / math.log(4.0)
    assert order > 1.8, errs  # second order in the spacing


def test_equilibrium_stop_agrees_with_the_asymptotic_formula_to_first_order_in_1_minus_r():
    # relative error of E[H] against D / (c + (4 omega / pi)(1 - r)/(1 + r)) is o(1) and at least O(1 - r)
    c, d = 0.05, 0.05
    rs = np.array([0.9, 0.95, 0.98, 0.99])
    err = []
    for r in rs:
        asym = d / (c + (4.0 / math.pi) * (1 - r) / (1 + r))
        err.append(abs(stationary_density(equilibrium_stop(r, c, d), "paper", h_max=40.0).mean_energy / asym - 1))
    slope = np.polyfit(np.log(1 - rs), np.log(err), 1)[0]
    assert slope > 0.95 and np.all(np.diff(err) < 0), (slope, err)


def test_drift_methods_refuse_a_wall_at_the_equilibrium_when_the_noise_vanishes_at_rest():
    from hybrid.errors import NormalisationError

    m = ImpactOscillator("x", "c*y", noise=("x",), parameters={"c": 0.05, "D": 0.05}, barriers=(0, None),
                         restitution=Newton(0.8))
    with pytest.raises(NormalisationError):
        stationary_density(m, "paper", h_max=4.0)


def test_diagnose_names_the_geometry():
    from vibro.solve.diagnostics import barrier_geometry, cycle_quantities, diagnose

    assert barrier_geometry(duffing((-0.6, 1.0))) == "asymmetric"
    assert barrier_geometry(duffing((0, None))) == "equilibrium"
    assert barrier_geometry(duffing((None, 1.0))) == "one-sided"
    law = Newton(0.7)
    H = np.array([G(1.0) + 0.3])
    _, _, loss = cycle_quantities(duffing((-0.6, 1.0), law), H)
    assert loss[0] == pytest.approx(METHODS["exact-two-impact"].cycle_loss(law, H, (G(-0.6), G(1.0)))[0])
    d = diagnose(duffing((0, None), law))
    assert d.geometry == "equilibrium" and d.barrier_energy == 0.0
    assert any("fitted on symmetric gaps" in n for n in d.notes)


MODEL_FILE = '''
from models import ImpactOscillator, Newton


class Gap(ImpactOscillator):
    name = "asymmetric-gap"

    def __init__(self):
        super().__init__("x + b*x**3", "c*y", parameters={"b": 0.5, "c": 0.05, "D": 0.05},
                         barriers=(-0.6, 1.0), restitution=Newton(0.8))
'''


@pytest.mark.parametrize("kind", ["asymmetric", "equilibrium", "multiplicative"])
def test_vibro_pdf_accepts_the_geometry_and_says_whether_its_accuracy_is_rated(tmp_path, kind, capsys):
    # every wall family is rated by benchmarks/method_ratings.py; multiplicative noise is outside its sweep (vibro pdf
    # in this process: the model files share a name, in folders of their own)
    import pandas as pd

    from vibro.cli import main

    text = {"asymmetric": MODEL_FILE, "equilibrium": MODEL_FILE.replace("(-0.6, 1.0)", "(0, None)"),
            "multiplicative": MODEL_FILE.replace('"c*y",', '"c*y", noise=("sqrt(1 + x**2)",),')}[kind]
    (tmp_path / "gap.py").write_text(text)
    out = tmp_path / "p.csv"
    capsys.readouterr()
    status = main(["pdf", "--model", f"{tmp_path}/gap.py:Gap", "--method", "jump", "--h-max", "3", "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 0, err
    assert ("not rated" in err) == (kind == "multiplicative"), err
    df = pd.read_csv(out)
    assert np.trapezoid(df.p, df.H) == pytest.approx(1.0, abs=1e-4)


def test_forced_averaging_on_an_unrated_model_warns():
    from vibro.solve import solve
    from vibro.solve.choice import UnmeasuredAccuracyWarning

    unrated = ImpactOscillator("x + b*x**3", "c*y", noise=("sqrt(1 + x**2)",),
                               parameters={"b": B, "c": 0.05, "D": 0.05}, barriers=(-0.6, 1.0), restitution=Newton(0.8))
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnmeasuredAccuracyWarning)
        with pytest.raises(UnmeasuredAccuracyWarning, match="not measured"):
            solve(unrated, method="jump")


@pytest.mark.slow  # the docs build in CI runs every example too, and stops on a failed self-check
def test_example_09_runs_headless_and_passes_its_checks():
    from examples_run import run_example

    res = run_example("09_asymmetric_gap.py", "--quick", timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "OK" in res.stdout


# ----------------------------------------------------------------------------- Monte Carlo (slow)

@pytest.mark.slow
def test_equilibrium_stop_averaging_error_against_monte_carlo_vanishes_at_least_like_1_minus_r():
    # averaging overestimates E[H] (the impacts come every half period, not at random): 33 %, 13 %, 4 % at
    # r = 0.6, 0.8, 0.9 with c = 0.05; the error falls at least linearly in 1 - r (faster once the impact loss is
    # comparable with c)
    from hybrid.stochastic import simulate_ensemble

    rs = np.array([0.6, 0.8, 0.9])
    err, ci = [], []
    for r in rs:
        m = equilibrium_stop(r)
        st = simulate_ensemble(m, "splitting", dt=0.005, paths=128, t_end=6200.0, t_burn=200.0, seed=11,
                               h_max=6.0, xy_bins=None, x0=(0.5, 0.0))
        avg = stationary_density(m, "jump", h_max=20.0).mean_energy
        err.append(avg / st.mean_energy.value - 1.0)
        ci.append(st.mean_energy.ci / st.mean_energy.value)
    assert all(e > 2 * c for e, c in zip(err, ci)), (err, ci)
    assert np.all(np.diff(err) < 0), err
    slope = np.polyfit(np.log(1 - rs), np.log(err), 1)[0]
    assert 0.9 < slope < 2.5, (slope, err, ci)


@pytest.mark.slow
@pytest.mark.parametrize("law", [Newton(0.8), Ma(0.2)], ids=["newton", "ma"])
def test_asymmetric_gap_jump_is_within_the_measured_distance_of_monte_carlo(law):
    from hybrid.stochastic import simulate_ensemble
    from vibro.solve.metrics import bin_masses, l1_masses, rebin_counts

    m = duffing((-0.6, 1.0), law, c=0.05, d=0.05, b=0.5)
    a, b = (simulate_ensemble(m, "splitting", dt=0.01, paths=64, t_end=3200.0, t_burn=200.0, seed=s, h_max=3.0,
                              bins=400, xy_bins=None) for s in (21, 22))
    ma, mb = (rebin_counts(s.h_counts, 100) / s.total("samples") for s in (a, b))
    noise = 0.5 * l1_masses(ma, mb)
    mc = 0.5 * (ma + mb)
    edges = np.linspace(0.0, 3.0, 101)
    l1 = {k: l1_masses(bin_masses(sd.H, sd.p, edges), mc)
          for k, sd in ((k, stationary_density(m, k, h_max=3.0)) for k in ("paper", "jump"))}
    assert l1["jump"] < 0.04 + 3 * noise, (l1, noise)
    assert l1["jump"] < l1["paper"], l1
