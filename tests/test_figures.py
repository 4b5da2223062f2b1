"""`vibro figure`: CLI contract, output files, L1 values recomputed from the CSV, the paper's qualitative claims,
reuse after an interrupted run, and the example script 05.

Budget: the module runs three cheap figures (2 and 16 with the ``--quick`` Monte Carlo, 15 analytic only) once and
shares them; the example smoke test runs Fig. 2 at the default preset (~5-10 s).
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vibro.cli import main

ROOT = Path(__file__).resolve().parents[1]
CSV_COLUMNS = ["curve", "case", "method", "quantity", "x", "y", "z", "x_lo", "x_hi", "y_lo", "y_hi", "ci"]
SIDECAR_KEYS = {"figure", "status", "kind", "caption", "claim", "choices", "preset", "spec_hash", "methods",
                "l1_definition", "spec", "cases", "claims", "disagreements", "versions", "wall_time_s", "outputs"}


@pytest.fixture(scope="module")
def outdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("figs")
    for argv in (["figure", "2", "--quick"], ["figure", "16", "--quick"], ["figure", "15", "--quick", "--no-mc"]):
        assert main(argv + ["--out-dir", str(d), "--no-progress"]) == 0
    return d


def _sidecar(d, n):
    return json.loads((Path(d) / f"fig{n:02d}.json").read_text(encoding="utf-8"))


def _csv(d, n):
    return pd.read_csv(Path(d) / f"fig{n:02d}.csv")


# ----------------------------------------------------------------------------------------------- CLI contract
@pytest.mark.parametrize("token", ["1", "17", "x", "0", "2.5"])
def test_bad_figure_number_exits_2_with_one_line(token, tmp_path, capsys):
    assert main(["figure", token, "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "figure" in err and "2 to 16" in err
    assert not any(tmp_path.iterdir())  # nothing written


def test_bad_dpi_exits_2(tmp_path, capsys):
    assert main(["figure", "2", "--dpi", "5", "--out-dir", str(tmp_path)]) == 2
    assert "--dpi" in capsys.readouterr().err


def test_list_prints_every_figure_with_choices(capsys):
    assert main(["figure", "list"]) == 0
    out = capsys.readouterr().out
    for n in range(2, 17):
        assert any(line.split()[:1] == [str(n)] for line in out.splitlines())
    assert "van der Pol reading" in out


# ----------------------------------------------------------------------------------------------- outputs
@pytest.mark.parametrize("n", [2, 16])
def test_outputs_png_csv_json(outdir, n):
    png = outdir / f"fig{n:02d}.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = _csv(outdir, n)
    assert list(table.columns) == CSV_COLUMNS
    side = _sidecar(outdir, n)
    assert SIDECAR_KEYS <= set(side)
    assert side["figure"] == n and side["status"] == "finished" and side["preset"] == "quick"
    assert set(side["outputs"]) == {f"fig{n:02d}.png", f"fig{n:02d}.csv"}
    methods = set(table["method"])
    assert methods == {"paper", "jump", "fpk", "mc"}
    assert side["methods"]["phase_plane"]["method"] == "fpk"
    for label, case in side["cases"].items():
        assert set(case["l1_energy"]) == {"paper_vs_mc", "jump_vs_mc", "fpk_vs_mc", "paper_vs_jump", "mc_noise"}
        assert case["fpk_wall_s"] > 0 and case["fpk"]["mean_energy"] > 0
        assert len(case["mc"]["seeds"]) == 2 and case["mc"]["seeds"][0] != case["mc"]["seeds"][1]
        assert label in set(table["case"])
    if side["kind"] == "joint":
        assert set(table["quantity"]) == {"p(H)", "p(x,y)"}
        (case,) = side["cases"].values()
        assert set(case["l1_joint"]) == {"paper_vs_mc", "jump_vs_mc", "fpk_vs_mc", "mc_noise"}
    else:
        assert set(table["quantity"]) == {"p(H)"}
        assert len(side["cases"]) == 3


def test_every_choice_is_in_caption_and_sidecar(outdir):
    side = _sidecar(outdir, 16)
    assert side["choices"] and all(c in side["caption"] for c in side["choices"])
    assert side["spec"]["cases"][0]["reading"] == "van-der-pol"
    assert "(c1 + c2 x^2)" in side["caption"]


# ----------------------------------------------------------------------------------------------- L1 from the CSV
def _bin_mean_of_linear_interpolant(x, p, lo, hi, sub=400):
    """Independent bin average: trapezoid on a fine sub-grid of each bin plus the interpolant's own knots."""
    out = np.empty(len(lo))
    for i, (a, b) in enumerate(zip(lo, hi)):
        t = np.union1d(np.linspace(a, b, sub), x[(x > a) & (x < b)])
        v = np.interp(t, x, p, left=0.0, right=0.0)
        out[i] = np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(t)) / (b - a)
    return out


