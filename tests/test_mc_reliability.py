"""Monte Carlo reliability (issue 9): kernel indices in range, every sample counted, exact run identity for
checkpoints, bounded work, in-kernel restitution checks and one-line errors for bad input.

Each test is built on the reproducer of the issue, scaled down to test time.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from hybrid.errors import (
    CheckpointError,
    HistogramRangeWarning,
    ModelError,
    ParameterError,
    RestitutionError,
    VibroError,
    VibroWarning,
)
from hybrid.stochastic import ChatteringWarning, StepSizeWarning, simulate_ensemble
from hybrid.stochastic._runner import CHECKPOINT_FILE
from models import CustomRestitution, DuffingImpact, Elastic, ImpactOscillator, Newton
from vibro.cli import main as vibro

ROOT = Path(__file__).resolve().parents[1]
CLI = ["mc", "--model", "duffing", "--restitution", "ma:vc=0.4", "--scheme", "milstein", "--dt", "1e-2",
       "--paths", "8", "--t-end", "100", "--t-burn", "10", "--seed", "1"]


def quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


# --------------------------------------------------------------------------- 1. kernel indices in range
# vibro mc --scheme em --param c=0 --param D=100 --dt 0.088 --paths 64 --t-end 200 --t-burn 10 --seed 2 aborted
# with munmap_chunk(): the crossing speed was negative and vh[k, int(_vb)] wrote below the array.
EM_REPRO = dict(dt=0.088, paths=8, t_end=30.0, t_burn=10.0, seed=2)


def test_em_crossing_speeds_are_magnitudes_and_every_impact_is_counted():
    # em's in-step velocity can turn before the wall; the automaton kernel bins |d guard / dt|, so no speed is
    # below the histogram (the oscillator kernel counted 11 negative ones here); every impact is binned or counted.
    # Elastic walls instead of the reproducer's Ma law: the em kernel of test_montecarlo.py's weak-order test (the
    # speeds binned do not depend on the law; the Ma-law em kernel runs under bounds checks in the next test)
    s = quiet(simulate_ensemble, DuffingImpact(restitution=Elastic(), c=0.0, D=100.0), "em", **EM_REPRO)
    sp = s.outside()["speed"]
    assert sp["below"] == 0 and s.impacts > 100
    assert int(s.v_counts.sum()) + sp["below"] + sp["above"] == s.impacts == sp["total"]
    assert s.violations == 0


_BOUNDSCHECK = textwrap.dedent("""
    import warnings
    warnings.simplefilter("ignore")
    from hybrid.stochastic import sample_paths, simulate_ensemble
    from models import DuffingImpact, Elastic
    s = simulate_ensemble(DuffingImpact(c=0.0, D=100.0), "em", dt=0.088, paths=8, t_end=30.0, t_burn=10.0, seed=2,
                          xy_bins=(7, 5))
    print("em", s.outside()["speed"]["below"], s.outside()["H"]["above"], s.outside()["xy"]["outside"])
    m = DuffingImpact(restitution=Elastic(), delta=0.3)
    s = simulate_ensemble(m, "splitting", dt=0.01, paths=4, t_end=20.0, t_burn=1.0, h_max=0.05, bins=7,
                          xy_bins=(50, 9), v_max=0.1, v_bins=3)
    print("splitting", s.outside()["H"]["above"] > 0, s.outside()["speed"]["above"] > 0)
    t, x, y = sample_paths(m, "splitting", dt=0.01, t_end=1.0, paths=2, every=7)
    print("paths", x.shape)
