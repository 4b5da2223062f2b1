"""``simulate_ensemble(..., scheduler="cuda")`` for oscillators, on numba's CUDA simulator (CI has no GPU).

The oscillator's GPU route is the automaton's CUDA target (hybrid/stochastic/_auto_cuda.py) on
``model.to_automaton()``, the job the CPU route runs, with its rows returned as :class:`EnsembleStatistics`. Checked:
the same statistics as the CPU route within the intervals, the same trajectories for the same normals, bitwise the
same numbers for two launch configurations and across a resume, the barrier invariant, f32 close to f64, the
counter-based generator, and the one-line error when CUDA is unavailable.

The simulator runs each thread as Python, so the runs are tiny (64 paths x 400 steps) and happen once, in a
subprocess started with ``NUMBA_ENABLE_CUDASIM=1`` (tests/cuda_sim_runs.py). What the simulator cannot show
(speed, the device's own rounding, FMA contraction) needs a GPU: benchmarks/gpu_throughput.py.
"""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from hybrid.errors import CudaUnavailableError, ParameterError
from hybrid.stochastic import EnsembleStatistics, _auto_cuda, _cuda_rng, drive_paths, simulate_ensemble
from hybrid.stochastic._auto_exec import CHECKPOINT_FILE
from models import DuffingImpact

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
import cuda_sim_runs  # noqa: E402

HAVE_NUMBA_CUDA = any(importlib.util.find_spec(m) is not None for m in ("numba_cuda", "numba.cuda"))
needs_sim = pytest.mark.skipif(not HAVE_NUMBA_CUDA, reason="numba.cuda is not importable (pip install -e '.[test]' "
                                                           "installs numba-cuda, whose simulator these tests use)")


def _env(**extra):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra)
    return env


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """Run tests/cuda_sim_runs.py once on the simulator; {run name: EnsembleStatistics}, plus the output folder."""
    out = tmp_path_factory.mktemp("cudasim")
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "cuda_sim_runs.py"), str(out)], cwd=ROOT,
                       env=_env(NUMBA_ENABLE_CUDASIM="1"), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    runs = {}
    for name in (*cuda_sim_runs.RUNS, "resumed"):
        with np.load(out / f"{name}.npz") as d:
            runs[name] = EnsembleStatistics.from_arrays(dict(d))
            if name == "resumed":
                runs["partial_steps"] = int(d["partial"])
    runs["out"] = out
    return runs


def _cpu(scheme, paths):
    kw = {k: v for k, v in cuda_sim_runs.BASE.items() if k != "scheduler"}
    kw["paths"] = paths
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate_ensemble(DuffingImpact(), scheme, **kw)


def _same(a: EnsembleStatistics, b: EnsembleStatistics) -> None:
    for attr in ("h_counts", "v_counts", "xy_counts", "chunk_ids", "chunk_paths", "chunk_counts", "chunk_sums"):
        np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr), err_msg=attr)


MOMENTS = ("mean_energy", "mean_x2", "mean_y2", "prob_below_barrier", "impact_rate")


# ---------------------------------------------------------------------------------------------------- simulator
@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
@pytest.mark.parametrize("scheme, run", [("splitting", "tpb32"), ("milstein", "milstein")])
def test_cuda_statistics_agree_with_the_cpu_kernel_within_the_intervals(sim, scheme, run):
    """Same model, step, times and histograms; independent streams: the difference of two estimates must lie within
    the 95 % interval of the difference, sqrt(ci_gpu**2 + ci_cpu**2). The CPU side has 32x the paths."""
    gpu, cpu = sim[run], _cpu(scheme, 2048)
    assert gpu.paths == 64 and gpu.settings["rng"] == _auto_cuda.RNG and gpu.settings["precision"] == "f64"
    assert gpu.settings["kernel"] == "cuda" and gpu.settings["cuda_kernel"].startswith("vibro_auto_cuda_")
    assert gpu.total("samples") * 32 == cpu.total("samples")  # the same samples per path
    for name in MOMENTS:
        g, c = getattr(gpu, name), getattr(cpu, name)
        assert math.isfinite(g.ci) and g.batches == 8
        assert abs(g.value - c.value) <= math.hypot(g.ci, c.ci), (name, g, c)


