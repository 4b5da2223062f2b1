"""The command line as a product: help texts with defaults and costs, progress in logs, closed pipes."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vibro.cli import EXIT_BROKEN_PIPE, build_parser, main, progress_mode

ROOT = Path(__file__).resolve().parent.parent


def _subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def test_every_option_has_help_and_every_default_is_shown():
    missing, no_default = [], []
    for name, sub in _subparsers().items():
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if not action.help:
                missing.append(f"{name} {action.option_strings or action.dest}")
                continue
            flag = isinstance(action, (argparse._StoreTrueAction, argparse._StoreConstAction))
            if action.option_strings and not action.required and not flag:
                # the help text as the parser's formatter expands it
                if "(default" not in sub.formatter_class("x")._get_help_string(action):
                    no_default.append(f"{name} {action.option_strings[0]}")
    assert missing == []
    assert no_default == []


def test_mc_help_states_the_default_cost():
    text = " ".join(_subparsers()["mc"].format_help().split())
    assert "5.6e8" in text and "paths x t_end / dt" in text
    assert "(default: 256)" in text and "(default: 0.001)" in text


def test_named_options_have_help():
    subs = _subparsers()
    for cmd, opt in (("orbit", "--backend"), ("orbit", "--max-impacts"), ("solve", "--seed"),
                     ("solve", "--progress"), ("figure", "--progress")):
        assert opt in subs[cmd].format_help()
        action = next(a for a in subs[cmd]._actions if opt in a.option_strings)
        assert action.help


def test_progress_mode_follows_the_terminal():
    class Tty:
        def isatty(self):
            return True

    class File:
        def isatty(self):
            return False

    assert progress_mode(None, Tty()) == "bars"
    assert progress_mode(None, File()) == "lines"
    assert progress_mode(False, Tty()) == "off"
    assert progress_mode(True, File()) == "bars"
    args = build_parser().parse_args(["solve", "--no-progress"])
    assert args.progress is False


def test_figure_into_a_log_writes_one_line_per_stage(tmp_path):
    # stderr is a file here, not a terminal: no tqdm bars (no carriage returns, no '%|'), one line per stage (in this
    # process, sys.stderr pointed at the log file; the tests below start vibro in fresh interpreters)
    import contextlib

    log = tmp_path / "log"
    with open(log, "w") as err, contextlib.redirect_stderr(err):
        status = main(["figure", "2", "--no-mc", "--out-dir", str(tmp_path / "f")])
    assert status == 0, log.read_text()
    text = log.read_text()
    assert "\r" not in text and "%|" not in text
    lines = text.splitlines()
    assert [ln for ln in lines if "case" in ln] == [f"figure 2: case {k}/3 Δ = {d}: averaging"
                                                    for k, d in ((1, 0.8), (2, 1.0), (3, 1.2))]
    assert any("drawing" in ln for ln in lines)
    assert len(lines) == 4


def test_solve_into_a_log_writes_stage_lines(capsys):
    # capsys's stderr is not a terminal
    argv = ["solve", "--tol", "0.05", "--param", "c=0.025", "--param", "D=0.005", "--restitution", "ma:vc=2.0"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert err.startswith("vibro solve: choosing and running a method for tol 0.05")
    assert "vibro solve: exact done in" in err and "\r" not in err


def test_closed_stdout_pipe_exits_quietly_with_141(tmp_path):
    # the reader is gone before vibro writes (as after `| head -1`): no traceback, status 128 + SIGPIPE
    proc = subprocess.Popen([sys.executable, "-m", "vibro", "figure", "list"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT, env=_env())
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == EXIT_BROKEN_PIPE == 141
    assert err == ""


@pytest.mark.skipif(sys.platform == "win32", reason="a POSIX shell pipeline")
def test_orbit_piped_into_head(tmp_path):
    cmd = (f"{sys.executable} -m vibro orbit --backend scipy --t-end 20 --rows 400 | head -1; "
           "echo status=${PIPESTATUS[0]}")
    proc = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, cwd=ROOT, env=_env(), timeout=300)
    assert proc.stdout.splitlines()[0].startswith("vibro orbit:")
    assert proc.stdout.splitlines()[-1] in ("status=141", "status=0")  # 0 when vibro finished before head left
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("script, needle", [("02_free_orbit_energy_loss.py", "wrote "),
                                            ("05_reproduce_paper.py", "-> ")])
def test_examples_write_outside_the_working_directory_and_keep_what_they_print(tmp_path, script, needle):
    # run from an empty folder without an output argument: nothing may appear there, and the path the script
    # prints must still exist after it exits
    import re
    import shutil

    proc = subprocess.run([sys.executable, str(ROOT / "examples" / script)], capture_output=True, text=True,
                          cwd=tmp_path, env={**_env(), "MPLBACKEND": "Agg"}, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert list(tmp_path.iterdir()) == []
    line = next(ln for ln in proc.stdout.splitlines() if needle in ln)
    printed = Path(re.search(r"(/\S+\.png)", line).group(1))
    try:
        assert printed.is_file() and printed.stat().st_size > 10_000
        if script == "05_reproduce_paper.py":  # its checks of the numbers pass, and the sidecar is beside the figure
            assert "OK" in proc.stdout, proc.stdout
            assert (printed.parent / "fig02.png").is_file() and (printed.parent / "fig02.json").is_file()
    finally:
        shutil.rmtree(printed.parent, ignore_errors=True)


def test_repository_stands_alone():
    # nothing tracked may point at the shared folder outside the repository or at its notes file (the names are
    # assembled here, so that this file does not name them either and needs no exception)
    forbidden = ("NOTES" + ".md", "shared" + "/paper", ".." + "/shared")
    files = subprocess.run(["git", "ls-files"], capture_output=True, text=True, cwd=ROOT, check=True).stdout.split()
    bad = []
    for name in files:
        if name.endswith((".py", ".md", ".toml", ".cff")):
            text = (ROOT / name).read_text(encoding="utf-8")
            if any(word in text for word in forbidden):
                bad.append(name)
    assert bad == []
    for name in ("LICENSE", "CITATION.cff", "CHANGELOG.md", "docs/paper-readings.md"):
        assert (ROOT / name).is_file()
    assert "BSD 3-Clause" in (ROOT / "LICENSE").read_text() and "the vibro-impact developers" in (
        ROOT / "LICENSE").read_text()


def test_throughput_benchmark_needs_no_outside_baseline(monkeypatch, tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("mc_throughput", ROOT / "benchmarks" / "mc_throughput.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    monkeypatch.delenv(bench.BASELINE_ENV, raising=False)
    assert bench.resolve_baseline(None) is None and bench.load_baseline(None) is None
    assert bench.resolve_baseline("none") is None
    with pytest.raises(SystemExit):
        bench.resolve_baseline(str(tmp_path / "missing.py"))
    h = bench.numpy_reference(32, 400, 1e-2, 0.4, seed=1, nburn=200)
    assert h.sum() == 32 * 200 and h.argmax() < 100  # every sample below h_max, mass at low energy
