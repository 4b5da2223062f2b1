"""Issue 24, items 3-5: densities written on grids that hold them, finite numbers, and averaging outside its validity
warns. One check (hybrid.resolution.check_density) serves every density writer: pdf's p(H) and p(x, y), and the
histograms of vibro mc."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from averaging import stationary_density
from averaging.chain import chain_density
from hybrid.errors import DensityResolutionWarning, NormalisationError, ParameterError, VibroWarning
from hybrid.resolution import axis_spread, check_density
from models import DuffingImpact, ImpactOscillator, Newton
from vibro.cli import main
from vibro.solve.choice import OutsideValidityWarning, averaging_cross_check


def _caught(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    return out, caught


def _trapezoid_moments(H, p):
    mass = np.trapezoid(p, H)
    return mass, np.trapezoid(H * p, H) / mass


# regression: at h_max 1e3 the CSV integrated to 1.05 (jump, paper, chain); at 1e6 to 330-450, one point held it all
@pytest.mark.parametrize("method", ["jump", "paper", "chain"])
@pytest.mark.parametrize("h_max", [1e3, 1e6])
def test_huge_h_max_density_integrates_to_one_on_its_own_grid(method, h_max):
    sd = stationary_density(DuffingImpact(), method, h_max=h_max, points=2000)
    mass, mean = _trapezoid_moments(sd.H, sd.p)
    assert len(sd.H) == 2000 and sd.H[-1] == h_max
    assert mass == pytest.approx(1.0, abs=1e-3)
    assert mean == pytest.approx(sd.mean_energy, rel=1e-3)
    _, caught = _caught(check_density, "p(H)", [sd.H], sd.p, sampled_on=[sd.H], mass=1.0, mean=sd.mean_energy,
                        hint=lambda spreads: "")
    assert not [w for w in caught if issubclass(w.category, DensityResolutionWarning)]


# regression: the chain spread its 400 energies over the no-loss range: E[H] 0.4935 at h_max 1e3 against 0.5012 at 4
def test_chain_mean_energy_does_not_depend_on_h_max():
    # h_max = 8 covers the chain's tail (since the tail is no longer cut at H = 3.5, h_max = 4 reflects 1e-4 of E[H])
    ref = chain_density(DuffingImpact(), h_max=8.0).mean_energy
    for h_max in (1e3, 1e6):
        assert chain_density(DuffingImpact(), h_max=h_max).mean_energy == pytest.approx(ref, rel=1e-4)


# regression: fpk at h_max 1e3 integrated to 0.97 and printed E[H] 0.788 against 0.5007 at h_max 4
def test_fpk_fits_its_rings_to_the_mass():
    from averaging.phase_plane import stationary_density_xy

    ref = stationary_density_xy(DuffingImpact(), h_max=4.0, check=False)
    sd = stationary_density_xy(DuffingImpact(), h_max=1e3, check=False)
    assert sd.h_support < 20.0 and sd.H[-1] == 1e3
    mass, mean = _trapezoid_moments(sd.H, sd.p)
    assert mass == pytest.approx(1.0, abs=1e-3) and mean == pytest.approx(sd.mean_energy, rel=1e-3)
    assert sd.mean_energy == pytest.approx(ref.mean_energy, rel=1e-3)  # Monte Carlo: 0.5020 +- 0.0025


# regression: fpk at h_max 1e300 died with an IndexError in the ring grid; the other methods blamed the model
def test_fpk_at_a_huge_h_max_answers_as_at_a_moderate_one_and_an_absurd_one_is_refused():
    from averaging.phase_plane import stationary_density_xy

    ref = stationary_density_xy(DuffingImpact(), h_max=1e3, check=False)
    sd = stationary_density_xy(DuffingImpact(), h_max=1e11, check=False)
    assert sd.h_support < 20.0 and sd.mean_energy == pytest.approx(ref.mean_energy, rel=1e-3)
    for method in ("jump", "paper", "chain"):
        with pytest.raises(ParameterError, match="h_max=1e\\+300 lies .* above the model's energy scale"):
            stationary_density(DuffingImpact(), method, h_max=1e300)
    with pytest.raises(ParameterError, match="h_max=1e-300 lies .* below the model's energy scale"):
        stationary_density_xy(DuffingImpact(), h_max=1e-300)


def test_pdf_cli_csv_and_joint_agree_with_the_printed_moments(tmp_path, capsys):
    out, joint = tmp_path / "p.csv", tmp_path / "j.csv"
    assert main(["pdf", "--method", "jump", "--h-max", "1e6", "--out", str(out), "--joint", str(joint)]) == 0
    printed = float(capsys.readouterr().out.split("E[H] = ")[1].split()[0])
    df = pd.read_csv(out)
    mass, mean = _trapezoid_moments(df.H.to_numpy(), df.p.to_numpy())
    assert mass == pytest.approx(1.0, abs=1e-3) and mean == pytest.approx(printed, rel=1e-3)
    j = pd.read_csv(joint)
    x, y = np.unique(j.x), np.unique(j.y)
    P = j.p.to_numpy().reshape(len(y), len(x))
    assert np.trapezoid(np.trapezoid(P, x, axis=1), y) == pytest.approx(1.0, abs=1e-3)  # was 11.2
    assert y.max() < 10.0  # the box of the energies that carry the mass, not |y| <= sqrt(2e6)


# regression: a = 0 (and 1e-300) wrote p(0) = inf: p(H) ~ H**-1/4 for a quartic well
@pytest.mark.parametrize("a", [0.0, 1e-300])
def test_flat_well_density_is_finite_and_integrates_to_one(tmp_path, a):
    out, joint = tmp_path / "p.csv", tmp_path / "j.csv"
    assert main(["pdf", "--method", "jump", "--param", f"a={a}", "--out", str(out), "--joint", str(joint)]) == 0
    df = pd.read_csv(out)
    assert np.all(np.isfinite(df.p)) and np.all(np.isfinite(pd.read_csv(joint).p))
    mass, mean = _trapezoid_moments(df.H.to_numpy(), df.p.to_numpy())
    assert mass == pytest.approx(1.0, abs=1e-3)
    assert mean == pytest.approx(stationary_density(DuffingImpact(a=a), "jump").mean_energy, rel=1e-3)


# regression: pdf without walls printed "G(delta) = inf"
def test_pdf_without_walls_prints_no_inf(tmp_path, capsys):
    assert main(["pdf", "--param", "delta=inf", "--h-max", "20", "--out", str(tmp_path / "p.csv")]) == 0
    model_line, *results = capsys.readouterr().out.splitlines()  # the first echoes the input, delta: inf
    assert "'delta': inf" in model_line and any(line.startswith("no walls") for line in results)
    assert not any("inf" in line for line in results)


def test_solve_without_walls_says_so(capsys):
    assert main(["solve", "--param", "delta=inf", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "walls: none" in text and "impacts are elastic" not in text and "no walls" in text


# -- the check itself -------------------------------------------------------------------------------------------
def test_point_mass_and_wide_range_are_not_resolved():
    s = axis_spread(np.linspace(0.0, 1000.0, 401), np.r_[1000, np.zeros(399)])
    assert s.cells == 1 and not s.resolved and s.hi == 2.5
    assert axis_spread(np.linspace(0.0, 4.0, 401), np.exp(-np.linspace(0.0, 4.0, 400))).resolved


def test_non_finite_density_is_refused_before_writing():
    with pytest.raises(NormalisationError, match="not finite") as info:
        check_density("p(H)", [np.linspace(0, 1, 3)], [np.inf, 1.0, 0.0], sampled_on=[np.linspace(0, 1, 3)],
                      hint=lambda spreads: "")
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("mean,expected", [(0.44, "--h-max 3.52"), (2e-8, "--h-max 1.6e-07"),
                                           (0.0, "point mass")])
def test_mc_histogram_in_one_bin_names_the_fix(mean, expected):
    """--h-max 1000 (mean 0.44), D = 1e-9 (2e-8) and D = 0 (0) all put every sample into the first of 400 bins."""
    from vibro.cli.density_check import check_energy_histogram

    ok, caught = _caught(check_energy_histogram, "h.csv", np.linspace(0.0, 1000.0, 401), np.r_[500, np.zeros(399)],
                         mean)
    msgs = [str(w.message) for w in caught if issubclass(w.category, DensityResolutionWarning)]
    assert not ok and len(msgs) == 1 and expected in msgs[0] and "\n" not in msgs[0]


def test_mc_cli_huge_h_max_warns_for_both_histograms(tmp_path, capsys):
    assert main(["mc", "--scheme", "splitting", "--dt", "0.02", "--paths", "16", "--t-end", "60", "--t-burn", "10",
                 "--h-max", "1000", "--out", str(tmp_path / "h.csv"), "--joint", str(tmp_path / "j.csv")]) == 0
    err = capsys.readouterr().err
    assert "the H histogram" in err and "not resolved along H" in err and "--h-max" in err
    assert "the (x, y) histogram" in err and "not resolved along y" in err


# -- item 5: averaging outside its validity ------------------------------------------------------------------
def _stop(r):
    return ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=(0, None), restitution=Newton(r))


# measured: Monte Carlo E[H] 0.1482 +- 0.0007 (r = 0.6), 0.2666 +- 0.0020 (r = 0.8); paper and jump +33 %, +14 %
@pytest.mark.parametrize("model,method", [(_stop(0.6), "jump"), (_stop(0.6), "paper"), (_stop(0.8), "jump"),
                                          (DuffingImpact(delta=0.5, restitution=Newton(0.3)), "jump"),
                                          (DuffingImpact(D=0.5, restitution=Newton(0.5)), "jump")])
def test_averaging_outside_its_validity_warns_and_names_the_better_method(model, method):
    h_max = 40.0 if model.params.get("D") == 0.5 else 4.0
    sd = stationary_density(model, method, h_max=h_max)
    check, caught = _caught(averaging_cross_check, model, sd)
    msgs = [str(w.message) for w in caught if issubclass(w.category, OutsideValidityWarning)]
    assert not check.valid and check.mean_gap > 0.10 and len(msgs) == 1
    assert "chain or fpk" in msgs[0] and "\n" not in msgs[0] and issubclass(OutsideValidityWarning, VibroWarning)


def test_averaging_inside_its_validity_does_not_warn():
    sd = stationary_density(DuffingImpact(), "jump")
    check, caught = _caught(averaging_cross_check, DuffingImpact(), sd, 0.0403)
    assert check.valid and abs(check.mean_gap) < 0.05
    assert not [w for w in caught if issubclass(w.category, OutsideValidityWarning)]


def test_pdf_cli_warns_outside_validity(tmp_path, capsys):
    assert main(["pdf", "--method", "jump", "--param", "delta=0.5", "--restitution", "newton:e=0.3", "--out",
                 str(tmp_path / "p.csv")]) == 0
    err = capsys.readouterr().err
    assert "outside its validity" in err and "--method chain or fpk" in err


def test_solve_forced_outside_validity_warns_and_reports_the_measured_error():
    from vibro.solve import solve

    model = DuffingImpact(delta=0.5, restitution=Newton(0.3))  # Monte Carlo E[H] 0.1314 +- 0.0005; jump 0.1463
    with pytest.warns(OutsideValidityWarning, match="use method fpk"):
        sol = solve(model, 0.02, method="jump")
    assert sol.estimated_error >= sol.choice.expected_error
