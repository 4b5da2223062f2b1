"""Issue 9, orbit half: Zeno at any ratio, no unreported tunnelling, bounded work, e checked at every impact."""

from __future__ import annotations

import math

import numpy as np
import pytest
from problems import bouncing_ball, bouncing_ball_zeno_time

from hybrid.deterministic import ZenoDetector, simulate_orbit
from hybrid.errors import ParameterError, RestitutionError
from hybrid.sizes import SizeError
from models import CustomRestitution, DuffingImpact, ImpactOscillator, Newton
from models.restitution import _CHECK_SPEEDS


def _left_push(e):
    """g = x + 5 with c = 0 and walls at +-1: a strong force presses the mass onto the left wall from rest."""
    return ImpactOscillator("x + 5", 0, parameters={"D": 0.0, "delta": 1.0}, restitution=Newton(e), name="push")


def _left_push_accumulation(e):
    """Exact accumulation time from rest at x = 0: first hit at acos(4/5) with speed 3, then flights 2 atan(v/4)."""
    t, v = math.acos(0.8), 3.0
    while v > 1e-300:
        v *= e
        t += 2.0 * math.atan(v / 4.0)
    return t


# ----------------------------------------------------------------------------- Zeno at any ratio below 1

# regression: heyoka returned status 'ok' with x = -3.65 (gap [-1, 1]) after 1822 impacts; scipy at e = 0.995
# ran to max_impacts (20,000 impacts in 27 s)
@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
@pytest.mark.parametrize("e", [0.99, 0.995])
def test_push_onto_a_wall_stops_as_zeno(backend, e):
    res = simulate_orbit(_left_push(e), (0.0, 0.0), 2000.0, backend=backend, max_impacts=20000)
    assert res.status == "zeno", res.message
    assert res.n_impacts < 400
    assert -1.0 - 1e-12 <= res.state[0] <= 1.0  # on the wall up to the rounding of the event location
    assert np.all(np.abs(res.impacts.x + 1.0) <= 1e-12)
    # the flight time 2 atan(v/4) is not proportional to v, so the ratios drift towards e while the detector
    # watches them: its geometric prediction is within 0.5% of the exact accumulation time
    assert res.zeno_time == pytest.approx(_left_push_accumulation(e), rel=5e-3)
    assert res.t < _left_push_accumulation(e)


# regression: heyoka ended at x = -490.8 (r = 0.99) with status 'ok'; the detector accepted only ratios < 0.99
@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
@pytest.mark.parametrize("r", [0.99, 0.995])
def test_bouncing_ball_zeno_time_close_to_one(backend, r):
    v0 = 3.0
    res = simulate_orbit(bouncing_ball(r=r), (0.0, v0), 1000.0, backend=backend)
    assert res.status == "zeno", res.message
    assert res.zeno_time == pytest.approx(bouncing_ball_zeno_time(v0, r), rel=1e-9)
    assert res.state[0] >= -1e-12


def test_zeno_detector_accepts_any_ratio_below_one():
    z = ZenoDetector(window=6)
    t, dt, found = 0.0, 1.0, None
    for _ in range(8):
        found = z.add(t)
        t += dt
        dt *= 0.9999
    # the closed form: t_k + dt_k r / (1 - r) with the last interval; the series sums to 1 / (1 - r) = 10000
    assert found == pytest.approx(10000.0, rel=1e-9)
    assert z.ratio == pytest.approx(0.9999, rel=1e-12)


def test_zeno_detector_ignores_intervals_converging_to_a_period():
    """dt_k = 1 + 0.5 * 0.9**k: ratios below 1 that tend to 1 (a periodic orbit), not an accumulation."""
    z = ZenoDetector(window=6)
    t = 0.0
    for k in range(400):
        assert z.add(t) is None
        t += 1.0 + 0.5 * 0.9**k


@pytest.mark.parametrize("kwargs", [dict(window=1), dict(window=2.5), dict(rtol=float("nan")), dict(rtol=-1.0),
                                    dict(max_ratio=1.5), dict(max_ratio=0.0)])
def test_zeno_detector_bad_arguments_are_parameter_errors(kwargs):
    with pytest.raises(ParameterError):
        ZenoDetector(**kwargs)


# ----------------------------------------------------------------------------- the admissible set

@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_missed_impact_is_reported_not_ok(backend):
    """With Zeno detection and min_dwell off, the integrators eventually step through the floor: say so."""
    res = simulate_orbit(bouncing_ball(r=0.99), (0.0, 3.0), 2000.0, backend=backend, zeno_window=0, min_dwell=0.0,
                         max_impacts=20000)
    assert res.status == "left_admissible_set"
    assert "missed" in res.message and "'floor'" in res.message
    assert res.state[0] < 0.0  # the state where it stopped is reported as it is