@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
def test_cuda_kernel_follows_the_cpu_trajectories_for_the_same_normals(sim):
    """The device module is the automaton generator's step code: fed the Philox normals of paths 0..7, the CPU
    kernel (drive_paths) ends where the simulated GPU threads ended (final x, y from the checkpoint)."""
    s = cuda_sim_runs.BASE
    with np.load(sim["out"] / "tpb32_ckpt" / CHECKPOINT_FILE) as d:
        xs, ys, n_done = d["XS"][:, 0], d["XS"][:, 1], int(d["n_done"][0])
    assert n_done == round(s["t_end"] / s["dt"])
    k0, k1 = _cuda_rng.seed_key(s["seed"])
    z = np.array([[v for j in range(n_done // 2) for v in _cuda_rng.normal_pair_f64(k0, k1, p, j)]
                  for p in range(8)])
    end = drive_paths(DuffingImpact(), "splitting", s["dt"], z)
    np.testing.assert_allclose(end[:, 0], xs[:8], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(end[:, 1], ys[:8], rtol=1e-9, atol=1e-12)


@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
def test_cuda_numbers_do_not_depend_on_the_launch_configuration(sim):
    """32 threads per block and whole-run launches vs 64 threads and launches of 37 steps (odd starts)."""
    assert sim["tpb32"].settings["threads_per_block"] == 32 and sim["tpb64"].settings["threads_per_block"] == 64
    _same(sim["tpb32"], sim["tpb64"])


@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
def test_cuda_stride_across_launches(sim):
    a, b = sim["stride3"], sim["stride3_split"]
    assert a.total("samples") == 32 * ((400 - 100) // 3)
    _same(a, b)


@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
def test_cuda_resume_after_an_interruption_gives_the_uninterrupted_numbers(sim):
    assert sim["partial_steps"] == 50  # interrupted after launch 2 of 8, before its checkpoint
    _same(sim["tpb32"], sim["resumed"])


@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
def test_cuda_barrier_invariant(sim):
    """|x| <= delta = 1: no step ended outside (counter), no sample in the x-bins beyond the walls (the histogram
    spans [-1.5, 1.5] in bins of 0.25), and the final positions."""
    for name in cuda_sim_runs.RUNS:
        st = sim[name]
        assert st.violations == 0 and st.total("stuck") == 0 and st.impacts > 0, name
        assert st.total("v_over") == 0 and st.v_counts.sum() == st.impacts, name
        assert st.xy_counts[:, :2].sum() == 0 and st.xy_counts[:, -2:].sum() == 0, name
        assert st.total("xy_out") == 0
    with np.load(sim["out"] / "tpb32_ckpt" / CHECKPOINT_FILE) as d:
        assert np.all(np.abs(d["XS"][:, 0]) <= 1.0)


@pytest.mark.slow  # one simulator run of about 20 s, kept out of the default suite (its 6-minute budget)
@needs_sim
def test_cuda_f32_is_close_to_f64(sim):
    """Single precision draws the same Philox words: p(H) and the moments move far less than their intervals."""
    a, b = sim["tpb32"], sim["f32"]
    assert b.settings["precision"] == "f32"
    for name in MOMENTS:
        assert abs(getattr(a, name).value - getattr(b, name).value) <= 0.1 * getattr(a, name).ci, name
    assert np.abs(a.h_density() - b.h_density()).sum() * 0.1 < 0.02  # L1 distance of p(H) (bin width 0.1)


# ---------------------------------------------------------------------------------------------------- generator
def test_philox_known_answers_and_normals():
    """Random123's known-answer vectors for Philox-4x32-10; Box-Muller pairs are standard normal."""
    u = lambda *w: [np.uint64(v) for v in w]  # noqa: E731
    kat = [((0, 0, 0, 0, 0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
           ((0xFFFFFFFF,) * 6, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
           ((0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344, 0xA4093822, 0x299F31D0),
            (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1))]
    for args, want in kat:
        assert tuple(int(w) for w in _cuda_rng.philox4x32_10(*u(*args))) == want
    k0, k1 = _cuda_rng.seed_key(11)
    z = np.array([_cuda_rng.normal_pair_f64(k0, k1, p, j) for p in range(40) for j in range(100)]).ravel()
    assert abs(z.mean()) < 4 / math.sqrt(z.size) and abs(z.var() - 1) < 5 * math.sqrt(2 / z.size)
    from scipy import stats

    assert stats.kstest(z, "norm").pvalue > 1e-3
    z32 = np.array([_cuda_rng.normal_pair_f32(k0, k1, p, 0) for p in range(2000)]).ravel()
    # (on the host math.* returns Python floats; on the device the same code is float32, see docs/gpu.md)
    assert stats.kstest(z32, "norm").pvalue > 1e-3 and np.abs(z32).max() < 6.7


# ---------------------------------------------------------------------------------------------------- options
def test_cuda_refuses_bad_options_before_any_work():
    m = DuffingImpact()
    with pytest.raises(ParameterError, match="needs scheduler='cuda'"):
        simulate_ensemble(m, "splitting", dt=0.01, paths=2, t_end=1.0, t_burn=0.5, precision="f32")
    with pytest.raises(ParameterError, match="unknown scheduler"):
        simulate_ensemble(m, "splitting", dt=0.01, paths=2, t_end=1.0, t_burn=0.5, scheduler="gpu")
    with pytest.raises(ParameterError, match="CPU kernel"):
        simulate_ensemble(m, "splitting", dt=0.01, paths=2, t_end=1.0, t_burn=0.5, scheduler="cuda",
                          kernel="automaton")


# ---------------------------------------------------------------------------------------------------- no CUDA
_CALL = ("from models import DuffingImpact\n"
         "from hybrid.stochastic import simulate_ensemble\n"
         "from hybrid.errors import CudaUnavailableError\n"
         "try:\n"
         "    simulate_ensemble(DuffingImpact(), 'splitting', dt=0.01, paths=2, t_end=1.0, t_burn=0.5,"
         " scheduler='cuda')\n"
         "except CudaUnavailableError as e:\n"
         "    print('ERR', e)\n")
_BLOCK = ("import sys, importlib.abc\n"
          "class Block(importlib.abc.MetaPathFinder):\n"
          "    def find_spec(self, name, path=None, target=None):\n"
          "        if name in ('numba.cuda', 'numba_cuda') or name.startswith(('numba.cuda.', 'numba_cuda.')):\n"
          "            raise ImportError(name)\n"
          "sys.meta_path.insert(0, Block())\n")


def _run(code, **env):
    e = _env()
    e.pop("NUMBA_ENABLE_CUDASIM", None)  # a real device, or none
    e.update(env)
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=e, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout.strip().splitlines()


def test_cuda_without_the_package_is_a_one_line_error():
    out = _run(_BLOCK + _CALL)
    assert len(out) == 1 and out[0].startswith("ERR ") and 'pip install -e ".[cuda]"' in out[0], out


_CLI_CALL = ("import sys\n"
             "from vibro.cli import main\n"
             "print('RC', main(['mc', '--scheduler', 'cuda', '--precision', 'f32', '--dt', '0.01', '--paths', '4',"
             " '--t-end', '1', '--t-burn', '0.5', '--out', sys.argv[1]]))\n")


@needs_sim
def test_cuda_without_a_device_is_a_one_line_error_in_python_and_on_the_command_line(tmp_path):
    # one interpreter without the simulator for both checks: simulate_ensemble's error, then vibro mc's
    from numba import cuda

    if cuda.is_available():
        pytest.skip("a CUDA device is present")
    e = _env()
    e.pop("NUMBA_ENABLE_CUDASIM", None)  # a real device, or none
    r = subprocess.run([sys.executable, "-c", _CALL + _CLI_CALL, str(tmp_path / "h.csv")], cwd=ROOT, env=e,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    out = r.stdout.strip().splitlines()
    assert len(out) == 2 and out[0].startswith("ERR ") and (
        "no CUDA device was found" in out[0] or 'pip install -e ".[cuda]"' in out[0]), out
    assert issubclass(CudaUnavailableError, ValueError)
    lines = r.stderr.strip().splitlines()
    assert out[1] == "RC 2" and len(lines) == 1, r.stderr
    assert lines[0].startswith("vibro mc: error: --scheduler='cuda'"), r.stderr


_PTX = """
import re, sys
import numba
from numba import cuda
if getattr(cuda, "implementation", "") != "NVIDIA":
    print("SKIP numba's built-in CUDA target compiles device functions only with a device; needs numba-cuda")
    sys.exit(0)
try:
    cuda.compile_ptx(lambda a: None, (numba.float64,), cc=(9, 0))
except Exception as exc:
    print("SKIP", type(exc).__name__, str(exc).splitlines()[0][:200] if str(exc) else "")
    sys.exit(0)
from models import DuffingImpact
from hybrid.stochastic import _auto_cuda, _front
automaton, observables, _, _ = _front._generated(DuffingImpact(), "baoab")  # what scheduler='cuda' runs
for prec in ("f64", "f32"):
    ptx = _auto_cuda.compile_ptx(automaton, "baoab", observables, histograms_width=402, v_bins=200, precision=prec)
    print(prec, " ".join(sorted(set(re.findall(r"^\\s+([a-z][\\w.]*)", ptx, re.M)))))
"""


def test_cuda_kernel_of_example_1_compiles_to_ptx_for_the_h100():
    """The real numba-cuda pipeline (typing, lowering, NVVM) on the kernel ``scheduler='cuda'`` runs for Example 1
    (its automaton, splitting), for sm_90, without a GPU. It needs NVVM and NVRTC (the ``nvidia-nvvm`` and
    ``nvidia-cuda-nvrtc`` wheels or a CUDA toolkit), which CI does not install: skipped there.
    """
    e = _env()
    e.pop("NUMBA_ENABLE_CUDASIM", None)
    r = subprocess.run([sys.executable, "-c", _PTX], cwd=ROOT, env=e, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    out = dict(line.split(" ", 1) for line in r.stdout.strip().splitlines())
    if "SKIP" in out:
        pytest.skip(f"cannot compile PTX here: {out['SKIP']}")
    f64, f32 = set(out["f64"].split()), set(out["f32"].split())
    assert {"atom.shared.add.u32", "atom.global.add.u64", "bar.sync"} <= f64 and "fma.rn.f64" in f64
    assert "fma.rn.f32" in f32
