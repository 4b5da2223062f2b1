"""``solve`` rates the forced and the coloured fpk solvers: it picks them, holds tol with their estimates, and the
result is within tol of an independent answer.

Oracles: the linear oscillator without walls under harmonic plus white forcing (every section is Gaussian with the
periodic response as mean and variance D / c, so 2 c H / D is noncentral chi-square with 2 degrees of freedom and
the time-averaged p(H) its average over the period); the linear oscillator under OU noise (the Lyapunov Gaussian);
the stored Monte Carlo of example 10's OU-filtered Duffing (benchmarks/data/fpk_coloured_mc.npz, noise 0.0004) and,
slow, of example 08's forced Duffing (benchmarks/data/fpk_forced_mc.npz, noise 0.0022 per phase).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, linalg, special
from scipy.stats import ncx2

from hybrid.errors import ModelError
from models import DuffingImpact, ImpactOscillator
from models.excitation import bandpass_filter, ou_filter
from vibro.solve import solve

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

A_, C_, W_, D_ = 0.4, 0.5, 1.3, 0.05
RESPONSE = A_ / (1.0 - W_**2 + 1j * C_ * W_)


def _linear_forced():
    return ImpactOscillator("x", "c*y", forcing="A*cos(W*t)", barriers=None,
                            parameters={"c": C_, "A": A_, "W": W_, "D": D_})


def _exact_section(t, edges):
    xp, yp = (RESPONSE * np.exp(1j * W_ * t)).real, (1j * W_ * RESPONSE * np.exp(1j * W_ * t)).real
    return np.diff(ncx2.cdf(2.0 * edges * C_ / D_, 2, (xp**2 + yp**2) * C_ / D_))


def test_solve_picks_the_forced_fpk_and_meets_tol_against_the_closed_form():
    tol = 0.05
    sol = solve(_linear_forced(), tol)
    assert sol.method == "fpk" and sol.choice.settings["scheme"] == "forced"
    assert "cells" in sol.estimate_source and "time steps" in sol.estimate_source
    assert sol.estimated_error <= tol
    # the time average of the exact sections, on solve's own bins (the period sampled at 64 times: the sections
    # are smooth in t, so the trapezoid rule on a period is spectrally accurate)
    T = 2.0 * np.pi / W_
    exact = np.mean([_exact_section(t, sol.edges) for t in T * np.arange(64) / 64], axis=0)
    true = float(np.abs(sol.masses - exact).sum())
    assert true <= tol and true <= sol.estimated_error
    # per phase: the worst of 4 sections is held to tol too
    phased = solve(_linear_forced(), tol, phases=4)
    sections = phased.result.sections(4)
    worst = max(float(np.abs(s.bin_masses(phased.edges) - _exact_section(t, phased.edges)).sum())
                for t, s in zip(phased.result.phase_times(4), sections))
    assert worst <= phased.estimated_error <= tol


def test_solve_picks_the_coloured_fpk_and_meets_tol_against_the_lyapunov_gaussian():
    c, D, alpha, tol = 0.5, 0.25, 2.0, 0.05
    lin = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None, name="linear")
    sol = solve(ou_filter(lin, alpha=alpha), tol)
    assert sol.method == "fpk" and sol.choice.settings["scheme"] == "coloured"
    A = np.array([[0.0, 1.0, 0.0], [-1.0, -c, 1.0], [0.0, 0.0, -alpha]])
    S = linalg.solve_continuous_lyapunov(A, -np.diag([0.0, 0.0, 2 * alpha**2 * D]))
    vx, vy = S[0, 0], S[1, 1]
    a, b = 0.5 * (1 / vx + 1 / vy), 0.5 * (1 / vx - 1 / vy)
    e = sol.edges
    exact = np.array([integrate.quad(lambda H: np.exp(-H * a) * special.i0(H * b) / np.sqrt(vx * vy), e[i],
                                     e[i + 1])[0] for i in range(len(e) - 1)])
    true = float(np.abs(sol.masses - exact).sum())
    assert sol.estimated_error <= tol and true <= tol


def test_solve_on_example_10s_ou_duffing_is_within_tol_of_monte_carlo():
    from benchmarks.fpk_coloured import mc_reference, model

    tol = 0.05
    sol = solve(model(), tol)
    assert sol.method == "fpk" and sol.choice.settings["scheme"] == "coloured"
    edges, ref, noise = mc_reference()
    l1 = float(np.abs(sol.result.bin_masses(edges) - ref).sum())
    assert noise < 0.001 and l1 + noise <= tol and sol.estimated_error <= tol


def test_solve_refuses_a_band_pass_filter_in_one_line():
    with pytest.raises(ModelError, match="4-D.*vibro mc"):
        solve(bandpass_filter(DuffingImpact(), zeta=0.5, omega_f=1.0), 0.05)


def test_forced_escalation_refines_the_part_that_misses_and_the_start_fits_in_memory():
    from hybrid.sizes import MAX_MEMORY
    from models import ForcedDuffingImpact
    from vibro.solve.choice import forced_choice
    from vibro.solve.solver import _escalate

    start = forced_choice(ForcedDuffingImpact(), 0.05)
    assert (start.settings["grid"], start.settings["steps"]) == ((30, 60), 16)
    cells = _escalate(start, 0.031, 0.02, (0.03, 0.001)).settings  # the cells miss: finer cells, same steps
    steps = _escalate(start, 0.031, 0.02, (0.001, 0.03)).settings  # the time steps miss: more steps, same cells
    both = _escalate(start, 0.031, 0.02, (0.016, 0.015)).settings
    assert cells["steps"] == 16 and cells["grid"][0] > 30
    assert steps["grid"] == (30, 60) and steps["steps"] == 32
    assert both["grid"][0] > 30 and both["steps"] == 32
    tight = forced_choice(ForcedDuffingImpact(), 0.001).settings  # (80, 160) at 64 steps would be refused
    g, k = tight["grid"], tight["steps"]
    assert g[0] * g[1] * 3500 * (k // 2 + 1) * 3 * 1.25 <= MAX_MEMORY


@pytest.mark.slow
def test_solve_on_example_08_meets_tol_against_monte_carlo():
    from benchmarks.fpk_forced import duffing, mc_reference

    edges, ref, noise = mc_reference("0.02")  # (16 phases, 40 bins of [0, 4])
    for tol in (0.05, 0.01):
        sol = solve(duffing(0.02), tol)
        assert sol.method == "fpk" and sol.estimated_error <= tol
        mean = float(np.abs(sol.result.mean.bin_masses(edges) - ref.mean(axis=0)).sum())
        assert mean <= tol


def test_cli_solve_filter_ou_and_forced_dry_run(tmp_path, capsys):
    from vibro.cli import main

    out = tmp_path / "p.csv"
    rc = main(["solve", "--filter", "ou", "--param", "alpha=1", "--param", "c=0.2", "--param", "D=0.1", "--param",
               "delta=0.6", "--restitution", "newton:e=0.8", "--tol", "0.05", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and out.exists() and "method: fpk" in text and "coloured fpk on" in text
    rc = main(["solve", "--model", "duffing-forced", "--param", "D=0.02", "--tol", "0.05", "--dry-run"])
    text = capsys.readouterr().out
    assert rc == 0 and "method: fpk" in text and "scheme=forced" in text
    assert main(["solve", "--filter", "ou", "--phases", "4", "--tol", "0.05"]) == 2  # one line, no run
