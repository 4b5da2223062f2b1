"""Example 1's fpk spectrum of x against the stored Monte Carlo reference (issue 26: L1 of the normalised spectrum
within 2 %, peak frequency within 0.5 %).

The reference (benchmarks/spectrum_reference.py, benchmarks/data/spectrum_reference.npz and .json) is Welch over
8192 paths of 4000 time units at each of dt = 0.01 and 0.005 (splitting, independent seeds), Hann segments of
409.6 time units: its expected L1 noise over [0, 6] is 0.0015 pooled, the two steps differ by 0.0028 where their
noise alone gives 0.0031, and the window's own bias is about 0.0005 in L1.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from averaging.phase_plane import spectrum_fpk
from averaging.phase_plane.spectrum import _half_power_width, fitted_peak
from models import DuffingImpact, Ma

DATA = Path(__file__).resolve().parent.parent / "benchmarks" / "data"


def reference(every_far, every_near):
    ref = np.load(DATA / "spectrum_reference.npz")
    omega = ref["omega"]
    idx = np.arange(len(omega))
    pick = (omega <= 6.0) & ((idx % every_far == 0) | ((omega >= 0.95) & (omega <= 1.35) & (idx % every_near == 0)))
    return omega[pick], ref["S"][pick], float(ref["variance"])


def compare(grid, every_far, every_near):
    w, mc, var = reference(every_far, every_near)
    s = spectrum_fpk(DuffingImpact(restitution=Ma(vc=0.4)), "x", omega=w, grid=grid)
    l1 = np.trapezoid(np.abs(s.S - mc), w) / np.trapezoid(mc, w)
    return s, w, mc, var, l1


def test_the_stored_reference_is_converged_to_well_below_the_goal():
    summary = json.loads((DATA / "spectrum_reference.json").read_text())
    assert summary["pooled_l1_noise"] < 0.0025  # an eighth of the 2 % goal
    # the step bias is below the noise: the two steps differ by what their noise gives
    assert summary["l1_between_steps"] < 1.5 * summary["l1_between_steps_expected_from_noise"]
    assert [r["dt"] for r in summary["runs"]] == [0.01, 0.005]
    assert len({r["seed"] for r in summary["runs"]}) == 2


def test_fpk_on_a_coarse_grid_meets_the_monte_carlo_spectrum_of_example_1():
    # 40 x 48 at 59 frequencies (2.6 s of CPU): measured L1 0.0093, peak -0.13 %
    s, w, mc, var, l1 = compare((40, 48), 8, 2)
    assert l1 < 0.02, l1
    assert abs(fitted_peak(w, s.S) / fitted_peak(w, mc) - 1) < 0.005
    assert abs(s.variance / var - 1) < 0.003  # measured -0.04 %; the two steps' variances differ by 0.03 %


@pytest.mark.slow
def test_fpk_on_the_default_grid_meets_the_monte_carlo_spectrum_of_example_1():
    # 80 x 96 (the default) at 118 frequencies, about 26 s of CPU: measured L1 0.0035 (the reference's noise alone gives
    # about 0.0015), peak -0.11 %, bandwidth -1 %
    s, w, mc, var, l1 = compare((80, 96), 4, 1)
    assert l1 < 0.02, l1
    assert abs(fitted_peak(w, s.S) / fitted_peak(w, mc) - 1) < 0.005
    width = _half_power_width(w, s.S, int(np.argmax(s.S)))
    assert abs(width / _half_power_width(w, mc, int(np.argmax(mc))) - 1) < 0.03
    assert abs(s.variance / var - 1) < 0.003
    assert abs(np.trapezoid(s.S, w) / s.variance - 1) < 0.002
