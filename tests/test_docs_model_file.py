"""The model file shown on the documentation's model-declaration page loads through the command line as shown."""

from pathlib import Path

from vibro.cli import main

MODEL_FILE = Path(__file__).resolve().parent.parent / "docs" / "user_model" / "my_models.py"


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
    assert code == 2 and len(err.splitlines()) == 1 and "no ImpactOscillator subclass named 'bouncing_mass'" in err
