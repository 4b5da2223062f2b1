"""ImpactOscillator as a front end of the automaton kernel, and the automaton kernel's symplectic and BAOAB schemes.

- ``simulate_ensemble`` runs every scheme on the kernel generated from ``model.to_automaton()``
  (``milstein`` as its ``symplectic``, ``splitting`` as its ``baoab``, ``em``, ``naive``); ``kernel="oscillator"``
  (the oscillator's own kernel, removed) is refused in one line.
- The symplectic scheme keeps the Gibbs density of an impact pair with elastic impacts (the n-DOF oracle) and,
  unlike the explicit em, does not pump energy into a lightly damped oscillator.
- Transition checks (the restitution coefficient in (0, 1]) are counted and reported; observables given no
  histogram are summed only.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from hybrid import HybridAutomaton, Mode, Transition
from hybrid.errors import ParameterError, VibroWarning
from hybrid.stochastic import AUTOMATON_SCHEMES, SCHEMES, simulate_automaton, simulate_ensemble
from models import DuffingImpact, Elastic, Newton

SLOW = pytest.mark.slow  # about 12 s each (two cold kernel compiles)


def test_kernel_choice_is_checked_and_reported():
    m = DuffingImpact()
    kw = dict(dt=0.01, paths=2, t_end=2.0, t_burn=0.0, xy_bins=None)
    with pytest.raises(ParameterError, match="kernel="):
        simulate_ensemble(m, "milstein", kernel="fast", **kw)
    with pytest.raises(ParameterError, match="is gone"):
        simulate_ensemble(m, "milstein", kernel="oscillator", **kw)
    with pytest.raises(ParameterError, match="CPU kernel"):
        simulate_ensemble(m, "milstein", kernel="automaton", scheduler="cuda", **kw)
    with pytest.warns(VibroWarning):  # two chunks only: the CI warning (elastic walls: test_montecarlo.py's em kernel)
        assert simulate_ensemble(DuffingImpact(restitution=Elastic()), "em", **kw).settings["kernel"] == "automaton"


X, Y = sp.symbols("x y")


def test_a_failed_transition_check_is_counted_and_reported():
    base = DuffingImpact(restitution=Newton(0.9)).to_automaton()  # the kernel of the event-log tests below
    checked = HybridAutomaton(
        base.states, dict(base.parameters), list(base.modes),
        [Transition(t.name, t.source, t.target, t.guard, t.direction, t.reset, t.priority, check=sp.Abs(Y) < 0.5)
         for t in base.transitions], observables=dict(base.observables))
    kw = dict(dt=2e-3, paths=8, t_end=100.0, x0=(0.0, 0.0), seed=1, histograms={"H": None})
    with pytest.warns(VibroWarning, match="failed their transition's check"):
        ens = simulate_automaton(checked, "symplectic", **kw)
    # firings surely above speed 0.5, from the speed histogram (bins starting at 0.5 or higher, and the overflow)
    fast = ens.speed_counts[:, :-1][:, ens.speed_edges[:-1] >= 0.5].sum() + ens.speed_counts[:, -1].sum()
    assert ens.flags["bad_reset"] >= fast > 0 and ens.first_bad_speed >= 0.5
    assert simulate_automaton(base, "symplectic", **kw).flags["bad_reset"] == 0


def test_two_entry_points_give_the_same_numbers_for_one_seed():
    """simulate_ensemble(model, 'milstein') and simulate_automaton(model.to_automaton(), 'symplectic') are one engine:
    the same seed and chunks give the same energy sums of every chunk and the same impacts, to the bit (the kernels
    are those of the test above and of the oscillator ensembles)."""
    model = DuffingImpact(restitution=Newton(0.9))
    kw = dict(dt=2e-3, paths=8, t_end=100.0, t_burn=10.0, seed=5, chunk_paths=1)
    osc = simulate_ensemble(model, "milstein", xy_bins=None, **kw)
    auto = simulate_automaton(model.to_automaton(), "symplectic", x0=(0.0, 0.0), histograms={"H": None}, **kw)
    order = np.argsort(osc.chunk_ids)
    np.testing.assert_array_equal(osc.chunk_sums[order, 0], auto.chunk_sums[:, 0])
    assert osc.impacts == int(auto.events.sum()) > 0
    assert osc.mean_energy.value == auto.mean("H").value


@SLOW  # two kernels
def test_summed_observables_have_means_but_no_histogram():
    a = DuffingImpact().to_automaton()
    kw = dict(dt=5e-3, paths=16, t_end=60.0, t_burn=5.0, x0=(0.0, 0.0), seed=2, chunk_paths=2)
    both = simulate_automaton(a, "symplectic", observables={"H": a.observables["H"], "x2": X**2},
                              histograms={"H": (0.0, 4.0, 40), "x2": (0.0, 2.0, 10)}, **kw)
    summed = simulate_automaton(a, "symplectic", observables={"H": a.observables["H"], "x2": X**2},
                                histograms={"H": (0.0, 4.0, 40), "x2": None}, **kw)
    # the same samples; with x2 only summed each lane keeps its own sums (the kernel's per-lane variant), so the sums
    # are added in another order: equal to rounding (11,000 samples a lane: relative error below 1e-12)
    assert summed.mean("x2").value == pytest.approx(both.mean("x2").value, rel=1e-12, abs=0.0)
    np.testing.assert_array_equal(summed.counts["H"], both.counts["H"])
    with pytest.raises(ParameterError, match="only summed"):
        summed.density("x2")


@SLOW  # two kernels
def test_a_finite_observable_whose_bin_coordinate_is_nan_goes_to_the_overflow_bin_in_both_statistics_loops():
    # a bin width of 5e-324 makes the scale inf, and (z - lo) * scale = 0 * inf is NaN for the finite z = 0: the
    # sample is not non-finite, so it must land in the overflow bin, in the one-loop statistics (every observable
    # binned) and in the per-lane ones (H only summed) alike; the per-lane loop once tested the coordinate instead
    a = DuffingImpact().to_automaton()
    kw = dict(dt=0.01, paths=8, t_end=3.0, t_burn=1.0, x0=(0.0, 0.0), seed=3,
              observables={"H": a.observables["H"], "z": 0 * X})
    for hist_h in ((0.0, 4.0, 40), None):
        ens = simulate_automaton(a, "symplectic", histograms={"H": hist_h, "z": (0.0, 5e-324, 1)}, **kw)
        n = ens.flags["samples"]
        assert n == 8 * 200 and ens.flags["nonfinite"] == 0
        np.testing.assert_array_equal(ens.counts["z"], [0, 0, n])
        assert ens.mean("z").value == 0.0


@SLOW  # two kernels; the default suite checks symplectic against the Gibbs marginal
def test_symplectic_scheme_does_not_pump_energy_where_explicit_em_does():
    # x'' + c x' + x = sqrt(2D) xi without walls: E[H] = D / c exactly. Explicit EM adds energy at a rate of about
    # dt * omega**2 per unit time against the damping's c: a relative bias of order dt / c = 0.4 here.
    c, D, dt = 0.05, 0.05, 0.02
    mode = Mode("m", (Y, -X - sp.Symbol("c") * Y), (0, sp.sqrt(2 * sp.Symbol("D"))))
    osc = HybridAutomaton((X, Y), {"c": c, "D": D}, [mode], observables={"H": (X**2 + Y**2) / 2})
    kw = dict(dt=dt, paths=64, t_end=2000.0, t_burn=100.0, x0=(0.0, 0.0), seed=4, histograms={"H": (0.0, 10.0, 20)})
    symp = simulate_automaton(osc, "symplectic", **kw).mean("H")
    em = simulate_automaton(osc, "em", **kw).mean("H")
    exact = D / c
    assert abs(symp.value - exact) < 3 * symp.ci + 0.02 * exact, (symp, exact)
    assert em.value - exact > 0.2 * exact, (em, exact)
    assert AUTOMATON_SCHEMES["symplectic"].orders(None)["strong"] == 1.0


def test_baoab_samples_the_exact_position_variance_of_a_harmonic_oscillator_at_a_large_step():
    # BAOAB on x'' + c x' + x = sqrt(2D) xi keeps the exact stationary E[x^2] = D / c at any stable step (Leimkuhler
    # and Matthews), and E[v^2] = (D / c)(1 - dt^2 / 4); the symplectic Milstein is off by O(dt) there.
    # Measured at dt = 0.5: baoab 1.003 +- 0.007 and 0.941 +- 0.007 (exact 1 and 0.9375), symplectic 1.071.
    # The oscillator without walls through its front end: its 'splitting' is this BAOAB (the kernel of
    # test_montecarlo.py's linear-recursion test, so no compile of its own).
    c, D, dt = 0.05, 0.05, 0.5
    osc = DuffingImpact(restitution=Elastic(), a=1.0, b=0.0, c=c, D=D, delta=math.inf)
    b = simulate_ensemble(osc, "splitting", dt=dt, paths=128, t_end=20000.0, t_burn=100.0, x0=(0.0, 0.0), seed=4,
                          h_max=20.0, xy_bins=None, check_dt=False)
    assert b.settings["kernel"] == "automaton"
    exact = D / c
    assert abs(b.mean_x2.value - exact) < 3 * b.mean_x2.ci, b.mean_x2
    assert abs(b.mean_y2.value - exact * (1 - dt**2 / 4)) < 3 * b.mean_y2.ci, b.mean_y2
    # precise enough to see the bias BAOAB avoids: the symplectic Milstein's 1.071 +- 0.008 at this step
    assert b.mean_x2.ci < 0.015
    assert AUTOMATON_SCHEMES["baoab"].orders(None) == {"strong": 1.0, "weak": 2.0}
    assert SCHEMES["splitting"].strong_order == 1.0  # the oscillator's name for it declares the same (fitted below)


def test_baoab_refuses_damping_or_noise_it_cannot_step_exactly():
    from hybrid.errors import ModelError

    kw = dict(dt=0.01, paths=8, t_end=1.0, t_burn=0.0, x0=(0.0, 0.0, 0.0, 0.0), histograms={}, seed=1)
    with pytest.raises(ModelError, match="noise that does not depend on the velocities"):
        simulate_automaton(_two_dof(True), "baoab", **kw)
    cubic = Mode("m", (Y, -X - sp.Symbol("c") * Y**3), (0, 1))
    with pytest.raises(ModelError, match="F\\(positions, t\\) - c\\(positions, t\\)"):
        simulate_automaton(HybridAutomaton((X, Y), {"c": 0.1}, [cubic]), "baoab", **{**kw, "x0": (0.0, 0.0)})


@pytest.mark.parametrize("scheme", ["symplectic", pytest.param("baoab", marks=SLOW)])
def test_free_flight_schemes_keep_the_gibbs_marginal_of_an_impact_pair(scheme):
    from scipy import special
    from test_automaton_mc import impact_pair

    gap, th, k1, k2 = 0.2, 0.05, 1.0, 0.6
    ens = simulate_automaton(impact_pair(), scheme, dt=0.01, paths=64, t_end=600.0, t_burn=30.0,
                             x0=(0, 0, 0, 0), seed=12, histograms={"z": (-gap, gap, 20), "kinetic": (0, 1, 10)})
    assert ens.flags["outside"] == 0 and ens.events.sum() > 1000
    sd = math.sqrt(th * (1 / k1 + 1 / k2))
    cdf = 0.5 * (1 + special.erf(ens.edges["z"] / (sd * math.sqrt(2))))
    exact = np.diff(cdf) / (cdf[-1] - cdf[0])
    mc = ens.counts["z"][1:-1] / ens.flags["samples"]
    assert np.abs(mc - exact).sum() < 0.03


def _two_dof(multiplicative: bool):
    """Two masses on springs, damped, one noise on v1 (proportional to v1 when ``multiplicative``)."""
    x1, x2, v1, v2 = sp.symbols("x1 x2 v1 v2")
    k1, k2, c, s = (sp.Symbol(n) for n in ("k1", "k2", "c", "s"))
    flow = (v1, v2, -k1 * x1 - k2 * (x1 - x2) - c * v1, -k2 * (x2 - x1) - c * v2)
    g = s * v1 if multiplicative else s
    return HybridAutomaton((x1, x2, v1, v2), {"k1": 1.0, "k2": 0.5, "c": 0.4, "s": 1.0},
                           [Mode("m", flow, (0, 0, g, 0))])


@pytest.mark.parametrize("scheme, multiplicative, order", [
    ("em", True, 0.5), ("milstein", True, 1.0), ("symplectic", True, 1.0), ("splitting", True, 0.5),
    ("em", False, 1.0), ("baoab", False, 1.0)])
def test_strong_orders_fitted_on_a_two_degree_of_freedom_system(scheme, multiplicative, order):
    # each scheme against itself at dt / 16 along the same Brownian path (sums of the fine increments); measured
    # slopes: em 0.53, milstein 0.99, symplectic 1.04, splitting 0.47 (multiplicative), em 1.0 and baoab 1.00
    # (additive; baoab refuses noise that depends on a velocity)
    from hybrid.stochastic import drive_automaton
    from hybrid.stochastic._auto_codegen import analyse

    automaton = _two_dof(multiplicative)
    T, fine, paths = 1.0, 2**11, 256
    dw = np.random.default_rng(5).standard_normal((paths, fine, 1)) * math.sqrt(T / fine)
    x0 = (0.5, -0.2, 0.0, 0.3)
    ref = drive_automaton(automaton, scheme, T / fine, dw, x0)
    levels = [2**k for k in range(3, 8)]
    errors = []
    for n in levels:  # the same Brownian path on the coarse grid: sums of fine increments
        coarse = dw.reshape(paths, n, fine // n, 1).sum(axis=2)
        end = drive_automaton(automaton, scheme, T / n, coarse, x0)
        errors.append(math.sqrt(np.mean(np.sum((end - ref) ** 2, axis=1))))
    slope = -np.polyfit(np.log(levels), np.log(errors), 1)[0]
    declared = AUTOMATON_SCHEMES[scheme].orders(analyse(automaton))["strong"]
    assert declared == order
    assert slope == pytest.approx(order, abs=0.15), (errors, slope)


@pytest.mark.parametrize("scheme", ["symplectic", "em", pytest.param("splitting", marks=SLOW),
                                    pytest.param("milstein", marks=SLOW), pytest.param("baoab", marks=SLOW)])
def test_zero_noise_impact_times_and_speeds_match_the_heyoka_orbit(scheme):
    # the kernel's own event log (drive_automaton(events=K)): crossings located inside the step, D = 0
    from hybrid.deterministic import simulate_orbit
    from hybrid.stochastic import drive_automaton

    automaton = DuffingImpact(restitution=Newton(0.9), a=1.0, b=0.2, c=0.02, D=0.0, delta=1.0).to_automaton()
    orbit = simulate_orbit(automaton, x0=[0.0, 3.0], t_end=6.0, backend="heyoka")
    times, speeds = orbit.impacts.t, np.abs(orbit.impacts.before[:, 1])
    assert len(times) == 6
    ratios = []
    for dt in (2e-3, 1e-3, 5e-4, 2.5e-4):
        n = int(round(6.0 / dt))
        _, log, count = drive_automaton(automaton, scheme, dt, np.zeros((1, n, 1)), x0=(0.0, 3.0), events=10)
        assert count[0] == 6
        assert [automaton.transitions[int(j)].name for j in log[0, :6, 1]] == list(orbit.impacts.transition)
        err_t = np.max(np.abs(log[0, :6, 0] - times))
        err_v = np.max(np.abs(log[0, :6, 2] - speeds))
        # first order: measured err_t / dt 1.6-3.5 (splitting, symplectic: the kicks make the constant vary with
        # where in the step the wall is met) and 8.3 (em, steady); speeds 1.2-2.0 and 6.4
        assert err_t < 10 * dt and err_v < 10 * dt, (dt, err_t / dt, err_v / dt)
        ratios.append(err_t / dt)
    if scheme == "em":  # a clean first-order constant: the fitted slope is 1
        assert max(ratios) / min(ratios) < 1.02, ratios


@pytest.mark.parametrize("scheme", ["symplectic", pytest.param("baoab", marks=SLOW)])
def test_ensemble_event_logs_match_the_heyoka_orbit_at_zero_noise(scheme):
    # the ensemble kernel's own per-path log (simulate_automaton(events=K)), D = 0: every path is the orbit;
    # measured worst time error 2.3 dt (symplectic) and 2.3 dt (baoab) at dt = 1e-3, 6 impacts
    from hybrid.deterministic import simulate_orbit

    automaton = DuffingImpact(restitution=Newton(0.9), a=1.0, b=0.2, c=0.02, D=0.0, delta=1.0).to_automaton()
    orbit = simulate_orbit(automaton, x0=[0.0, 3.0], t_end=6.0, backend="heyoka")
    times, speeds = orbit.impacts.t, np.abs(orbit.impacts.before[:, 1])
    dt = 1e-3
    ens = simulate_automaton(automaton, scheme, dt=dt, paths=3, t_end=6.0, x0=(0.0, 3.0), seed=1, events=8,
                             chunk_paths=2, histograms={"H": None}, check_dt=False)
    assert ens.event_log.shape == (3, 8, 3) and list(ens.event_totals) == [6, 6, 6]
    assert np.all(np.isnan(ens.event_log[:, 6:, :]))  # fewer firings than rows: NaN, not zeros
    for path in range(3):
        log = ens.event_log[path, :6]
        assert [ens.transitions[int(j)] for j in log[:, 1]] == list(orbit.impacts.transition)
        assert np.max(np.abs(log[:, 0] - times)) < 5 * dt and np.max(np.abs(log[:, 2] - speeds)) < 5 * dt
    first_left = ens.first_event_times("left")
    assert np.allclose(first_left, ens.event_log[:, 1, 0]) and abs(first_left[0] - times[1]) < 5 * dt
    table = ens.events_to_pandas()
    assert len(table) == 18 and set(table.transition) == {"left", "right"}


def test_event_log_requests_are_checked():
    # the automaton (and so the kernel) of the heyoka test above
    a = DuffingImpact(restitution=Newton(0.9), a=1.0, b=0.2, c=0.02, D=0.0, delta=1.0).to_automaton()
    kw = dict(dt=0.01, paths=8, t_end=1.0, x0=(0.0, 0.0), seed=1, histograms={"H": None})
    for bad in (-1, 2.5, True):
        with pytest.raises(ParameterError, match="events="):
            simulate_automaton(a, "symplectic", events=bad, **kw)
    with pytest.raises(ParameterError, match="the event log of events=1000000000 .* GB of memory"):
        simulate_automaton(a, "symplectic", events=10**9, **kw)
    with pytest.raises(ParameterError, match="no event log"):
        simulate_automaton(a, "symplectic", **kw).first_event_times()
    with pytest.raises(ParameterError, match="no transition 'up'"):
        simulate_automaton(a, "symplectic", events=2, **kw).first_event_times("up")


@pytest.mark.parametrize("scheme", [pytest.param("splitting", marks=SLOW), "baoab"])
def test_direction_zero_guards_give_the_directed_guards_numbers(scheme):
    # modes a -> b when x crosses 0.5 and b -> a when x crosses -0.5 on x'' + c x' + x = noise: from x = 0 moving
    # up, the first crossing of each guard is in the direction a +1 / -1 guard also fires in, so a guard of
    # direction 0 must give the same firings and paths. (The values bound before the loops once shared names with
    # the fast step's direction-0 guard values and were overwritten in the loop: the kick went wrong silently.)
    c, s = sp.Symbol("c"), sp.Symbol("s")

    def automaton(up, down):
        flow = (Y, -X - c * Y)
        modes = [Mode("a", flow, (0, s)), Mode("b", flow, (0, s))]
        return HybridAutomaton((X, Y), {"c": 0.02, "s": 0.2}, modes, [
            Transition("up", "a", "b", X - sp.Rational(1, 2), up, (X, Y)),
            Transition("down", "b", "a", X + sp.Rational(1, 2), down, (X, Y))],
            observables={"H": (X**2 + Y**2) / 2})

    kw = dict(dt=0.01, paths=8, t_end=100.0, t_burn=0.0, x0=(0.0, math.sqrt(2.0)), seed=2, chunk_paths=1,
              histograms={"H": (0.0, 2.0, 40)}, check_dt=False)
    undirected = simulate_automaton(automaton(0, 0), scheme, **kw)
    directed = simulate_automaton(automaton(1, -1), scheme, **kw)
    np.testing.assert_array_equal(undirected.counts["H"], directed.counts["H"])
    np.testing.assert_array_equal(undirected.events, directed.events)
    # started at the stationary mean E[H] = s^2 / (2 c) = 1 (splitting's O(dt) bias is far below the interval);
    # the modes alternate, so each path has as many 'down' firings as 'up' ones, or one fewer
    h = undirected.mean("H")
    assert abs(h.value - 1.0) < 3 * h.ci, h
    up, down = undirected.events
    assert up > 8 * 8 and 0 <= up - down <= 8


@SLOW  # a kernel of its own
def test_a_division_by_zero_in_the_kernel_is_a_one_line_parameter_error():
    k = sp.Symbol("k")
    singular = HybridAutomaton((X, Y), {"k": 0.0}, [Mode("m", (Y, -X / k - Y), (0, 1))])
    with pytest.raises(ParameterError, match="divided by zero") as info:
        simulate_automaton(singular, "symplectic", dt=0.01, paths=8, t_end=1.0, x0=(0.1, 0.0), seed=1,
                           observables={"x": X}, histograms={"x": None}, check_dt=False)
    assert "\n" not in str(info.value)
