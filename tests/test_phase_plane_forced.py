"""The forced phase-plane solver (``fpk`` for a periodically forced model) against closed forms and exact limits.

Oracles: the linear oscillator without walls under harmonic plus white forcing (every section is Gaussian, mean =
the periodic response, variance = D / (c w0**2)); the unforced limit with elastic walls (the Gibbs density, and the
autonomous solver's own answer); the half-period symmetry of a symmetric model. The comparison with Monte Carlo is
``benchmarks/fpk_forced.py`` (and the slow test at the end).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from problems import elastic_duffing

from averaging.phase_plane import solve_phase_plane
from averaging.phase_plane.forced import periodic_density_xy, unforced
from hybrid.errors import ModelError, NormalisationError, ParameterError
from models import Elastic, ForcedDuffingImpact, ImpactOscillator, Newton
from vibro.cli import main


def _linear(A=0.4, c=0.5, W=1.3, D=0.05):
    return ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t)", barriers=None,
                            parameters={"c": c, "w0": 1.0, "W": W, "A": A, "D": D})


def _section_errors(sol, A=0.4, c=0.5, W=1.3, D=0.05):
    """Largest relative error of the section means (of x and y, relative to their amplitudes) and variances."""
    z = A / (1.0 - W**2 + 1j * c * W)
    var = D / c  # w0 = 1: Var x = D / (c w0**2) = Var y
    err_mean, err_var = 0.0, 0.0
    for t, s in zip(sol.phase_times(8), sol.sections(8)):
        mx, my = s.cell_mass @ s.cell_x, s.cell_mass @ s.cell_y
        err_mean = max(err_mean, abs(mx - (z * np.exp(1j * W * t)).real) / abs(z),
                       abs(my - (1j * W * z * np.exp(1j * W * t)).real) / abs(W * z))
        err_var = max(err_var, abs((s.cell_mass @ s.cell_x**2 - mx**2) / var - 1.0),
                      abs((s.cell_mass @ s.cell_y**2 - my**2) / var - 1.0))
    return err_mean, err_var


def test_linear_forced_sections_are_the_gaussian_of_the_periodic_response():
    # Measured (benchmarks/fpk_forced.py): 3.1e-2 / 2.9e-2 at (60, 64) with 32 steps, 1.3e-2 / 8e-3 at (120, 128)
    # with 64 steps; the goal of 1e-3 is not reached at these grids (the discretisation error of a density that
    # moves across the rings, see docs/results/fpk-forced.md). The bounds hold the measured error with a margin of
    # 1.3 and the refinement must reduce it.
    coarse = periodic_density_xy(_linear(), grid=(40, 48), steps=16, h_max=3.0, phases=8)
    fine = periodic_density_xy(_linear(), grid=(60, 64), steps=32, h_max=3.0, phases=8)
    m_c, v_c = _section_errors(coarse)
    m_f, v_f = _section_errors(fine)
    assert m_f < 0.04 and v_f < 0.04
    assert m_f < 0.6 * m_c and v_f < 0.6 * v_c
    assert fine.conservation < 1e-12 and fine.periodicity < 1e-8
    assert fine.impact_rate == 0.0


def test_extrapolation_removes_the_leading_grid_error():
    # E[H | t] of the linear oscillator is D/c + (x_p**2 + y_p**2) / 2 exactly. The Richardson combination of
    # (60, 64) and (30, 32) removes the grid's leading error, not the time steps' (the same 32 for both): measured
    # 3.1e-2 -> 2.7e-2 here, 1.35e-2 -> 1.09e-2 at (120, 128) with 64 steps; against Monte Carlo on example 08 it
    # takes the L1 of p(H | t) from 0.024 to 0.009 (the slow test below)
    A, c, W, D = 0.4, 0.5, 1.3, 0.05
    z = A / (1.0 - W**2 + 1j * c * W)
    sol = periodic_density_xy(_linear(), grid=(60, 64), steps=32, h_max=3.0, phases=8, extrapolate=True)
    t = sol.phase_times(8)
    exact = D / c + 0.5 * (np.real(z * np.exp(1j * W * t)) ** 2 + np.real(1j * W * z * np.exp(1j * W * t)) ** 2)
    err = np.max(np.abs(sol.mean_energy_at(t) / exact - 1.0))
    err_fine = np.max(np.abs(sol.fine.mean_energy_at(t) / exact - 1.0))
    assert err < 0.9 * err_fine
    section = sol.section(t[3])
    fine, coarse = sol.fine.section(t[3]), sol.coarse.section(t[3])
    edges = np.linspace(0.0, 3.0, 31)
    assert np.allclose(section.bin_masses(edges), (4 * fine.bin_masses(edges) - coarse.bin_masses(edges)) / 3)
    assert section.bin_masses([0.0, 3.0])[0] == pytest.approx(1.0, abs=1e-9)
    assert section.mean_energy == pytest.approx(sol.mean_energy_at(t[3])[0], rel=1e-9)


def test_without_forcing_the_sections_are_the_stationary_gibbs_density():
    # A = 0 keeps the model forced (its equations name t) but every section is the stationary density: with elastic
    # walls the Gibbs density exp(-c H / D), which the autonomous solver reproduces to 2e-4 in L1 at this grid
    model, ex = elastic_duffing(delta=1.0, c=0.1, D=0.05)
    forced = ImpactOscillator("a*x + b*x**3", "c*y", forcing="A*cos(W*t)", restitution=Elastic(),
                              parameters={**model.params, "A": 0.0, "W": 1.2})
    h_max = 6.0
    sol = periodic_density_xy(forced, grid=(120, 128), steps=8, h_max=h_max)
    auto = solve_phase_plane(unforced(forced), grid=(120, 128), h_max=h_max)
    assert sol.factors == 1
    assert np.max(np.abs(sol.cell_p - auto.cell_p)) < 1e-8 * np.max(auto.cell_p)
    edges = np.linspace(0.0, h_max, 101)
    cdf = np.array([ex.probability_below(h) for h in edges]) / ex.probability_below(h_max)
    for t in (0.0, 0.37 * sol.period):
        assert np.abs(sol.section(t).bin_masses(edges) - np.diff(cdf)).sum() < 1e-3
    assert sol.impact_rate == pytest.approx(auto.impact_rate, rel=1e-8)


def test_symmetric_forced_impacts_repeat_every_half_period():
    # walls at +-1, odd restoring force and forcing cos: (x, y, t) -> (-x, -y, t + T/2) maps the problem onto itself,
    # so E[H | t] and the impact rate have period T/2 (the grid and the steps keep that symmetry)
    m = ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=0.02)
    sol = periodic_density_xy(m, grid=(40, 48), steps=16, h_max=4.0)
    half = len(sol.times) // 2
    assert np.allclose(sol.mean_energy_t[:half], sol.mean_energy_t[half:], rtol=1e-7)
    assert np.allclose(sol.impact_rate_t[:half], sol.impact_rate_t[half:], rtol=1e-6)
    assert sol.conservation < 1e-12
    assert np.all(sol.impact_rate_t > 0) and sol.impact_rate_t.max() > 3 * sol.impact_rate_t.min()
    # between the stored steps: the spline passes through them and stays normalised
    t = 0.5 * (sol.times[3] + sol.times[4])
    assert sol.section(t).ring_mass.sum() == pytest.approx(1.0, abs=1e-9)
    assert sol.mean_energy_at(sol.times[5])[0] == pytest.approx(sol.mean_energy_t[5], rel=1e-12)


def test_refusals():
    with pytest.raises(ModelError, match="no forcing"):
        periodic_density_xy(unforced(ForcedDuffingImpact()))
    aperiodic = ImpactOscillator("x", "c*y", forcing="A*cos(W*t) + A*cos(sqrt(2)*W*t)", barriers=None,
                                 parameters={"c": 0.1, "A": 0.1, "W": 1.0, "D": 0.05})
    with pytest.raises(ModelError, match="no period"):
        periodic_density_xy(aperiodic)
    with pytest.raises(ParameterError, match="steps"):
        periodic_density_xy(ForcedDuffingImpact(), steps=0)
    with pytest.raises(ParameterError, match="scheme"):
        periodic_density_xy(ForcedDuffingImpact(), scheme="rk4")
    # an h_max below the mass: refused from the unforced density, before any period map
    with pytest.raises(NormalisationError, match="does not decay"):
        periodic_density_xy(ForcedDuffingImpact(), grid=(40, 48), steps=8, h_max=1e-9)


def test_a_huge_h_max_puts_the_rings_where_the_mass_is():
    # h_max = 1e12 would put the whole density into the first ring; the rings are fitted to the energies the
    # unforced density reaches (doubled), and the answer is that of a moderate h_max
    m = ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=0.02)
    huge = periodic_density_xy(m, grid=(40, 48), steps=16, h_max=1e12)
    moderate = periodic_density_xy(m, grid=(40, 48), steps=16, h_max=huge.grid.h_max)
    assert huge.grid.h_max < 100 and huge.mean.h_max == 1e12
    assert huge.mean_energy == pytest.approx(moderate.mean_energy, rel=1e-12)


def test_cli_pdf_fpk_forced_writes_the_sections_of_vibro_mc(tmp_path, capsys):
    out = tmp_path / "p.csv"
    rc = main(["pdf", "--method", "fpk", "--model", "duffing-forced", "--param", "D=0.02", "--grid", "40", "48",
               "--steps", "16", "--phases", "4", "--bins", "40", "--xy-bins", "20", "20", "--out", str(out),
               "--joint", str(tmp_path / "j.csv"), "--joint-points", "41"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "E[H | t]" in text
    table = pd.read_csv(tmp_path / "p_phases.csv")
    assert list(table.columns) == ["observable", "phase", "t_phase", "lo", "hi", "density"]
    assert sorted(table.phase.unique()) == [0, 1, 2, 3]
    for (name, _k), rows in table.groupby(["observable", "phase"]):
        # H: exact ring masses; x, y: marginals of p(x, y), which jumps at the walls (first-order quadrature, the 1 %
        # that vibro pdf's own check of p(x, y) allows)
        mass = ((rows.hi - rows.lo) * rows.density).sum()
        assert mass == pytest.approx(1.0, abs=1e-9 if name == "H" else 1e-2)
    assert (tmp_path / "p.csv").exists()
    joint = pd.read_csv(tmp_path / "j.csv")  # the time-averaged p(x, y) (its box from the unforced energy levels)
    assert list(joint.columns) == ["x", "y", "p"] and len(joint) == 41 * 41 and joint.p.max() > 0


def test_cli_phases_on_an_unforced_model_is_one_line(tmp_path, capsys):
    rc = main(["pdf", "--method", "fpk", "--phases", "4", "--out", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "--phases needs" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.slow
def test_against_monte_carlo_phase_resolved():
    # example 08's forced Duffing (D = 0.02) against the stored Monte Carlo (2 x 384 000 samples per phase; noise
    # 0.003 in L1 on 40 bins): measured 0.024 mean over the 16 phases at the default grid (the goal is 0.005; see
    # docs/results/fpk-forced.md); the bound guards that figure
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import fpk_forced

    edges, ref, noise = fpk_forced.mc_reference("0.02")
    sol = periodic_density_xy(fpk_forced.duffing(0.02), phases=16)
    l1 = np.array([np.abs(s.bin_masses(edges) - r).sum() for s, r in zip(sol.sections(16), ref)])
    assert noise.max() < 0.006
    assert l1.mean() < 0.03 and l1.max() < 0.04
    # Richardson with the grid twice coarser: measured 0.0090 mean, 0.0118 max
    sol = periodic_density_xy(fpk_forced.duffing(0.02), phases=16, extrapolate=True)
    l1 = np.array([np.abs(s.bin_masses(edges) - r).sum() for s, r in zip(sol.sections(16), ref)])
    assert l1.mean() < 0.012 and l1.max() < 0.015