@pytest.mark.parametrize("n", [2, 16])
def test_sidecar_energy_l1_recomputed_from_csv(outdir, n):
    table = _csv(outdir, n)
    side = _sidecar(outdir, n)
    energy = table[table["quantity"] == "p(H)"]
    for label, case in side["cases"].items():
        rows = energy[energy["case"] == label]
        mc = rows[rows["method"] == "mc"].sort_values("x")
        lo, hi, p_mc = mc["x_lo"].to_numpy(), mc["x_hi"].to_numpy(), mc["y"].to_numpy()
        width = hi - lo
        # the merged histogram is a density on its own bins
        assert np.sum(p_mc * width) == pytest.approx(1.0, abs=0.02)
        for method in ("paper", "jump", "fpk"):
            cur = rows[rows["method"] == method].sort_values("x")
            pa = _bin_mean_of_linear_interpolant(cur["x"].to_numpy(), cur["y"].to_numpy(), lo, hi)
            mine = float(np.sum(np.abs(pa - p_mc) * width))
            assert case["l1_energy"][f"{method}_vs_mc"] == pytest.approx(mine, rel=2e-3, abs=2e-4), method
        # ci = 1.96 * |half A - half B| / 2, and mc_noise = L1(A, B) / 2 = sum(ci / 1.96 * width)
        noise = float(np.sum(mc["ci"].to_numpy() / 1.96 * width))
        assert case["l1_energy"]["mc_noise"] == pytest.approx(noise, rel=1e-6, abs=1e-9)


def test_sidecar_joint_l1_recomputed_from_csv(outdir):
    from scipy.interpolate import RegularGridInterpolator

    table = _csv(outdir, 16)
    (case,) = _sidecar(outdir, 16)["cases"].values()
    joint = table[table["quantity"] == "p(x,y)"]
    mc = joint[joint["method"] == "mc"]
    area = (mc["x_hi"] - mc["x_lo"]).to_numpy() * (mc["y_hi"] - mc["y_lo"]).to_numpy()
    assert np.sum(mc["z"].to_numpy() * area) == pytest.approx(1.0, abs=0.02)
    for method in ("paper", "jump", "fpk"):
        grid = joint[joint["method"] == method]
        xs, ys = np.unique(grid["x"]), np.unique(grid["y"])
        z = grid.set_index(["y", "x"])["z"].unstack().loc[ys, xs].to_numpy()
        f = RegularGridInterpolator((ys, xs), z, bounds_error=False, fill_value=0.0)
        # cell means by an 8 x 8 midpoint rule on the bilinear interpolant of the 121 x 121 CSV grid
        offs = (np.arange(8) + 0.5) / 8
        total = 0.0
        for x_lo, x_hi, y_lo, y_hi, z_mc, a in zip(mc["x_lo"], mc["x_hi"], mc["y_lo"], mc["y_hi"], mc["z"], area):
            X, Y = np.meshgrid(x_lo + (x_hi - x_lo) * offs, y_lo + (y_hi - y_lo) * offs)
            total += abs(float(np.mean(f(np.column_stack([Y.ravel(), X.ravel()])))) - z_mc) * a
        # the grid is finer than the cells but not exact: 3 % relative agreement
        assert case["l1_joint"][f"{method}_vs_mc"] == pytest.approx(total, rel=0.03), method


