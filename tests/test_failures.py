"""Every known failure mode is detected and reported (status, warning or error), never silently wrong.

Monte Carlo: dt against the barrier-crossing time, stiff potentials, chattering against a wall (inelastic collapse).
Orbits: Zeno accumulation, chattering, grazing. Averaging: non-confining potentials, densities that cannot be
normalised, heavily dissipative regimes (the chooser refuses averaging). Where a piece owned by another part lacks
the detection, the test is marked ``xfail(strict=True)`` with the exact missing behaviour as the reason.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from problems import bouncing_ball, bouncing_ball_zeno_time

from averaging import stationary_density
from hybrid.deterministic import simulate_orbit
from hybrid.errors import ModelError, NormalisationError, StepSizeError
from hybrid.stochastic import StepSizeWarning, check_step, simulate_ensemble
from models import DuffingImpact, Elastic, ImpactOscillator, Ma, Newton
from vibro.solve import choose, diagnose, solve


def _push(e=0.5, c=0.0, D=0.0):
    """x'' = 2 - x with a wall at x = 1: a constant-like force presses the mass into the wall (inelastic collapse)."""
    return ImpactOscillator("x - 2", "c*y", parameters={"c": c, "D": D, "delta": 1.0}, restitution=Newton(e),
                            name="push")


# ----------------------------------------------------------------------------- Monte Carlo

def test_mc_step_larger_than_the_barrier_crossing_time_is_refused():
    m = DuffingImpact(restitution=Elastic(), c=0.1, D=0.1, delta=0.25)
    # speed scale sqrt(D/c) = 1, 4x = 4; gap 0.5: dt = 0.1 crosses 0.8 of the gap in one step
    with pytest.raises(StepSizeError, match="crosses"):
        simulate_ensemble(m, "splitting", dt=0.1, paths=2, t_end=10.0, t_burn=1.0, xy_bins=None)


def test_mc_coarse_step_warns():
    m = DuffingImpact(restitution=Elastic(), c=0.1, D=0.1, delta=1.0)
    with pytest.warns(StepSizeWarning, match="coarse"):
        check_step(m, 0.1, 4.0)


def test_mc_stiff_potential_is_refused():
    with pytest.raises(StepSizeError, match="stiffest"):
        check_step(DuffingImpact(a=1e4), 0.02, 4.0)


def test_mc_chattering_against_a_wall_is_reported():
    # x'' = x - c x' + noise: the inverted spring presses the mass into the wall at x = 1 with the force 1 of _push
    # there (0.32 impacts per step, as _push's), on the Newton-law Duffing kernel other tests compile
    m = DuffingImpact(restitution=Newton(0.3), a=-1.0, b=0.0, c=0.1, D=0.01, delta=1.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = simulate_ensemble(m, "milstein", dt=0.01, paths=2, t_end=20.0, t_burn=1.0, h_max=4.0, xy_bins=None,
                              x0=(0.5, 0.0))
    impacts_per_step = s.impacts / s.path_steps
    assert impacts_per_step > 0.05  # the failure is really there: chattering at the step scale
    flagged = any("chatter" in str(w.message).lower() for w in caught) or "chattering" in s.settings
    assert flagged


# regression: EM at dt = 0.05 here has L1 = 0.27 from the exact density (splitting: 0.011) and used to pass
def test_mc_explicit_euler_bias_is_flagged():
    m = DuffingImpact(restitution=Elastic(), c=0.1, D=0.1, delta=1.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate_ensemble(m, "em", dt=0.05, paths=2, t_end=20.0, t_burn=1.0, h_max=4.0, xy_bins=None)
    assert any(issubclass(w.category, StepSizeWarning) for w in caught)


# ----------------------------------------------------------------------------- orbits

def test_zeno_bouncing_ball_is_stopped_with_status_and_time():
    r = 0.5
    res = simulate_orbit(bouncing_ball(r=r), x0=(0.0, 1.0), t_end=5.0, backend="heyoka")
    assert res.status == "zeno"
    assert res.zeno_time == pytest.approx(bouncing_ball_zeno_time(1.0, r), rel=1e-6)


def test_zeno_against_a_wall_heyoka():
    res = simulate_orbit(_push(), x0=(0.9, 0.5), t_end=50.0, backend="heyoka")
    assert res.status == "zeno"
    assert res.zeno_time < 50.0 and res.n_impacts >= 6


# regression: the scipy backend used to miss these shrinking bounces (no sign change at step ends)
def test_zeno_against_a_wall_scipy():
    res = simulate_orbit(_push(e=0.3), x0=(0.9, 0.5), t_end=50.0, backend="scipy", dense=True)
    xs = res.trajectory.to_pandas()["x"].to_numpy()
    assert res.status == "zeno" or (res.status != "ok" and np.all(xs <= 1.0 + 1e-9))


@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_chattering_is_reported_when_zeno_detection_is_off(backend):
    res = simulate_orbit(_push(), x0=(0.9, 0.5), t_end=50.0, backend=backend, zeno_window=0, min_dwell=1e-6)
    assert res.status == "chattering"
    assert "min_dwell" in res.message


@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
@pytest.mark.parametrize("excess", [1e-4, 1e-8])
def test_grazing_impact_is_located_with_the_right_speed(backend, excess):
    m = DuffingImpact(c=0.0, D=0.0, restitution=Newton(0.9))
    v0 = math.sqrt(2.0 * (m.barrier_energy + excess))
    # the wall speed sqrt(2 (H - G)) carries the energy error rtol*H amplified by H / (2 excess): at excess 1e-8
    # a 1e-3 check needs rtol ~1e-13 (heyoka's default is machine precision already)
    rtol = 1e-13 if backend == "scipy" else None
    res = simulate_orbit(m, x0=(0.0, v0), t_end=3.0, backend=backend, rtol=rtol)
    assert res.status == "ok"
    df = res.impacts.to_pandas()
    assert len(df) >= 1
    # speed at the wall sqrt(2 (H - G(delta))): located, not skipped
    assert abs(df.v_minus.iloc[0]) == pytest.approx(math.sqrt(2 * excess), rel=1e-3)


# ----------------------------------------------------------------------------- averaging and the chooser

def test_averaging_refuses_a_non_confining_potential():
    m = ImpactOscillator("x - x**3", "c*y", parameters={"c": 0.1, "D": 0.05, "delta": 1.5},
                         restitution=Newton(0.8))
    with pytest.raises((ModelError, NormalisationError), match="single well"):
        stationary_density(m, "paper", h_max=4.0)
    with pytest.raises(ModelError, match="single well"):
        diagnose(m)


def test_density_that_cannot_be_normalised_raises():
    m = ImpactOscillator("x", "c*y", parameters={"c": -0.01, "D": 0.05}, barriers=None)
    with pytest.raises(NormalisationError):
        stationary_density(m, "paper", h_max=4.0)
    with pytest.raises(NormalisationError):
        solve(m, tol=0.02)


def test_heavily_dissipative_regime_gets_a_method_that_meets_the_tolerance():
    # no longer refused outright (issue 23): the averaging methods are rated against fpk where the sweep covers the
    # model, and the one chosen does meet the tolerance (checked here against fpk itself); never Monte Carlo
    from averaging.phase_plane import stationary_density_xy
    from vibro.solve import solve

    m = DuffingImpact(restitution=Ma(0.2), c=0.3, D=0.15, delta=0.7)
    sol = solve(m, tol=0.05)
    assert sol.method != "monte-carlo" and sol.estimated_error <= 0.05
    ref = stationary_density_xy(m, grid=(80, 96), h_max=float(sol.edges[-1]))
    assert np.abs(sol.masses - ref.bin_masses(sol.edges)).sum() <= 0.05


def test_heavy_damping_with_elastic_walls_still_gets_the_exact_formula():
    # refusing averaging is about inelastic impacts; the elastic formula is exact at any damping
    ch = choose(DuffingImpact(restitution=Elastic(), c=0.5, D=0.1), tol=0.02, mc_pilot=False)
    assert ch.method == "exact"


def test_monte_carlo_over_budget_warns_that_the_tolerance_is_not_reached():
    # Monte Carlo's plan (choose no longer takes it where fpk applies: planned directly, as for a forced run)
    from vibro.solve.choice import mc_choice

    m = DuffingImpact(restitution=Ma(0.2), c=0.3, D=0.15, delta=0.7)
    with pytest.warns(UserWarning, match="capped"):
        ch = mc_choice(m, 1e-4, diagnose(m), "forced", {}, 0.01, False, 1)
    assert ch.method == "monte-carlo" and ch.expected_error > 1e-4


# regression: found by the validity map (L1 1.6 from Monte Carlo at V_C = 0.1); fixed in averaging by f9816f4
def test_exact_two_impact_density_is_consistent_at_small_critical_speed():
    sd = stationary_density(DuffingImpact(restitution=Ma(0.1)), "exact-two-impact", h_max=4.0, points=800)
    assert 0.0 <= sd.mean_energy <= 4.0
    assert sd.prob_below_barrier > 0.3


def test_self_excited_damping_is_rated_not_refused():
    # issue 23: the sweep of benchmarks/method_ratings.py rates the averaging methods on van der Pol, Rayleigh and
    # negative linear damping, so a self-excited model within it gets a deterministic method, not Monte Carlo
    from models import DuffingVanDerPolImpact

    d = diagnose(DuffingVanDerPolImpact(delta=3.0))
    assert d.self_excited and not diagnose(DuffingImpact()).self_excited
    ch = choose(DuffingVanDerPolImpact(delta=3.0), tol=0.02, mc_pilot=False, diagnostics=d)
    assert ch.method in ("paper", "jump", "chain", "fpk") and "self-excited" not in ch.reason


# regression: the scipy backend skipped near-grazing impacts (22-27 of 86 over t = 200) before it watched
# the guard extremum inside each step
@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_orbit_impact_count_matches_quadrature(backend):
    from vibro.studies.workprecision import free_quasi_period

    e, v0, t_end = 0.95, 2.2, 60.0
    m = DuffingImpact(restitution=Newton(e), c=0.0, D=0.0)
    Gd = m.barrier_energy
    H, t, expected = 0.5 * v0 * v0, free_quasi_period(m, 0.5 * v0 * v0) / 2.0, 0
    while t < t_end:  # oracle: impact times are sums of free crossing times, energies G + e^2 (H - G)
        expected += 1
        H = Gd + e * e * (H - Gd)
        t += free_quasi_period(m, H)
    res = simulate_orbit(m, x0=(0.0, v0), t_end=t_end, backend=backend, rtol=1e-6)
    assert res.n_impacts == expected