""")


def test_kernels_run_under_numba_boundscheck():
    # numba compiles with bounds checks, so any index out of range raises IndexError; the kernels' names carry
    # NUMBA_BOUNDSCHECK (kernel_key), so the shared kernel cache keeps them apart from the unchecked ones and a
    # second run of the suite loads them instead of compiling them again
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", PYTHONPATH=str(ROOT))
    res = subprocess.run([sys.executable, "-c", _BOUNDSCHECK], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.split("\n")
    assert lines[0].startswith("em 0 ") and lines[1] == "splitting True True" and lines[2] == "paths (2, 15)"


def test_a_sample_exactly_on_the_right_wall_lands_in_the_last_bin():
    # no force, no noise, at rest on the right wall: every sample is at x = delta. With delta = 0.3 and 50 bins,
    # (x - x_lo) * 50 / (2 delta) rounds to 50.000000000000014 and the sample used to be dropped. (Example 1 with
    # a = b = c = D = 0: the kernel of the Newton-law milstein ensembles of test_automaton_front.py, no compile here)
    m = DuffingImpact(restitution=Newton(0.5), a=0.0, b=0.0, c=0.0, D=0.0, delta=0.3)
    s = simulate_ensemble(m, "milstein", dt=0.01, paths=2, t_end=1.0, t_burn=0.5, x0=(0.3, 0.0), xy_bins=(50, 4))
    n = s.total("samples")
    assert n == 100 and s.xy_counts[:, -1].sum() == n and s.outside()["xy"]["outside"] == 0
    assert s.xy_density().sum() * (0.6 / 50) * (s.xy_edges[1][1] - s.xy_edges[1][0]) == pytest.approx(1.0)


# --------------------------------------------------------------------------- 5. every sample counted
def test_h_max_below_every_sample_warns_and_reports_the_overflow(tmp_path, capsys):
    out, js = tmp_path / "h.csv", tmp_path / "s.json"
    assert vibro(CLI + ["--h-max", "1e-6", "--out", str(out), "--summary-json", str(js)]) == 0
    captured = capsys.readouterr()
    assert "HistogramRangeWarning" in captured.err and "raise h_max" in captured.err
    import pandas as pd

    df = pd.read_csv(out)
    n = 8 * 9000
    assert df["count"].iloc[-1] == n and df["count"].iloc[:-1].sum() == 0  # the overflow row holds every sample
    assert df["H_lo"].iloc[-1] == 1e-6 and np.isinf(df["H_hi"].iloc[-1]) and np.isinf(df["H_lo"].iloc[0])
    h = json.loads(js.read_text())["results"]["outside_histograms"]["H"]
    assert h == {"below": 0, "above": n, "outside": n, "total": n, "fraction": 1.0}
    assert "1 uncounted" in captured.out


def test_negative_damping_reports_the_uncounted_fraction(capsys, tmp_path):
    # --param c=-0.5 counted 102,919 of 316,800 samples and its density still integrated to 1
    with pytest.warns(HistogramRangeWarning, match="above"):
        s = simulate_ensemble(DuffingImpact(c=-0.5), "milstein", dt=1e-2, paths=8, t_end=100.0, t_burn=10.0,
                              xy_bins=(20, 20))
    h = s.outside()["H"]
    assert h["total"] == s.total("samples") == 72000 and h["fraction"] > 0.5
    assert (s.h_density() * np.diff(s.h_edges)).sum() == pytest.approx(1 - h["fraction"], rel=1e-12)
    xe, ye = s.xy_edges
    area = np.outer(np.diff(ye), np.diff(xe))
    assert (s.xy_density() * area).sum() == pytest.approx(1 - s.outside()["xy"]["fraction"], rel=1e-12)
    assert s.summary()["outside_histograms"]["H"]["fraction"] == h["fraction"]
    assert vibro(CLI + ["--param", "c=-0.5", "--out", str(tmp_path / "h.csv")]) == 0
    line = [t for t in capsys.readouterr().out.splitlines() if "H outside bins" in t][0]
    assert f"{h['fraction']:.4g} uncounted" in line and f"of {h['total']} samples" in line


def test_warning_classes_share_a_base():
    assert issubclass(HistogramRangeWarning, VibroWarning)
    assert issubclass(StepSizeWarning, VibroWarning) and issubclass(ChatteringWarning, VibroWarning)


# --------------------------------------------------------------------------- 4. exact run identity
KW = dict(dt=0.01, paths=8, t_end=40.0, t_burn=5.0, xy_bins=None, chunk_paths=2, seed=3)


def _law_a(v):
    return 0.9 + 0.0 * v


def _law_b(v):
    return 0.5 + 0.0 * v


def test_resume_with_another_callable_law_is_refused(tmp_path, caplog):
    # a checkpoint of one callable law resumed with another mixed the two ensembles (E[H] 0.921 vs 1.652 / 0.717)
    simulate_ensemble(DuffingImpact(restitution=CustomRestitution(_law_a)), "milstein", checkpoint=tmp_path, **KW)
    caplog.set_level("INFO", logger="hybrid.stochastic.compile")
    caplog.clear()
    with pytest.raises(CheckpointError, match=r"restitution law differ"):
        simulate_ensemble(DuffingImpact(restitution=CustomRestitution(_law_b)), "milstein", checkpoint=tmp_path,
                          resume=True, **KW)
    # refused before law b's kernel (compiled in memory, never cached) is built
    assert not [r for r in caplog.records if r.name == "hybrid.stochastic.compile"]
    # the same law (another function object with the same code and constants) resumes
    same = eval(compile("lambda v: 0.9 + 0.0 * v", "<law>", "eval"))
    caplog.clear()
    s = simulate_ensemble(DuffingImpact(restitution=CustomRestitution(same)), "milstein", checkpoint=tmp_path,
                          resume=True, **KW)
    assert s.paths == 8
    # ... with law a's kernel: a callable law's kernel is named by the law's digest, not by the function object
    assert not [r for r in caplog.records if r.name == "hybrid.stochastic.compile"]
    # and cached on disk like an expression law's: another process loads it (no compile)
    code = _LAW_KERNEL_CACHED.format(tests=str(ROOT / "tests"), checkpoint=str(tmp_path / "again"), kw=KW)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.split()[-2:] == ["1", "0"], res.stdout  # cache hits, misses of run_chunk


_LAW_KERNEL_CACHED = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})  # numba's cache entry refers to the law's module: it must be importable
    from hybrid.stochastic import _front, simulate_ensemble
    from models import CustomRestitution, DuffingImpact
    model = DuffingImpact(restitution=CustomRestitution(eval(compile("lambda v: 0.9 + 0.0 * v", "<law>", "eval"))))
    simulate_ensemble(model, "milstein", checkpoint={checkpoint!r}, **{kw!r})
    stats = _front.kernel_module(model, "milstein")[0].run_chunk.stats
    print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))
""")


