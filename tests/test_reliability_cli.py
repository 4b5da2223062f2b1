"""Issue 9: bad command-line arguments exit with status 2 and one line on stderr, never a traceback."""

from __future__ import annotations

import pytest

from vibro.cli import main

_RAISING = "from models import DuffingImpact\nclass Bad(DuffingImpact):\n    def __init__(self):\n" \
           "        raise RuntimeError('constructor failed')\n"
_NEEDS_ARGS = "from models import DuffingImpact\nclass Needs(DuffingImpact):\n    def __init__(self, k):\n" \
              "        super().__init__()\n"

BAD = [
    # restitution specs, in all four subcommands (custom:zoo was a KeyError in each)
    (["orbit", "--restitution", "custom:zoo"], "not a finite real expression"),
    (["pdf", "--out", "{tmp}/p.csv", "--restitution", "custom:zoo"], "not a finite real expression"),
    (["mc", "--out", "{tmp}/h.csv", "--restitution", "custom:zoo"], "not a finite real expression"),
    (["solve", "--dry-run", "--restitution", "custom:zoo"], "not a finite real expression"),
    (["orbit", "--restitution", "ma"], "needs vc=VALUE"),
    (["orbit", "--restitution", "custom:1/(1+"], "invalid syntax"),
    (["pdf", "--out", "{tmp}/p.csv", "--restitution", "newton:e=2"], "outside (0, 1]"),
    # numbers beyond double precision
    (["solve", "--tol", "1e-300"], "double precision"),
    (["pdf", "--out", "{tmp}/p.csv", "--param", "D=1e-300"], "energy scale"),
    (["pdf", "--out", "{tmp}/p.csv", "--param", "c=1e300"], "energy scale"),
    (["pdf", "--out", "{tmp}/p.csv", "--param", "D=nan"], "not finite"),
    (["orbit", "--rtol", "1e-300"], "machine epsilon"),
    (["orbit", "--backend", "scipy", "--rtol", "1e-15"], "double precision"),
    # work and memory bounds
    (["pdf", "--out", "{tmp}/p.csv", "--points", "1000000000"], "GiB"),
    (["pdf", "--out", "{tmp}/p.csv", "--points", "1e9"], "--points: '1e9' is not an integer"),
    (["pdf", "--out", "{tmp}/p.csv", "--joint", "{tmp}/j.csv", "--joint-points", "100000"], "GiB"),
    (["orbit", "--max-impacts", "1000000000000"], "GB"),
    (["orbit", "--max-steps", "0"], "--max-steps=0"),
    # user model classes
    (["orbit", "--model", "{tmp}/bad.py:Bad"], "raised RuntimeError: constructor failed"),
    (["orbit", "--model", "{tmp}/bad.py:Needs"], "cannot be built without arguments"),
    (["orbit", "--model", "{tmp}/missing.py:Bad"], "does not exist"),
    (["orbit", "--model", "{tmp}/bad.py:Nothing"], "has no object named"),
]


@pytest.fixture
def tmp(tmp_path):
    (tmp_path / "bad.py").write_text(_RAISING + _NEEDS_ARGS)
    return tmp_path


def _run(argv) -> int:
    """``main(argv)``'s status; argparse's own errors exit through SystemExit."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("argv,words", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_argument_exits_2_with_one_line(argv, words, tmp, capsys):
    rc = _run([a.replace("{tmp}", str(tmp)) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert words in lines[0] and "Traceback" not in err
    assert not (tmp / "p.csv").exists() and not (tmp / "h.csv").exists()


def test_h_max_that_cuts_the_mass_is_one_warning_line(tmp, capsys):
    rc = main(["pdf", "--method", "jump", "--out", str(tmp / "p.csv"), "--h-max", "1e-9", "--points", "101"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 0
    assert len(err) == 1 and err[0].startswith("vibro pdf: warning: h_max=1e-09 cuts off 1 of the")


def test_huge_t_end_is_refused_with_the_estimate(capsys):
    rc = main(["orbit", "--t-end", "1e300", "--max-steps", "2000", "--rows", "0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "needs about 3.16e+299 integration steps" in err[0] and "above the limit 2000" in err[0]
    assert "--max-steps" in err[0]


def test_an_orbit_longer_than_estimated_stops_at_the_step_budget(capsys):
    rc = main(["orbit", "--t-end", "500", "--max-steps", "300", "--rows", "0"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "status max_steps" in out and "max_steps=300" in out
