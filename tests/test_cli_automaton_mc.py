"""``vibro mc`` on automaton models: built-ins, user files, filtered oscillators, observables; one-line errors.

Oracles: the impact pair's Gibbs mean energy (elastic, fluctuation-dissipation), the OU velocity's stationary
variance s^2 / (2 c), and the linear oscillator driven by Ornstein-Uhlenbeck noise (quadrature of its spectrum,
tests/test_excitation.py).
"""

from __future__ import annotations

import json
import math

import pandas as pd
import pytest
from scipy import special
from test_excitation import response, splitting_chain

from vibro.cli import main

USER = '''
import sympy as sp
from hybrid import HybridAutomaton, Mode
from models import ImpactOscillator


class Linear(ImpactOscillator):
    def __init__(self):
        super().__init__("w2*x", "c*y", parameters={"w2": 1.0, "c": 0.5, "D": 0.25}, barriers=None, name="lin")


def ou_velocity():
    v = sp.Symbol("v")
    return HybridAutomaton((v,), {"c": 1.0, "s": 1.0}, [Mode("m", (-sp.Symbol("c") * v,), ("s",))],
                           observables={"v2": v**2})


INSTANCE = ou_velocity()
NOT = 42


def needs(k):
    return ou_velocity()


def broken():
    raise RuntimeError("no luck")
'''


@pytest.fixture
def tmp(tmp_path):
    (tmp_path / "user.py").write_text(USER)
    return tmp_path


def _run(argv) -> int:
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def test_impact_pair_from_the_command_line_meets_its_gibbs_mean_energy(tmp, capsys):
    out, summary = tmp / "h.csv", tmp / "s.json"
    rc = _run(["mc", "--model", "impact_pair", "--scheme", "splitting", "--dt", "0.01", "--paths", "64",
               "--t-end", "400", "--t-burn", "20", "--seed", "4", "--range", "z=-0.2:0.2:20", "--h-max", "1",
               "--bins", "50", "--out", out, "--summary-json", summary])
    assert rc == 0, capsys.readouterr().err
    rec = json.loads(summary.read_text())
    # Gibbs: kinetic theta, potential theta/2 + E[z^2] / (2 (1/k1 + 1/k2)) with z Gaussian cut to |z| <= gap
    p = rec["model"]["parameters"]
    th, gap, kk = p["theta"], p["gap"], 1 / p["k1"] + 1 / p["k2"]
    s = math.sqrt(th * kk)
    a = gap / s
    ez2 = s**2 * (1 - 2 * a * math.exp(-a * a / 2) / math.sqrt(2 * math.pi) / special.erf(a / math.sqrt(2)))
    gibbs = 1.5 * th + ez2 / (2 * kk)
    e = rec["results"]["mean_energy"]
    assert abs(e["value"] - gibbs) <= 3 * e["ci"], (e, gibbs)
    assert set(rec["results"]["rates"]) == {"hit_right", "hit_left"} and rec["results"]["rates"]["hit_left"] > 0
    assert rec["settings"]["scheme"] == "splitting" and rec["settings"]["dt"] == 0.01 and rec["settings"]["seed"] == 4
    assert rec["model"]["states"] == ["x1", "x2", "v1", "v2"] and "versions" in rec
    h = pd.read_csv(out)
    assert list(h.columns) == ["H_lo", "H_hi", "count", "density"] and h["count"].sum() == rec["results"]["samples"]
    z = pd.read_csv(tmp / "h_z.csv")
    assert list(z.columns) == ["z_lo", "z_hi", "count", "density"] and len(z) == 22
    tr = pd.read_csv(tmp / "h_transitions.csv")
    assert list(tr["transition"]) == ["hit_right", "hit_left"]
    for name in ("z", "transitions"):  # every file written has its provenance sidecar, naming the output
        side = json.loads((tmp / f"h_{name}.json").read_text())
        assert side["output"] == name and side["settings"]["seed"] == 4 and side["model"] == rec["model"]


