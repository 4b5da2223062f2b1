"""Issue 24, items 4 (orbit), 6 and 7: absurd sizes refused up front with the estimate; declarations checked.

Each refusal is timed loosely (< 5 s) where the defect was a hang or a late failure; nothing here integrates long
or compiles a Monte Carlo kernel.
"""

from __future__ import annotations

import time

import pytest
import sympy as sp

from hybrid.automaton import HybridAutomaton, Mode, Transition
from hybrid.deterministic import simulate_orbit
from hybrid.errors import ModelError, ParameterError
from hybrid.sizes import SizeError, check_size
from models import DuffingImpact, Elastic, ImpactOscillator
from models.automata import impact_pair
from vibro.cli import main


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    return err[0]


def _refused_quickly(call, error=SizeError, match=None):
    start = time.perf_counter()
    with pytest.raises(error, match=match) as info:
        call()
    assert time.perf_counter() - start < 5.0
    assert "\n" not in str(info.value)
    return str(info.value)


# ----------------------------------------------------------------------------- the estimator itself

def test_check_size_names_the_estimate_the_limit_and_the_fix():
    check_size("x", work=10, max_work=10, memory=4e9)  # at the limits: accepted
    with pytest.raises(SizeError, match=r"^x needs about 1e\+12 steps, about 3.17e\+04 years \(how\), above the limit "
                                        r"1e\+07; do less$"):
        check_size("x", work=1e12, max_work=1e7, seconds_per_unit=1.0, detail="how", fix="do less")
    with pytest.raises(SizeError, match="needs about 8 GB of memory, above the limit 4 GB"):
        check_size("x", memory=8e9)
    with pytest.raises(SizeError):
        check_size("x", work=float("nan"), max_work=1.0)  # an estimate that overflowed is not under the limit


# ----------------------------------------------------------------------------- item 6: orbits

@pytest.mark.parametrize("extra", [[], ["--backend", "scipy"], ["--restitution", "elastic"],
                                   ["--backend", "scipy", "--restitution", "elastic"]])
def test_cli_orbit_with_t_end_1e12_is_refused_with_the_estimate(extra, capsys):
    start = time.perf_counter()
    assert main(["orbit", "--t-end", "1e12", *extra]) == 2  # ran until killed
    assert time.perf_counter() - start < 5.0
    err = _one_line(capsys)
    assert "--t-end=1e+12 needs about 3.16e+11 integration steps" in err and "above the limit 1e+07" in err
    assert "--max-steps" in err and "years" in err


def test_api_orbit_with_dense_output_is_refused_by_steps_and_by_memory():
    m = DuffingImpact(c=0.0, D=0.0, restitution=Elastic())
    _refused_quickly(lambda: simulate_orbit(m, (0.0, 2.2), 1e12, dense=True), match="integration steps")
    # within a raised step budget the samples kept would still need about 80 GB
    msg = _refused_quickly(lambda: simulate_orbit(m, (0.0, 2.2), 1e9, dense=True, max_steps=10**12),
                           match="the dense output of the orbit")
    assert "GB of memory" in msg and "above the limit 4.29 GB" in msg


@pytest.mark.parametrize("param,backend", [("a=1e300", "heyoka"), ("a=1e300", "scipy"), ("b=1e300", "scipy"),
                                           ("c=1e300", "heyoka")])
def test_cli_orbit_with_a_parameter_of_1e300_is_refused(param, backend, capsys):
    # scipy hung on a=1e300 and b=1e300; heyoka stopped with NaN states
    start = time.perf_counter()
    assert main(["orbit", "--param", param, "--backend", backend]) == 2
    assert time.perf_counter() - start < 5.0
    assert "integration steps" in _one_line(capsys)


# ----------------------------------------------------------------------------- item 4 (orbit)

