"""Example 1's first passage by fpk against the stored Monte Carlo reference (issue 26).

The reference (``benchmarks/data/first_passage_reference.json``, made by ``benchmarks/first_passage_reference.py``)
is event-exact Monte Carlo with the continuity-corrected level at two or three time steps, 24,000-160,000 paths per
level, 95 % CI 0.36-0.74 % (docs/results/first-passage-spectra.md has the table). fpk is judged on a coarse grid
with its own two-grid error estimate: the tolerance is that estimate plus the reference's CI, no more.
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


# at H_c = 2.0 fpk on 60x64 (120.93) passes by its large two-grid estimate (2.34, against 30x32: 118.59); 240x256
# (120.61) is +1.3 % from the reference (119.03 +- 0.77, three steps agreeing)
@pytest.mark.filterwarnings("ignore:grid 60 x 64")  # at 2.0 the 60x64 estimate exceeds 1 %, as said above
@pytest.mark.parametrize("level", ["0.25", "0.5", "1.0", "1.5", "2.0"])
def test_fpk_mean_first_passage_time_meets_the_monte_carlo_reference(reference, level):
    row = reference[level]
    r = first_passage_fpk(example1(), f"H < {level}", grid=(60, 64), check=True, survival=False)
    assert abs(r.mean_time - row["mean"]) <= r.error_estimate + row["ci95"], (r.mean_time, r.error_estimate, row)


def test_fpk_survival_meets_the_kaplan_meier_curve_within_0_005(reference):
    # H_c = 0.25: 160,000 paths (Wilson half-width at most 0.0025); measured sup |R_fpk - R_mc| = 0.0028 on 60 x 64
    sv = reference["0.25"]["survival"]
    t, R, lo, hi = (np.array(sv[k]) for k in ("t", "R", "R_lo", "R_hi"))
    r = first_passage_fpk(example1(), "H < 0.25", grid=(60, 64), check=False, t_max=float(t[-1]), steps=2000)
    gap = np.abs(r.survival(t) - R)
    assert gap.max() <= 0.005, gap.max()
    # beyond the Monte Carlo's own interval by at most the survival's grid error (60 x 64 against 30 x 32: 1e-3)
    assert np.max(gap - (hi - lo) / 2) <= 1.5e-3
