"""Monte Carlo of general hybrid automata (hybrid.stochastic.simulate_automaton) against independent oracles.

- Euler-Maruyama on a linear n-DOF system: its stationary covariance is known exactly (a discrete Lyapunov
  equation), and its bias against the continuous covariance is first order in dt (fitted slope).
- An impact pair (two masses, a clearance, momentum-conserving elastic impacts) with damping and noise obeying
  fluctuation-dissipation keeps the Gibbs density: the relative coordinate is a Gaussian truncated to the clearance.
- The linear oscillator against a stop at its equilibrium, declared as an automaton, agrees with the oscillator
  kernel and tends to the asymptotic mean energy as r -> 1.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy import linalg, special

from hybrid import HybridAutomaton, Mode, Transition
from hybrid.errors import ModelError, ParameterError
from hybrid.stochastic import AUTOMATON_SCHEMES, simulate_automaton

x1, x2, v1, v2, x, y = sp.symbols("x1 x2 v1 v2 x y")
P = {name: sp.Symbol(name) for name in ("c", "D", "r", "k1", "k2", "m1", "m2", "c1", "c2", "theta", "gap", "s")}


def coupled_linear():
    """Two unit masses, springs k1 (ground-x1), k2 (x1-x2), damping c on both, noise s on v1 only."""
    k1, k2, c, s = P["k1"], P["k2"], P["c"], P["s"]
    flow = (v1, v2, -k1 * x1 - k2 * (x1 - x2) - c * v1, -k2 * (x2 - x1) - c * v2)
    return HybridAutomaton((x1, x2, v1, v2), {"k1": 1.0, "k2": 0.5, "c": 0.4, "s": 1.0},
                           [Mode("m", flow, (0, 0, s, 0))], observables={"x1sq": x1**2})


def _linear_system(k1=1.0, k2=0.5, c=0.4, s=1.0):
    A = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [-k1 - k2, k2, -c, 0], [k2, -k2, 0, -c]], dtype=float)
    B = np.array([[0], [0], [s], [0]], dtype=float)
    return A, B @ B.T


def x1sq_at(T, dt=0.0):
    """E[x1(T)**2] from rest: of the SDE (dt = 0, Van Loan's matrix exponential) or of its Euler-Maruyama chain
    P' = (I + A dt) P (I + A dt)^T + B B^T dt (exactly, step by step)."""
    A, Q = _linear_system()
    if dt == 0:
        M = np.block([[-A, Q], [np.zeros((4, 4)), A.T]]) * T
        E = linalg.expm(M)
        return float((E[4:, 4:].T @ E[:4, 4:])[0, 0])
    F = np.eye(4) + A * dt
    P = np.zeros((4, 4))
    for _ in range(int(round(T / dt))):
        P = F @ P @ F.T + Q * dt
    return float(P[0, 0])


def test_em_matches_its_exact_chain_and_has_weak_order_one_on_a_4_state_system():
    T, dts = 2.0, [0.2, 0.1, 0.05]
    errors = []
    for dt in dts:
        # statistics of the last step only: E[x1(T)^2] over 160k paths
        ens = simulate_automaton(coupled_linear(), "em", dt=dt, paths=160_000, t_end=T, t_burn=T - dt,
                                 x0=(0, 0, 0, 0), seed=7, histograms={"x1sq": (0.0, 20.0, 10)}, chunk_paths=4000)
        est = ens.mean("x1sq")
        assert abs(est.value - x1sq_at(T, dt)) < est.ci, (dt, est, x1sq_at(T, dt))  # the chain, exactly
        errors.append(abs(est.value - x1sq_at(T)))
    slope = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert AUTOMATON_SCHEMES["em"].orders(None)["weak"] == 1.0
    assert slope == pytest.approx(1.0, abs=0.2), (errors, slope)


def impact_pair(r=1.0):
    """Primary mass m1 on a spring, a second mass m2 on a spring in a clearance |x2 - x1| <= gap inside it."""
    k1, k2, m1, m2, c1, c2, th, gap = (P[k] for k in ("k1", "k2", "m1", "m2", "c1", "c2", "theta", "gap"))
    rr = sp.Symbol("rr")
    flow = (v1, v2, (-k1 * x1 - c1 * v1) / m1, (-k2 * x2 - c2 * v2) / m2)
    noise = ((0, 0), (0, 0), (sp.sqrt(2 * c1 * th) / m1, 0), (0, sp.sqrt(2 * c2 * th) / m2))
    # momentum kept, relative velocity u = v2 - v1 -> -rr u
    u = v2 - v1
    reset = (x1, x2, v1 + (1 + rr) * m2 / (m1 + m2) * u, v2 - (1 + rr) * m1 / (m1 + m2) * u)
    return HybridAutomaton(
        (x1, x2, v1, v2),
        {"k1": 1.0, "k2": 0.6, "m1": 1.0, "m2": 0.3, "c1": 0.3, "c2": 0.2, "theta": 0.05, "gap": 0.2, "rr": r},
        [Mode("m", flow, noise)],
        [Transition("hit_right", "m", "m", x2 - x1 - gap, +1, reset),
         Transition("hit_left", "m", "m", x1 - x2 - gap, +1, reset, priority=1)],
        observables={"z": x2 - x1, "kinetic": (m1 * v1**2 + m2 * v2**2) / 2},
    )


def test_impact_pair_keeps_the_gibbs_marginal_of_the_relative_coordinate():
    gap, th, k1, k2 = 0.2, 0.05, 1.0, 0.6
    ens = simulate_automaton(impact_pair(), "splitting", dt=0.01, paths=64, t_end=600.0, t_burn=30.0,
                             x0=(0, 0, 0, 0), seed=11, histograms={"z": (-gap, gap, 20), "kinetic": (0, 1, 10)})
    assert ens.flags["outside"] == 0 and ens.outside_fraction("z") == 0.0
    assert ens.events.sum() > 1000  # the clearance is hit often: the oracle tests the impacts
    # z = x2 - x1 under exp(-(k1 x1^2 + k2 x2^2) / (2 theta)): Gaussian, variance theta (1/k1 + 1/k2), cut to |z| <= gap
    sd = math.sqrt(th * (1 / k1 + 1 / k2))
    edges = ens.edges["z"]
    cdf = 0.5 * (1 + special.erf(edges / (sd * math.sqrt(2))))
    exact = np.diff(cdf) / (cdf[-1] - cdf[0])
    mc = ens.counts["z"][1:-1] / ens.flags["samples"]
    assert np.abs(mc - exact).sum() < 0.03
    kin = ens.mean("kinetic")
    assert abs(kin.value - th) < 3 * kin.ci + 0.01 * th  # theta/2 per velocity, two velocities


def equilibrium_stop_automaton():
    c, D, r = P["c"], P["D"], P["r"]
    return HybridAutomaton((x, y), {"c": 0.05, "D": 0.05, "r": 0.95},
                           [Mode("free", (y, -x - c * y), (0, sp.sqrt(2 * D)))],
                           [Transition("stop", "free", "free", -x, +1, (x, -r * y))],
                           observables={"H": (x**2 + y**2) / 2})


def test_equilibrium_stop_as_an_automaton_agrees_with_the_oscillator_kernel():
    from hybrid.stochastic import simulate_ensemble
    from models import ImpactOscillator, Newton

    r, c, D = 0.95, 0.05, 0.05
    auto = simulate_automaton(equilibrium_stop_automaton(), "splitting", dt=0.01, paths=64, t_end=2500.0,
                              t_burn=200.0, x0=(0.5, 0.0), seed=21, histograms={"H": (0.0, 8.0, 40)})
    model = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=(0, None), restitution=Newton(r))
    osc = simulate_ensemble(model, "splitting", dt=0.01, paths=64, t_end=2500.0, t_burn=200.0, seed=22, h_max=8.0)
    a, b = auto.mean("H"), osc.mean_energy
    assert abs(a.value - b.value) < 1.5 * math.hypot(a.ci, b.ci)  # two independent estimates of one number
    expected = D / (c + (4.0 / math.pi) * (1 - r) / (1 + r))  # asymptotic as r -> 1 (O((1-r)^2) relative)
    assert abs(a.value - expected) < 3 * a.ci + 0.01 * expected
    assert auto.rate("stop") == pytest.approx(1 / math.pi, rel=0.02)  # one impact per half period, pi