# ----------------------------------------------------------------------------------------------- paper's claims
def test_fig2_peak_of_analytic_pH_falls_as_delta_grows(outdir):
    table = _csv(outdir, 2)
    labels = list(_sidecar(outdir, 2)["cases"])
    deltas = [float(lab.split("=")[1]) for lab in labels]
    assert deltas == sorted(deltas)
    for method in ("paper", "jump"):
        peaks = [table[(table["case"] == lab) & (table["method"] == method)]["y"].max() for lab in labels]
        assert np.all(np.diff(peaks) < 0), (method, peaks)
        # and each analytic p(H) integrates to 1 on its grid
        for lab in labels:
            cur = table[(table["case"] == lab) & (table["method"] == method)].sort_values("x")
            assert np.trapezoid(cur["y"], cur["x"]) == pytest.approx(1.0, abs=2e-3)


def _joint_grid(d, n, method="paper"):
    table = _csv(d, n)
    g = table[(table["quantity"] == "p(x,y)") & (table["method"] == method)]
    xs, ys = np.unique(g["x"]), np.unique(g["y"])
    z = g.set_index(["y", "x"])["z"].unstack().loc[ys, xs].to_numpy()
    return xs, ys, z


def test_fig15_ring_complete_fig16_truncated(outdir):
    # Delta = 3: a ring around the limit cycle (|x| ~ 2.7 on y = 0), a crater at the origin, nothing at the barrier
    xs, ys, z = _joint_grid(outdir, 15)
    row = z[np.argmin(np.abs(ys))]
    at = {v: row[np.argmin(np.abs(xs - v))] for v in (0.0, 2.7, -2.7, 3.0, -3.0)}
    assert at[0.0] < 0.2 * min(at[2.7], at[-2.7])
    x_peak = abs(xs[np.argmax(row)])
    assert 2.3 < x_peak < 2.95
    assert max(at[3.0], at[-3.0]) < min(at[2.7], at[-2.7])  # the ring peaks inside the barriers
    # Delta = 1: the window stops at the barriers; on y = 0 the density keeps rising up to x = +-1 (the ring is cut)
    xs16, ys16, z16 = _joint_grid(outdir, 16)
    assert xs16.min() == pytest.approx(-1.0) and xs16.max() == pytest.approx(1.0)
    row16 = z16[np.argmin(np.abs(ys16))]
    half = row16[xs16 >= 0]
    assert np.all(np.diff(half) > 0)
    assert row16[0] > 0.5 * z16.max() and row16[-1] > 0.5 * z16.max()
    side15, side16 = _sidecar(outdir, 15), _sidecar(outdir, 16)
    ring, impacts = side15["claims"]
    assert ring["holds"] is True
    # the paper says 'no impact' at Delta = 3; at D = 0.01 our p(H) puts ~10 % above G(3) and the sidecar says so
    assert impacts["holds"] is False and 0.05 < impacts["detail"]["prob_above_barrier"]["paper"] < 0.2
    assert any("no impacts" in msg for msg in side15["disagreements"])
    assert [c["holds"] for c in side16["claims"] if "truncated" in c["statement"]] == [True]


# ----------------------------------------------------------------------------------------------- reuse
def test_finished_figure_is_reused_partial_is_recomputed(outdir, tmp_path):
    from vibro.studies.figures import run_figure

    d = tmp_path / "out"
    shutil.copytree(outdir, d)  # includes the Monte Carlo cache, so recomputing is cheap
    first = run_figure(2, d, preset="quick")
    assert first.status == "reused"
    png_mtime = (d / "fig02.png").stat().st_mtime_ns

    # interrupted after the PNG: no sidecar -> recomputed, sidecar rewritten
    (d / "fig02.json").unlink()
    again = run_figure(2, d, preset="quick")
    assert again.status == "finished" and (d / "fig02.json").is_file()
    assert (d / "fig02.png").stat().st_mtime_ns != png_mtime

    # a sidecar from another spec (different hash) -> recomputed
    side = _sidecar(d, 2)
    side["spec_hash"] = "0" * 20
    (d / "fig02.json").write_text(json.dumps(side), encoding="utf-8")
    assert run_figure(2, d, preset="quick").status == "finished"
    assert _sidecar(d, 2)["spec_hash"] != "0" * 20

    # an output changed after the sidecar was written -> recomputed
    with open(d / "fig02.csv", "a", encoding="utf-8") as fh:
        fh.write("truncated")
    assert run_figure(2, d, preset="quick").status == "finished"
    assert run_figure(2, d, preset="quick").status == "reused"

    # with and without Monte Carlo are different figures
    assert run_figure(15, d, preset="quick", with_mc=False).status == "reused"
    assert run_figure(15, d, preset="quick", with_mc=True).status == "finished"


