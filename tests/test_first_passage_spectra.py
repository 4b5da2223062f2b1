"""First passage, survival and spectra from the phase-plane generator (issue 26, items 1, 4, 5, 6), against known
answers: the averaged closed form of the linear oscillator's mean first-passage time at small damping, the free
linear oscillator's exact spectrum, and the linear oscillator with an elastic stop at its equilibrium, which is the
free oscillator folded (x = |s|): its stationary density is twice the Gaussian, its covariance is
(2 sigma^2 / pi)(sqrt(1 - rho^2) + rho arcsin rho - 1) with rho the free oscillator's correlation, and its first
passage to x = b is the free oscillator's first passage out of |s| < b.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.special import expi

import vibro
from averaging import mean_first_passage_time
from averaging.phase_plane import first_passage_fpk, solve_phase_plane, spectrum_fpk
from averaging.phase_plane.passage import BackwardProblem, Domain, crossing_rate
from hybrid.errors import ParameterError
from hybrid.sizes import SizeError
from models import DuffingImpact, Elastic, ImpactOscillator, Ma


def linear(c, D):
    return ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)


def averaged_mfpt(c, D, H_c, H0=0.0):
    """E[T] of dH = (D - c H) dt + sqrt(2 D H) dW from H0 to H_c: (1/c) int_{H0}^{H_c} (e^{c h/D} - 1)/h dh."""
    def ein(z):
        return expi(z) - np.log(z) - np.euler_gamma if z > 0 else 0.0
    return (ein(c * H_c / D) - ein(c * H0 / D)) / c


def free_psd(c, D, omega):
    """One-sided PSD of x'' + c x' + x = sqrt(2 D) xi: (2 D / pi) / ((1 - w^2)^2 + c^2 w^2), integral D / c."""
    return (2 * D / np.pi) / ((1 - omega**2) ** 2 + c**2 * omega**2)


def folded_psd(c, D, omega, tau_max=None, n=200_001):
    """One-sided PSD of |s|, s the free oscillator: (2/pi) int_0^inf C(tau) cos(omega tau) d tau with C the
    covariance of the folded Gaussian process."""
    s2 = D / c
    wd = np.sqrt(1 - c * c / 4)
    tau = np.linspace(0.0, tau_max or 60.0 / c, n)
    rho = np.exp(-c * tau / 2) * (np.cos(wd * tau) + c / (2 * wd) * np.sin(wd * tau))
    rho = np.clip(rho, -1.0, 1.0)
    C = 2 * s2 / np.pi * (np.sqrt(1 - rho**2) + rho * np.arcsin(rho) - 1)
    h = tau[1] - tau[0]
    w = np.full(n, h)
    w[0] = w[-1] = h / 2
    return np.array([2 / np.pi * np.sum(w * C * np.cos(om * tau)) for om in omega])


# ------------------------------------------------------------------ first passage
def test_mean_first_passage_matches_the_averaged_closed_form_at_small_damping():
    # c = 0.02: the averaged energy is exact to O(c); measured 10.540 (grid 40 x 48) against 10.523, 0.16 %
    c, D, H_c = 0.02, 0.05, 0.5
    exact = averaged_mfpt(c, D, H_c)
    r = first_passage_fpk(linear(c, D), f"H < {H_c}", grid=(40, 48), check=True, survival=False)
    assert abs(r.mean_time / exact - 1) < 3e-3, (r.mean_time, exact)
    # the estimate (half the rings: 10.5644, half the angles: 10.5222) covers the error: 0.0167 against 0.0305
    assert abs(r.mean_time - exact) <= r.error_estimate, (r.mean_time, r.error_estimate, exact)
    # the averaged chain (method 'paper') reaches the closed form itself
    assert abs(mean_first_passage_time(linear(c, D), H_c, 0.0, points=2000) / exact - 1) < 1e-6


def test_survival_integrates_to_the_mean_time_and_decays_at_the_principal_rate():
    c, D, H_c = 0.05, 0.05, 0.5
    r = first_passage_fpk(linear(c, D), f"H < {H_c}", grid=(40, 48), check=False, t_max=None, steps=400)
    assert r.R[0] == 1.0 and np.all(np.diff(r.R) <= 1e-12) and 0 < r.R[-1] < 0.02
    # int_0^inf R dt = E[T]; the tail beyond 5 E[T] is R(t_end) / rate
    area = np.trapezoid(r.R, r.t) + r.R[-1] / r.decay_rate
    assert abs(area / r.mean_time - 1) < 2e-3, (area, r.mean_time)
    # the density is -dR/dt and the tail is exponential at the decay rate
    slope = -np.diff(np.log(r.R[-50:])) / np.diff(r.t[-50:])
    assert np.allclose(slope, r.decay_rate, rtol=2e-3)
    assert abs(np.trapezoid(r.density, r.t) - (1 - r.R[-1])) < 2e-3


