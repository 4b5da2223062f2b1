"""``scheduler="cuda"`` for automaton ensembles (hybrid/stochastic/_auto_cuda.py) on numba's CUDA simulator.

Every model of issue 22, item 2: Example 1 (Ma's law), the stop at the equilibrium, the impact pair, the vibrating
table, a forced model with phase sections and an OU-filtered model; and a guard of the velocities (an energy level,
located in the kicks and the noise too). One subprocess (tests/auto_cuda_sim_runs.py)
runs them all, tiny (32 paths x 200-300 steps), with their CPU references. Checked here:

* the device module is the automaton generator's own code (the same functions, the same fast step);
* each model agrees with the CPU kernel's ensemble (its own streams, 4x the paths) within 3 combined 95 % CIs;
* stronger: fed the GPU's Philox normals, the CPU kernel's ``drive`` ends where the simulated GPU threads ended
  (1e-12) after the same number of events;
* bitwise the same numbers for two launch configurations, and across an interrupted and resumed run;
* f32 stays close to f64; sample counts and the admissible set; ``vibro mc --scheduler cuda`` on an automaton and on
  a forced model; the one-line error without a device.

What the simulator cannot show (speed, registers, occupancy, the device's own rounding) needs a GPU:
benchmarks/gpu_throughput.py.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from hybrid.errors import ParameterError
from hybrid.stochastic import _auto_codegen, _auto_cuda, _auto_exec, simulate_automaton
from models import DuffingImpact, ForcedDuffingImpact
from models.automata import impact_pair, vibrating_table

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
import auto_cuda_sim_runs as runs  # noqa: E402

HAVE_NUMBA_CUDA = any(importlib.util.find_spec(m) is not None for m in ("numba_cuda", "numba.cuda"))
needs_sim = pytest.mark.skipif(not HAVE_NUMBA_CUDA, reason="numba.cuda is not importable (pip install -e '.[test]' "
                                                           "installs numba-cuda, whose simulator these tests use)")
MODELS = ("example1", "stop", "impact_pair", "table", "forced", "ou", "energy_level", "three_noises")


def _env(**extra):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra)
    return env


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """The output folder of one run of tests/auto_cuda_sim_runs.py on the simulator (about 20 s on 2 cores)."""
    out = tmp_path_factory.mktemp("autocudasim")
    # VIBRO_CUDA_ON_DEVICE=1 runs the same checks on a real GPU (and the CPU references compiled)
    on_device = os.environ.get("VIBRO_CUDA_ON_DEVICE") == "1"
    env = _env() if on_device else _env(NUMBA_ENABLE_CUDASIM="1", NUMBA_DISABLE_JIT="1")
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "auto_cuda_sim_runs.py"), str(out)], cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=900)
    if on_device:
        print(r.stdout)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    return out


def _load(out: Path, name: str):
    with open(out / f"{name}.pkl", "rb") as f:
        return pickle.load(f)


def _checkpoint(out: Path, name: str) -> dict:
    with np.load(out / f"{name}_ckpt" / "automaton_checkpoint.npz") as d:
        return {k: d[k] for k in d.files}


def _same(a, b) -> None:
    """Every number of two ensembles, bitwise (NaN rows of the event logs included)."""
    assert a.names == b.names and a.transitions == b.transitions
    for name in a.counts:
        np.testing.assert_array_equal(a.counts[name], b.counts[name], err_msg=name)
    for attr in ("chunk_sums", "chunk_samples", "events", "speed_counts", "speed_sums", "phase_sums", "phase_samples",
                 "event_log", "event_totals"):
        np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr), err_msg=attr)
    assert a.flags == b.flags
    for name in a.phase_counts or {}:
        np.testing.assert_array_equal(a.phase_counts[name], b.phase_counts[name], err_msg=f"phase {name}")


# ---------------------------------------------------------------------------------------------------- generation
def _function(src: str, name: str) -> list[str]:
    m = re.search(rf"^def {name}\(.*?(?=^@|\Z)", src, re.M | re.S)
    assert m, name
    return [line for line in m.group(0).rstrip().splitlines() if "vhist" not in line]


@pytest.mark.parametrize("automaton, scheme", [(impact_pair(), "splitting"), (vibrating_table(), "symplectic")])
def test_device_module_is_the_generators_own_code(automaton, scheme):
    """The model's functions, the event code and the fast step of the CPU kernel appear in the device module as
    they are (only the decorators and the speed histogram's increment differ): one source, not a second template."""
    obs = dict(automaton.observables)
    lay = _auto_cuda.layout(len(obs), 22, len(automaton.transitions), 100, (1, 1), 0)
    dev, st = _auto_cuda.generate_cuda_source(automaton, scheme, obs, lay=lay, joint=False)
    cpu, _ = _auto_codegen.generate_source(automaton, scheme, obs)
    for name in ("model", "_observe", "crosses", "interpolate", "locate", "event_step", "outside"):
        assert _function(dev, name) == _function(cpu, name), name
    fast = cpu[cpu.index("                if mode == 0:"):cpu.index("                    _slow = True")]
    assert fast.count("\n") > 5 and fast in dev
    assert "@nb.njit" not in dev and dev.count("@cuda.jit(device=True)") >= 7
    assert "cuda.atomic.add(vhist, best * VW + np.int64(vb), 1)" in dev
    # the observables' cells fit in the block's shared copy: straight there, 32-bit bins; where they do not, count()
    # sends each to the shared or the global cells
    assert "cuda.atomic.add(sh, H_OFF + 0 * WIDTH + np.int32(_b) + 1, 1)" in dev and "count(sh, gh, H_OFF" not in dev
    wide = _auto_cuda.layout(len(obs), 20_000, len(automaton.transitions), 100, (1, 1), 0)
    big, _ = _auto_cuda.generate_cuda_source(automaton, scheme, obs, lay=wide)
    assert "count(sh, gh, H_OFF + 0 * WIDTH + np.int64(_b) + 1)" in big and "np.int32(_b)" not in big
    # what the run does not use is not generated: no phase sections, no joint histogram
    assert "PSM[ip, kp, o]" not in dev and "J_OFF + int(by)" not in dev
    both, _ = _auto_cuda.generate_cuda_source(automaton, scheme, obs, lay=lay, phases=True, joint=True)
    assert "PSM[ip, kp, o]" in both and "J_OFF + int(by)" in both


def test_step_times_only_where_read():
    """The step's times leave the loop's head when only the event code and the admissible-set test read them, and
    stay where the fast step (a forced model) or an observable reads the time."""
    duffing = DuffingImpact().to_automaton()
    lay = _auto_cuda.layout(2, 42, len(duffing.transitions), 100, (1, 1), 0)
    times = "_t1 = t0 + _fty(step + 1) * dt"

    def in_head(automaton, obs):  # the loop's head: from the loop's line to the draw of the normals
        src = _auto_cuda.generate_cuda_source(automaton, "symplectic", obs, lay=lay)[0]
        return times in src[src.index("for _k in range"):src.index("if _odd == 0")], src

    head, autonomous = in_head(duffing, {"H": duffing.observables["H"]})
    # the slow branch and the admissible-set test of a sample (a block that FAST_CHECKS_SET makes dead here)
    assert not head and autonomous.count(times) == 2
    assert in_head(duffing, {"H": duffing.observables["H"], "s": sp.sin(sp.Symbol("t"))})[0]
    forced = ForcedDuffingImpact(A=0.3, Omega=1.2).to_automaton()
    assert in_head(forced, {"H": forced.observables["H"]})[0]


def test_f32_module_types_every_float_literal():
    import ast

    automaton = impact_pair()
    obs = dict(automaton.observables)
    lay = _auto_cuda.layout(len(obs), 22, 2, 100, (1, 1), 0)
    src, _ = _auto_cuda.generate_cuda_source(automaton, "splitting", obs, lay=lay, precision="f32")
    tree = ast.parse(src)
    wrapped = {id(a) for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
               and n.func.id == "_fty" for a in n.args}
    bare = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, float)
            and id(n) not in wrapped]
    assert bare == [] and "float(" not in src.replace("_fty(", "")


