"""``vibro plot``: every kind of CSV the project writes becomes a readable PNG; anything else is a one-line error."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from matplotlib.text import Text

from hybrid.stochastic import EnsembleStatistics
from vibro.cli import main
from vibro.studies.plots import kind_of, plot_files

PNG = b"\x89PNG\r\n\x1a\n"


def _is_png(path):
    return path.read_bytes()[:8] == PNG and path.stat().st_size > 5_000


def _fonts(fig):
    return [t.get_fontsize() for t in fig.findobj(Text) if t.get_text().strip()]


def _mc_stats(rng, with_joint=True):
    """A Monte Carlo result with made-up counts, written by the project's own writers (no kernel needed)."""
    settings = {"h_max": 4.0, "bins": 40, "xy_bins": [20, 16] if with_joint else None, "v_max": 4.0, "v_bins": 10,
                "seed": 1, "t_sample": 1.0, "chunk_paths": 1, "xy_range": [[-1.0, 1.0], [-2.8, 2.8]]}
    s = EnsembleStatistics.empty(settings)
    h = np.linspace(0.05, 3.95, 40)
    s.h_counts[:] = rng.poisson(1e4 * np.exp(-2 * h))
    if with_joint:
        x, y = np.meshgrid(np.linspace(-0.95, 0.95, 20), np.linspace(-2.6, 2.6, 16))
        s.xy_counts[:] = rng.poisson(1e3 * np.exp(-(y**2 / 2 + x**2) * 2))
    return s


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(3)
    H = np.linspace(0, 4, 200)
    pd.DataFrame({"H": H, "p": 2 * np.exp(-2 * H)}).to_csv(tmp_path / "p.csv", index=False)
    (tmp_path / "p.json").write_text(json.dumps({"model": {"G_delta": 0.55, "params": {"delta": 1.0}}}))
    s = _mc_stats(rng)
    s.to_csv(tmp_path / "h.csv")
    (tmp_path / "joint_mc.csv").write_text(s.joint_to_pandas().to_csv(index=False))
    x, y = np.meshgrid(np.linspace(-1, 1, 31), np.linspace(-2.8, 2.8, 31))
    pd.DataFrame({"x": x.ravel(), "y": y.ravel(), "p": np.exp(-(y.ravel()**2 / 2 + x.ravel()**2))}).to_csv(
        tmp_path / "joint.csv", index=False)
    t = np.arange(1, 9, dtype=float)
    hm = 2.4 * 0.9 ** t
    pd.DataFrame({"t": t, "x": np.where(t % 2, 1.0, -1.0), "v_minus": np.sqrt(2 * (hm - 0.55)), "v_plus": -0.9,
                  "e": 0.9, "H_minus": hm, "H_plus": 0.9 * hm, "barrier": "right"}).to_csv(tmp_path / "imp.csv",
                                                                                       index=False)
    tt = np.linspace(0, 10, 101)
    pd.DataFrame({"t": np.tile(tt, 2), "path": np.repeat([0, 1], 101), "x": np.sin(np.r_[tt, tt + 1]),
                  "y": np.cos(np.r_[tt, tt + 1])}).to_csv(tmp_path / "paths.csv", index=False)
    return tmp_path


def test_kinds_are_recognised_by_columns_of_the_project_writers(files):
    kinds = {f: kind_of(pd.read_csv(files / f, nrows=1).columns)
             for f in ("p.csv", "h.csv", "joint.csv", "joint_mc.csv", "imp.csv", "paths.csv")}
    assert kinds == {"p.csv": "energy", "h.csv": "energy-histogram", "joint.csv": "joint",
                     "joint_mc.csv": "joint-histogram", "imp.csv": "impacts", "paths.csv": "paths"}


def test_energy_files_compared_on_linear_and_log_panels_with_g_delta(files):
    out = files / "e.png"
    fig = plot_files([files / "p.csv", files / "h.csv"], out, labels=["averaging", "Monte Carlo"])
    assert _is_png(out)
    lin, log = fig.axes
    assert (lin.get_yscale(), log.get_yscale()) == ("linear", "log")
    assert [t.get_text() for t in lin.get_legend().get_texts()] == ["averaging", "Monte Carlo"]
    # G(Δ) = 0.55 from p.json (the histogram has no sidecar): one dotted line per panel and one label
    for ax in (lin, log):
        assert [ln.get_xdata()[0] for ln in ax.get_lines() if ln.get_linestyle() == ":"] == [0.55]
    assert [t.get_text() for t in lin.texts] == ["G(Δ)"]
    assert min(_fonts(fig)) >= 9


def test_barrier_energy_option_overrides_the_sidecar(files):
    fig = plot_files([files / "h.csv"], None, barrier_energy=0.7)
    assert [ln.get_xdata()[0] for ln in fig.axes[0].get_lines() if ln.get_linestyle() == ":"] == [0.7]