def test_folded_oscillator_first_passage_is_the_free_oscillators_two_sided_problem():
    c, D, b = 0.1, 0.05, 0.6
    folded = first_passage_fpk(linear(c, D), f"x < {b}", grid=(60, 64), walls=(0.0, None), restitution=Elastic(),
                               h_max=1.0, check=False, survival=False)
    free = first_passage_fpk(linear(c, D), f"abs(x) < {b}", grid=(60, 64), walls=None, h_max=1.0, check=False,
                             survival=False)
    assert abs(folded.mean_time / free.mean_time - 1) < FOLDED_PASSAGE_TOL, (folded.mean_time, free.mean_time)


FOLDED_PASSAGE_TOL = 0.02


def test_a_level_domain_gives_the_poisson_estimate_from_rices_rate():
    c, D = 0.1, 0.05
    lin = linear(c, D)
    sd = solve_phase_plane(lin, (60, 64), h_max=2.0, walls=None)
    # Rice for the Gaussian oscillator: nu+(b) = (1 / 2 pi) exp(-b^2 / (2 sigma^2)), sigma^2 = D / c
    for b in (0.0, 0.5):
        exact = np.exp(-b * b / (2 * D / c)) / (2 * np.pi)
        assert abs(crossing_rate(sd, b) / exact - 1) < 0.01
        assert abs(crossing_rate(sd, -b, -1) / exact - 1) < 0.01
    r = first_passage_fpk(lin, "abs(x) < 0.8", grid=(60, 64), walls=None, h_max=2.0, check=False, steps=100)
    nu = r.details["out_crossing_rate"]
    # measured 1.6 % off at this grid: |x| = 0.8 is 1.6 sigma out, where the joint density is coarser
    assert abs(nu / (2 * np.exp(-0.64 / (2 * D / c)) / (2 * np.pi)) - 1) < 0.025
    assert np.allclose(r.poisson, np.exp(-nu * r.t))




def test_example_1_mean_first_passage_at_hard_impacts_has_a_small_error_estimate():
    # averaging is 14-16 % short at H_c = 2, where every orbit impacts hard; fpk measured 120.85 (120x128); against
    # the Monte Carlo reference: tests/test_first_passage_reference.py
    m = DuffingImpact(restitution=Ma(vc=0.4))
    r = first_passage_fpk(m, "H < 2.0", grid=(120, 128), check=True, survival=False)
    assert r.error_estimate < 0.01 * r.mean_time  # half the rings and half the angles: 0.66 (0.55 %)
    # its CPU time (goal 2 s) is measured by benchmarks/first_passage_fpk.py, not asserted here


def test_backward_problem_of_a_single_state():
    bp = BackwardProblem(np.array([[2.0]]), [1.0])
    assert bp.mean_time()[0] == 0.5 and bp.decay_rate() == 2.0


# ------------------------------------------------------------------ spectra
def test_free_linear_oscillator_spectrum_matches_its_transfer_function():
    c, D = 0.2, 0.05
    s = spectrum_fpk(linear(c, D), "x", omega_max=4.0, points=40, refine=30, grid=(40, 48), h_max=3.0,
                     extrapolate=True)
    exact = free_psd(c, D, s.omega)

    def l1(S):
        return np.trapezoid(np.abs(S - exact), s.omega) / np.trapezoid(exact, s.omega)

    # rings graded towards H = 0 (stretch 0.02): L1 0.0074 on 40 x 48 (0.029 with the uniform-ish 0.4), and 0.0025
    # extrapolated from 40 x 48, 20 x 24 and 10 x 16 at the observed order (1.5)
    assert l1(s.S) < 0.004, l1(s.S)
    # the a-posteriori estimate of the unextrapolated error is within a factor 2 of the true one (0.0050 / 0.0074)
    assert 0.5 < s.details["error_estimate"] / l1(s.unextrapolated) < 2.0
    assert abs(s.peak_omega / np.sqrt(1 - c * c / 2) - 1) < 2e-3
    assert abs(s.variance / (D / c) - 1) < 5e-3
    # the integral over [0, 4] holds the variance up to the tail above 4 (about 6e-4 of it) and the trapezoid rule
    # on these 75 frequencies (measured 1.0066)
    assert abs(s.variance_check - 1) < 1e-2


