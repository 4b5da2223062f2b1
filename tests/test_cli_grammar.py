"""One grammar for the command line (issue 25): shared options read alike in every subcommand, and ``--model
FILE.py:NAME`` means one thing everywhere."""

from __future__ import annotations

import argparse
import textwrap

import pytest

from vibro.cli import build_parser, main
from vibro.cli.grammar import SHARED_OPTIONS, grammar_problems


def test_every_subcommand_reads_the_shared_options_alike():
    parser = build_parser()
    assert grammar_problems(parser) == []
    # the walk sees the commands that matter (a check over nothing would pass too)
    commands = {name for a in parser._actions if isinstance(a, argparse._SubParsersAction) for name in a.choices}
    assert {"orbit", "pdf", "solve", "mc", "plot", "figure"} <= commands


def test_the_grammar_check_finds_departures():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    odd = sub.add_parser("odd")
    odd.add_argument("--h-max", type=int)          # wrong type
    odd.add_argument("--x0", type=float)           # wrong arity
    odd.add_argument("--output")                   # an avoided spelling
    problems = grammar_problems(parser)
    assert any("--h-max" in p and "float" in p for p in problems)
    assert any("--x0" in p and "nargs" in p for p in problems)
    assert any("--output" in p and "--out" in p for p in problems)
    assert set(SHARED_OPTIONS) >= {"--model", "--seed", "--h-max", "--bins", "--x0", "--out"}


@pytest.fixture
def model_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.py").write_text(textwrap.dedent("""
        from models import ImpactOscillator, Newton
        from models.automata import AUTOMATA

        class Lin(ImpactOscillator):
            def __init__(self, k=1.0, c=0.05, D=0.05, delta=1.0):
                super().__init__("k*x", "c*y", parameters={"k": k, "c": c, "D": D, "delta": delta},
                                 restitution=Newton(0.8))

        lin = Lin()

        def make():
            return Lin(c=0.04)

        pair = AUTOMATA["impact_pair"]()

        def nothing():
            return 3
    """))
    return tmp_path


@pytest.mark.parametrize("name, found", [
    ("Lin", "an ImpactOscillator subclass"),
    ("lin", "an ImpactOscillator instance"),
    ("make", "a function returning an ImpactOscillator"),
])
def test_a_model_file_may_hold_a_class_an_instance_or_a_factory(model_file, capsys, name, found):
    assert main(["pdf", "--model", f"m.py:{name}", "--method", "jump", "--out", "p.csv"]) == 0
    out = capsys.readouterr().out
    assert f"model: m.py:{name} is {found}" in out
    assert (model_file / "p.csv").is_file()


def test_an_automaton_is_refused_by_oscillator_commands_in_one_line(model_file, capsys):
    assert main(["pdf", "--model", "m.py:pair", "--method", "jump", "--out", "p.csv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "HybridAutomaton" in err[0] and "vibro mc" in err[0]
    assert not (model_file / "p.csv").exists()


def test_a_factory_returning_no_model_is_refused(model_file, capsys):
    assert main(["pdf", "--model", "m.py:nothing", "--out", "p.csv"]) == 2
    assert "returned 'int', not a model" in capsys.readouterr().err


def test_solve_takes_h_max_like_pdf_and_mc(tmp_path, capsys):
    import pandas as pd

    out = tmp_path / "p.csv"
    assert main(["solve", "--tol", "0.05", "--h-max", "6", "--out", str(out)]) == 0
    assert pd.read_csv(out)["H"].max() == pytest.approx(6.0)
    assert main(["solve", "--h-max", "-1"]) == 2
    assert "--h-max -1 must be a finite positive energy" in capsys.readouterr().err
