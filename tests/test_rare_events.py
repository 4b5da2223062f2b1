"""Rare events by fixed-level splitting on event-exact paths (issue 26, item 3), against exact answers.

The oracle is the exact exceedance probability of the simulated process itself: for the Euler chain of
dx = -theta x dt + s dW, read at step ends, ``problems.euler_ou_exceedance`` carries the density of the surviving
paths by quadrature (relative accuracy better than 1e-6 here, far inside the intervals tested). theta = 0 is Brownian
motion watched every dt. All tests share one automaton (theta and s are parameters) and the em scheme: one kernel.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import sympy as sp
from problems import euler_ou_exceedance

from hybrid.automaton import HybridAutomaton, Mode
from hybrid.errors import ModelError, ParameterError
from hybrid.stochastic import RareEventWarning, simulate_first_passage, splitting_probability
from models import DuffingImpact, Ma


def ou():
    """dx = -th x dt + s dW (th = 0: Brownian motion)."""
    x = sp.Symbol("x")
    return HybridAutomaton((x,), {"th": 1.0, "s": math.sqrt(2.0)},
                           [Mode("m", (-sp.Symbol("th") * x,), (sp.Symbol("s"),))])


def split(b, *, levels, clones, seed, theta=1.0, replicas=8, s: float = math.sqrt(2.0)):
    return splitting_probability(ou(), "x", b, levels=levels, t_max=1.0, x0=(0.0,), dt=0.01, clones=clones,
                                 replicas=replicas, scheme="em", seed=seed, params={"th": theta, "s": s})


def test_splitting_meets_the_exact_chain_at_1e_3():
    exact = euler_ou_exceedance(3.25, per_sigma=10)
    assert 0.9e-3 < exact < 1.1e-3
    est = split(3.25, levels=5, clones=300, seed=5)
    assert abs(est.probability - exact) <= est.ci, (est, exact)
    assert est.relative_error < 0.5 and est.stage_shares.shape == (8, 5)
    assert np.all((est.stage_shares > 0) & (est.stage_shares < 1))
    assert est.replica_relative_variance < 0.3 and est.cpu_time > 0
    # the variance reduction is real: brute force needs more steps for the same relative error
    assert est.speedup > 3
    again = split(3.25, levels=5, clones=300, seed=5)
    assert np.array_equal(again.replicas, est.replicas)  # same seed, same numbers


def test_brownian_motion_against_the_exact_random_walk():
    # theta = 0, s = 1: the Gaussian random walk watched every dt. The reflection principle with the continuity
    # correction, 2 P(W_1 >= b + 0.5826 sqrt(dt)) = 3.733e-4, is 1.7 % low of the exact 3.7988e-4 at dt = 0.01
    exact = euler_ou_exceedance(3.5, theta=0.0, s=1.0, per_sigma=10)
    assert 3.79e-4 < exact < 3.81e-4
    est = split(3.5, levels=6, clones=300, seed=3, theta=0.0, s=1.0)
    assert abs(est.probability - exact) <= est.ci, (est, exact)


def test_skewed_replicas_are_warned_about():
    # 20 clones for 1e-6: replicas die out or spread far beyond what the Student interval holds
    with pytest.warns(RareEventWarning, match="undercovers"):
        split(4.69, levels=10, clones=20, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RareEventWarning)
        split(3.25, levels=5, clones=300, seed=5)


@pytest.mark.slow
@pytest.mark.parametrize("b, levels, clones, exact_range", [(4.69, 10, 1000, (1e-6, 1.05e-6)),
                                                            (5.80, 15, 2000, (1e-9, 1.05e-9))])
def test_splitting_reaches_1e_6_and_1e_9_within_its_interval(b, levels, clones, exact_range):
    exact = euler_ou_exceedance(b)
    assert exact_range[0] < exact < exact_range[1]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RareEventWarning)  # these clones keep the replicas' spread in range
        est = split(b, levels=levels, clones=clones, seed=11, replicas=16)
    assert abs(est.probability - exact) <= est.ci and est.relative_error < 0.3, (est, exact)
    assert est.speedup > 1000


@pytest.mark.slow
def test_interval_coverage_over_seeds_at_1e_3():
    # 100 independent estimates (8 replicas of 200 clones each): the 95 % interval must cover the exact answer
    # about 95 times; 0.88 is 3 binomial standard errors below
    exact = euler_ou_exceedance(3.25)
    hits = [abs(e.probability - exact) <= e.ci for e in (split(3.25, levels=5, clones=200, seed=2000 + k)
                                                         for k in range(100))]
    assert 0.88 <= np.mean(hits) <= 1.0


@pytest.mark.slow
def test_example_1_splitting_against_brute_force_at_1e_3():
    model = DuffingImpact(restitution=Ma(0.4))
    run = simulate_first_passage(model, "H < 2.7", "splitting", dt=0.01, paths=200_000, t_max=10.0, x0=(0.0, 0.0),
                                 snapshots=1, chunk_paths=6250, seed=4)
    p = 1 - run.survival[-1]
    lo, hi = run.survival_interval()
    assert 7e-4 < p < 1.5e-3
    est = splitting_probability(model, "H", 2.7, levels=6, t_max=10.0, x0=(0.0, 0.0), dt=0.01, clones=300,
                                replicas=8, seed=3)
    assert abs(est.probability - p) <= est.ci + (hi[-1] - lo[-1]) / 2, (est, p)


def test_splitting_requests_are_checked():
    with pytest.raises(ParameterError, match="levels must increase"):
        splitting_probability(ou(), "x", 2.0, levels=[1.5, 1.0, 2.0], t_max=1.0, x0=(0.0,), dt=0.01, scheme="em")
    with pytest.raises(ParameterError, match="clones"):
        splitting_probability(ou(), "x", 2.0, levels=2, t_max=1.0, x0=(0.0,), dt=0.01, clones=1, scheme="em")
    with pytest.raises(ParameterError, match="levels must increase"):  # the start H = 0.72 is above the level
        splitting_probability(DuffingImpact(), "H", 0.5, levels=[0.5], t_max=1.0, x0=(0.0, 1.2), dt=0.01)
    x = sp.Symbol("x")
    two = HybridAutomaton((x,), {}, [Mode("a", (sp.Integer(1),), (sp.Integer(1),)),
                                     Mode("b", (sp.Integer(-1),), (sp.Integer(1),))])
    with pytest.raises(ModelError, match="one mode"):
        splitting_probability(two, "x", 2.0, levels=2, t_max=1.0, x0=(0.0,), dt=0.01, scheme="em")


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:.*had not left the domain")  # most mc paths are censored at t_max, by design
def test_vibro_splitting_and_mc_watch_the_same_corrected_level():
    # both move the level in by the continuity correction (default): the same probability, which the plain level
    # undercounts by about 12 % at dt = 0.01 against the dt -> 0 limit, 10 % against the corrected level
    # (docs/results/rare-events.md)
    import vibro

    model, kw = DuffingImpact(restitution=Ma(0.4)), {"dt": 0.01, "t_max": 10.0, "scheme": "splitting", "seed": 5}
    mc = vibro.first_passage(model, "H < 2.0", (0.0, 0.0), method="mc", paths=100_000, points=2, **kw)
    sp_ = vibro.first_passage(model, "H < 2.0", (0.0, 0.0), method="splitting", levels=5, clones=300, replicas=16,
                              **kw)
    assert mc.details["continuity_correction"] and sp_.details["continuity_correction"]
    p_mc, p_sp = 1 - mc.R[-1], sp_.details["probability"]
    half_mc = (mc.R_hi[-1] - mc.R_lo[-1]) / 2
    assert 0.01 < p_mc < 0.025
    assert abs(p_sp - p_mc) <= sp_.error_estimate + half_mc, (p_sp, p_mc)