def test_event_logs_from_the_command_line(tmp, capsys):
    out, summary = tmp / "h.csv", tmp / "s.json"
    rc = _run(["mc", "--model", "impact_pair", "--scheme", "splitting", "--dt", "0.01", "--paths", "16",
               "--t-end", "40", "--t-burn", "0", "--seed", "4", "--events", "3", "--out", out,
               "--range", "z=-0.2:0.2:20", "--summary-json", summary])  # the observables (kernel) of the test above
    assert rc == 0, capsys.readouterr().err
    ev = pd.read_csv(tmp / "h_events.csv")
    assert list(ev.columns) == ["path", "k", "t", "transition", "speed"]
    assert json.loads((tmp / "h_events.json").read_text())["output"] == "events"
    assert set(ev["path"]) == set(range(16)) and ev["k"].max() == 2 and (ev["t"] > 0).all()
    first = json.loads(summary.read_text())["results"]["first_event_time"]
    for name, rec in first.items():  # the mean over the paths whose kept firings include the transition
        firsts = ev[ev.transition == name].groupby("path")["t"].min()
        assert rec["paths"] == len(firsts) and rec["mean"] == pytest.approx(firsts.mean(), rel=1e-12)


def test_oscillator_and_automaton_routes_write_the_same_files(tmp_path, capsys):
    """One writer (vibro/cli/mc_outputs.py): an oscillator run and an automaton run write the same files, columns,
    sidecars and result keys (the impact pair's kernel of the test above; Example 1's milstein kernel)."""
    common = ["--dt", "0.01", "--paths", "4", "--t-end", "10", "--t-burn", "1", "--seed", "2"]
    runs = {"osc": ["--model", "duffing", "--scheme", "milstein"],
            "pair": ["--model", "impact_pair", "--scheme", "splitting", "--range", "z=-0.2:0.2:20"]}
    keys = {}
    for name, argv in runs.items():
        d = tmp_path / name
        d.mkdir()
        assert _run(["mc", *argv, *common, "--out", d / "h.csv", "--summary-json", d / "s.json"]) == 0, \
            capsys.readouterr().err
        files = {p.name for p in d.iterdir()} - {"h_z.csv", "h_z.json"}  # the pair's extra observable
        assert files == {"h.csv", "h.json", "h_transitions.csv", "h_transitions.json", "s.json"}, files
        assert list(pd.read_csv(d / "h.csv").columns) == ["H_lo", "H_hi", "count", "density"]
        tr = pd.read_csv(d / "h_transitions.csv")
        assert list(tr.columns) == ["transition", "firings", "rate"] and tr["firings"].sum() > 0
        assert json.loads((d / "h_transitions.json").read_text())["output"] == "transitions"
        rec = json.loads((d / "s.json").read_text())
        assert rec == json.loads((d / "h.json").read_text())
        assert rec["results"]["firings"] == dict(zip(tr["transition"], tr["firings"]))
        keys[name] = set(rec["results"])
    shared = {"paths", "samples", "wall_time", "observables", "rates", "firings", "counters", "mean_energy"}
    assert shared <= keys["osc"] and shared <= keys["pair"]


