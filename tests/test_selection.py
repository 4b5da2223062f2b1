"""The chooser of vibro.solve: its diagnostics against closed forms, its rules, its command line.

Oracles: the elastic stationary density of tests/problems.py (closed form + scipy quadrature), mpmath periods,
the two-impact loss formula of docs/paper-readings.md and Rice's formula for the impact-speed tail.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from problems import ElasticStationary, duffing_period, duffing_potential, elastic_duffing, exact_two_impact_loss

from hybrid.errors import ModelError, NormalisationError, ParameterError
from models import DuffingImpact, Elastic, ImpactOscillator, Ma, Newton, RayleighImpact
from vibro.cli import main
from vibro.solve import (
    bin_masses,
    choose,
    cycle_quantities,
    diagnose,
    l1_between_histograms,
    predict_averaging_error,
    solve,
)
from vibro.studies.workprecision import ElasticOracle, free_quasi_period

# ----------------------------------------------------------------------------- diagnostics vs closed forms

def test_cycle_quantities_match_mpmath_periods_and_loss_formula():
    m = DuffingImpact(restitution=Ma(0.4), c=0.025)
    H = np.array([0.2, 0.5, 0.9, 2.0, 4.0])
    W, T, loss = cycle_quantities(m, H)
    for h, t in zip(H, T):
        assert t == pytest.approx(duffing_period(h, delta=1.0), rel=1e-6)
    Gd = m.barrier_energy
    for h, l in zip(H, loss):
        expected = exact_two_impact_loss(m.restitution, h, Gd) if h > Gd else 0.0
        assert l == pytest.approx(expected, rel=1e-12, abs=1e-15)
    # damping work of h = c y over one cycle: 2 c * int y dx (action); check against an mpmath action below G(delta)
    from problems import action_mpmath

    A = float(m.amplitude(0.2))
    act = action_mpmath(lambda x: duffing_potential(x), 0.2, -A, A)
    assert W[0] == pytest.approx(2 * 0.025 * act, rel=1e-6)


def test_tail_for_linear_damping_is_rayleigh_and_general_branch_agrees():
    # closed form exp(-c V_C^2 / (2 D)) for h = c y
    d = diagnose(DuffingImpact(restitution=Ma(0.4), c=0.025, D=0.05))
    assert d.tail_impact_speed == pytest.approx(math.exp(-0.025 * 0.16 / 0.1), rel=1e-12)
    # nearly linear Rayleigh damping goes through the general flux branch (p(H)/T(H)); it must agree with Rice
    r = RayleighImpact(restitution=Ma(0.6), c=0.05, k3=1e-7, D=0.05)
    dr = diagnose(r)
    assert not dr.linear_damping
    assert dr.tail_impact_speed == pytest.approx(math.exp(-0.05 * 0.36 / 0.1), rel=2e-3)


def test_elastic_oracle_agrees_with_shared_problems():
    model, exact = elastic_duffing(delta=0.8, c=0.05, D=0.04)
    o = ElasticOracle.for_model(model)
    assert o.mean_x2() == pytest.approx(exact.mean_x2(), rel=1e-9)
    assert o.impact_rate() == pytest.approx(2 * exact.impact_rate_per_wall(), rel=1e-9)
    for level in (0.1, 0.3, 1.0):
        assert o.cdf(level) == pytest.approx(exact.probability_below(level), rel=1e-7)


def test_free_quasi_period_is_half_the_mpmath_quasi_period():
    m = DuffingImpact(c=0.0, D=0.0, delta=0.8)
    assert free_quasi_period(m, 1.3) == pytest.approx(duffing_period(1.3, delta=0.8) / 2, rel=1e-9)


def test_l1_helpers():
    H = np.linspace(0.0, 2.0, 2001)
    p = np.exp(-H)
    edges = np.linspace(0.0, 2.0, 3)
    m = bin_masses(H, p, edges)
    exact = np.array([1 - math.exp(-1), math.exp(-1) - math.exp(-2)])
    # masses are not renormalised over the bins: mass outside them counts as error in every L1 (one definition)
    assert np.allclose(m, exact, rtol=1e-6)
    assert bin_masses(H, p, [0.0, 1.0]).sum() == pytest.approx(1 - math.exp(-1), rel=1e-6)
    assert l1_between_histograms([2, 0], [0, 5]) == 2.0
    with pytest.raises(NormalisationError):
        bin_masses(H, np.full_like(H, np.nan), edges)


# ----------------------------------------------------------------------------- rules

def test_elastic_impacts_choose_exact_and_it_is_exact():
    model = DuffingImpact(restitution=Elastic(), c=0.05, D=0.04, delta=0.8)
    sol = solve(model, tol=0.02)
    assert sol.method == "exact"
    o = ElasticOracle.for_model(model)
    assert l1_between_histograms(sol.masses, o.bin_masses(sol.edges)) < 2e-3


def test_high_critical_speed_counts_as_elastic_only_when_the_tail_is_below_tol_over_10():
    # tail exp(-c V^2 / (2D)): V = 1.5, c = 0.025, D = 0.005 -> exp(-5.625) = 3.6e-3
    m = DuffingImpact(restitution=Ma(1.5), D=0.005)
    assert choose(m, tol=0.05, mc_pilot=False).method == "exact"       # 3.6e-3 < 5e-3
    assert choose(m, tol=0.02, mc_pilot=False).method != "exact"       # 3.6e-3 > 2e-3


def _order():
    """The cost order of ``choose``: exact, the averaging methods by their cost in solve (paper and jump include
    their cross-check against the chain, so the chain comes first), fpk."""
    from vibro.solve.choice import AVERAGING_ORDER

    return ("exact", *AVERAGING_ORDER, "fpk")


@pytest.mark.parametrize("tol", [0.5, 0.05, 0.02, 0.005])
def test_the_cheapest_rated_method_within_tol_is_chosen(tol):
    # Fig. 2, delta = 1: every method is a candidate; the chosen one is the first of the cost order whose
    # estimated error meets tol, and Monte Carlo is never chosen where a deterministic method applies
    order = _order()
    assert order[1] == "chain"
    ch = choose(DuffingImpact(), tol=tol, mc_pilot=False)
    assert ch.method in order and ch.expected_error <= tol
    assert all(not ch.predictions.get(n, math.inf) <= tol for n in order[:order.index(ch.method)])
    assert all(math.isfinite(ch.predictions[n]) for n in ("paper", "jump", "chain"))  # rated here
    assert ch.predictions["chain"] < ch.predictions["jump"] < ch.predictions["paper"]


def test_paper_figures_12_to_14_are_not_refused_where_rated():
    from vibro.solve.choice import averaging_refusal
    from vibro.studies.figures.specs import FIGURES

    for n in (12, 13):
        d = diagnose(FIGURES[n].cases[1].build())
        assert d.self_excited and averaging_refusal(d) is None
        assert math.isfinite(predict_averaging_error("chain", d))


def test_unrated_model_gets_fpk_with_its_own_estimate():
    # multiplicative noise: the sweep held additive noise only, so no averaging rating covers the model
    m = ImpactOscillator("x", "c*y", noise=("sqrt(1 + x**2)",), parameters={"c": 0.1, "D": 0.05, "delta": 0.8},
                         restitution=Newton(0.8))
    ch = choose(m, tol=0.02, mc_pilot=False)
    assert ch.method == "fpk" and "no rating" in ch.reason and math.isnan(ch.predictions["chain"])


def test_escalation_ladder():
    from vibro.solve.choice import Choice
    from vibro.solve.solver import _escalate

    preds = {"paper": 0.1, "jump": 0.05, "chain": 0.01, "fpk": 0.001}
    d = diagnose(DuffingImpact())
    nxt = _escalate(Choice("paper", "r", 0.01, 0.05, {}, preds, d), 0.1, 0.02)
    assert nxt.method == "chain"  # jump's rating misses tol too
    nxt = _escalate(Choice("chain", "r", 0.01, 0.15, {}, preds, d), 0.03, 0.02)
    assert nxt.method == "fpk" and "grid" in nxt.settings
    g = nxt.settings["grid"]
    finer = _escalate(nxt, 0.08, 0.02)
    assert finer.method == "fpk" and finer.settings["grid"][0] > g[0]


def test_solve_refines_the_fpk_grid_when_its_estimate_misses(monkeypatch):
    # start fpk on the coarsest grid (as if it were predicted good enough): its own estimate (0.0024) misses 0.0015,
    # so solve refines the grid until the estimate meets it, and reports every run
    import vibro.solve.choice as choice_mod

    monkeypatch.setattr(choice_mod, "fpk_grid_for", lambda tol, start=None: choice_mod.FPK_GRIDS[0])
    m = DuffingImpact().with_params(c=0.05)
    tol = 0.0015
    sol = solve(m, tol=tol, method="auto")
    assert sol.method == "fpk" and sol.attempts[0][1]["grid"] == choice_mod.FPK_GRIDS[0]
    assert sol.estimated_error <= tol and "three grids" in sol.estimate_source
    assert len(sol.attempts) >= 2 and sol.attempts[0][2] > tol and "escalated" in sol.summary()


def test_nonlinear_damping_never_gets_the_exact_formula():
    d = diagnose(RayleighImpact(restitution=Elastic()))
    assert predict_averaging_error("exact", d) == math.inf
    with pytest.raises(ModelError, match="linear damping"):
        solve(RayleighImpact(restitution=Elastic()), method="exact")


def test_elastic_walls_of_any_geometry_are_exact():
    m = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=(-0.5, 1.0), restitution=Elastic())
    assert choose(m, tol=0.02, mc_pilot=False).method == "exact"


def test_bad_tolerance_is_refused():
    with pytest.raises(ParameterError, match="tol"):
        choose(DuffingImpact(), tol=0.0)
    with pytest.raises(ParameterError, match="method"):
        solve(DuffingImpact(), method="magic")
    with pytest.raises(ParameterError, match="max_cost"):
        choose(DuffingImpact(), tol=0.05, max_cost=-1.0, mc_pilot=False)
    # forced Monte Carlo skips choose(); its request is checked before anything runs
    with pytest.raises(ParameterError, match="tol"):
        solve(DuffingImpact(), tol=math.nan, method="monte-carlo")
    with pytest.raises(ParameterError, match="max_cost"):
        solve(DuffingImpact(), tol=0.05, method="monte-carlo", max_cost=0.0)


def test_error_model_is_monotone_in_impact_losses():
    from dataclasses import replace

    d = diagnose(DuffingImpact())
    lo, hi = replace(d, r_imp=0.8 * d.r_imp), replace(d, r_imp=1.2 * d.r_imp)
    for method in ("paper", "jump", "chain"):
        assert predict_averaging_error(method, lo) < predict_averaging_error(method, hi)
    assert predict_averaging_error("jump", hi) < predict_averaging_error("paper", hi)


# ----------------------------------------------------------------------------- command line

def test_cli_solve_dry_run_prints_choice(capsys):
    assert main(["solve", "--dry-run", "--tol", "0.05", "--restitution", "elastic"]) == 0
    out = capsys.readouterr().out
    assert "method: exact" in out and "why:" in out and "expected L1" in out and "expected cost" in out


def test_cli_solve_writes_density(tmp_path, capsys):
    out = tmp_path / "p.csv"
    assert main(["solve", "--tol", "0.05", "--param", "c=0.05", "--param", "D=0.04", "--restitution", "elastic",
                 "--out", str(out)]) == 0
    import pandas as pd

    df = pd.read_csv(out)
    assert list(df.columns) == ["H", "p"]
    assert np.trapezoid(df.p, df.H) == pytest.approx(1.0, rel=1e-3)


def test_cli_solve_bad_input_exits_2(capsys):
    assert main(["solve", "--tol", "5"]) == 2
    assert "tol" in capsys.readouterr().err


def test_cli_bench_parser_knows_the_tasks():
    from vibro.cli import build_parser

    args = build_parser().parse_args(["bench", "validity", "--quick", "--parts", "orbits"])
    assert args.task == "validity" and args.parts == "orbits"


# ----------------------------------------------------------------------------- verification (slow)

@pytest.mark.slow
def test_solve_verification_on_cases_not_used_for_calibration(tmp_path):
    from vibro.studies.validity import solve_verification, verification_cases

    tol = 0.02
    df = solve_verification(tmp_path, tol=tol, quick=True, cases=verification_cases(quick=True), progress=print)
    assert (tmp_path / "solve_verification.csv").exists()
    for _, r in df.iterrows():
        # the chosen method reaches the tolerance up to the reference's own noise
        assert r.actual_l1 <= tol + 3 * r.ref_noise + 0.005, r.case
        if r.method != "monte-carlo":
            assert r.time_saved > 0, r.case


def test_elastic_stationary_problem_is_used_consistently():
    # guard: problems.ElasticStationary uses c/D, the oracle 2c/sigma^2 = c/D for f = 1
    model, exact = elastic_duffing()
    assert ElasticOracle.for_model(model).beta == pytest.approx(exact.beta)
    assert isinstance(exact, ElasticStationary)


def test_forced_fpk_on_elastic_walls_is_the_exact_density():
    model = elastic_duffing(c=0.1, D=0.1)[0]
    o = ElasticOracle.for_model(model)
    sol = solve(model, tol=0.02, method="fpk")
    assert sol.method == "fpk"
    assert l1_between_histograms(sol.masses, o.bin_masses(sol.edges)) < 5e-3