def _host_function(src: str, **names):
    """The device module's plain-Python ``hoisted_values`` with ``HOISTED_NAMES``, without importing numba.cuda."""
    import ast
    from types import SimpleNamespace

    namespace = {"math": math, **names}
    exec(src[src.index("def hoisted_values(p, dt):"):], namespace)
    names, texts = (ast.literal_eval(re.search(rf"^{key} = (\(.*?\))(  #.*)?$", src, re.M).group(1))
                    for key in ("HOISTED_NAMES", "HOISTED_TEXTS"))
    return SimpleNamespace(hoisted_values=namespace["hoisted_values"], HOISTED_NAMES=names, HOISTED_TEXTS=texts)


def test_loop_invariants_are_evaluated_on_the_host_and_refused_when_undefined():
    """The device kernel takes the loop invariants of the model's expressions as a launch argument, evaluated once
    on the host by the module's ``hoisted_values``: for Example 1 they are -a, -b, -c, sqrt(2 D), -delta, a/2 and
    b/4 (its drift, noise, guard and energy), in the order the kernel unpacks them; with IEEE semantics, as the
    device had them (1 / (1 + exp(800)) is 0, not an overflow); an invariant that is NaN (D < 0) is a one-line
    ParameterError, not a NaN on the device."""
    from types import SimpleNamespace

    from models import DuffingImpact, Ma

    automaton = DuffingImpact(restitution=Ma(vc=0.4), a=1.0, b=0.2, c=0.025, D=0.05, delta=1.0).to_automaton()
    lay = _auto_cuda.layout(1, 22, 2, 100, (1, 1), 0)
    obs = {"H": automaton.observables["H"]}
    src, st = _auto_cuda.generate_cuda_source(automaton, "symplectic", obs, lay=lay)
    module = _host_function(src)
    p = [automaton.parameters[name] for name in st.params]
    assert st.params == ("a", "b", "c", "D", "delta")
    values = _auto_cuda.hoisted_values(module, p, 1e-3, np.float64)
    assert values == (-1.0, -0.2, -0.025, math.sqrt(2 * 0.05), -1.0, 0.5, 0.05)
    unpacked = re.findall(r"^    (_\w+) = hv\[(\d+)\]$", src, re.M)
    assert [(name, int(k)) for name, k in unpacked] == [(name, k) for k, name in enumerate(module.HOISTED_NAMES)]
    assert module.HOISTED_NAMES == tuple(f"_inv{k}" for k in range(7))
    assert module.HOISTED_TEXTS[3] == "_inv3 = sqrt(2)*sqrt(D)"  # what the message names
    with pytest.raises(ParameterError, match=re.escape("make _inv3 = sqrt(2)*sqrt(D) NaN")):
        _auto_cuda.hoisted_values(module, [1.0, 0.2, 0.025, -0.05, 1.0], 1e-3, np.float64)
    # the f32 module's own function (its literals typed float32), rounded to float32
    src32, _ = _auto_cuda.generate_cuda_source(automaton, "symplectic", obs, lay=lay, precision="f32")
    values32 = _auto_cuda.hoisted_values(_host_function(src32, _fty=np.float32), p, 1e-3, np.float32)
    assert values32 == tuple(np.float32(v) for v in values)
    # the impact pair under baoab: the exact OU factors of its damping come first, in the kernel's order too
    pair = impact_pair()
    src_pair, st_pair = _auto_cuda.generate_cuda_source(pair, "baoab", dict(pair.observables), lay=lay)
    pair_module = _host_function(src_pair)
    assert pair_module.HOISTED_NAMES[:2] == ("_oa0_2", "_oc0_2")
    unpacked = re.findall(r"^    (_\w+) = hv\[(\d+)\]$", src_pair, re.M)
    assert [(name, int(k)) for name, k in unpacked] == [(n, k) for k, n in enumerate(pair_module.HOISTED_NAMES)]
    pv = _auto_cuda.hoisted_values(pair_module, [pair.parameters[n] for n in st_pair.params], 1e-3, np.float64)
    assert all(np.isfinite(pv)) and 0.0 < pv[0] < 1.0  # _oa = exp(-c dt)
    # IEEE semantics: an overflowing intermediate is inf, as on the device; a NaN is refused
    namespace = {"math": math}
    exec("def hoisted_values(p, dt):\n    return (1.0 / (1.0 + math.exp(p[0])), p[1] ** (1 / 3))\n", namespace)
    fake = SimpleNamespace(hoisted_values=namespace["hoisted_values"], HOISTED_NAMES=("_inv0", "_inv1"),
                           HOISTED_TEXTS=("_inv0 = 1/(exp(k) + 1)", "_inv1 = m**(1/3)"))
    assert _auto_cuda.hoisted_values(fake, [800.0, 8.0], 1e-3, np.float64) == (0.0, 2.0)
    with pytest.raises(ParameterError, match=re.escape("make _inv1 = m**(1/3) NaN")):
        _auto_cuda.hoisted_values(fake, [800.0, -8.0], 1e-3, np.float64)