def test_missed_impact_against_the_left_wall_heyoka():
    res = simulate_orbit(_left_push(0.99), (0.0, 0.0), 2000.0, zeno_window=0, min_dwell=0.0, max_impacts=20000)
    assert res.status == "left_admissible_set"
    assert "'left'" in res.message and res.state[0] < -1.0


# ----------------------------------------------------------------------------- bounded work

@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_huge_t_end_is_refused_with_the_estimate(backend):
    import time

    m = DuffingImpact(c=0.0, D=0.0, restitution=Newton(0.9))
    start = time.perf_counter()
    with pytest.raises(SizeError, match=r"t_end=1e\+300 needs about 3.16e\+299 integration steps.*above the limit 300"):
        simulate_orbit(m, (0.0, 2.2), 1e300, backend=backend, max_steps=300)
    assert time.perf_counter() - start < 5.0  # estimated, before any integrator is built


@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_an_orbit_longer_than_estimated_still_stops_at_max_steps(backend):
    m = DuffingImpact(c=0.0, D=0.0, restitution=Newton(0.9))
    res = simulate_orbit(m, (0.0, 2.2), 500.0, backend=backend, max_steps=300)  # estimated at 158 steps
    assert res.status == "max_steps" and res.n_steps == 300
    assert "max_steps=300" in res.message and res.t < 500.0


@pytest.mark.parametrize("backend,kwargs", [
    ("heyoka", dict(rtol=1e-300)), ("heyoka", dict(rtol=1e-17)), ("heyoka", dict(rtol=float("nan"))),
    ("scipy", dict(rtol=1e-15)), ("scipy", dict(atol=float("inf"))), ("scipy", dict(atol=float("nan"))),
    ("heyoka", dict(max_steps=0)), ("heyoka", dict(max_steps=2.5)), ("heyoka", dict(max_impacts=10**12)),
    ("heyoka", dict(max_impacts=True)),
])
def test_unbounded_or_impossible_settings_are_refused(backend, kwargs):
    m = DuffingImpact(c=0.0, D=0.0, restitution=Newton(0.9))
    with pytest.raises(ParameterError) as info:
        simulate_orbit(m, (0.0, 2.2), 10.0, backend=backend, **kwargs)
    assert "\n" not in str(info.value)
    if "max_impacts" in kwargs and kwargs["max_impacts"] is not True:
        assert "GB" in str(info.value)


def test_machine_precision_tolerance_is_still_accepted():
    m = DuffingImpact(c=0.0, D=0.0, restitution=Newton(0.9))
    assert simulate_orbit(m, (0.0, 2.2), 5.0, rtol=float(np.finfo(float).eps)).status == "ok"
    assert simulate_orbit(m, (0.0, 2.2), 5.0, backend="scipy", rtol=1e-13).status == "ok"


# ----------------------------------------------------------------------------- e at every impact

def _window_between_grid_points(v=1.9):
    """An interval of speeds (a, b) around ``v`` with no speed of the validation grid inside."""
    grid = np.sort(_CHECK_SPEEDS)
    hi = grid[np.searchsorted(grid, v)]
    lo = grid[np.searchsorted(grid, v) - 1]
    return lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo)


def _orbit_hitting_at(speed):
    m = DuffingImpact(c=0.0, D=0.0)
    return m, math.sqrt(speed**2 + 2.0 * m.barrier_energy)


# regression: a law returning 1.3 between grid points raised H from 1.78 to 2.66 at an impact, exit 0
@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
@pytest.mark.parametrize("kind", ["callable", "expression"])
def test_restitution_above_one_between_grid_points_is_refused_at_the_impact(backend, kind):
    a, b = _window_between_grid_points()
    if kind == "callable":
        law = CustomRestitution(lambda v: np.where((v > a) & (v < b), 1.3, 0.9), label="bump")
    else:
        mid, half = 0.5 * (a + b), 0.5 * (b - a)
        law = CustomRestitution(f"9/10 + 4/10 * Piecewise((1, Abs(v - {float(mid)!r}) < {float(half)!r}), (0, True))")
    law.validate()  # the grid check cannot see it
    m, v0 = _orbit_hitting_at(0.5 * (a + b))
    with pytest.raises(RestitutionError, match=r"e = 1\.3.*\|v-\| = 1\.9") as info:
        simulate_orbit(m.with_restitution(law), (0.0, v0), 5.0, backend=backend)
    assert "\n" not in str(info.value)


def test_a_valid_law_passes_the_per_impact_check():
    m, v0 = _orbit_hitting_at(1.9)
    res = simulate_orbit(m.with_restitution(CustomRestitution(lambda v: 0.8 + 0 * v)), (0.0, v0), 5.0)
    assert res.status == "ok" and np.allclose(res.impacts.e, 0.8, rtol=1e-15)
