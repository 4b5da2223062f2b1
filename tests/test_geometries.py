"""Barrier geometries beyond the symmetric gap: one-sided stops and a stop at the equilibrium.

Oracles: the free linear oscillator against a stop at x = 0 (impacts every half period, H multiplied by r**2),
the Gibbs marginal p(x) ~ exp(-c G(x) / D) of elastic walls (any geometry, fluctuation-dissipation), and the
asymptotic E[H] = D / (c + (4 omega / pi)(1 - r)/(1 + r)) of the linear oscillator against a stop at its
equilibrium as r -> 1.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hybrid.deterministic import simulate_orbit
from hybrid.errors import ModelError, ParameterError
from hybrid.stochastic import simulate_ensemble
from models import Elastic, ImpactOscillator, Newton


def equilibrium_stop(r: float, c: float = 0.05, D: float = 0.05):
    return ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=(0, None), restitution=Newton(r))


def test_barrier_pairs_with_none_mean_no_barrier_on_that_side():
    m = ImpactOscillator("x + b*x**3", "c*y", parameters={"b": 0.2, "c": 0.1, "D": 0.1, "delta": 1.0},
                         barriers=(None, "delta"))
    assert m.barriers == (-math.inf, 1.0)
    assert [t.name for t in m.to_automaton().transitions] == ["right"]
    assert equilibrium_stop(0.8).barriers == (0.0, math.inf)
    assert [t.name for t in equilibrium_stop(0.8).to_automaton().transitions] == ["left"]
    with pytest.raises(ModelError, match="enclose or touch"):
        ImpactOscillator("x", parameters={"D": 0.1}, barriers=(0.5, None))
    with pytest.raises(ModelError, match="pair"):
        ImpactOscillator("x", parameters={"D": 0.1}, barriers=(1.0,))


@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_free_orbit_against_a_stop_at_the_equilibrium(backend):
    # x'' + x = 0 on x >= 0 from (0.5, 0): first impact at t = pi/2, then every half period pi, H -> r**2 H
    m = equilibrium_stop(0.8, c=0.0, D=0.0)
    df = simulate_orbit(m, (0.5, 0.0), 20.0, backend=backend).to_pandas()
    assert len(df) == 6
    assert np.allclose(df.t.to_numpy(), math.pi / 2 + math.pi * np.arange(6), rtol=0, atol=1e-8)
    assert np.allclose(df.H_plus.to_numpy() / df.H_minus.to_numpy(), 0.64, rtol=1e-9)
    assert np.allclose(df.H_minus.to_numpy()[1:], df.H_plus.to_numpy()[:-1], rtol=1e-9)


def test_start_on_a_wall_moving_outwards_is_refused():
    with pytest.raises(ParameterError, match="outwards"):
        simulate_ensemble(equilibrium_stop(0.8), "splitting", dt=0.01, paths=2, t_end=1.0, t_burn=0.0, x0=(0.0, -1.0),
                          seed=1)


def test_one_sided_elastic_wall_keeps_the_gibbs_marginal():
    # elastic stop at x = 0.5 on the right only, Duffing spring: p(x) ~ exp(-c G(x) / D) on x <= 0.5
    c, D, b, wall = 0.2, 0.1, 0.2, 0.5
    m = ImpactOscillator("x + b*x**3", "c*y", parameters={"b": b, "c": c, "D": D, "w": wall},
                         barriers=(None, "w"), restitution=Elastic())
    lo = -3.0
    st = simulate_ensemble(m, "splitting", dt=0.01, paths=64, t_end=800.0, t_burn=50.0, seed=5, h_max=6.0,
                           xy_bins=(35, 10), xy_range=((lo, wall), (-4.0, 4.0)))
    counts = st.xy_counts.sum(axis=0).astype(float)
    n = st.total("samples")
    x_edges = st.xy_edges[0]
    xs = np.linspace(lo, wall, 20001)
    G = 0.5 * xs**2 + 0.25 * b * xs**4
    w = np.exp(-(c / D) * G)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(xs))])
    Z = cdf[-1]  # the mass beyond lo is e^-(c/D) G(3) ~ 1e-12: negligible
    exact = np.diff(np.interp(x_edges, xs, cdf)) / Z
    l1 = float(np.abs(counts / n - exact).sum())
    # 64 paths x 750 time units, relaxation time 1/c = 5: the histogram noise is about 0.01 in L1
    assert l1 < 0.03, l1
    assert st.xy_counts.sum() / n > 0.999  # the window holds the samples


@pytest.mark.parametrize("r", [0.95])
def test_stop_at_the_equilibrium_tends_to_the_asymptotic_mean_energy(r):
    # E[H] -> D / (c + (4 omega / pi)(1 - r)/(1 + r)) as r -> 1 (an asymptotic formula: its error is O((1 - r)^2)
    # relative, ~0.3 % here, far below the 3-sigma Monte Carlo band that the tolerance is)
    c, D = 0.05, 0.05
    st = simulate_ensemble(equilibrium_stop(r, c, D), "splitting", dt=0.01, paths=64, t_end=3000.0, t_burn=200.0,
                           seed=3, h_max=6.0)
    expected = D / (c + (4.0 / math.pi) * (1 - r) / (1 + r))
    est = st.mean_energy
    assert abs(est.value - expected) < 3.0 * est.ci + 0.01 * expected, (est, expected)


# ----------------------------------------------------------------------------- averaging on a one-sided stop

def one_sided_duffing(law, c=0.2, D=0.1, b=0.2, wall=0.5):
    return ImpactOscillator("x + b*x**3", "c*y", parameters={"b": b, "c": c, "D": D, "w": wall},
                            barriers=(None, "w"), restitution=law)


@pytest.mark.parametrize("method", ["paper", "exact-two-impact", "jump", "chain"])
def test_averaging_on_a_one_sided_elastic_stop_is_the_gibbs_density(method):
    from scipy import integrate

    from averaging import stationary_density

    c, D, b, wall = 0.2, 0.1, 0.2, 0.5
    sd = stationary_density(one_sided_duffing(Elastic(), c, D, b, wall), method=method, h_max=10.0)
    G = lambda x: 0.5 * x * x + 0.25 * b * x**4  # noqa: E731
    z = integrate.quad(lambda x: math.exp(-c * G(x) / D), -10.0, wall, epsabs=0, epsrel=1e-12)[0]
    mean_G = integrate.quad(lambda x: G(x) * math.exp(-c * G(x) / D), -10.0, wall, epsabs=0, epsrel=1e-12)[0] / z
    assert sd.mean_energy == pytest.approx(D / (2 * c) + mean_G, rel=1e-6)
    # Rice: the wall flux of the Gibbs density, p_x(w) * E[y+] = p_x(w) * sqrt(D / (2 pi c))
    rate = math.exp(-c * G(wall) / D) / z * math.sqrt(D / (2 * math.pi * c))
    assert sd.impact_rate == pytest.approx(rate, rel=1e-6)


def test_one_sided_stop_loses_one_impact_per_quasi_period():
    from averaging import averaged_coefficients

    m = one_sided_duffing(Newton(0.5))
    H = np.array([m.barrier_energy + 0.4])
    for method in ("paper", "exact-two-impact"):
        assert averaged_coefficients(m, H, method).loss[0] == pytest.approx(0.75 * 0.4, rel=1e-12)
    jump = averaged_coefficients(m, H, "jump")
    assert jump.jump_rate[0] == pytest.approx(1.0 / jump.period[0], rel=1e-12)