def test_layout_keeps_the_speeds_shared_and_refuses_what_cannot_be():
    lay = _auto_cuda.layout(3, 402, 2, 100, (1, 1), 20)  # 20 phase sections of 3 x 402 cells: beyond 48 KiB
    assert lay["shared"] == lay["p_off"] < lay["cells"]
    with pytest.raises(ParameterError, match="speed histograms"):
        _auto_cuda.layout(1, 12, 2, 10**4, (1, 1), 0)


def test_cuda_options_need_the_cuda_scheduler():
    with pytest.raises(ParameterError, match="options of scheduler='cuda'"):
        simulate_automaton(impact_pair(), "splitting", dt=0.01, paths=2, t_end=1.0, x0=(0, 0, 0, 0), seed=1,
                           histograms={"H": (0, 1, 4), "z": (-1, 1, 4)}, precision="f32")


# ---------------------------------------------------------------------------------------------------- simulator
@needs_sim
@pytest.mark.parametrize("name", MODELS)
def test_each_model_agrees_with_the_cpu_kernel_within_three_combined_intervals(sim, name):
    gpu, cpu = _load(sim, name), _load(sim, f"cpu_{name}")
    assert gpu.settings["scheduler"] == "cuda" and gpu.settings["precision"] == "f64"
    assert "scheduler" not in cpu.settings
    assert gpu.flags["samples"] * runs.CPU_FACTOR == cpu.flags["samples"] > 0
    assert gpu.settings["dt"] == cpu.settings["dt"]
    for obs in gpu.names:
        g, c = gpu.mean(obs), cpu.mean(obs)
        assert math.isfinite(g.ci) and g.ci > 0 and abs(g.value - c.value) <= 3 * math.hypot(g.ci, c.ci), (obs, g, c)


