"""A kernel compiled rather than loaded from the disk cache says so: one record from the library
(hybrid.stochastic._kernel_modules.COMPILE_LOG, nothing printed by itself), one line on stderr from the command line."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hybrid.stochastic import _kernel_modules
from vibro.cli import compile_notices

ROOT = Path(__file__).resolve().parent.parent

TINY = '''
import numba as nb


@nb.njit(cache=True)
def run_chunks(x):
    return x + 1.0
'''


def _load_fresh(name):
    _kernel_modules._LOADED.pop(name, None)
    sys.modules.pop(name, None)
    module, _ = _kernel_modules.load_source(name, TINY, label="tiny/test")
    return module


def test_a_cache_miss_is_logged_once_and_a_cache_hit_is_silent(tmp_path, monkeypatch, caplog, capsys):
    monkeypatch.setenv("VIBRO_CACHE_DIR", str(tmp_path))
    name = f"vibro_auto_tiny_{os.getpid()}_{tmp_path.name.replace('-', '')}"
    with caplog.at_level(logging.INFO, logger="hybrid.stochastic.compile"):
        assert _load_fresh(name).run_chunks(1.0) == 2.0
        assert _load_fresh(name).run_chunks(2.0) == 3.0  # a new process's view: loaded from numba's disk cache
    notes = [r for r in caplog.records if r.name == "hybrid.stochastic.compile"]
    assert [r.getMessage() for r in notes] == ["compiling the Monte Carlo kernel for tiny/test (first run only, ~8 s)"]
    assert notes[0].kernel == "tiny/test" and notes[0].estimate_s == 8
    assert capsys.readouterr().err == ""  # the library prints nothing unasked


def test_the_command_line_prints_the_compile_line_on_stderr(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("VIBRO_CACHE_DIR", str(tmp_path))
    with compile_notices():
        _load_fresh(f"vibro_auto_tiny_{os.getpid()}_cli").run_chunks(1.0)
    err = capsys.readouterr().err
    assert err == "vibro: compiling the Monte Carlo kernel for tiny/test (first run only, ~8 s)\n"
    assert logging.getLogger("hybrid.stochastic.compile").handlers == []  # removed after the command


@pytest.mark.slow
def test_first_mc_run_into_a_pipe_says_it_compiles(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "VIBRO_CACHE_DIR": str(tmp_path / "cache")}
    argv = [sys.executable, "-m", "vibro", "mc", "--scheme", "splitting", "--dt", "0.02", "--paths", "16", "--t-end",
            "60", "--t-burn", "10"]
    first = subprocess.run(argv + ["--out", str(tmp_path / "a.csv")], capture_output=True, text=True, env=env,
                           timeout=300)
    assert first.returncode == 0, first.stderr
    assert "vibro: compiling the Monte Carlo kernel for duffing/baoab (first run only" in first.stderr
    second = subprocess.run(argv + ["--out", str(tmp_path / "b.csv")], capture_output=True, text=True, env=env,
                            timeout=300)
    assert second.returncode == 0 and "compiling" not in second.stderr


def test_a_kernel_family_without_a_measured_compile_time_claims_none(tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("VIBRO_CACHE_DIR", str(tmp_path))
    name = f"vibro_auto_cuda_tiny_{os.getpid()}"
    with caplog.at_level(logging.INFO, logger="hybrid.stochastic.compile"):
        _load_fresh(name).run_chunks(1.0)
    notes = [r for r in caplog.records if r.name == "hybrid.stochastic.compile"]
    assert [r.getMessage() for r in notes] == ["compiling the Monte Carlo kernel for tiny/test (first run only)"]
    assert notes[0].estimate_s is None