def test_a_user_oscillator_with_an_ou_filter_meets_the_closed_form_response(tmp, capsys):
    out, summary = tmp / "h.csv", tmp / "s.json"
    alpha, dt = 2.0, 0.01
    rc = _run(["mc", "--model", f"{tmp}/user.py:Linear", "--filter", "ou", "--param", f"alpha={alpha}",
               "--scheme", "splitting", "--dt", dt, "--paths", "64", "--t-end", "1500", "--t-burn", "30",
               "--h-max", "20", "--bins", "20", "--observable", "z2=z**2", "--range", "z2=0:1000:1",
               # x2 and y2 too: the observables (and kernel) of test_excitation.py's OU runs
               "--observable", "x2=x**2", "--range", "x2=0:1000:1", "--observable", "y2=y**2", "--range", "y2=0:1000:1",
               "--out", out, "--summary-json", summary])
    assert rc == 0, capsys.readouterr().err
    rec = json.loads(summary.read_text())
    var_z, var_x, var_y = response("ou", alpha=alpha)
    chain = splitting_chain(dt, alpha, 0.0)
    exact, scheme = (var_y + var_x) / 2, (chain[1, 1] + chain[0, 0]) / 2  # H = (y^2 + w0^2 x^2) / 2, w0 = 1
    e = rec["results"]["mean_energy"]
    assert abs(e["value"] - exact) <= 3 * e["ci"] + abs(scheme - exact), (e, exact, scheme)
    z2 = rec["results"]["observables"]["z2"]
    assert abs(z2["mean"] - var_z) <= 3 * z2["ci"] + abs(chain[3, 3] - var_z), (z2, var_z)
    assert rec["model"]["filter"]["kind"] == "ou" and rec["settings"]["params"]["alpha"] == alpha
    assert rec["model"]["filter"]["base"]["model"] == "lin"


def test_a_user_function_and_instance_run_with_their_observables(tmp, capsys):
    rc = _run(["mc", "--model", f"{tmp}/user.py:ou_velocity", "--scheme", "em", "--dt", "0.01", "--paths", "32",
               "--t-end", "400", "--t-burn", "10", "--range", "v2=0:10:50", "--out", tmp / "v.csv",
               "--summary-json", tmp / "s.json"])
    assert rc == 0, capsys.readouterr().err
    est = json.loads((tmp / "s.json").read_text())["results"]["observables"]["v2"]
    chain = 1.0 / (2.0 - 0.01)  # Euler-Maruyama's exact stationary variance s^2 dt / (1 - (1 - c dt)^2)
    assert abs(est["mean"] - 0.5) <= 3 * est["ci"] + abs(chain - 0.5), est
    assert "mean_energy" not in json.loads((tmp / "s.json").read_text())["results"]  # no H declared
    assert list(pd.read_csv(tmp / "v.csv").columns) == ["v2_lo", "v2_hi", "count", "density"]
    rc = _run(["mc", "--model", f"{tmp}/user.py:INSTANCE", "--scheme", "em", "--dt", "0.01", "--paths", "8",
               "--t-end", "50", "--t-burn", "5", "--param", "s=2", "--range", "v2=0:10:50", "--out", tmp / "w.csv"])
    assert rc == 0, capsys.readouterr().err


BAD = [
    (["--model", "duffing", "--scheme", "symplectic"], "--scheme milstein runs the same step"),
    (["--model", "{tmp}/missing.py:f"], "does not exist"),
    (["--model", "{tmp}/user.py:NOT"], "is not a model"),
    (["--model", "{tmp}/user.py:nothing"], "has no object named"),
    (["--model", "{tmp}/user.py:needs"], "cannot be built without arguments"),
    (["--model", "{tmp}/user.py:broken"], "raised RuntimeError: no luck"),
    (["--model", "impact_pair", "--observable", "q=x1 +* 2", "--range", "q=0:1:10"], "cannot read"),
    (["--model", "impact_pair", "--observable", "q=foo*x1", "--range", "q=0:1:10"], "unknown names ['foo']"),
    (["--model", "impact_pair", "--observable", "q=x1"], "--range q=LO:HI:BINS"),
    (["--model", "impact_pair", "--range", "z=1:0:10"], "need finite LO < HI"),
    (["--model", "impact_pair", "--range", "z=abc"], "must read NAME=LO:HI:BINS"),
    (["--model", "impact_pair", "--range", "w=0:1:10"], "no such observable"),
    (["--model", "impact_pair", "--param", "nosuch=1"], "unknown parameter 'nosuch'"),
    (["--model", "impact_pair", "--param", "gap"], "must read NAME=VALUE"),
    (["--model", "impact_pair", "--restitution", "newton:e=0.5"], "--restitution applies to oscillator models"),
    (["--model", "impact_pair", "--x0", "0", "0"], "--x0 gives 2 values for the 4 states"),
    (["--model", "duffing", "--filter", "ou", "--param", "alpha=0"], "alpha=0.0 must be a positive finite"),
    (["--model", "duffing", "--filter", "ou", "--param", "alpha=nan"], "alpha=nan must be a positive finite"),
    (["--model", "duffing", "--filter", "bandpass", "--param", "zeta=-1"], "zeta=-1.0 must be a positive"),
    (["--model", "duffing", "--filter", "ou", "--param", "D=-1"], "negative"),
    (["--model", "{tmp}/user.py:ou_velocity"], "nothing to histogram"),
    (["--model", "impact_pair", "--range", "z=0:1:10000000", "--max-memory-gb", "0.01"], "GB of memory (histograms"),
    (["--model", "vibrating_table", "--phases", "4"], "--phases needs a forced oscillator model"),
    (["--model", "impact_pair", "--events", "-1"], "events=-1 must be an integer >= 0"),
]