def test_folded_oscillator_spectrum_matches_the_folded_gaussian_covariance():
    c, D = 0.2, 0.05
    s = spectrum_fpk(linear(c, D), "x", omega_max=4.0, points=41, refine=0, grid=(80, 96), h_max=3.0,
                     walls=(0.0, None), restitution=Elastic())
    # stationary mean E|s| = sigma sqrt(2 / pi), variance sigma^2 (1 - 2 / pi)
    s2 = D / c
    assert abs(s.mean / np.sqrt(2 * s2 / np.pi) - 1) < 5e-3
    # the wall at the equilibrium meets it at a corner of the grid: first order (measured 0.11 % at 80 x 96)
    assert abs(s.variance / (s2 * (1 - 2 / np.pi)) - 1) < 5e-3
    exact = folded_psd(c, D, s.omega)
    l1 = np.trapezoid(np.abs(s.S - exact), s.omega) / np.trapezoid(exact, s.omega)
    assert l1 < FOLDED_PSD_L1, l1


FOLDED_PSD_L1 = 1e-3
"""The issue's goal. Measured 0.00066 on 80 x 96 with the phase flux of second order at the arcs' ends
(``arc_end_order=2``, the spectrum's default); 0.0100 with the first-order upwind flux there, which smeared the
phase and the harmonics (4.6e-3 against 0.038 on 40 x 48; benchmarks/spectrum_accuracy.py)."""


# ------------------------------------------------------------------ interfaces and refusals
def test_api_methods_and_refusals():
    m = DuffingImpact(restitution=Ma(vc=0.4))
    paper = vibro.first_passage(m, "H < 0.5", method="paper", points=400)
    assert paper.method == "paper" and list(paper.to_pandas().columns) == ["t", "R", "density"]
    assert abs(paper.mean_time - mean_first_passage_time(m, 0.5, 0.0, points=400)) < 1e-9
    with pytest.raises(ParameterError, match="needs t_max"):  # a probability of leaving before t_max
        vibro.first_passage(m, "H < 0.5", method="splitting")
    with pytest.raises(ParameterError, match="segment"):  # the Monte Carlo spectrum checks its request first
        vibro.spectrum(m, "x", method="mc", segment=7)
    with pytest.raises(ParameterError, match="H < H_c only"):
        vibro.first_passage(m, "abs(x) < 0.5", method="jump")
    with pytest.raises(ParameterError, match="outside the domain"):
        vibro.first_passage(m, "H < 0.5", x0=(0.0, 2.0))
    with pytest.raises(ParameterError, match="inequality"):
        Domain("H + 1", m)
    with pytest.raises(ParameterError, match="unknown names"):
        Domain("z < 1", m)
    with pytest.raises(ParameterError, match="holds the whole grid"):
        first_passage_fpk(m, "abs(x) < 5", grid=(20, 32), h_max=1.0, check=False)


def test_cli_defaults_are_the_librarys():
    from averaging.phase_plane import passage, spectrum
    from vibro.cli import cmd_passage, cmd_spectrum

    assert cmd_passage.PASSAGE_GRID == passage.PASSAGE_GRID and cmd_passage.DEFAULT_STEPS == passage.DEFAULT_STEPS
    assert cmd_spectrum.SPECTRUM_GRID == spectrum.SPECTRUM_GRID


def test_cli_passage_and_spectrum_write_csv_sidecar_and_summary(tmp_path):
    from vibro.cli import main

    out, summary = tmp_path / "R.csv", tmp_path / "R_summary.json"
    assert main(["passage", "--domain", "H < 0.5", "--grid", "40", "48", "--steps", "50", "--out", str(out),
                 "--summary-json", str(summary)]) == 0
    assert out.read_text().splitlines()[0] == "t,R,density"
    rec = json.loads(summary.read_text())
    assert rec["kind"] == "passage" and rec["results"]["mean_time"] > 0
    assert (tmp_path / "R.json").exists()
    S = tmp_path / "S.csv"
    assert main(["spectrum", "--grid", "20", "32", "--points", "20", "--refine", "0", "--out", str(S)]) == 0
    assert S.read_text().splitlines()[0] == "omega,S"
    assert main(["passage", "--domain", "H < 0.5", "--method", "splitting", "--out", str(out)]) == 2  # no --t-max
    assert main(["passage", "--domain", "H < 0.5", "--x0", "0", "--out", str(out)]) == 2  # a state has two numbers


