"""Example 1's first passage by fpk against the stored Monte Carlo reference (issue 26).

The reference (``benchmarks/data/first_passage_reference.json``, made by ``benchmarks/first_passage_reference.py``)
is event-exact Monte Carlo with the continuity-corrected level at two time steps, 120,000-320,000 paths per level,
95 % CI 0.31-0.47 % (docs/results/first-passage-spectra.md has the table). Its runs read the level on states whose
position and velocity belong to one instant; the reference before (118.84 +- 0.59 at H_c = 2) read it on the
splitting's half-kicked states and was 1 % low there. fpk is judged on a coarse grid
with its own error estimate (half the rings, half the angles): the tolerance is that estimate plus the reference's
CI, no more.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from averaging.phase_plane import first_passage_fpk
from models import DuffingImpact, Ma

REFERENCE = Path(__file__).resolve().parent.parent / "benchmarks" / "data" / "first_passage_reference.json"


@pytest.fixture(scope="module")
def reference():
    return json.loads(REFERENCE.read_text())["levels"]


def example1():
    return DuffingImpact(restitution=Ma(vc=0.4))


def test_the_reference_is_converged_in_the_time_step_and_holds_about_one_percent(reference):
    assert set(reference) == {"0.25", "0.5", "1.0", "1.5", "2.0"}
    for level, row in reference.items():
        assert row["relative_ci95"] <= 0.0125, (level, row["relative_ci95"])
        assert len(row["steps"]) >= 2
        differences = row["step_differences"].values()
        # pooled over the steps only where every step agrees with the finest within their CI (the corrected level
        # leaves O(dt)); else the finest step alone is the reference
        assert row["pooled_over_steps"] == all(abs(d) <= ci for d, ci in differences)
        finest = min(row["steps"], key=float)
        if not row["pooled_over_steps"]:
            assert row["mean"] == row["steps"][finest]["mean"]
        # the survival curve stored beside it counts every path of the steps it uses
        assert row["survival"]["paths"] == sum(row["steps"][str(dt)]["paths"] for dt in row["reference_steps"])


def test_the_replicate_runs_scatter_as_their_intervals_say():
    # runs of one level and step are replicates: their chi2 about the pooled mean tests the CIs (measured 12.0 on 13
    # degrees of freedom); a larger scatter widens every CI by sqrt(chi2 / dof)
    scatter = json.loads(REFERENCE.read_text())["scatter_factor"]
    assert scatter["dof"] >= 5
    assert scatter["factor"] == max(1.0, (scatter["chi2"] / scatter["dof"]) ** 0.5)


# at H_c = 2.0 fpk on 60x64 (120.93) is 0.8 % above the reference (120.00 +- 0.38), within its estimate (1.57: 0.61
# from half the rings, 0.97 from half the angles); its converged answer (120.27) is 0.2 % above
@pytest.mark.filterwarnings("ignore:grid 60 x 64")  # at 2.0 the 60x64 estimate exceeds 1 %, as said above
@pytest.mark.parametrize("level", ["0.25", "0.5", "1.0", "1.5", "2.0"])
def test_fpk_mean_first_passage_time_meets_the_monte_carlo_reference(reference, level):
    row = reference[level]
    r = first_passage_fpk(example1(), f"H < {level}", grid=(60, 64), check=True, survival=False)
    assert abs(r.mean_time - row["mean"]) <= r.error_estimate + row["ci95"], (r.mean_time, r.error_estimate, row)


def test_fpk_survival_meets_the_kaplan_meier_curve_within_0_005(reference):
    # H_c = 0.25: 160,000 paths (Wilson half-width at most 0.0025); measured sup |R_fpk - R_mc| = 0.0013 on 60 x 64
    sv = reference["0.25"]["survival"]
    t, R, lo, hi = (np.array(sv[k]) for k in ("t", "R", "R_lo", "R_hi"))
    r = first_passage_fpk(example1(), "H < 0.25", grid=(60, 64), check=False, t_max=float(t[-1]), steps=2000)
    gap = np.abs(r.survival(t) - R)
    assert gap.max() <= 0.005, gap.max()
    # beyond the Monte Carlo's own interval by at most the survival's grid error (60 x 64 against 30 x 32: 1e-3)
    assert np.max(gap - (hi - lo) / 2) <= 1.5e-3


@pytest.mark.slow
def test_fpk_at_its_default_grid_meets_the_reference_at_hard_impacts(reference):
    # 120 x 128 (the default), with its estimate: 120.85 +- 0.66 against 120.00 +- 0.38 (+0.71 %; it was marked
    # xfail against the reference read on half-kicked states, 118.84 +- 0.59)
    row = reference["2.0"]
    r = first_passage_fpk(example1(), "H < 2.0", check=True, survival=False)
    assert abs(r.mean_time - row["mean"]) <= r.error_estimate + row["ci95"], (r.mean_time, r.error_estimate, row)


@pytest.mark.slow
@pytest.mark.parametrize("level", ["0.5", "1.0", "1.5", "2.0"])
def test_fpk_survival_meets_the_kaplan_meier_curves_at_higher_levels(reference, level):
    # 120,000-320,000 paths (Wilson half-width at most 0.0028 / 0.0028 / 0.0028 / 0.0017); sup |R_fpk - R_mc| on
    # 60 x 64 measured 0.0029 / 0.0044 / 0.0029 / 0.0031 (benchmarks/data/first_passage_survival.json). At 2.0 it
    # was 0.0079 against the reference read on half-kicked states (a strict xfail then)
    sv = reference[level]["survival"]
    t, R, lo, hi = (np.array(sv[k]) for k in ("t", "R", "R_lo", "R_hi"))
    r = first_passage_fpk(example1(), f"H < {level}", grid=(60, 64), check=False, t_max=float(t[-1]), steps=2000)
    assert np.max(np.abs(r.survival(t) - R)) <= 0.005
