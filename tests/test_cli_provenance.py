"""vibro pdf's default method and diagnosis, the phase-plane method on the command line, provenance sidecars of
every output, and the warning on too few chunks for batch-means intervals."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest

from hybrid.errors import VibroWarning
from hybrid.stochastic import simulate_ensemble
from models import DuffingImpact
from vibro.cli import build_parser, main


def _sidecar(path):
    return json.loads(path.with_suffix(".json").read_text())


def test_pdf_defaults_to_the_automatic_choice_and_writes_its_provenance(tmp_path, capsys):
    assert build_parser().parse_args(["pdf", "--out", "p.csv"]).method == "auto"
    out = tmp_path / "p.csv"
    assert main(["pdf", "--out", str(out), "--points", "200"]) == 0
    printed = capsys.readouterr().out
    rec = _sidecar(out)
    assert rec["kind"] == "pdf" and rec["settings"]["method"] == "auto" and rec["settings"]["tol"] == 0.01
    assert rec["results"]["chosen_method"] in ("chain", "fpk") and rec["results"]["estimated_error"] <= 0.01
    assert f"auto -> {rec['results']['chosen_method']}" in printed and "estimated L1 error" in printed
    assert rec["model"]["parameters"]["delta"] == 1.0 and rec["model"]["restitution"] == "ma:vc=0.4"
    # Monte Carlo: 0.502 +- 0.002 (jump, the old default, 0.516)
    assert rec["results"]["mean_energy"] == pytest.approx(0.502, abs=3e-3)
    assert rec["versions"]["numpy"] == np.__version__ and rec["wall_time_s"] > 0


SELF_EXCITED_UNRATED = '''
from models import ImpactOscillator, Ma


class Unrated(ImpactOscillator):
    name = "self-excited-multiplicative"

    def __init__(self):
        super().__init__("x + b*x**3", "c*y", noise=("sqrt(1 + x**2)",), parameters={"b": 0.2, "c": -0.1,
                         "D": 0.05, "delta": 1.0}, restitution=Ma(0.4))
'''


def test_pdf_refuses_averaging_where_the_diagnosis_does_unless_forced(tmp_path, capsys):
    # self-excited and with multiplicative noise: outside the sweep that rates the averaging methods
    (tmp_path / "m.py").write_text(SELF_EXCITED_UNRATED)
    model = ["--model", f"{tmp_path}/m.py:Unrated"]
    out = tmp_path / "p.csv"
    assert main(["pdf", *model, "--method", "jump", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert any("self-excited" in line and "--force" in line for line in err) and not out.exists()
    assert main(["pdf", *model, "--method", "jump", "--out", str(out), "--force", "--points", "200"]) == 0
    assert "warning: --force" in capsys.readouterr().err and out.exists()
    assert _sidecar(out)["results"]["averaging_refusal"].startswith("averaging not trusted")


def test_pdf_method_fpk_writes_the_same_columns_and_the_joint_density(tmp_path, capsys):
    out, joint = tmp_path / "p.csv", tmp_path / "j.csv"
    assert main(["pdf", "--method", "fpk", "--grid", "60", "72", "--out", str(out), "--joint", str(joint),
                 "--joint-points", "21", "--points", "300"]) == 0
    df = pd.read_csv(out)
    assert list(df.columns) == ["H", "p"] and len(df) == 300
    assert np.trapezoid(df.p, df.H) == pytest.approx(1.0, abs=0.01)
    assert list(pd.read_csv(joint).columns) == ["x", "y", "p"]
    assert _sidecar(out)["settings"]["grid"] == [60, 72]


def test_mc_orbit_and_solve_write_provenance(tmp_path, capsys):
    h = tmp_path / "h.csv"
    summary = tmp_path / "s.json"
    assert main(["mc", "--scheme", "splitting", "--dt", "0.02", "--paths", "16", "--t-end", "60", "--t-burn", "10",
                 "--out", str(h), "--summary-json", str(summary)]) == 0
    rec = _sidecar(h)
    assert rec["settings"]["seed"] == 1 and rec["settings"]["chunk_paths"] >= 1 and rec["settings"]["dt"] == 0.02
    assert "same seed and chunk_paths" in rec["settings"]["reproducible_as"]
    assert rec["noise"]["noises"] == 1 and rec["noise"]["states"] == 2 and not rec["noise"]["multiplicative"]
    assert "noise           1 noise, 2 states, additive" in capsys.readouterr().out
    assert json.loads(summary.read_text())["results"]["mean_energy"]["ci"] > 0
    o = tmp_path / "o.csv"
    assert main(["orbit", "--param", "c=0", "--param", "D=0", "--v0", "2.2", "--t-end", "10", "--out", str(o)]) == 0
    assert _sidecar(o)["results"]["status"] == "ok" and _sidecar(o)["kind"] == "orbit"
    s = tmp_path / "sol.csv"
    assert main(["solve", "--tol", "0.05", "--restitution", "elastic", "--out", str(s), "--no-progress"]) == 0
    assert _sidecar(s)["results"]["method"] == "exact"


def test_too_few_chunks_warn_that_the_intervals_are_unreliable():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate_ensemble(DuffingImpact(), "splitting", dt=0.02, paths=4, t_end=40.0, t_burn=5.0, seed=1)
    assert any(issubclass(w.category, VibroWarning) and "only 4 chunks" in str(w.message) for w in caught)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate_ensemble(DuffingImpact(), "splitting", dt=0.02, paths=16, t_end=40.0, t_burn=5.0, seed=1)
    assert not any("chunks" in str(w.message) for w in caught)