@needs_sim
@pytest.mark.parametrize("name", MODELS)
def test_gpu_threads_follow_the_cpu_kernel_for_the_same_normals(sim, name):
    """The CPU kernel's drive (every step through event_step), fed the Philox normals of the first paths, ends where
    the simulated GPU threads (fast step, event_step where a guard may fire) ended, after the same events."""
    ck, d = _checkpoint(sim, name), np.load(sim / f"drive_{name}.npz")
    n_trans = len(_load(sim, name).transitions)
    k = runs.DRIVEN
    np.testing.assert_allclose(ck["XS"][:k], d["end"], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(ck["IWS"][:k, 6 + n_trans], d["nlog"])  # event_step's IW_NLOG: the events
    assert d["nlog"].sum() > 0
    if name == "impact_pair":  # its run keeps the first 4 events of every path: times and transitions
        log = _load(sim, name).event_log[:k]
        np.testing.assert_allclose(log[:, :, :2], d["log"][:, :4, :2], rtol=1e-12, atol=1e-12)


@needs_sim
@pytest.mark.parametrize("name", MODELS)
def test_device_chunk_sums_match_the_paths_rows(sim, name):
    """The per-chunk rows the device adds up (hybrid/stochastic/_cuda_rows.py) against numpy's sums of the final
    per-path rows of the same run (its checkpoint): samples, counters, events, speeds; the float sums to rounding
    (numpy adds in another order)."""
    ens, ck = _load(sim, name), _checkpoint(sim, name)
    cp, nt = ens.settings["chunk_paths"], len(ens.transitions)
    starts = np.arange(0, ck["XS"].shape[0], cp)
    assert len(starts) > 1 or name == "energy_level"  # several chunks: the split by chunk is exercised
    np.testing.assert_array_equal(ens.chunk_samples, np.add.reduceat(ck["CNT"][:, 0], starts))
    np.testing.assert_allclose(ens.chunk_sums, np.add.reduceat(ck["SM"], starts, axis=0)[:, :len(ens.names)],
                               rtol=1e-13, atol=0)
    np.testing.assert_array_equal(ens.events, ck["IWS"][:, 6:6 + nt].sum(axis=0))  # IW_EVENTS = 6
    np.testing.assert_allclose(ens.speed_sums, ck["FWS"][:, :nt].sum(axis=0), rtol=1e-13, atol=0)
    counts = ck["CNT"].sum(axis=0)
    counts[[1, 5]] += ck["IWS"][:, [1, 5]].sum(axis=0)  # the event code's own counters
    assert ens.flags == dict(zip(_auto_exec.COUNT_NAMES, counts.tolist())) and ens.flags["samples"] > 0
    if ens.phase_sums is not None:  # the forced model's sections
        np.testing.assert_allclose(ens.phase_sums, np.add.reduceat(ck["PSM"], starts, axis=0)[:, :, :len(ens.names)],
                                   rtol=1e-13, atol=0)


@needs_sim
def test_rows_filled_on_the_device_are_the_hosts(sim):
    """Every simulated run's per-path rows at t = 0, filled by the device (hybrid/stochastic/_cuda_rows.py), equal
    the host's ``fresh`` rows: values, NaN event logs, the guard statistics' +-inf, dtypes (f32 state included)."""
    lines = (sim / "device_fresh.txt").read_text().splitlines()
    assert len(lines) >= len(MODELS) and any("_f32_" in line for line in lines)
    assert all(line.endswith(" equal") for line in lines), lines


@needs_sim
@pytest.mark.parametrize("name", ["impact_pair", "forced"])
def test_launch_configuration_changes_no_number(sim, name):
    """32 threads per block in one launch vs 64 threads and launches of 37 (23) steps: bitwise the same, events,
    speeds, event logs and phase sections included."""
    a, b = _load(sim, name), _load(sim, f"{name}_tpb64")
    assert a.settings["threads_per_block"] == 32 and b.settings["threads_per_block"] == 64
    assert b.settings["launch_steps"] in (37, 23) and a.settings["launch_steps"] > 400
    _same(a, b)


@needs_sim
def test_resume_after_an_interruption_gives_the_uninterrupted_numbers(sim):
    resumed = _load(sim, "impact_pair_resumed")
    assert resumed.settings["partial_steps"] == 80  # stopped after launch 3 of 40 steps, before its checkpoint
    _same(_load(sim, "impact_pair"), resumed)


@needs_sim
def test_f32_draws_the_same_philox_words_and_stays_close(sim):
    a, b = _load(sim, "impact_pair"), _load(sim, "impact_pair_f32")
    assert b.settings["precision"] == "f32" and b.flags["samples"] == a.flags["samples"]
    assert _checkpoint(sim, "impact_pair_f32")["XS"].dtype == np.float32
    for obs in a.names:
        assert abs(a.mean(obs).value - b.mean(obs).value) <= 0.05 * a.mean(obs).ci, obs


@needs_sim
def test_counts_and_the_admissible_set(sim):
    for name in MODELS:
        ens = _load(sim, name)
        s = ens.settings
        n_samp = int(round((s["t_end"] - s["t_burn"]) / s["dt"]))
        assert ens.flags["samples"] == s["paths"] * n_samp, name
        assert ens.flags["outside"] == ens.flags["event_overflow"] == ens.flags["nonfinite"] == 0, name
        assert sum(ens.events) > 0, name
        for obs in ens.counts:
            assert ens.counts[obs].sum() == ens.flags["samples"], (name, obs)
    pair = _load(sim, "impact_pair")
    assert pair.counts["z"][0] == pair.counts["z"][-1] == 0  # |x2 - x1| <= gap = 0.2 < 0.25
    stop = _load(sim, "stop").counts["x"]  # underflow, then bins of 0.1 from x = -0.3
    assert stop[:3].sum() == 0 and stop[4:].sum() > 0  # the wall at x = 0 keeps x >= 0 (to within the event location)
    forced = _load(sim, "forced")
    per_section = forced.phase_samples.sum(axis=0)  # counted on the host; the CPU kernel counts them itself
    np.testing.assert_array_equal(per_section * runs.CPU_FACTOR, _load(sim, "cpu_forced").phase_samples.sum(axis=0))
    assert per_section.min() > 0
    for k in range(forced.settings["phases"]):
        assert forced.phase_counts["H"][k].sum() == per_section[k]


@needs_sim
def test_rows_beyond_the_device_memory_are_refused_with_the_estimate(sim):
    text = (sim / "too_many.txt").read_text()
    assert text.startswith("SizeError: ") and "1000000000 paths" in text and "bytes of state" in text, text
    assert "\n" not in text


@needs_sim
def test_oscillator_route_gives_the_automaton_routes_numbers(sim):
    """Two entry points, one answer: ``simulate_ensemble(DuffingImpact(), "milstein", scheduler="cuda")`` runs
    Example 1's automaton on this target, so with the same seed, step and bins it has the "example1" run's H
    histogram, samples and impacts bit for bit, and its energy sum to rounding (other chunk groupings)."""
    from hybrid.stochastic import EnsembleStatistics

    with np.load(sim / "oscillator_example1.npz") as d:
        osc = EnsembleStatistics.from_arrays(dict(d))
    ens = _load(sim, "example1")
    assert osc.settings["kernel"] == "cuda" and osc.settings["rng"] == ens.settings["rng"]
    np.testing.assert_array_equal(osc.h_counts, ens.counts["H"][1:-1])
    assert osc.total("h_under") == ens.counts["H"][0] and osc.total("h_over") == ens.counts["H"][-1]
    assert osc.total("samples") == ens.chunk_samples.sum() and osc.impacts == ens.events.sum() > 0
    assert osc.chunk_sums[:, 0].sum() == pytest.approx(ens.chunk_sums[:, 0].sum(), rel=1e-12)


@needs_sim
def test_vibro_mc_runs_automata_and_forced_models_on_cuda(sim):
    assert (sim / "cli_rc.txt").read_text() == "0 0"
    for stem in ("cli_pair", "cli_forced"):
        rec = json.loads((sim / f"{stem}.json").read_text())
        assert rec["settings"]["scheduler"] == "cuda", stem
    assert (sim / "cli_pair_transitions.csv").exists() and (sim / "cli_forced_phases.csv").exists()


# ---------------------------------------------------------------------------------------------------- no CUDA
_NO_DEVICE = """
import sys
from models.automata import impact_pair
from hybrid.stochastic import simulate_automaton
from hybrid.errors import CudaUnavailableError
try:
    simulate_automaton(impact_pair(), "splitting", dt=0.01, paths=2, t_end=1.0, x0=(0, 0, 0, 0), seed=1,
                       histograms={"H": (0, 1, 4), "z": (-1, 1, 4)}, scheduler="cuda")
except CudaUnavailableError as e:
    print("ERR", e)
from vibro.cli import main
print("RC", main(["mc", "--model", "impact_pair", "--scheduler", "cuda", "--dt", "0.01", "--paths", "4", "--t-end",
                  "1", "--t-burn", "0.5", "--out", sys.argv[1]]))
"""


@needs_sim
def test_without_a_device_one_line(tmp_path):
    from numba import cuda

    if cuda.is_available():
        pytest.skip("a CUDA device is present")
    e = _env()
    e.pop("NUMBA_ENABLE_CUDASIM", None)
    r = subprocess.run([sys.executable, "-c", _NO_DEVICE, str(tmp_path / "h.csv")], cwd=ROOT, env=e,
                       capture_output=True, text=True, timeout=300)
    out = r.stdout.strip().splitlines()
    assert r.returncode == 0 and len(out) == 2 and out[0].startswith("ERR "), r.stdout + r.stderr[-2000:]
    assert "no CUDA device was found" in out[0] or 'pip install -e ".[cuda]"' in out[0]
    assert out[1] == "RC 2" and len(r.stderr.strip().splitlines()) == 1 and "vibro mc: error:" in r.stderr
    assert not (tmp_path / "h.csv").exists()


def test_automaton_kernel_compiles_to_ptx_for_the_h100():
    """The real numba-cuda pipeline (typing, lowering, NVVM) on the impact pair's kernel, for sm_90, without a GPU.

    The simulator runs the kernel as Python and checks no types; this does. It needs NVVM and NVRTC (the
    ``nvidia-cuda-nvcc-cu12`` and ``nvidia-cuda-nvrtc-cu12`` wheels on LD_LIBRARY_PATH, or a CUDA toolkit), which CI
    does not install: skipped there.
    """
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" or not HAVE_NUMBA_CUDA:
        pytest.skip("needs numba-cuda without the simulator")
    import numba
    from numba import cuda

    try:
        cuda.compile_ptx(lambda a: None, (numba.float64,), cc=(9, 0))
    except Exception as exc:
        pytest.skip(f"cannot compile PTX here: {type(exc).__name__}")
    automaton = impact_pair()
    ptx = _auto_cuda.compile_ptx(automaton, "splitting", dict(automaton.observables), phases=4)
    ops = set(re.findall(r"^\s+([a-z][\w.]*)", ptx, re.M))
    assert {"atom.shared.add.u32", "atom.global.add.u64", "bar.sync", "fma.rn.f64"} <= ops


@needs_sim
@pytest.mark.slow
def test_gpu_ablation_rewrites_keep_the_numbers_on_the_simulator():
    """benchmarks/gpu_ablation.py's rewrites still fit the generated source and give the kernel's own numbers (the
    histogram and the mean, all bits) across launches that start at odd steps; the script refuses otherwise. The
    ablations run. Example 1 (one noise) and the impact pair (two), tiny: about 80 s on 2 cores. (``extevent``
    needs a device: on the simulator it is refused with a skipped line.)"""
    for model in ("Example 1", "impact pair"):
        r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "gpu_ablation.py"), "--quick", "--models", model],
                           cwd=ROOT, env=_env(NUMBA_ENABLE_CUDASIM="1", NUMBA_DISABLE_JIT="1"), capture_output=True,
                           text=True, timeout=900)
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
        table = [line.split() for line in r.stdout.split("registers local  numbers")[-1].splitlines()[1:] if line]
        exact = [row[0] for row in table if row[-1] in ("same", "CHANGED")]
        assert "nobook" in exact and all(row[-1] != "CHANGED" for row in table), r.stdout
        # Example 1's values as literals: only on Example 1's source (the impact pair's is refused, a skipped line)
        assert ("bake" in exact and "bakeparams" in exact) == (model == "Example 1"), r.stdout
