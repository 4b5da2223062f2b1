"""What the documentation shows, checked without building it: the model file of the model-declaration page loads
through the command line as shown, and every example carries the title the gallery needs."""

import ast
import re
from pathlib import Path

import pytest

from vibro.cli import main

ROOT = Path(__file__).resolve().parent.parent
MODEL_FILE = ROOT / "docs" / "user_model" / "my_models.py"
EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))


def test_oscillator_class_runs_vibro_pdf(tmp_path, capsys):
    out = tmp_path / "p.csv"
    assert main(["pdf", "--model", f"{MODEL_FILE}:SofteningStop", "--method", "jump", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "model softening-stop" in printed and "E[H] = 0.3819063" in printed  # the figure the page shows
    assert out.is_file() and (tmp_path / "p.json").is_file()


def test_automaton_factory_is_what_vibro_mc_loads():
    from hybrid import HybridAutomaton
    from vibro.cli.common import load_model_object

    automaton = load_model_object(f"{MODEL_FILE}:bouncing_mass")
    assert isinstance(automaton, HybridAutomaton)
    assert [t.name for t in automaton.transitions] == ["floor"] and "H" in automaton.observables


def test_automaton_given_to_vibro_pdf_is_refused_in_one_line(tmp_path, capsys):
    code = main(["pdf", "--model", f"{MODEL_FILE}:bouncing_mass", "--out", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "a function returning a HybridAutomaton; vibro pdf needs an ImpactOscillator model" in err


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_docstring_opens_with_a_gallery_title(script):
    # sphinx-gallery makes the page title from the docstring's first line, underlined with "="; without the
    # underline the page has no title and the docs build fails (warnings are errors)
    doc = ast.get_docstring(ast.parse(script.read_text()), clean=False)
    first, underline = (doc or "").split("\n")[:2]
    assert first.strip() and re.fullmatch(r"=+", underline) and len(underline) >= len(first), (first, underline)