def test_same_seed_and_chunks_give_the_same_numbers_on_any_thread_count():
    kw = dict(dt=0.02, paths=12, t_end=40.0, t_burn=0.0, x0=(0.5, 0.0), seed=5, histograms={"H": (0.0, 4.0, 20)},
              chunk_paths=4, events=5)
    a = simulate_automaton(equilibrium_stop_automaton(), "splitting", threads=1, **kw)
    b = simulate_automaton(equilibrium_stop_automaton(), "splitting", threads=3, **kw)
    assert np.array_equal(a.counts["H"], b.counts["H"]) and np.array_equal(a.chunk_sums, b.chunk_sums)
    assert np.array_equal(a.event_log, b.event_log, equal_nan=True) and np.array_equal(a.event_totals, b.event_totals)
    # t_burn = 0: every firing counted after burn-in is one of the paths' own (the log's totals)
    assert a.event_totals.sum() == a.events.sum() > 12 * 5
    assert np.all(np.isfinite(a.event_log[:, :, 0])) and np.all(np.diff(a.event_log[:, :, 0], axis=1) > 0)


def test_chunk_paths_are_chosen_from_paths_and_steps_and_shown_in_the_settings():
    # many short paths: chunks of 64 paths (at least 64 chunks), not 512 chunks of 8; few long paths: 8 lanes
    kw = dict(dt=0.02, t_burn=0.0, x0=(0.5, 0.0), seed=5, histograms={"H": (0.0, 4.0, 20)})
    many = simulate_automaton(equilibrium_stop_automaton(), "splitting", paths=4096, t_end=2.0, **kw)
    assert many.settings["chunk_paths"] == 64 and len(many.chunk_samples) == 64
    given = simulate_automaton(equilibrium_stop_automaton(), "splitting", paths=4096, t_end=2.0, chunk_paths=64, **kw)
    assert np.array_equal(many.counts["H"], given.counts["H"]) and np.array_equal(many.chunk_sums, given.chunk_sums)
    few = simulate_automaton(equilibrium_stop_automaton(), "splitting", paths=12, t_end=40.0, **kw)
    assert few.settings["chunk_paths"] == 1  # under 64 paths: 8 chunks or more, as before


