"""``vibro orbit``: in-process through vibro.cli.main, plus one run of the installed script."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from problems import energy_loss_per_impact, exact_two_impact_loss

from hybrid.deterministic import write_csv_atomically
from models import Ma
from vibro.cli import main

BASE = ["orbit", "--model", "duffing", "--param", "a=1", "--param", "b=0.2", "--param", "c=0", "--param", "D=0",
        "--param", "delta=1.0", "--restitution", "ma:vc=0.4", "--x0", "0", "--v0", "2.2", "--t-end", "60"]


@pytest.mark.parametrize("backend", ["heyoka", "scipy"])
def test_orbit_writes_impact_log_and_compares(tmp_path, capsys, backend):
    out = tmp_path / "impacts.csv"
    assert main(BASE + ["--backend", backend, "--out", str(out)]) == 0
    df = pd.read_csv(out)
    assert {"t", "x", "v_minus", "v_plus", "e", "H_minus", "H_plus"} <= set(df.columns)
    assert len(df) == 29
    law = Ma(0.4)
    e = np.array([law.coefficient(abs(v)) for v in df.v_minus])
    pred = np.array([energy_loss_per_impact(ei, h, 0.55) for ei, h in zip(e, df.H_minus)])
    np.testing.assert_allclose(df.H_minus - df.H_plus, pred, rtol=1e-7, atol=1e-12)
    loss2 = df.H_minus[0] - df.H_plus[1]
    assert loss2 == pytest.approx(exact_two_impact_loss(law, 2.42, 0.55), rel=1e-9)
    text = capsys.readouterr().out
    for needle in ("eq. 11", "eq.13 paper", "exact 2-imp", "eq.14", "largest relative deviation"):
        assert needle in text
    # the log and its provenance sidecar, no temporary file left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == ["impacts.csv", "impacts.json"]


def test_orbit_below_barrier_reports_free_period(capsys):
    assert main(["orbit", "--param", "c=0", "--param", "D=0", "--v0", "0.5", "--t-end", "5"]) == 0
    text = capsys.readouterr().out
    assert "no impacts" in text and "eq. 8" in text


def test_orbit_defaults_keep_model_parameters(capsys):
    # only delta given: a, b, c, D keep the defaults; damping is reported as a deviation from the free formulas
    assert main(["orbit", "--param", "delta=0.8", "--t-end", "10", "--rows", "1"]) == 0
    text = capsys.readouterr().out
    assert "c=0.025" in text and "delta=0.8" in text and "noise is ignored" in text


@pytest.mark.parametrize(
    "extra,needle",
    [
        (["--param", "delta=0"], "delta"),
        (["--param", "delta=-1"], "delta"),
        (["--restitution", "newton:e=1.5"], "(0, 1]"),
        (["--restitution", "newton:e=0"], "(0, 1]"),
        (["--restitution", "ma:vc=-0.1"], "vc"),
        (["--restitution", "bogus"], "unknown restitution"),
        (["--x0", "1.5"], "outside the gap"),
        (["--model", "nosuchmodel"], "unknown model"),
        (["--param", "zz=1"], "unknown parameters"),
        (["--param", "a=abc"], "not a number"),
        (["--t-end", "nan"], "t-end"),
        (["--t-end", "-1"], "t-end"),
        (["--rtol", "5"], "rtol"),
    ],
)
def test_orbit_bad_input_exits_2_with_one_line(tmp_path, capsys, extra, needle):
    out = tmp_path / "impacts.csv"
    try:
        status = main(BASE + extra + ["--out", str(out)])
    except SystemExit as exc:  # refused while the command line is read (NaN is not a number)
        status = exc.code
    assert status == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not out.exists()


def test_orbit_user_model_file(tmp_path, capsys):
    src = tmp_path / "mymodel.py"
    src.write_text(
        "from models import ImpactOscillator, Newton\n"
        "class Linear(ImpactOscillator):\n"
        "    name = 'linear'\n"
        "    def __init__(self, restitution=None, **p):\n"
        "        super().__init__('k*x', 0, parameters={'k': 1.0, 'D': 0.0, 'delta': 1.0, **p},\n"
        "                         restitution=restitution or Newton(0.8))\n"
    )
    out = tmp_path / "lin.csv"
    assert main(["orbit", "--model", f"{src}:Linear", "--v0", "2", "--t-end", "5", "--out", str(out)]) == 0
    df = pd.read_csv(out)
    # x = 2 sin t reaches the barrier at t = pi/6 with v = sqrt(3); Newton 0.8 scales it by -0.8
    assert df.t[0] == pytest.approx(math.pi / 6, rel=1e-13)
    assert df.v_plus[0] == pytest.approx(-0.8 * math.sqrt(3), rel=1e-13)
    assert "linear" in capsys.readouterr().out
    assert main(["orbit", "--model", f"{src}:Nope", "--t-end", "5"]) == 2


def test_atomic_write_keeps_old_file_on_failure(tmp_path):
    target = tmp_path / "impacts.csv"
    target.write_text("old\n")

    class Broken(pd.DataFrame):
        def to_csv(self, fh, **kw):
            fh.write("t,x\n0.1,")
            raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_csv_atomically(Broken({"t": [1.0]}), target)
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["impacts.csv"]


def test_vibro_script_subprocess(tmp_path):
    exe = shutil.which("vibro") or str(Path(sys.executable).with_name("vibro"))
    out = tmp_path / "impacts.csv"
    proc = subprocess.run([exe, *BASE, "--t-end", "20", "--out", str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_csv(out)
    assert len(df) == 11 and math.isclose(df.H_minus[0], 2.42, rel_tol=1e-14)