def test_cli_reports_reuse(outdir, tmp_path, capsys):
    d = tmp_path / "out"
    shutil.copytree(outdir, d)
    assert main(["figure", "2", "--quick", "--out-dir", str(d), "--no-progress"]) == 0
    assert "reused" in capsys.readouterr().out


# ----------------------------------------------------------------------------------------------- example 05
# example 05 runs (its checks, fig02.png and its sidecar) in test_cli_product.py, from an empty working directory


# ----------------------------------------------------------------------------------------------- no pickles
def test_mc_cache_holds_numbers_only_and_never_unpickles(outdir, tmp_path, monkeypatch):
    import pickle

    from vibro.studies.figures import run_figure

    cache = outdir / ".mc-cache"
    assert not list(outdir.rglob("*.pkl"))
    assert list(cache.glob("mc-*.npz")) and list(cache.glob("mc-*.json"))
    for f in cache.glob("mc-*.npz"):
        with np.load(f, allow_pickle=False) as data:  # raises on an object array
            assert all(data[k].dtype != object for k in data.files)

    d = tmp_path / "out"
    shutil.copytree(outdir, d)
    # a planted pickle that would leave a file behind if anything unpickled it
    marker = tmp_path / "pwned"

    class Payload:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    (d / ".mc-cache" / "mc-planted.pkl").write_bytes(pickle.dumps(Payload()))

    def refuse(*a, **k):
        raise AssertionError("pickle used")

    for name in ("load", "loads", "dump", "dumps"):
        monkeypatch.setattr(pickle, name, refuse)
    res = run_figure(3, d, preset="quick")  # Fig. 3 is Fig. 2's first case: its Monte Carlo comes from the cache
    assert res.status == "finished"
    assert all(case["mc"]["cached"] for case in res.sidecar["cases"].values())
    assert not marker.exists()
    assert [p.name for p in d.rglob("*.pkl")] == ["mc-planted.pkl"]


def _fonts_and_axes(fig):
    from matplotlib.text import Text

    sizes = [t.get_fontsize() for t in fig.findobj(Text) if t.get_text().strip()]
    return sizes, fig.axes


def test_figures_are_readable_joint_colour_bar_labelled_beside_the_panels(outdir, tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from vibro.studies.figures import run_figure

    drawn = []
    real = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **k: (drawn.append(self), real(self, *a, **k))[1])
    d = tmp_path / "out"
    shutil.copytree(outdir, d)
    assert run_figure(3, d, preset="quick").status == "finished"   # joint, Monte Carlo from the cache
    assert run_figure(2, d, preset="quick", force=True).status == "finished"  # energy
    joint, energy = drawn
    for fig in (joint, energy):
        sizes, _ = _fonts_and_axes(fig)
        assert min(sizes) >= 9.0
        caption = fig.texts[0].get_text()
        assert "A new type of bilateral vibro-impact model: random vibration analysis" in caption.replace("\n", " ")
        assert "docs/paper-readings.md" in caption.replace("\n", " ")
    *panels, bar = joint.axes
    assert bar.get_ylabel() == "joint density p(x, y)"
    gap_in = (bar.get_position().x0 - panels[-1].get_position().x1) * joint.get_figwidth()
    assert 0 < gap_in < 0.3