def test_checkpoint_resume_and_dask_give_the_thread_numbers_bitwise(tmp_path):
    from hybrid.errors import CheckpointError
    from hybrid.stochastic import _auto_exec

    kw = dict(dt=0.02, paths=24, t_end=60.0, t_burn=5.0, x0=(0.5, 0.0), seed=8, histograms={"H": (0.0, 4.0, 20)},
              chunk_paths=3, events=3)
    whole = simulate_automaton(equilibrium_stop_automaton(), "splitting", **kw)
    ck = tmp_path / "ck"
    # interrupted after 5 of 8 chunks: the accept callback raises as a Ctrl-C would
    real = _auto_exec.execute

    def stop_after_five(job, pending, states, accept, **opts):
        seen = []

        def take(k, out):
            if len(seen) == 5:
                raise KeyboardInterrupt
            seen.append(k)
            accept(k, out)

        return real(job, pending, states, take, **{**opts, "threads": 1})

    _auto_exec.execute = stop_after_five
    try:
        with pytest.raises(KeyboardInterrupt):
            simulate_automaton(equilibrium_stop_automaton(), "splitting", checkpoint=ck, checkpoint_every=100, **kw)
    finally:
        _auto_exec.execute = real
    with np.load(ck / _auto_exec.CHECKPOINT_FILE) as d:
        assert int(d["done"].sum()) == 5  # written on the interrupt although checkpoint_every was not reached
    resumed = simulate_automaton(equilibrium_stop_automaton(), "splitting", checkpoint=ck, resume=True, **kw)
    on_dask = simulate_automaton(equilibrium_stop_automaton(), "splitting", scheduler="dask", **kw)
    for other in (resumed, on_dask):
        assert np.array_equal(other.counts["H"], whole.counts["H"]) and np.array_equal(other.chunk_sums,
                                                                                     whole.chunk_sums)
        assert np.array_equal(other.events, whole.events)
        assert np.array_equal(other.event_log, whole.event_log) and np.array_equal(other.event_totals,
                                                                                   whole.event_totals)
    with pytest.raises(CheckpointError, match="another run"):
        simulate_automaton(equilibrium_stop_automaton(), "splitting", checkpoint=ck, resume=True,
                           params={"r": 0.9}, **kw)
    with pytest.raises(ParameterError, match="exists; pass resume=True"):
        simulate_automaton(equilibrium_stop_automaton(), "splitting", checkpoint=ck, **kw)
    path = ck / _auto_exec.CHECKPOINT_FILE
    with np.load(path) as d:
        arrays = {k: d[k] for k in d.files}
    arrays["counts"] = arrays["counts"] * 2  # doubled counts, old checksum
    np.savez(path, **arrays)
    with pytest.raises(CheckpointError, match="checksum"):
        simulate_automaton(equilibrium_stop_automaton(), "splitting", checkpoint=ck, resume=True, **kw)
    with pytest.raises(ParameterError, match="unknown scheduler"):
        simulate_automaton(equilibrium_stop_automaton(), "splitting", scheduler="mpi", **kw)


