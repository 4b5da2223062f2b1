"""``vibro pdf`` and the averaging examples, run as a user would."""

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from problems import elastic_duffing

from vibro.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_vibro_pdf_writes_normalised_density_and_joint(tmp_path, capsys):
    out, joint = tmp_path / "p.csv", tmp_path / "joint.csv"
    argv = ["pdf", "--model", "duffing", "--param", "a=1", "--param", "b=0.2", "--param", "c=0.025",
            "--param", "D=0.05", "--param", "delta=1.0", "--restitution", "ma:vc=0.4", "--method", "jump",
            "--h-max", "4", "--points", "2000", "--out", str(out), "--joint", str(joint)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "E[H] =" in text and "P(H < G(delta)) =" in text
    df = pd.read_csv(out)
    assert list(df.columns) == ["H", "p"] and len(df) == 2000
    assert df.H.iloc[0] == 0.0 and df.H.iloc[-1] == 4.0
    assert np.trapezoid(df.p, df.H) == pytest.approx(1.0, abs=1e-4)
    jd = pd.read_csv(joint)
    assert list(jd.columns) == ["x", "y", "p"]
    assert (jd.p >= 0).all() and jd.p.max() > 0
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".")]  # no temporary files left


def test_vibro_pdf_elastic_matches_exact_density(tmp_path):
    out = tmp_path / "p.csv"
    assert main(["pdf", "--restitution", "elastic", "--h-max", "60", "--points", "601", "--out", str(out)]) == 0
    df = pd.read_csv(out)
    _, ex = elastic_duffing(delta=1.0)
    H = df.H.to_numpy()[[5, 100, 300]]
    np.testing.assert_allclose(df.p.to_numpy()[[5, 100, 300]], ex.energy_density(H), rtol=1e-6)


def test_vibro_pdf_prints_equations(tmp_path, capsys):
    assert main(["pdf", "--equations", "latex", "--points", "50", "--out", str(tmp_path / "p.csv")]) == 0
    out = capsys.readouterr().out
    assert r"\bar{m}(H)" in out and "E[H] =" in out


def test_vibro_pdf_user_model_file(tmp_path, capsys):
    spec = os.path.join(ROOT, "examples", "04_user_model.py") + ":HardeningSoftening"
    out = tmp_path / "p.csv"
    assert main(["pdf", "--model", spec, "--method", "jump", "--h-max", "5", "--points", "300",
                 "--out", str(out)]) == 0
    assert "hardening-softening" in capsys.readouterr().out
    df = pd.read_csv(out)
    assert np.trapezoid(df.p, df.H) == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("argv, message", [
    (["--param", "delta=-1"], "delta"),
    (["--param", "zeta=1"], "unknown parameters"),
    (["--h-max", "-2"], "h-max"),
    (["--points", "1"], "points"),
    (["--restitution", "newton:e=1.5"], "outside"),
])
def test_vibro_pdf_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, message):
    status = main(["pdf", "--out", str(tmp_path / "p.csv"), *argv])
    err = capsys.readouterr().err
    assert status == 2
    assert message in err and err.strip().count("\n") == 0
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.slow  # the docs build in CI runs every example too, and stops on a failed self-check
@pytest.mark.parametrize("script", ["01_quickstart.py", "04_user_model.py"])
def test_examples_run_headless_and_pass_their_self_checks(script):
    env = dict(os.environ, MPLBACKEND="Agg")
    res = subprocess.run([sys.executable, os.path.join(ROOT, "examples", script)], capture_output=True, text=True,
                         timeout=60, env=env, cwd=ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "OK" in res.stdout
