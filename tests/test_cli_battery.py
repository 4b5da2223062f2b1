"""Issue 24: the command line against hostile numbers, bad output paths, colliding outputs and file-system faults.

The hostile-number cases come from ``tests/cli_battery.py`` (every int/float option of every writing command, found
by walking the parser, and the model parameters through ``--param``); hypothesis draws a bounded sample of them (and
values of its own) so that the default suite spends about a minute here. ``python tests/cli_battery.py`` runs all.
"""

from __future__ import annotations

import errno
import os
import time
from pathlib import Path

import cli_battery
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import hybrid.io
from vibro.cli import main

BAD_KINDS = ("crashed", "hung", "wrong", "unclear")
CHEAP = [c for c in cli_battery.cases() if c.argv[0] in ("orbit", "pdf", "plot")
         and "fpk" not in c.argv and c.option != "--t-end"]


def _check(outcome):
    assert outcome.kind not in BAD_KINDS, (outcome.kind, outcome.case.argv, outcome.detail, outcome.stderr[-2000:])


# no shrinking: a case is one process run, and the report names the failing command line already
QUICK = {"deadline": None, "derandomize": True, "suppress_health_check": list(HealthCheck),
         "phases": (Phase.explicit, Phase.generate)}


@settings(max_examples=16, **QUICK)
@given(case=st.sampled_from(CHEAP))
def test_hostile_numbers_and_paths_are_refused_or_answered(case):
    _check(cli_battery.run_case(case, timeout=60.0))


NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                    st.integers(min_value=-(2**80), max_value=2**80).map(str),
                    st.text(alphabet="0123456789.e+-naif", max_size=8))


@settings(max_examples=10, **QUICK)
@given(option=st.sampled_from([(c, o, n) for c, o, n in cli_battery._numeric_options() if c == "pdf"]),
       value=NUMBERS)
def test_any_number_to_any_pdf_option(option, value):
    command, flag, nargs = option
    width = nargs if isinstance(nargs, int) else 1
    argv = cli_battery._with(cli_battery.BASE["pdf"], flag, [value] * width)
    _check(cli_battery.run_case(cli_battery.Case(argv, flag, value), timeout=60.0))


@pytest.mark.parametrize("argv", cli_battery.COLLISIONS[:2] + cli_battery.COLLISIONS[4:], ids=lambda a: " ".join(a))
def test_outputs_on_one_file_are_refused(argv):
    outcome = cli_battery.run_case(cli_battery.Case(argv, "collision"), timeout=60.0)
    assert outcome.kind == "refused", (outcome.kind, outcome.detail, outcome.stderr[-2000:])
    assert "one file" in outcome.detail or "own provenance sidecar" in outcome.detail


# ----------------------------------------------------------------------------- file-system faults, every writer

WRITERS = {
    "orbit": ["orbit", "--t-end", "5", "--rows", "1", "--out", "{d}/o.csv"],
    "pdf": ["pdf", "--method", "jump", "--points", "300", "--out", "{d}/p.csv", "--joint", "{d}/j.csv",
            "--joint-points", "11"],
    "solve": ["solve", "--tol", "0.05", "--method", "jump", "--out", "{d}/s.csv"],
    "mc": ["mc", "--scheme", "splitting", "--dt", "0.02", "--paths", "16", "--t-end", "60", "--t-burn", "10",
           "--out", "{d}/h.csv", "--summary-json", "{d}/summary.json"],
    "plot": ["plot", "{src}/in.csv", "--out", "{d}/pic.png"],
    "figure": ["figure", "2", "--no-mc", "--quick", "--out-dir", "{d}/fig"],
}


def _argv(name, folder, src):
    return [a.format(d=folder, src=src) for a in WRITERS[name]]


@pytest.fixture
def source(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "in.csv").write_text(cli_battery.PLOT_INPUT)
    return src


# bench writes too: it is refused before its minutes of work, so it joins only the read-only case
READ_ONLY = {**WRITERS, "bench": ["bench", "validity", "--quick", "--parts", "orbits", "--out-dir", "{d}/bench"]}


@pytest.mark.parametrize("name", sorted(READ_ONLY))
def test_read_only_folder_is_refused_before_the_work(name, tmp_path, source, monkeypatch, capsys):
    """EACCES for every file created in the output folder (what a read-only folder gives a user who is not root):
    refused in one line, within a second, nothing written."""
    out = tmp_path / "ro"
    out.mkdir()
    real_open = os.open

    def guarded(path, *args, **kwargs):
        if str(out) in os.fspath(path):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(hybrid.io.os, "open", guarded)
    t0 = time.perf_counter()
    assert main([a.format(d=out, src=source) for a in READ_ONLY[name]]) == 2
    elapsed = time.perf_counter() - t0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Permission denied" in err[0] and "error:" in err[0], err
    assert elapsed < 10.0, f"refused only after {elapsed:.1f} s: the work ran first"
    assert list(out.rglob("*")) == []


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into read-only folders")
@pytest.mark.parametrize("name", ["pdf", "orbit"])
def test_really_read_only_folder(name, tmp_path, source, capsys):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        assert main(_argv(name, out, source)) == 2
    finally:
        out.chmod(0o755)
    assert "error:" in capsys.readouterr().err and list(out.iterdir()) == []