def test_cli_orbit_with_v0_1e30_is_refused_not_nan(capsys):
    assert main(["orbit", "--v0", "1e30"]) == 2
    err = _one_line(capsys)
    # Ma(vc=0.4) gives e = 8.6e-6 at that speed: the rebound still crosses the gap in 2.3e-25
    assert "v0=1e+30 hits a wall at about that speed and rebounds at 8.58e+24 (e = 8.58e-06), crossing the gap " \
           "[-1, 1] in 2.33e-25 time units, less than min_dwell=1e-09" in err
    assert main(["orbit", "--v0", "1e6", "--t-end", "1", "--rows", "0"]) == 0  # slower starts still run


@pytest.mark.parametrize("delta", ["inf", "1e300"])
def test_cli_orbit_without_reachable_walls_prints_no_inf(delta, capsys):
    assert main(["orbit", "--param", f"delta={delta}", "--t-end", "10", "--rows", "0"]) == 0
    captured = capsys.readouterr()
    results = captured.out.split("\n", 1)[1]  # after the header, which repeats the parameters as given
    assert "inf" not in results and "nan" not in results
    assert "no comparison with eqs. 11-14" in captured.out and "free period (eq. 8) T(H0) = 5.084" in captured.out
    assert captured.err == ""  # no overflow warning from G at the far walls


# ----------------------------------------------------------------------------- item 6: grids

def test_phase_plane_grid_of_1e5_by_1e5_is_refused_before_allocating():
    from averaging.phase_plane import solve_phase_plane, stationary_density_xy

    for solve in (solve_phase_plane, stationary_density_xy):
        msg = _refused_quickly(lambda solve=solve: solve(DuffingImpact(), grid=(100_000, 100_000)))
        assert "phase-plane grid 100000 x 100000 needs about 8e+03 GB" in msg and "coarser grid" in msg


def test_energy_grids_of_1e10_points_are_refused_before_allocating():
    from averaging.transient import mean_first_passage_time, transient_density

    msg = _refused_quickly(lambda: transient_density(DuffingImpact(), 1.0, [0.0, 5.0], points=10**10))
    assert "transient_density on points=1e+10 needs about" in msg and "implicit-euler" in msg
    msg = _refused_quickly(lambda: mean_first_passage_time(DuffingImpact(), 1.0, points=10**10))
    assert "mean_first_passage_time on points=1e+10 needs about 4e+03 GB" in msg
    # the exact-in-time scheme keeps N x N eigenvectors: 3e4 points is 14 GB; the sparse scheme runs
    _refused_quickly(lambda: transient_density(DuffingImpact(), 1.0, [0.0, 5.0], points=30_000),
                     match="two dense N x N matrices")


# ----------------------------------------------------------------------------- item 6: solve and bench

def test_solve_with_tol_1e_9_is_refused_before_the_pilot():
    import hybrid.stochastic  # noqa: F401 - its import (numba) is not the refusal's time
    from vibro.solve import solve

    start = time.perf_counter()
    with pytest.raises(SizeError, match=r"Monte Carlo to tol=1e-09 needs about 3.12e\+23 path-steps") as info:
        solve(DuffingImpact(), 1e-9)  # ran a pilot of 1.3e9 path-steps first
    assert time.perf_counter() - start < 5.0  # the diagnostics, then the estimate (no scheme check, no pilot)
    assert "--tol" in str(info.value)


@pytest.mark.parametrize("parts", ["", ",", "mc,,orbits", "mc,mc", "nope"])
def test_bench_with_an_empty_or_bad_part_list_is_refused(parts, tmp_path, capsys):
    out = tmp_path / "bench"
    start = time.perf_counter()
    assert main(["bench", "validity", "--parts", parts, "--out-dir", str(out)]) == 2  # '' ran every part
    assert time.perf_counter() - start < 5.0
    assert "--parts" in _one_line(capsys)
    assert not out.exists()


# ----------------------------------------------------------------------------- item 7: declarations

X, V, Q = sp.symbols("x v q")