@pytest.mark.parametrize("argv,words", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_automaton_requests_exit_2_with_one_line(argv, words, tmp, capsys):
    rc = _run(["mc", "--out", f"{tmp}/h.csv", "--paths", "2", "--t-end", "1", "--t-burn", "0"]
              + [a.replace("{tmp}", str(tmp)) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in err, err
    assert not (tmp / "h.csv").exists()


def test_filter_names_match_the_registry():
    from models.excitation import FILTER_KINDS
    from vibro.cli.mc_automaton import FILTERS

    assert FILTERS == FILTER_KINDS


def test_automaton_checkpoint_and_resume_from_the_command_line_match_one_run(tmp, capsys):
    base = ["mc", "--model", "impact_pair", "--scheme", "splitting", "--dt", "0.01", "--paths", "16", "--t-end", "40",
            "--t-burn", "5", "--seed", "2", "--range", "z=-0.2:0.2:20", "--h-max", "1", "--bins", "20",
            "--chunk-paths", "2"]
    assert _run(base + ["--out", tmp / "one.csv"]) == 0
    assert _run(base + ["--out", tmp / "two.csv", "--checkpoint", tmp / "ck", "--checkpoint-every", "1"]) == 0
    capsys.readouterr()
    # resuming a finished run recomputes nothing and writes the same histogram
    assert _run(base + ["--out", tmp / "three.csv", "--checkpoint", tmp / "ck", "--resume"]) == 0
    capsys.readouterr()  # its warnings (H on 20 bins of [0, 1] is coarse) are the first runs' too
    one = (tmp / "one.csv").read_text()
    assert one == (tmp / "two.csv").read_text() == (tmp / "three.csv").read_text()
    rc = _run(base + ["--out", tmp / "four.csv", "--checkpoint", tmp / "ck", "--resume", "--seed", "3"])
    err = capsys.readouterr().err
    assert rc == 2 and "another run" in err and len(err.strip().splitlines()) == 1


def test_oscillator_scheme_names_mean_the_same_on_the_automaton_route():
    # an oscillator model sent through the automaton engine (--observable, --range, --x0, --events) runs milstein
    # and splitting as the oscillator path does (symplectic, baoab) where it admits them; a filtered model, or one
    # BAOAB refuses, keeps the automaton's own schemes
    from argparse import Namespace

    from models import DuffingImpact, ImpactOscillator
    from vibro.cli.mc_automaton import scheme_for

    duffing = DuffingImpact().to_automaton()
    rayleigh = ImpactOscillator("x", "c*y + y**3", parameters={"c": 0.1, "D": 0.05, "delta": 1.0}).to_automaton()
    assert scheme_for(Namespace(scheme="milstein"), duffing, True) == "symplectic"
    assert scheme_for(Namespace(scheme="splitting"), duffing, True) == "baoab"
    assert scheme_for(Namespace(scheme="splitting"), rayleigh, True) == "splitting"
    assert scheme_for(Namespace(scheme="splitting"), duffing, False) == "splitting"
    assert scheme_for(Namespace(scheme="em"), duffing, True) == "em"