@pytest.mark.parametrize("name", sorted(WRITERS))
def test_full_disk_leaves_no_partial_file(name, tmp_path, source, monkeypatch, capsys):
    """ENOSPC injected into the first completed write: one line, status 2, no temporary or partial file left."""
    out = tmp_path / "full"
    out.mkdir()
    real_replace = os.replace

    def full(src, dst, *args, **kwargs):
        if str(out) in os.fspath(dst):
            raise OSError(errno.ENOSPC, "No space left on device", os.fspath(dst))
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(hybrid.io.os, "replace", full)
    assert main(_argv(name, out, source)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if "error:" in line]
    assert len(errors) == 1 and "no space left" in errors[0], err
    assert [p for p in out.rglob("*") if p.is_file()] == []


def test_name_longer_than_the_file_system_allows(tmp_path, capsys):
    name = tmp_path / ("a" * 300 + ".csv")
    assert main(["pdf", "--method", "jump", "--points", "300", "--out", str(name)]) == 2
    assert "above the file system's limit" in capsys.readouterr().err
    # a name that fits, but whose temporary name would not, is written
    fits = tmp_path / ("b" * 250 + ".csv")
    assert main(["pdf", "--method", "jump", "--points", "300", "--out", str(fits)]) == 0
    assert fits.is_file() and Path(str(fits)[:-4] + ".json").is_file()


@pytest.mark.parametrize("target", ["/proc/x.csv", "{d}/fifo", "", "{d}", "{d}/missing/x.csv"])
def test_paths_that_cannot_take_a_file(target, tmp_path, capsys):
    os.mkfifo(tmp_path / "fifo")  # a special file (not /dev/null: a defective build run as root would replace it)
    assert main(["orbit", "--t-end", "5", "--out", target.format(d=tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0], err


# ----------------------------------------------------------------------------- the reproducers, items 8 and 9

HUGE = "1" + "0" * 30


@pytest.mark.parametrize("argv,needle", [
    (["mc", "--chunk-paths", HUGE, "--out", "{d}/h.csv"], f"--chunk-paths: {HUGE} is beyond a 64-bit integer"),
    (["orbit", "--max-steps", HUGE], f"--max-steps: {HUGE} is beyond a 64-bit integer"),
    (["mc", "--max-memory-gb", "0", "--out", "{d}/h.csv"], "--max-memory-gb 0 must be a positive number"),
    (["orbit", "--max-impacts", "0"], "--max-impacts=0 must be an integer >= 1"),
    (["orbit", "--x0", "0", "1", "--v0", "2"], "--x0 X V already sets the velocity"),
    (["orbit", "--x0", "0", "1", "2"], "--x0 gives 3 values"),
])
def test_numbers_on_the_command_line_are_refused_by_their_flag(argv, needle, tmp_path, capsys):
    try:
        status = main([a.format(d=tmp_path) for a in argv])
    except SystemExit as exc:  # refused while the command line is read
        status = exc.code
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_orbit_state_has_the_spelling_of_mc(capsys):
    assert main(["orbit", "--x0", "0", "0", "--t-end", "3"]) == 0  # from rest: no impact, no traceback
    assert "starts at rest" in capsys.readouterr().out
    assert main(["orbit", "--x0", "0.1", "1.5", "--t-end", "3", "--rows", "1"]) == 0
    assert "H0 = 1.13" in capsys.readouterr().out  # 1.5^2/2 + 0.1^2/2 + 0.2 * 0.1^4/4


def test_plot_of_a_csv_with_nan(tmp_path, capsys):
    some = tmp_path / "some.csv"
    some.write_text("H,p\n0,0.5\n0.5,nan\n1,1\n2,inf\n3,0.2\n")
    assert main(["plot", str(some), "--out", str(tmp_path / "some.png")]) == 0
    assert "2 of 5 rows hold NaN or infinite values" in capsys.readouterr().err
    none = tmp_path / "none.csv"
    none.write_text("H,p\n0,nan\n1,nan\n")
    assert main(["plot", str(none), "--out", str(tmp_path / "none.png")]) == 2
    assert "no row holds only finite numbers" in capsys.readouterr().err
    assert not (tmp_path / "none.png").exists()