def _ball(noise=None, guard="x", reset=("x", "-v"), observables=None, check=None):
    return HybridAutomaton((X, V), {"g": 1.0}, [Mode("air", (V, -sp.Symbol("g")), noise)],
                           [Transition("floor", "air", "air", guard=guard, direction=-1, reset=reset, check=check)],
                           observables=observables or {})


@pytest.mark.parametrize("kwargs,where", [
    (dict(reset=("x", "-q(v)")), "reset of transition 'floor'"),
    (dict(guard="x - q(x)"), "guard of transition 'floor'"),
    (dict(noise=(0, "q(x)")), "noise of mode 'air'"),
    (dict(observables={"E": "q(x)"}), "observable 'E'"),
])
def test_undefined_functions_are_refused_where_declared(kwargs, where):
    # they were NameError: name 'q' is not defined at run time (a numba TypingError in an observable)
    with pytest.raises(ModelError, match=rf"^{where} calls q\(\.\.\.\), which is no known function"):
        _ball(**kwargs)


def test_unknown_symbols_in_a_check_are_refused():
    with pytest.raises(ModelError, match=r"check of transition 'floor' uses unknown symbols \['q'\]"):
        _ball(check=Q < 1)


def test_cli_observable_with_an_undefined_function_is_one_line(tmp_path, capsys):
    rc = main(["mc", "--model", "impact_pair", "--observable", "E=q(x1)", "--range", "E=0:1:10", "--paths", "4",
               "--t-end", "2", "--t-burn", "0", "--out", str(tmp_path / "h.csv")])
    assert rc == 2 and "--observable E calls q(...)" in _one_line(capsys)


def test_restoring_force_outside_its_domain_is_refused_when_declared():
    with pytest.raises(ModelError, match=r"g\(x\) = sqrt\(x\) is not a finite real number at x = -1, inside the "
                                         r"admissible range \[-1, 1\] between the walls"):
        ImpactOscillator("sqrt(x)", "c*y", parameters={"c": 0.05, "D": 0.05, "delta": 1.0})
    ImpactOscillator("sign(x)*sqrt(Abs(x))", "c*y", parameters={"c": 0.05, "D": 0.05, "delta": 1.0})


def test_non_confining_restoring_force_is_refused_when_declared():
    with pytest.raises(ModelError, match="does not confine the motion on the left: there is no wall"):
        ImpactOscillator("-x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=None)
    with pytest.raises(ModelError, match=r"g\(x\) = a\*x \+ b\*x\*\*3 does not confine the motion"):
        DuffingImpact().with_params(b=-1.0, delta=float("inf"))
    ImpactOscillator("-x", "c*y", parameters={"c": 0.05, "D": 0.05, "delta": 1.0})  # walls confine it


@pytest.mark.parametrize("body,words", [
    ("import sys\nsys.exit(3)\n", "could not import"),
    ("import sys\nfrom models import DuffingImpact\nclass M(DuffingImpact):\n    def __init__(self):\n"
     "        sys.exit(3)\n", "model class M() called sys.exit(3)"),
])
def test_model_file_calling_sys_exit_is_one_line_with_status_2(body, words, tmp_path, capsys):
    path = tmp_path / "exits.py"
    path.write_text(body)
    assert main(["orbit", "--model", f"{path}:M"]) == 2  # ended vibro with status 3 and no message
    err = _one_line(capsys)
    assert words in err and "sys.exit(3)" in err


@pytest.mark.parametrize("gap", [0.0, -1.0, float("nan")])
def test_impact_pair_gap_is_checked_by_name(gap):
    with pytest.raises(ParameterError, match=rf"^gap={gap:g} must be > 0"):
        impact_pair(gap=gap)
    with pytest.raises(ParameterError, match=rf"^gap={gap:g} must be > 0"):
        impact_pair().resolve_parameters({"gap": gap})


def test_cli_impact_pair_gap_is_checked_by_name(tmp_path, capsys):
    assert main(["mc", "--model", "impact_pair", "--param", "gap=0", "--out", str(tmp_path / "h.csv")]) == 2
    assert "gap=0 must be > 0" in _one_line(capsys)