def test_joint_densities_contours_labelled_colour_bar_and_barriers(files):
    out = files / "j.png"
    fig = plot_files([files / "joint.csv", files / "joint_mc.csv"], out, barriers=(-1.0, 1.0))
    assert _is_png(out)
    *panels, bar = fig.axes
    assert len(panels) == 2 and bar.get_ylabel() == "joint density p(x, y)"
    for ax in panels:
        assert ax.collections  # filled contours
        walls = [ln.get_xdata()[0] for ln in ax.get_lines()]
        assert walls == [-1.0, 1.0]
        assert ax.get_xlim()[0] < -1.0 and ax.get_xlim()[1] > 1.0  # the walls are inside the frame
    gap_in = (bar.get_position().x0 - panels[-1].get_position().x1) * fig.get_figwidth()
    assert 0 < gap_in < 0.4  # beside the panel, not at the edge of the figure
    assert min(_fonts(fig)) >= 9


def test_joint_barriers_from_the_sidecar(files):
    (files / "joint.json").write_text(json.dumps({"parameters": {"delta": 0.8}}))
    fig = plot_files([files / "joint.csv"], None)
    assert [ln.get_xdata()[0] for ln in fig.axes[0].get_lines()] == [-0.8, 0.8]


def test_impact_log_energy_against_time_and_impact_speeds(files):
    out = files / "i.png"
    fig = plot_files([files / "imp.csv"], out, barrier_energy=0.55)
    assert _is_png(out)
    left, right = fig.axes
    assert (left.get_xlabel(), left.get_ylabel()) == ("time t", "energy H")
    assert right.get_ylabel() == "impact speed |v-|"
    speeds = right.get_lines()[0].get_ydata()
    assert np.all(speeds > 0) and len(speeds) == 8
    assert min(_fonts(fig)) >= 9


def test_sample_paths_one_line_per_path(files):
    out = files / "s.png"
    fig = plot_files([files / "paths.csv"], out)
    assert _is_png(out)
    assert len(fig.axes[0].get_lines()) == 2 and len(fig.axes[1].get_lines()) == 2


def test_cli_writes_png_atomically_and_nothing_else(files, capsys):
    out_dir = files / "out"
    out_dir.mkdir()
    assert main(["plot", str(files / "p.csv"), str(files / "h.csv"), "--out", str(out_dir / "cmp.png")]) == 0
    assert sorted(p.name for p in out_dir.iterdir()) == ["cmp.png", "cmp.png.json"]  # the picture and its record
    assert _is_png(out_dir / "cmp.png")


@pytest.mark.parametrize("content, needle", [
    ("a,b\n1,2\n", "columns a,b match no known output"),
    ("H,p\n", "no rows to plot"),
])
def test_cli_unknown_columns_exit_2_with_one_line(tmp_path, capsys, content, needle):
    f = tmp_path / "x.csv"
    f.write_text(content)
    assert main(["plot", str(f), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.strip().count("\n") == 0
    assert not (tmp_path / "x.png").exists()


def test_cli_mixed_kinds_and_missing_file_exit_2(files, capsys):
    assert main(["plot", str(files / "p.csv"), str(files / "imp.csv"), "--out", str(files / "m.png")]) == 2
    assert "cannot draw different kinds" in capsys.readouterr().err
    assert main(["plot", str(files / "nope.csv"), "--out", str(files / "m.png")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["plot", str(files / "p.csv"), "--label", "a", "--label", "b", "--out", str(files / "m.png")]) == 2
    assert "labels for 1 files" in capsys.readouterr().err


def test_real_pdf_outputs_plot(tmp_path, capsys):
    # the files exactly as `vibro pdf` writes them
    p, j = tmp_path / "p.csv", tmp_path / "j.csv"
    assert main(["pdf", "--param", "delta=1.0", "--restitution", "ma:vc=0.4", "--points", "200", "--out", str(p),
                 "--joint", str(j), "--joint-points", "21"]) == 0
    assert main(["plot", str(p), "--out", str(tmp_path / "p.png"), "--barrier-energy", "0.55"]) == 0
    assert main(["plot", str(j), "--out", str(tmp_path / "j.png"), "--barriers", "-1", "1"]) == 0
    assert _is_png(tmp_path / "p.png") and _is_png(tmp_path / "j.png")
    import json

    # the picture's own record (PNG.json, apart from p.json of the CSV it draws) holds the record of its input
    drawn = json.loads((tmp_path / "p.png.json").read_text())
    assert drawn["kind"] == "plot"
    assert drawn["results"]["inputs"][str(p)] == json.loads((tmp_path / "p.json").read_text())
    # the joint CSV has its own sidecar: the barriers are found without --barriers
    from vibro.studies.plots import read_table

    assert read_table(j).barriers == (-1.0, 1.0) and read_table(j).barrier_energy == pytest.approx(0.55)
    assert main(["plot", str(j), "--out", str(tmp_path / "j2.png")]) == 0 and _is_png(tmp_path / "j2.png")