def test_a_law_reading_an_unhashable_object_cannot_be_checkpointed(tmp_path):
    class Table:
        e = 0.9

    table = Table()
    law = CustomRestitution(lambda v: table.e + 0.0 * v)
    with pytest.raises(CheckpointError, match="cannot be fingerprinted"):
        simulate_ensemble(DuffingImpact(restitution=law), "milstein", checkpoint=tmp_path, **KW)


def test_resume_with_vc_changed_in_the_seventh_digit_is_refused(tmp_path, capsys):
    args = CLI + ["--chunk-paths", "2", "--checkpoint", str(tmp_path / "ck"), "--out", str(tmp_path / "h.csv")]
    assert vibro(args) == 0
    bad = [a.replace("ma:vc=0.4", "ma:vc=0.4000001") for a in args]
    capsys.readouterr()
    assert vibro(bad + ["--resume"]) == 2
    assert "restitution law differ" in one_line_error(capsys)
    assert vibro(args + ["--resume", "--param", "c=0.025000000000000001"]) == 0  # the same double: accepted


def test_edited_or_corrupt_checkpoint_is_refused_in_one_line(tmp_path, capsys):
    model = DuffingImpact()
    simulate_ensemble(model, "milstein", checkpoint=tmp_path, **KW)
    path = tmp_path / CHECKPOINT_FILE
    with np.load(path) as d:
        arrays = {k: d[k] for k in d.files}
    arrays["h_counts"] = arrays["h_counts"] * 2  # a valid npz with doubled counts
    np.savez(path, **arrays)
    with pytest.raises(CheckpointError, match="fails its checksum"):
        simulate_ensemble(model, "milstein", checkpoint=tmp_path, resume=True, **KW)
    path.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(CheckpointError, match="cannot be read"):
        simulate_ensemble(model, "milstein", checkpoint=tmp_path, resume=True, **KW)
    args = CLI + ["--checkpoint", str(tmp_path), "--resume", "--out", str(tmp_path / "h.csv")]
    assert vibro(args) == 2
    assert "corrupt" in one_line_error(capsys)


