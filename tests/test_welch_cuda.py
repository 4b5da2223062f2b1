"""The Monte Carlo spectrum (Welch) with ``scheduler="cuda"`` (hybrid/stochastic/_welch.py, the recording variant
of the CUDA kernel in hybrid/stochastic/_auto_cuda.py), on numba's CUDA simulator.

One small subprocess (tests/welch_cuda_sim_runs.py, about 10 s) gives: the same numbers for two launch
configurations and two batchings of the paths; the recorded states against the CPU kernel's ``drive`` fed the same
Philox normals; ``vibro spectrum --method mc --scheduler cuda``. A second one (slow) gives the free linear
oscillator's spectrum, checked against the expectation of Welch's estimator computed from the exact autocovariance
(an independent oracle) and against the CPU route (its own xoshiro streams) within the combined intervals.
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hybrid.errors import ParameterError
from hybrid.stochastic import _auto_cuda, _front
from hybrid.stochastic._welch import _observable_function, welch_spectrum
from models import DuffingImpact

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
import welch_cuda_sim_runs as runs  # noqa: E402

HAVE_NUMBA_CUDA = any(importlib.util.find_spec(m) is not None for m in ("numba_cuda", "numba.cuda"))
needs_sim = pytest.mark.skipif(not HAVE_NUMBA_CUDA, reason="numba.cuda is not importable (pip install -e '.[test]' "
                                                           "installs numba-cuda, whose simulator these tests use)")


def _simulate(out: Path, *extra: str) -> Path:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               NUMBA_ENABLE_CUDASIM="1", NUMBA_DISABLE_JIT="1")
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "welch_cuda_sim_runs.py"), str(out), *extra], cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    return _simulate(tmp_path_factory.mktemp("welchcudasim"))


@needs_sim
def test_launch_configurations_and_batches_give_the_same_numbers(sim):
    """32 threads per block, one launch, one batch; 64 threads, launches of 37 steps, batches of one chunk."""
    a, b = (np.load(sim / f"config_{k}.npz") for k in range(len(runs.CONFIGS)))
    assert a["segments"] == b["segments"] > 0
    for key in ("S", "ci", "variance", "mean"):
        assert np.array_equal(a[key], b[key]), key


@needs_sim
def test_recorded_states_are_the_cpu_kernel_driven_by_the_same_normals(sim):
    """Samples 0, 1 and the last of the first two paths: the CPU kernel's ``drive`` along the host's Philox normals
    ends where the simulated threads recorded (the same generated step code, the same numbers)."""
    d = np.load(sim / "driven.npz")
    assert d["recorded"].shape == d["driven"].shape == (2, 3, 2)
    np.testing.assert_allclose(d["recorded"], d["driven"], rtol=0, atol=1e-12)
    assert np.ptp(d["recorded"][:, :, 0]) > 0.01  # the paths moved


@needs_sim
def test_cli_spectrum_on_the_simulated_gpu(sim):
    assert (sim / "cli_rc.txt").read_text() == "0"
    data = np.loadtxt(sim / "cli.csv", delimiter=",", skiprows=1)
    assert (sim / "cli.csv").read_text().splitlines()[0] == "omega,S,S_lo,S_hi"
    assert data.shape == (9, 4) and np.all(np.isfinite(data)) and np.all(data[:, 1] > 0)


def _expected_welch(omega, segment: int, dt_s: float, c: float, D: float) -> np.ndarray:
    """The expectation of Welch's estimate (Hann, ``segment`` samples of spacing dt_s) of x for the free linear
    oscillator x'' + c x' + x = sqrt(2 D) xi: the window's double sum over the exact autocovariance
    C(tau) = (D / c) exp(-c tau / 2) (cos(w tau) + c / (2 w) sin(w tau)), w = sqrt(1 - c**2 / 4) (leakage and
    aliasing included; the grand-mean centring, which touches the first two bins only, left out)."""
    w = np.hanning(segment + 2)[1:-1]
    wd = math.sqrt(1 - c * c / 4)
    m = np.arange(segment)
    lag = np.abs(m[:, None] - m[None, :]) * dt_s
    cov = D / c * np.exp(-c * lag / 2) * (np.cos(wd * lag) + c / (2 * wd) * np.sin(wd * lag))
    ww = w[:, None] * w[None, :] * cov
    return np.array([np.sum(ww * np.cos(om * lag)) for om in omega]) * dt_s / (math.pi * segment * np.mean(w**2))


@needs_sim
@pytest.mark.slow
def test_gpu_welch_meets_the_exact_expectation_and_the_cpu(tmp_path):
    """64 paths x 1200 steps of dt = 0.05 on the simulator (about 10 s). Where omega dt <= 0.25 (the scheme's own
    high-frequency error, a few per cent at omega dt = 0.5, stays below the interval) every bin from the first
    lies within 3 of its 95 % half-widths of the exact expectation; every bin meets the CPU route's estimate (its
    own streams, 2x the paths, the same scheme and so the same discretisation) within 3 combined half-widths."""
    g = np.load(_simulate(tmp_path, "oracle") / "oracle.npz")
    o = runs.ORACLE
    dt_s = o["dt"] * o["every"]
    expected = _expected_welch(g["omega"], o["segment"], dt_s, runs.C, runs.D)
    near = (g["omega"] > 0) & (g["omega"] * o["dt"] <= 0.25)
    assert near.sum() >= 5
    assert np.all(np.abs(g["S"] - expected)[near] <= 3 * g["ci"][near])
    assert float(g["variance"]) == pytest.approx(runs.D / runs.C, rel=0.1)  # about 3 standard deviations
    cpu = welch_spectrum(runs.oscillator(), "x", **dict(o, paths=2 * o["paths"], seed=o["seed"] + 1))
    assert np.array_equal(cpu.omega, g["omega"])
    band = g["omega"] > 0
    assert np.all(np.abs(g["S"] - cpu.S)[band] <= 3 * np.hypot(g["ci"], cpu.ci)[band])


def test_the_recording_kernel_is_the_ensemble_kernel_plus_its_records():
    """Generated only when asked: the recording variant is the ensemble kernel's text with two more arguments, the
    path offset in the Philox counter and one store per state at every sample."""
    automaton = runs.oscillator().to_automaton()
    observables = _front._generated(runs.oscillator(), "baoab")[1]
    lay = _auto_cuda.layout(len(observables), 10, 0, 8, (1, 1), 0)
    plain, _ = _auto_cuda.generate_cuda_source(automaton, "baoab", observables, lay=lay, cache=False)
    rec, _ = _auto_cuda.generate_cuda_source(automaton, "baoab", observables, lay=lay, cache=False, record=True)
    assert not re.search(r"\b(REC|ip0)\b", plain) and re.search(r"\bREC\[ip, _r, 1\] = _x1\b", rec)
    undone = (rec.replace("elogs, gh, ip0, REC):", "elogs, gh):").replace("normal_pair(rk, ip0 + ip,",
                                                                          "normal_pair(rk, ip,"))
    undone = re.sub(r"\n +_r = \(step \+ 1 - n_burn\) // stride - 1\n( +REC\[ip, _r, \d\] = _x\d\n)+", "\n", undone)
    assert undone == plain


def test_the_energy_observable_of_a_model_with_real_symbols():
    """``H`` of Example 1 (its energy in the model's own, real, symbols) as a number on both routes (it was left
    an expression of the parameters, a TypeError)."""
    m = DuffingImpact()
    x, y = np.array([0.3, -0.5]), np.array([0.2, 0.1])
    a, b = m.params["a"], m.params["b"]
    np.testing.assert_allclose(_observable_function(m, "H")(x, y), y**2 / 2 + a * x**2 / 2 + b * x**4 / 4,
                               rtol=1e-14)


def test_gpu_settings_are_refused_elsewhere_and_checked():
    m = runs.oscillator()
    small = dict(dt=0.05, t_end=16.0, t_burn=2.0, paths=8, every=2, segment=32, chunk_paths=4)
    with pytest.raises(ParameterError, match="scheduler='cuda'"):
        welch_spectrum(m, "x", precision="f32", **small)
    with pytest.raises(ParameterError, match="cuda or a distributed.Client"):
        welch_spectrum(m, "x", scheduler="gpu", **small)


@needs_sim
def test_without_a_device_the_cli_says_so_in_one_line(tmp_path, capsys):
    """No device and no simulator: exit 2, one line, no file."""
    from numba import cuda

    from vibro.cli import main as cli

    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" or cuda.is_available():
        pytest.skip("a CUDA device (or the simulator) is present")
    out = tmp_path / "S.csv"
    rc = cli(["spectrum", "--method", "mc", "--scheduler", "cuda", "--paths", "16", "--t-end", "20", "--t-burn", "2",
              "--segment", "64", "--out", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "vibro spectrum: error:" in lines[0] and "Traceback" not in err, err
    assert "no CUDA device was found" in lines[0] or 'pip install -e ".[cuda]"' in lines[0]
    assert not out.exists()