def test_bad_requests_are_refused_in_one_line():
    A = equilibrium_stop_automaton()
    base = dict(dt=0.01, paths=4, t_end=1.0, x0=(0.5, 0.0), seed=1, histograms={"H": (0.0, 4.0, 20)})
    with pytest.raises(ParameterError, match="histogram range"):
        simulate_automaton(A, "em", **{**base, "histograms": {}})
    with pytest.raises(ParameterError, match="path-steps"):
        simulate_automaton(A, "em", **{**base, "paths": 10**9, "t_end": 1e6})
    with pytest.raises(ParameterError, match="finite numbers"):
        simulate_automaton(A, "em", **{**base, "x0": (0.5,)})
    with pytest.raises(ParameterError, match="unknown scheme"):
        simulate_automaton(A, "rk4", **base)
    # a filter state that is neither position nor velocity: splitting refuses and names the alternative
    f = sp.Symbol("f")
    ou_driven = HybridAutomaton((x, y, f), {"c": 0.1}, [Mode("m", (y, -x - P["c"] * y + f, -f), (0, 0, 1))],
                                observables={"x": x})
    with pytest.raises(ModelError, match="use scheme='em'"):
        simulate_automaton(ou_driven, "splitting", **{**base, "x0": (0, 0, 0), "histograms": {"x": (-1, 1, 4)}})
    # non-commutative noise: Milstein refuses
    nc = HybridAutomaton((x, y), {}, [Mode("m", (0, 0), ((1, 0), (0, x)))], observables={"x": x})
    with pytest.raises(ModelError, match="not commutative"):
        simulate_automaton(nc, "milstein", **{**base, "histograms": {"x": (-1, 1, 4)}})
    with pytest.raises(ModelError, match="equally many"):
        simulate_automaton(HybridAutomaton((x, y), {}, [Mode("m", (0, 0), ((1, 0), (1,)))]), "em",
                           **{**base, "histograms": {}, "x0": (0, 0)})


def test_step_rule_for_any_guard_agrees_with_the_oscillator_rule_on_walls():
    """The guard rule (4 x rms guard change per step against the guard's span) is the oscillator's speed * dt / gap
    rule for walls x = +-delta: the pilot refuses where check_step refuses, the run warns on a coarse step, and
    the figures it reports scale like dt."""
    from hybrid.errors import StepSizeError
    from hybrid.stochastic import StepSizeWarning, check_step
    from models import DuffingImpact, Newton

    # Example 1 with Newton's law, H only summed: the symplectic kernel of test_automaton_front.py's transition-check
    # and entry-point tests (the rule reads the guards' changes over the steps, whatever the scheme)
    model = DuffingImpact(restitution=Newton(0.9))
    auto = model.to_automaton()
    kw = dict(paths=16, chunk_paths=2, t_end=200.0, t_burn=20.0, x0=(0.0, 0.0), seed=3, histograms={"H": None})
    with pytest.raises(StepSizeError):
        check_step(model, 0.5)
    with pytest.raises(StepSizeError, match="moves the guard of transition") as err:
        simulate_automaton(auto, "symplectic", dt=0.5, **kw)
    assert "\n" not in str(err.value) and "use dt <=" in str(err.value)
    with pytest.warns(StepSizeWarning, match="coarse"):
        coarse = simulate_automaton(auto, "symplectic", dt=0.2, **kw)
    fine = simulate_automaton(auto, "symplectic", dt=0.01, **kw)
    assert fine.settings["step_rule"]["ratio"] < 0.1 < coarse.settings["step_rule"]["ratio"] < 0.5
    # the span of each wall guard is the gap 2 delta, and the move is first order in dt
    assert fine.settings["step_rule"]["right"]["span"] == pytest.approx(2.0, rel=0.05)
    ratio = coarse.settings["step_rule"]["ratio"] / fine.settings["step_rule"]["ratio"]
    assert 10 < ratio < 30  # dt ratio 20


def test_inelastic_chattering_on_the_step_scale_is_reported():
    from hybrid.stochastic import ChatteringWarning

    # r = 0.2 at an equilibrium stop with strong noise: low-energy paths re-impact (rate 0.62 at dt = 0.1 against
    # 0.73 at dt = 0.01, not resolved), about one transition every 16 steps
    A = equilibrium_stop_automaton()
    with pytest.warns(ChatteringWarning, match="transitions per path-step"):
        simulate_automaton(A, "splitting", dt=0.1, paths=16, chunk_paths=2, t_end=100.0, t_burn=10.0, x0=(0.5, 0.0),
                           seed=2, params={"r": 0.2, "D": 2.0, "c": 0.01}, histograms={"H": (0, 50, 20)},
                           check_dt=False)


@pytest.mark.slow  # the docs build in CI runs every example too, and stops on a failed self-check
@pytest.mark.parametrize("script", ["06_equilibrium_stop.py", "07_impact_pair.py"])
def test_examples_06_07_run_headless_and_pass_their_checks(script):
    from examples_run import run_example

    res = run_example(script, "--quick")
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.strip().splitlines()[-1] == "OK"