def test_monte_carlo_level_is_moved_in_by_the_continuity_correction():
    # a level watched at steps of dt is crossed late by O(sqrt(dt)); the slack of H < 0.25 has the local noise
    # sqrt(2 D) |y|, so the exit guard becomes H + 0.5826 sqrt(2 D dt) |y| - 0.25 (no kernel is compiled here)
    from vibro.passage import _exit_relation

    m = DuffingImpact(restitution=Ma(vc=0.4))
    base, rel, corrected = _exit_relation(m, Domain("H < 0.25", m), 0.002)
    values = {"x": 0.3, "y": -0.7, **base.parameters}
    H = 0.5 * 0.7**2 + values["a"] * 0.3**2 / 2 + values["b"] * 0.3**4 / 4
    expected = H - 0.25 + 0.5826 * np.sqrt(2 * values["D"] * 0.002) * 0.7
    guard = rel.lhs.subs({s: values[s.name] for s in rel.lhs.free_symbols})
    assert corrected and float(guard) == pytest.approx(expected, rel=1e-12)
    assert _exit_relation(m, Domain("H < 0.25", m))[2] is False


@pytest.mark.slow  # compiles two kernels of its own, 40,000 paths each (about 40 CPU s each)
def test_monte_carlo_first_passage_with_the_exit_as_a_guard():
    # against the converged reference of benchmarks/data/first_passage_reference.json (5.1618 +- 0.0185, splitting
    # at two steps); measured on 27 November: corrected 5.1830 +- 0.0369 (+0.4 %), uncorrected 5.2890 +- 0.0377
    # (+2.5 %)
    from pathlib import Path

    m = DuffingImpact(restitution=Ma(vc=0.4))
    stored = Path(__file__).resolve().parent.parent / "benchmarks" / "data" / "first_passage_reference.json"
    row = json.loads(stored.read_text())["levels"]["0.25"]
    ref, ref_ci = row["mean"], row["ci95"]
    runs = {corr: vibro.first_passage(m, "H < 0.25", method="mc", paths=40_000, t_max=60.0, seed=11, points=40,
                                      chunk_paths=2500, continuity_correction=corr) for corr in (True, False)}
    mc = runs[True]
    assert mc.details["continuity_correction"] and mc.details["censored"] == 0
    assert abs(mc.mean_time - ref) < 3 * np.hypot(mc.error_estimate / 1.96, ref_ci / 1.96)
    late = runs[False]
    assert late.mean_time - ref > 2 * np.hypot(late.error_estimate / 1.96, ref_ci / 1.96)  # the bias it removes
    assert np.all(mc.R_lo <= mc.R) and np.all(mc.R <= mc.R_hi)


@pytest.mark.slow  # the docs build in CI runs every example too, and stops on a failed self-check
@pytest.mark.parametrize("script", ["11_first_passage.py", "12_spectrum.py"])
def test_examples_run(script):
    from examples_run import run_example

    res = run_example(script, "--quick")
    assert res.returncode == 0 and res.stdout.strip().endswith("OK"), res.stdout + res.stderr


def test_monte_carlo_statistics_that_cannot_be_held_are_refused_before_compiling():
    # 625 chunks x 400 sections x 20,002 exit-time bins: 40 GB, refused with the estimate (it was a MemoryError)
    m = DuffingImpact(restitution=Ma(vc=0.4))
    with pytest.raises(SizeError, match="statistics of 625 chunks needs about 40.1 GB"):
        vibro.first_passage(m, "H < 0.25", method="mc", paths=40_000, t_max=60.0, points=400, chunk_paths=64)


def test_a_start_within_the_correction_band_keeps_the_plain_level_and_says_so():
    # H = 0.2415 at (0, 0.695) is inside H < 0.25 as written but within 0.5826 sqrt(2 D dt) |y| = 0.0057 of the level
    # at dt = 0.01: the corrected relation would refuse the start in words the user never wrote (found in review)
    from averaging.phase_plane import PassageWarning
    from hybrid.sizes import SizeError
    from vibro.passage import _exit_relation, _slack_at

    m = DuffingImpact(restitution=Ma(vc=0.4))
    base, rel, corrected = _exit_relation(m, Domain("H < 0.25", m), 0.01)
    assert corrected and _slack_at(base, rel.lhs, (0.0, 0.695)) > 0 > _slack_at(base, rel.lhs, (0.0, 0.3))
    with pytest.warns(PassageWarning, match="within 0.5826 sqrt"):
        with pytest.raises(SizeError):  # stops at the size check, before any compile: the warning came first
            vibro.first_passage(m, "H < 0.25", (0.0, 0.695), method="mc", dt=0.01, paths=40_000, t_max=60.0,
                                points=400, chunk_paths=64)
    with pytest.raises(ParameterError, match="lies outside the domain 'H < 0.25'"):  # outside as written
        vibro.first_passage(m, "H < 0.25", (0.0, 0.8), method="mc", dt=0.01, paths=64, t_max=1.0)
