"""Ensemble statistics at fixed times from a given start (issue 25, item 4), against the exact moments of the
linear oscillator: the second moments from rest solve a linear ODE, integrated exactly by a matrix exponential."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from hybrid.errors import ParameterError
from hybrid.stochastic import simulate_snapshots
from models import ImpactOscillator
from vibro.cli import main


def exact_mean_energy(c: float, D: float, t: float) -> float:
    """E[H](t) of x'' + c x' + x = sqrt(2D) xi from rest: (E x^2, E x y, E y^2)' = A m + (0, 0, 2D)."""
    generator = np.zeros((4, 4))
    generator[:3, :3] = [[0, 2, 0], [-1, -c, 1], [0, -2, -2 * c]]
    generator[2, 3] = 2 * D
    exx, _, eyy = (expm(generator * t) @ [0.0, 0.0, 0.0, 1.0])[:3]
    return 0.5 * (exx + eyy)


def test_linear_oscillator_from_rest_meets_its_exact_mean_energy():
    c, D = 0.2, 0.1
    m = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    snap = simulate_snapshots(m, "splitting", dt=0.01, paths=2000, t_end=12.0, snapshots=3, x0=(0.0, 0.0), seed=3,
                              histograms={"H": (0.0, 4.0, 40)}, chunk_paths=125)
    assert np.allclose(snap.times, [4.0, 8.0, 12.0])
    table = snap.to_pandas()
    assert list(table["samples"]) == [2000] * 3  # every path counted once at every time
    for j, t in enumerate(snap.times):
        est, exact = snap.mean("H", j), exact_mean_energy(c, D, t)
        # splitting's weak bias at dt = 0.01 is ~1e-4 here, far below the CI (~0.01)
        assert abs(est.value - exact) <= 3 * est.ci, (t, est, exact)
        assert est.ci < 0.2 * exact  # the check has power: the CI is small against the signal
    hist = snap.histograms_to_pandas()
    inside = hist[np.isfinite(hist["density"])]
    for t, group in inside.groupby("t"):  # each time's histogram holds every path (none fell outside [0, 4])
        assert hist[hist.t == t]["count"].sum() == 2000
        assert np.sum(group["density"] * (group["hi"] - group["lo"])) == pytest.approx(1.0, abs=0.01)


def test_snapshot_requests_are_checked():
    m = ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.1}, barriers=None)
    with pytest.raises(ParameterError, match="snapshots"):
        simulate_snapshots(m, dt=0.01, paths=8, t_end=1.0, snapshots=0, x0=(0.0, 0.0))
    with pytest.raises(ParameterError, match="t_burn"):
        simulate_snapshots(m, dt=0.01, paths=8, t_end=1.0, snapshots=2, x0=(0.0, 0.0), t_burn=0.5)


@pytest.mark.parametrize("extra, words", [(["--t-burn", "3"], "drop --t-burn 3"),
                                          (["--phases", "4"], "give one of them")])
def test_snapshots_on_the_command_line_refuse_contradictions(tmp_path, capsys, extra, words):
    out = tmp_path / "s.csv"
    assert main(["mc", "--snapshots", "4", *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]
    assert list(tmp_path.iterdir()) == []