def test_corrupt_kernel_cache_entry_is_rebuilt(tmp_path):
    # the kernel of the checkpoint tests above, compiled once in the shared cache: its entries (generated module,
    # numba's index and machine code) are copied into an empty cache, garbled there, and a second process must
    # rebuild them (one compile) and give this process's numbers
    import shutil

    from hybrid.stochastic import _front

    expected = quiet(simulate_ensemble, DuffingImpact(), "milstein", **KW).mean_energy.value
    code = ("import warnings; warnings.simplefilter('ignore')\n"
            "from hybrid.stochastic import simulate_ensemble\nfrom models import DuffingImpact\n"
            f"s = simulate_ensemble(DuffingImpact(), 'milstein', **{KW!r})\n"
            "print(repr(s.mean_energy.value))\n")
    env = dict(os.environ, VIBRO_CACHE_DIR=str(tmp_path), PYTHONPATH=str(ROOT))
    env.pop("NUMBA_CACHE_DIR", None)  # numba's entries next to the kernel, in tmp_path
    module = _front.kernel_module(DuffingImpact(), "milstein")[0]
    source = Path(module.__file__)
    if os.environ.get("NUMBA_CACHE_DIR"):
        # numba's entries of the shared cache are elsewhere: garble copies, beside the module, of those of every
        # function the run compiles (index and machine code; building them in a first process cost a compile and an
        # interpreter start)
        shared = Path(module.run_chunk._cache.cache_path)
        compiled = ("run_chunk", "event_step", "model", "locate", "interpolate", "crosses", "outside")
        numba_entries = [(p, tmp_path / "__pycache__" / p.name) for name in compiled
                         for p in shared.glob(f"{module.__name__}.{name}-*")]
        assert {p.name.split("-")[0].rsplit(".", 1)[1] for p, _ in numba_entries} == set(compiled)
    else:
        numba_entries = [(p, tmp_path / p.relative_to(source.parent))
                         for p in source.parent.glob(f"__pycache__/{module.__name__}.*")]
    entries = [(source, tmp_path / source.name), *numba_entries]
    assert {p.suffix for p, _ in entries} == {".py", ".nbi", ".nbc"}
    garbage = b"\xff\x00garbage" * 10
    for p, copy in entries:
        copy.parent.mkdir(exist_ok=True)
        if copy != p:
            shutil.copyfile(p, copy)
        copy.write_bytes(garbage)
    again = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=ROOT)
    assert again.returncode == 0, again.stderr[-2000:]
    assert again.stdout == f"{expected!r}\n"
    # the module and numba's entries were written again
    assert (tmp_path / source.name).read_text() == Path(module.__file__).read_text()
    assert all(p.read_bytes() != garbage for p in tmp_path.glob(f"__pycache__/{module.__name__}.*"))


# --------------------------------------------------------------------------- 6. bounded work
@pytest.mark.parametrize("kw,words", [
    (dict(paths=10**12), "path-steps"), (dict(t_end=1e12), "path-steps"), (dict(dt=1e-300), "path-steps"),
    (dict(t_end=1e300), "path-steps"), (dict(bins=10**9), "GB"), (dict(xy_bins=(100000, 100000)), "GB"),
])
def test_unbounded_work_is_refused_with_the_estimate(kw, words):
    base = dict(dt=0.01, paths=8, t_end=100.0, t_burn=1.0, xy_bins=None)
    with pytest.raises(ParameterError, match=words) as info:
        simulate_ensemble(DuffingImpact(), "milstein", **{**base, **kw})
    assert "limit" in str(info.value) and "\n" not in str(info.value)


def test_the_limits_can_be_lowered_and_raised():
    kw = dict(dt=0.01, paths=8, t_end=100.0, t_burn=1.0, xy_bins=None)
    with pytest.raises(ParameterError, match=r"8e\+04 path-steps"):
        simulate_ensemble(DuffingImpact(), "milstein", max_path_steps=1e4, **kw)
    with pytest.raises(ParameterError, match="GB"):
        simulate_ensemble(DuffingImpact(), "milstein", max_memory=1e3, **kw)
    with pytest.raises(ParameterError, match="path-steps"):
        simulate_ensemble(DuffingImpact(), "milstein", **{**kw, "paths": 2 * 10**10, "t_end": 10.0})
    assert quiet(simulate_ensemble, DuffingImpact(), "milstein", max_path_steps=1e5, **kw).paths == 8


def test_too_many_chunks_are_refused_before_seeding_them():
    """10**8 paths over 10 steps is little work but 1.25e7 chunks of 8, whose seeds alone would take minutes."""
    import time

    from hybrid.stochastic import simulate_automaton
    from models import DuffingImpact as Model

    # chunks of 8 asked for (the automatic choice would take chunks large enough to stay under the limit)
    kw = dict(dt=0.01, paths=10**8, t_end=0.1, t_burn=0.0, xy_bins=None, check_dt=False, chunk_paths=8)
    start = time.perf_counter()
    with pytest.raises(ParameterError, match=r"chunks, above the limit .*chunk_paths >= 96") as info:
        simulate_ensemble(Model(), "milstein", **kw)
    assert "\n" not in str(info.value)
    with pytest.raises(ParameterError, match="chunk_paths >= 96"):
        simulate_automaton(Model().to_automaton(), "em", dt=0.01, paths=10**8, t_end=0.1, x0=(0, 0), seed=1,
                           histograms={"H": (0, 4, 4)}, chunk_paths=8)
    assert time.perf_counter() - start < 5.0  # refused up front, not after spawning the streams


