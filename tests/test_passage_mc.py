"""First passage by event-exact Monte Carlo of any automaton (issue 26, item 2), against closed forms."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import sympy as sp

from hybrid.automaton import HybridAutomaton, Mode
from hybrid.errors import ParameterError
from hybrid.stochastic import simulate_first_passage
from hybrid.stochastic._passage import CensoredWarning, exit_guards
from models import DuffingImpact

# -zeta(1/2)/sqrt(2 pi): a barrier watched every dt acts as one moved out by this x s sqrt(dt)
BROADIE_GLASSERMAN = 0.5826


def brownian(s: float = 1.0):
    x = sp.Symbol("x")
    return HybridAutomaton((x,), {"s": s}, [Mode("m", (sp.Integer(0),), (sp.Symbol("s"),))])


def survival_exact(t: float, a: float, s: float = 1.0) -> float:
    """P(|x| < a on [0, t]) for x = s W from 0: the eigenfunction series of the heat equation on (-a, a)."""
    return sum(4 / math.pi * (-1) ** ((k - 1) // 2) / k * math.exp(-k * k * math.pi**2 * s * s * t / (8 * a * a))
               for k in range(1, 400, 2))


def test_brownian_exit_from_an_interval_meets_the_closed_form():
    dt, s = 2.5e-4, 1.0
    run = simulate_first_passage(brownian(s), "abs(x) < 1", "em", dt=dt, paths=4000, t_max=4.0, x0=(0.0,),
                                 snapshots=8, chunk_paths=250, seed=7)
    # the located crossing of a discretely watched path: the exact answer for the moved barrier (a bias of ~1.5 %
    # in R, several times below the binomial interval here)
    a = 1.0 + BROADIE_GLASSERMAN * s * math.sqrt(dt)
    lo, hi = run.survival_interval()
    for t, r, low, high in zip(run.times, run.survival, lo, hi):
        exact = survival_exact(t, a, s)
        assert abs(r - exact) <= 1.5 * (high - low) / 2, (t, r, exact)
    assert np.all(np.diff(run.survival) <= 0) and run.survivors[-1] == run.censored
    table = run.to_pandas()
    assert list(table.columns) == ["t", "R", "R_lo", "R_hi", "inside"] and table["R"].iloc[0] == 1.0
    with pytest.warns(CensoredWarning):  # a few paths are still inside at t = 4 (R ~ 0.01): said, not hidden
        mean = run.mean_time()
    # E[min(T, 4)] with T the exit time of (-a, a): a^2/s^2 minus the tail integral of R beyond 4
    tail = sum(4 / math.pi * (-1) ** ((k - 1) // 2) / k * 8 * a * a / (k * k * math.pi**2 * s * s)
               * math.exp(-k * k * math.pi**2 * s * s * 4.0 / (8 * a * a)) for k in range(1, 400, 2))
    assert abs(mean.value - (a * a / (s * s) - tail)) <= 1.5 * mean.ci
    edges, density = run.density()
    assert np.sum(density * np.diff(edges)) == pytest.approx(1 - run.censored / run.paths, abs=1e-12)


def test_domains_are_read_as_inequalities_in_states_parameters_and_observables():
    duffing = DuffingImpact().to_automaton()
    (g,) = exit_guards(duffing, "H < 2")
    assert sp.simplify(g - (duffing.observables["H"] - 2)) == 0
    guards = exit_guards(duffing, "x > -0.5 & y <= 1")
    assert [str(g) for g in guards] == ["-x - 0.5", "y - 1"]
    for bad, words in (("H", "not an inequality"), ("z < 1", "not states"), ("H <", "cannot read"),
                       ("", "no inequality")):
        with pytest.raises(ParameterError, match=words):
            exit_guards(duffing, bad)


def test_a_start_outside_the_domain_is_refused():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ParameterError, match="not inside the domain"):
            simulate_first_passage(brownian(), "x < 1", "em", dt=0.01, paths=8, t_max=1.0, x0=(2.0,))
