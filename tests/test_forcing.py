"""Harmonic forcing (time in flows, guards and resets) in every engine, against closed forms.

- A forced linear oscillator without barriers: the orbit backends against the closed-form solution (transient plus
  steady state).
- A forced linear oscillator between elastic walls: the symmetric period-1 orbit (one impact per wall and half
  period), derived in closed form below, is reproduced by both backends.
- The vibrating table (a moving guard): heyoka and scipy agree on the impact times; with D = 0 the Monte Carlo
  kernel fires at the same times to O(dt), with the same impact speeds.
- Phase-resolved Monte Carlo of the forced linear oscillator with additive white noise: on each Poincaré section the
  density is Gaussian with mean = the periodic response at that phase and variance = the unforced stationary
  variance D / (c w0**2); checked per phase within batch-means confidence intervals.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from hybrid.deterministic import simulate_orbit
from hybrid.errors import ModelError, ParameterError
from hybrid.stochastic import simulate_automaton, simulate_ensemble
from models import Elastic, ForcedDuffingImpact, ImpactOscillator, automata


def forced_linear(c=0.3, w0=1.0, W=1.7, A=0.8, phi=0.4, D=0.0, **kw):
    return ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t + phi)",
                            parameters=dict(c=c, w0=w0, W=W, A=A, phi=phi, D=D, **kw.pop("extra", {})),
                            barriers=kw.pop("barriers", None), **kw)


def periodic_response(t, c, w0, W, A, phi):
    """x_p(t) and x_p'(t) of x'' + c x' + w0**2 x = A cos(W t + phi)."""
    z = A * np.exp(1j * (W * t + phi)) / (w0**2 - W**2 + 1j * c * W)
    return z.real, (1j * W * z).real


def linear_solution(t, x0, v0, c, w0, W, A, phi):
    """Closed form: periodic response plus the damped free oscillation that matches (x0, v0) at t = 0."""
    xp0, vp0 = periodic_response(0.0, c, w0, W, A, phi)
    wd = math.sqrt(w0**2 - c**2 / 4)
    a = x0 - xp0
    b = (v0 - vp0 + c * a / 2) / wd
    env = np.exp(-c * t / 2)
    xh = env * (a * np.cos(wd * t) + b * np.sin(wd * t))
    vh = env * (-c / 2 * (a * np.cos(wd * t) + b * np.sin(wd * t)) + wd * (-a * np.sin(wd * t) + b * np.cos(wd * t)))
    xp, vp = periodic_response(t, c, w0, W, A, phi)
    return xp + xh, vp + vh


@pytest.mark.parametrize("backend, options, tol", [("heyoka", {}, 1e-12), ("scipy", {"rtol": 1e-12}, 1e-9)])
def test_forced_linear_oscillator_matches_its_closed_form(backend, options, tol):
    p = dict(c=0.3, w0=1.0, W=1.7, A=0.8, phi=0.4)
    m = forced_linear(**p)
    x0, v0 = 0.2, -0.5
    for t_end in (2.5, 60.0):  # inside the transient, and after it has decayed by e**-9
        r = simulate_orbit(m, (x0, v0), t_end=t_end, backend=backend, **options)
        assert r.status == "ok" and r.n_impacts == 0
        exact = linear_solution(t_end, x0, v0, **p)
        assert np.allclose(r.state, exact, rtol=0, atol=tol), (r.state, exact)


def test_forced_orbit_starts_at_t0_in_the_forcing_phase():
    """The forcing reads absolute time: starting at t0 = 1 gives the closed form shifted by the phase W * 1."""
    p = dict(c=0.3, w0=1.0, W=1.7, A=0.8, phi=0.4)
    r = simulate_orbit(forced_linear(**p), (0.2, -0.5), t0=1.0, t_end=4.0, backend="heyoka")
    exact = linear_solution(3.0, 0.2, -0.5, **{**p, "phi": p["phi"] + p["W"] * 1.0})
    assert np.allclose(r.state, exact, rtol=0, atol=1e-12)


def test_forced_impact_oscillator_follows_the_symmetric_period_one_orbit():
    """x'' + w0**2 x = A cos(W t), elastic walls at +-d: the orbit hitting x = d at t = 0 and x = -d at t = T/2.

    Free motion after an impact at x = d at time t1: x = C cos(w0 s) + S sin(w0 s) + P cos(W (t1 + s)), with
    P = A / (w0**2 - W**2), s = t - t1. Symmetry x(t + h) = -x(t), h = T/2 = pi / W, asks x(0) = d, x'(0) = -V,
    x(h) = -d, x'(h) = -V. The position conditions give C = d - P c1, S = (1 + cos w0 h)(P c1 - d) / sin w0 h
    (c1 = cos W t1); adding the velocity conditions leaves 2 P W sin(W t1) = 0, so t1 = 0 (c1 = 1) and
    V = -w0 S = w0 (d - P) cot(w0 h / 2).
    """
    w0, W, A, d = 1.0, 2.5, 1.0, 0.5
    h = math.pi / W
    P = A / (w0**2 - W**2)
    V = w0 * (d - P) / math.tan(w0 * h / 2)
    # the orbit stays between the walls: checked on the closed form, not assumed
    s = np.linspace(0.0, h, 4001)
    x = (d - P) * np.cos(w0 * s) - V / w0 * np.sin(w0 * s) + P * np.cos(W * s)
    assert x.max() <= d + 1e-12 and x.min() >= -d - 1e-12
    m = ImpactOscillator("w0**2*x", 0, forcing="A*cos(W*t)", parameters=dict(w0=w0, W=W, A=A, D=0.0, delta=d),
                         restitution=Elastic())
    for backend, options, tol in (("heyoka", {}, 1e-12), ("scipy", {"rtol": 1e-12}, 1e-10)):
        r = simulate_orbit(m, (d, -V), t_end=10 * h + 0.1, backend=backend, **options)
        assert r.status == "ok" and r.n_impacts == 10
        assert np.allclose(r.impacts.t, h * np.arange(1, 11), rtol=0, atol=tol)
        assert list(r.impacts.transition[:2]) == ["left", "right"]
        assert np.allclose(np.abs(r.impacts.before[:, 1]), V, rtol=0, atol=tol)


def table_orbit(backend, t_end=12.0, **params):
    table = automata.vibrating_table(A=0.3, omega=2.5, r=0.7, **params)
    options = {"rtol": 1e-13} if backend == "scipy" else {}
    return simulate_orbit(table, x0=[1.0, 0.0], t_end=t_end, backend=backend, **options)


def test_vibrating_table_backends_agree_on_impact_times():
    hey, sci = table_orbit("heyoka"), table_orbit("scipy")
    assert hey.status == sci.status == "ok"
    assert hey.n_impacts == sci.n_impacts >= 6
    assert np.max(np.abs(hey.impacts.t - sci.impacts.t)) < 1e-8
    # the reset reads the table's velocity at the impact instant: the ball leaves upwards relative to the table
    t = hey.impacts.t
    table_v = 0.3 * 2.5 * np.cos(2.5 * t)
    assert np.all(hey.impacts.after[:, 1] - table_v > 0)
    assert np.allclose(hey.impacts.after[:, 0], 0.3 * np.sin(2.5 * t), atol=1e-12)


def test_zero_noise_monte_carlo_fires_at_the_orbit_impact_times():
    """D = 0 on the vibrating table: the Monte Carlo kernel's impact count over [0, t] steps up at the heyoka impact
    times to O(dt), and its impact speeds |s'(t) - v| match the orbit's."""
    orbit = table_orbit("heyoka", t_end=12.0)
    times = orbit.impacts.t[:6]
    table = automata.vibrating_table(A=0.3, omega=2.5, r=0.7)
    dt = 1e-4
    kw = dict(dt=dt, paths=1, x0=(1.0, 0.0), seed=1, observables={"x": "x"}, histograms={"x": (-5.0, 5.0, 10)},
              chunk_paths=1)
    eps = 20 * dt
    for k, tk in enumerate(times):
        before = simulate_automaton(table, "splitting", t_end=tk - eps, **kw)
        after = simulate_automaton(table, "splitting", t_end=tk + eps, **kw)
        assert before.events[0] == k and after.events[0] == k + 1, (k, tk)
    # speeds: the relative speed at each impact, histogrammed in bins of 1e-3
    w = 1e-3
    ens = simulate_automaton(table, "splitting", t_end=times[-1] + eps, speed_range=(0.0, 5.0, 5000), **kw)
    with pytest.raises(ParameterError, match="no phase sections"):  # a run without phases has none to give
        ens.phase_mean("x", 0)
    c = ens.speed_counts[0]
    mc_speeds = np.repeat((np.arange(c.size - 1) + 0.5) * w, c[:-1])
    v_rel = np.abs(0.3 * 2.5 * np.cos(2.5 * times) - orbit.impacts.before[:6, 1])
    assert mc_speeds.size == 6
    assert np.max(np.abs(np.sort(mc_speeds) - np.sort(v_rel))) <= w / 2 + 100 * dt


# ------------------------------------------------------------------------------------------------ the model front end
def test_time_terms_of_the_restoring_force_become_the_forcing():
    m = ImpactOscillator("x + x**3 - A*cos(W*t + phi)", "c*y",
                         parameters={"A": 0.3, "W": 1.2, "phi": 0.0, "c": 0.1, "D": 0.01, "delta": 1.0})
    assert str(m.g) == "x**3 + x"
    assert str(m.forcing) == "A*cos(W*t + phi)"
    assert m.is_forced and math.isclose(m.forcing_period, 2 * math.pi / 1.2)
    assert math.isclose(float(m.potential(1.0)), 0.75)  # G of the unforced g


def test_forcing_period_needs_commensurate_harmonics():
    m = forced_linear()
    assert math.isclose(m.forcing_period, 2 * math.pi / 1.7)
    two = ImpactOscillator("x", forcing="A*cos(W*t) + A*sin(2.5*W*t)", parameters={"A": 1.0, "W": 1.0, "D": 0.0},
                           barriers=None)
    assert two.forcing_period is None
    assert ImpactOscillator("x", parameters={"D": 0.0}, barriers=None).forcing_period is None


@pytest.mark.parametrize("params, words", [
    ({"W": 0.0}, "non-zero frequency"), ({"W": float("nan")}, "not finite"), ({"A": float("nan")}, "not finite"),
])
def test_bad_forcing_parameters_are_refused_in_one_line(params, words):
    with pytest.raises(ParameterError, match=words) as info:
        forced_linear().with_params(**params)
    assert "\n" not in str(info.value)
    with pytest.raises(ParameterError, match=words):
        forced_linear(**params)


def test_time_outside_the_forcing_is_refused():
    with pytest.raises(ModelError, match="only the forcing may depend on time"):
        ImpactOscillator("x", "c*y*cos(t)", parameters={"c": 0.1, "D": 0.0}, barriers=None)
    with pytest.raises(ModelError, match="reserved for time"):
        ImpactOscillator("x", parameters={"t": 1.0, "D": 0.0}, barriers=None)


def test_averaging_and_the_oscillator_kernel_refuse_a_forced_model():
    from averaging import stationary_density

    m = ForcedDuffingImpact()
    with pytest.raises(ModelError, match="simulate_automaton") as info:
        stationary_density(m)
    assert "\n" not in str(info.value)
    with pytest.raises(ModelError, match="simulate_automaton"):
        simulate_ensemble(m, "splitting", dt=0.01, paths=8, t_end=10.0, t_burn=1.0)


# ------------------------------------------------------------------------------------------------ phase sections
def test_phase_sections_are_gaussian_around_the_periodic_response():
    c, w0, W, A, phi, D = 0.5, 1.0, 1.3, 0.4, 0.0, 0.05
    m = forced_linear(c=c, w0=w0, W=W, A=A, phi=phi, D=D)
    T, N = m.forcing_period, 8
    zr = A / (w0**2 - W**2 + 1j * c * W)  # x_p(t) = Re(zr exp(i W t)) = a cos(W t) + b sin(W t)
    a, b = zr.real, -zr.imag
    dev2 = f"(x - ({a!r})*cos(W*t) - ({b!r})*sin(W*t))**2"
    ens = simulate_automaton(m.to_automaton(), "splitting", dt=0.01, paths=64, t_end=400.0, t_burn=40.0, x0=(0, 0),
                             seed=3, observables={"x": "x", "dev2": dev2},
                             histograms={"x": (-3.0, 3.0, 60), "dev2": (0.0, 2.0, 20)}, phases=N, period=T,
                             chunk_paths=4)
    dt = ens.settings["dt"]
    steps = ens.settings["phase_steps"]
    assert dt <= 0.01 and ens.settings["dt_requested"] == 0.01
    assert math.isclose(N * steps * dt, T, rel_tol=1e-14)
    var = D / (c * w0**2)
    xp, _ = periodic_response(ens.phase_times(), c, w0, W, A, phi)
    misses = 0
    for k in range(N):
        mean, second = ens.phase_mean("x", k), ens.phase_mean("dev2", k)
        # the scheme's bias (splitting, dt = 0.01) is below 1e-3 here: the CI alone decides
        misses += (not mean.covers(xp[k])) + (not second.covers(var))
        e, dens = ens.phase_density("x", k)
        centres = (e[:-1] + e[1:]) / 2
        gauss = np.exp(-(centres - xp[k]) ** 2 / (2 * var)) / math.sqrt(2 * math.pi * var)
        assert np.sum(np.abs(dens - gauss) * np.diff(e)) < 0.08  # L1 of the section's histogram (noise ~0.05)
    # 16 intervals at 95 %: allow the misses a 95 % interval allows by chance (P(more than 3) < 1 %)
    assert misses <= 3
    df = ens.phase_to_pandas("x")
    assert sorted(df.phase.unique()) == list(range(N)) and int(df["count"].sum()) == int(ens.phase_samples.sum())


def test_phase_requests_are_checked():
    A = forced_linear(D=0.01).to_automaton()
    kw = dict(dt=0.01, paths=2, t_end=20.0, x0=(0, 0), seed=1, observables={"x": "x"},
              histograms={"x": (-3, 3, 10)})
    with pytest.raises(ParameterError, match="period"):
        simulate_automaton(A, "em", phases=4, **kw)
    with pytest.raises(ParameterError, match="phases=N"):
        simulate_automaton(A, "em", period=2.0, **kw)
    with pytest.raises(ParameterError, match="phases"):
        simulate_automaton(A, "em", phases=-1, period=2.0, **kw)
    with pytest.raises(ParameterError, match="period"):
        simulate_automaton(A, "em", phases=4, period=float("nan"), **kw)


def test_vibro_mc_writes_phase_resolved_histograms(tmp_path, capsys):
    import os
    import subprocess
    import sys

    import pandas as pd

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root)
    out = tmp_path / "h.csv"
    cmd = [sys.executable, "-m", "vibro", "mc", "--model", "duffing-forced", "--param", "A=0.3", "--param",
           "Omega=1.2", "--scheme", "splitting", "--dt", "0.01", "--paths", "16", "--t-end", "60", "--t-burn", "10",
           "--phases", "4", "--out", str(out), "--summary-json", str(tmp_path / "s.json")]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    h = pd.read_csv(out)
    assert list(h.columns) == ["H_lo", "H_hi", "count", "density"]
    ph = pd.read_csv(tmp_path / "h_phases.csv")
    assert set(ph.observable) == {"H", "x", "y"} and sorted(ph.phase.unique()) == [0, 1, 2, 3]
    per_phase = ph[ph.observable == "x"].groupby("phase")["count"].sum()
    assert per_phase.min() > 0
    import json

    side = json.loads((tmp_path / "h_phases.json").read_text())  # its own provenance sidecar
    assert side["output"] == "phases" and side["settings"]["phases"] == 4 and side["model"]["forcing"]
    assert not list(tmp_path.glob("*.tmp*"))  # written atomically: no temporary left
    tr = pd.read_csv(tmp_path / "h_transitions.csv")  # the walls' firings, as on every route of vibro mc
    assert list(tr.columns) == ["transition", "firings", "rate"] and set(tr.transition) == {"left", "right"}
    # a forced model takes checkpoints: a checkpointed run and its resume write the bytes of the plain run
    from vibro.cli import main

    ck = ["--checkpoint", str(tmp_path / "ck")]
    for name, extra in (("ck.csv", ck), ("resumed.csv", [*ck, "--resume"])):
        assert main([*cmd[3:-4], "--out", str(tmp_path / name), *extra]) == 0
        assert (tmp_path / name).read_bytes() == out.read_bytes()
    capsys.readouterr()
    for bad, words in ((["--param", "Omega=0"], "frequency"), (["--param", "A=nan"], "not finite")):
        # in this process (the command line's start in a fresh interpreter is the first run's, above)
        assert main(["mc", "--model", "duffing-forced", *bad, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err


def test_forced_duffing_impact_backends_agree():
    m = ForcedDuffingImpact(D=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hey = simulate_orbit(m, (0.0, 0.5), t_end=30.0, backend="heyoka")
        sci = simulate_orbit(m, (0.0, 0.5), t_end=30.0, backend="scipy", rtol=1e-12)
    assert hey.n_impacts == sci.n_impacts
    if hey.n_impacts:
        assert np.max(np.abs(hey.impacts.t - sci.impacts.t)) < 1e-7
    assert np.allclose(hey.state, sci.state, atol=1e-7)


@pytest.mark.slow  # the docs build in CI runs every example too, and stops on a failed self-check
def test_example_08_runs_headless_and_passes_its_checks():
    from examples_run import run_example

    res = run_example("08_harmonic_random.py", "--quick")
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.strip().splitlines()[-1] == "OK"


def test_vibro_orbit_runs_a_forced_model_and_vibro_pdf_refuses_it(tmp_path, capsys):
    import os
    import subprocess
    import sys

    from vibro.cli import main

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root)
    base = [sys.executable, "-m", "vibro"]
    res = subprocess.run([*base, "orbit", "--model", "duffing-forced", "--param", "A=0.5", "--t-end", "30", "--out",
                          str(tmp_path / "o.csv")], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "the model is forced" in res.stdout and (tmp_path / "o.csv").is_file()
    # averaging refuses a forced model, pointing to the periodic phase-plane solver (vibro pdf's own default there);
    # in this process (a fresh interpreter's start is the orbit run's above)
    capsys.readouterr()
    assert main(["pdf", "--model", "duffing-forced", "--method", "jump", "--out", str(tmp_path / "p.csv")]) == 2
    err = capsys.readouterr().err
    assert "--method fpk" in err and len(err.strip().splitlines()) == 1, err