@pytest.mark.parametrize("bad", [
    ["--paths", "1000000000000"], ["--t-end", "1e12"], ["--bins", "1000000000"], ["--dt", "1e-300"],
    ["--t-end", "1e300"], ["--joint", "JOINT", "--xy-bins", "100000", "100000"],
])
def test_cli_unbounded_work_is_one_line(bad, tmp_path, capsys):
    bad = [str(tmp_path / "j.csv") if a == "JOINT" else a for a in bad]
    assert vibro(CLI + bad + ["--out", str(tmp_path / "h.csv")]) == 2
    err = one_line_error(capsys)
    assert "limit" in err and ("path-steps" in err or "GB" in err)
    assert not (tmp_path / "h.csv").exists()


# --------------------------------------------------------------------------- 7. restitution checked at every impact
# the grid of RestitutionLaw.validate has points 1.2309 and 1.3192: a law giving 1.3 between them passed
def _law_between_grid_points(v):
    return 0.9 + 0.4 * ((v > 1.24) & (v < 1.31))


def test_callable_law_above_one_between_grid_points_is_refused(tmp_path):
    law = CustomRestitution(_law_between_grid_points)  # passes the grid validation
    with pytest.raises(RestitutionError, match=r"gave e\(1\.2[4-9]\d*\) = 1\.3, outside \(0, 1\]") as info:
        simulate_ensemble(DuffingImpact(restitution=law, D=0.2), "milstein", dt=0.01, paths=8, t_end=100.0,
                          t_burn=1.0, xy_bins=None, checkpoint=tmp_path, checkpoint_every=1)
    assert "\n" not in str(info.value)
    from hybrid.stochastic import drive_paths

    z = np.zeros((1, 400))
    with pytest.raises(RestitutionError, match="of the driven paths"):
        # from x = 0 at speed 1.647 the path reaches the wall at about 1.27, inside the bad band
        drive_paths(DuffingImpact(restitution=law, D=0.0, c=0.0), "splitting", 0.01, z, x0=(0.0, 1.647))


def _law_raising(v):
    if np.any((np.asarray(v) > 1.24) & (np.asarray(v) < 1.31)):  # between grid points, as above
        raise ValueError("law undefined on (1.24, 1.31)")
    return 0.9 + 0.0 * v


def test_a_law_that_raises_during_the_run_is_one_line():
    law = CustomRestitution(_law_raising)
    with pytest.raises(RestitutionError, match=r"raised ValueError\('law undefined on \(1.24, 1.31\)'\) during"):
        simulate_ensemble(DuffingImpact(restitution=law, D=0.2), "milstein", dt=0.01, paths=8, t_end=100.0,
                          t_burn=1.0, xy_bins=None)


# --------------------------------------------------------------------------- 8. one-line errors
def test_out_directory_fails_before_the_run(tmp_path, capsys):
    assert vibro(CLI + ["--paths", "10000000", "--out", str(tmp_path)]) == 2  # refused at once, not after
    assert "is a directory" in one_line_error(capsys)


def test_checkpoint_that_is_a_file_is_one_line(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert vibro(CLI + ["--checkpoint", str(f), "--out", str(tmp_path / "h.csv")]) == 2
    assert "is a file, not a folder" in one_line_error(capsys)


# the model refuses a constant negative intensity itself (not positive semi-definite) before any simulation
@pytest.mark.parametrize("intensity,words", [(-0.1, "not positive semi-definite"), (0.1j, "complex|real"),
                                             ("sqrt(-1)*D0", "complex|real")])
def test_negative_or_complex_intensity_is_a_parameter_error(intensity, words):
    with pytest.raises((ParameterError, ModelError), match=words):
        m = ImpactOscillator("x", "c*y", intensity=intensity, parameters={"c": 0.1, "delta": 1.0, "D0": 0.1})
        simulate_ensemble(m, "milstein", dt=0.01, paths=2, t_end=2.0, t_burn=1.0, xy_bins=None)


def test_negative_intensity_through_a_parameter_is_a_parameter_error():
    with pytest.raises(ParameterError, match="noise intensities must be >= 0|use noise intensities >= 0|"
                                             "not positive semi-definite"):
        m = ImpactOscillator("x", "c*y", intensity="q", parameters={"c": 0.1, "delta": 1.0, "q": -0.1})
        simulate_ensemble(m, "milstein", dt=0.01, paths=2, t_end=2.0, t_burn=1.0, xy_bins=None)


@pytest.mark.parametrize("x0", [1.3, "ab", (0.0, 1j), None])
def test_x0_that_is_not_a_pair_is_a_parameter_error(x0):
    with pytest.raises(ParameterError, match="x0=.*must be two finite numbers"):
        simulate_ensemble(DuffingImpact(), "milstein", dt=0.01, paths=2, t_end=2.0, t_burn=1.0, x0=x0)
    assert issubclass(ParameterError, VibroError)
