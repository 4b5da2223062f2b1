"""Rare events by fixed-level splitting on event-exact paths (issue 26, item 3), against the reflection principle.

For x = W (Brownian motion from 0), P(max_{t <= T} x >= b) = 2 P(W_T >= b). A path watched every dt crosses a
level as if it were moved out by 0.5826 sqrt(dt) (Broadie and Glasserman's continuity correction), which gives the
exact answer of the simulated process to well below the intervals tested here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.stats import norm

from hybrid.automaton import HybridAutomaton, Mode
from hybrid.errors import ModelError, ParameterError
from hybrid.stochastic import splitting_probability
from models import DuffingImpact


def brownian():
    x = sp.Symbol("x")
    return HybridAutomaton((x,), {"s": 1.0}, [Mode("m", (sp.Integer(0),), (sp.Symbol("s"),))])


def exceedance(b: float, dt: float, t_max: float = 1.0) -> float:
    return 2 * norm.sf((b + 0.5826 * math.sqrt(dt)) / math.sqrt(t_max))


def test_splitting_meets_the_reflection_principle_at_4e_4():
    dt = 1e-3
    est = splitting_probability(brownian(), "x", 3.5, levels=6, t_max=1.0, x0=(0.0,), dt=dt, clones=300,
                                replicas=6, scheme="em", seed=5)
    exact = exceedance(3.5, dt)
    assert abs(est.probability - exact) <= est.ci, (est, exact)
    assert est.relative_error < 0.5 and est.stage_shares.shape == (6, 6)
    assert np.all((est.stage_shares > 0) & (est.stage_shares < 1))
    # the variance reduction is real: brute force needs more steps for the same relative error
    assert est.speedup > 5
    again = splitting_probability(brownian(), "x", 3.5, levels=6, t_max=1.0, x0=(0.0,), dt=dt, clones=300,
                                  replicas=6, scheme="em", seed=5)
    assert np.array_equal(again.replicas, est.replicas)  # same seed, same numbers


@pytest.mark.slow
def test_splitting_reaches_one_in_a_million_within_its_interval():
    dt = 1e-3
    est = splitting_probability(brownian(), "x", 4.75, levels=24, t_max=1.0, x0=(0.0,), dt=dt, clones=3200,
                                replicas=8, scheme="em", seed=9)
    exact = exceedance(4.75, dt)
    assert 1e-6 < exact < 3e-6
    assert abs(est.probability - exact) <= est.ci and est.relative_error < 0.3, (est, exact)
    assert est.speedup > 100


def test_splitting_requests_are_checked():
    with pytest.raises(ParameterError, match="levels must increase"):
        splitting_probability(brownian(), "x", 2.0, levels=[1.5, 1.0, 2.0], t_max=1.0, x0=(0.0,), dt=0.01,
                              scheme="em")
    with pytest.raises(ParameterError, match="clones"):
        splitting_probability(brownian(), "x", 2.0, levels=2, t_max=1.0, x0=(0.0,), dt=0.01, clones=1, scheme="em")
    with pytest.raises(ParameterError, match="levels must increase"):  # the start H = 0.72 is above the level
        splitting_probability(DuffingImpact(), "H", 0.5, levels=[0.5], t_max=1.0, x0=(0.0, 1.2), dt=0.01)
    x = sp.Symbol("x")
    two = HybridAutomaton((x,), {}, [Mode("a", (sp.Integer(1),), (sp.Integer(1),)),
                                     Mode("b", (sp.Integer(-1),), (sp.Integer(1),))])
    with pytest.raises(ModelError, match="one mode"):
        splitting_probability(two, "x", 2.0, levels=2, t_max=1.0, x0=(0.0,), dt=0.01, scheme="em")
