"""What the command line assumes, said where the numbers are printed: the noise convention and the number of noises
and states (summary and sidecar), and no deviation from a formula that does not apply (eq. 14 on one stop)."""

from __future__ import annotations

import json
import textwrap

import pytest

from models import DuffingImpact, ImpactOscillator
from vibro.cli import main
from vibro.provenance import noise_assumption, record

MODELS = textwrap.dedent('''
    from models import ImpactOscillator


    class Multiplicative(ImpactOscillator):
        def __init__(self):
            super().__init__("x", "c*y", noise=("1 + k*x**2",), parameters={"c": 0.1, "D": 0.02, "k": 0.5,
                             "delta": 1.0}, name="multiplicative")


    class OneStop(ImpactOscillator):
        def __init__(self):
            super().__init__("x + b*x**3", "c*y", parameters={"b": 0.2, "c": 0.0, "D": 0.0, "delta": 1.0},
                             barriers=(None, "delta"), name="one-stop")


    class StopAtEquilibrium(ImpactOscillator):
        def __init__(self):
            super().__init__("x + b*x**3", "c*y", parameters={"b": 0.2, "c": 0.0, "D": 0.0}, barriers=(0, None),
                             name="stop-at-equilibrium")
''')


@pytest.fixture
def model_file(tmp_path):
    path = tmp_path / "models_of_a_user.py"
    path.write_text(MODELS)
    return path


def test_noise_assumption_counts_noises_and_states_and_names_the_convention():
    additive = noise_assumption(DuffingImpact())
    assert (additive["noises"], additive["states"], additive["multiplicative"]) == (1, 2, False)
    assert "Itô and Stratonovich agree" in additive["text"]
    two = noise_assumption(ImpactOscillator("x", "c*y", noise=("1", "x*y"), parameters={"c": 0.1, "D": 0.05},
                                            barriers=None))
    assert (two["noises"], two["multiplicative"], two["depends_on"]) == (2, True, ["x", "y"])
    assert two["text"] == "2 noises, 2 states, Stratonovich (multiplicative: f depends on x, y)"
    # the automaton of an oscillator reads its noise the same way
    assert noise_assumption(DuffingImpact().to_automaton())["text"] == additive["text"]
    assert record("pdf", model=DuffingImpact())["noise"]["convention"] == "stratonovich"


def test_pdf_prints_and_records_the_stratonovich_reading_of_multiplicative_noise(tmp_path, capsys, model_file):
    out = tmp_path / "p.csv"
    assert main(["pdf", "--model", f"{model_file}:Multiplicative", "--method", "jump", "--out", str(out),
                 "--points", "300", "--force"]) == 0
    text = capsys.readouterr().out
    assert "noise: 1 noise, 2 states, Stratonovich (multiplicative: f depends on x)" in text
    rec = json.loads(out.with_suffix(".json").read_text())
    assert rec["noise"]["convention"] == "stratonovich" and rec["noise"]["depends_on"] == ["x"]


def test_solve_prints_the_noise_of_an_additive_model(capsys):
    assert main(["solve", "--dry-run"]) == 0
    assert "noise: 1 noise, 2 states, additive (Itô and Stratonovich agree)" in capsys.readouterr().out


@pytest.mark.parametrize("name,stop", [("OneStop", "right one at x = 1"), ("StopAtEquilibrium", "left one at x = 0")])
def test_orbit_on_one_stop_does_not_compare_with_eq14(capsys, model_file, name, stop):
    assert main(["orbit", "--model", f"{model_file}:{name}", "--x0", "0.5", "--v0", "2", "--t-end", "20",
                 "--backend", "scipy"]) == 0
    text = capsys.readouterr().out
    assert f"eq. 14: not compared: it assumes two symmetric walls hit alternately, and this model has one stop " \
           f"(the {stop})" in text
    assert "eq14 not applicable" in text and "1.00e+00" not in text
    # eq. 13 (two impacts at one level) still holds and is still compared
    assert "eq.13 paper" in text


def test_mc_of_an_automaton_prints_and_records_its_noises_and_states(tmp_path, capsys):
    out = tmp_path / "h.csv"
    assert main(["mc", "--model", "impact_pair", "--scheme", "splitting", "--dt", "0.01", "--paths", "16", "--t-end",
                 "50", "--t-burn", "5", "--range", "z=-0.2:0.2:20", "--out", str(out)]) == 0
    assert "noise           2 noises, 4 states, additive" in capsys.readouterr().out
    noise = json.loads(out.with_suffix(".json").read_text())["noise"]
    assert (noise["noises"], noise["states"], noise["convention"]) == (2, 4, "stratonovich")


def test_help_prints_whole_numbers_as_integers():
    from vibro.cli import build_parser

    text = " ".join(build_parser()._subparsers._group_actions[0].choices["mc"].format_help().split())
    assert "(default: 1e13)" in text and "(default: 2200)" in text and "10000000000000.0" not in text


def test_the_joint_sidecar_is_claimed_before_the_run(tmp_path, capsys):
    # --joint j.csv writes j.json: a --summary-json there is refused before any work, and nothing is written
    argv = ["pdf", "--points", "200", "--out", str(tmp_path / "p.csv"), "--joint", str(tmp_path / "j.csv"),
            "--joint-points", "21"]
    assert main(argv) == 0
    side = json.loads((tmp_path / "j.json").read_text())
    assert side["output"] == "joint" and side["model"]["barriers"] == [-1.0, 1.0]
    assert main(["mc", "--out", str(tmp_path / "h.csv"), "--joint", str(tmp_path / "k.csv"), "--summary-json",
                 str(tmp_path / "k.json")]) == 2
    assert "provenance sidecar of --joint" in capsys.readouterr().err
    assert not (tmp_path / "h.csv").exists()
