"""Issue 9: the stationary density does not depend on h_max once h_max covers the mass, and says when it cuts it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from averaging import stationary_density
from hybrid.errors import NormalisationError, ParameterError, TruncationWarning, VibroWarning
from models import DuffingImpact, Elastic, Ma

CASES = {"jump": ("jump", Ma(0.4)), "paper": ("paper", Ma(0.4)), "elastic": ("paper", Elastic())}


def _mean(case, h_max, points=2000):
    method, law = CASES[case]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sd = stationary_density(DuffingImpact(restitution=law), method, h_max=h_max, points=points)
    return sd, [w for w in caught if issubclass(w.category, TruncationWarning)]


# regression: h_max = 1e8 gave E[H] = 0.259 (jump, converged 0.516) and 0.826 (elastic, converged 1.164)
@pytest.mark.parametrize("case,tol", [("jump", 1e-6), ("paper", 1e-12), ("elastic", 1e-12)])
def test_mean_energy_does_not_depend_on_h_max_once_it_covers_the_mass(case, tol):
    ref, _ = _mean(case, 1e3)
    for h_max in (1e3, 1e8, 1e12):
        sd, warned = _mean(case, h_max)
        assert not warned
        assert sd.mass_above_h_max == 0.0
        assert sd.mean_energy == pytest.approx(ref.mean_energy, rel=tol)
        assert sd.H[-1] == h_max and len(sd.H) == 2000  # the output grid is still the one asked for
    converged = {"jump": 0.51606, "paper": 0.54080, "elastic": 1.16394}[case]
    assert ref.mean_energy == pytest.approx(converged, rel=2e-5)


@pytest.mark.parametrize("case", ["jump", "paper"])
def test_h_max_that_cuts_little_mass_agrees_within_that_mass(case):
    ref, _ = _mean(case, 1e3)
    for h_max in (4.0, 10.0):
        sd, warned = _mean(case, h_max)
        assert not warned and sd.mass_above_h_max < 1e-3
        # conditioning on H <= h_max moves the mean by about the cut mass times the distance to h_max
        assert sd.mean_energy == pytest.approx(ref.mean_energy, rel=1e-3)


def test_elastic_h_max_that_cuts_mass_warns_with_the_mass():
    ref, _ = _mean("elastic", 1e3)
    sd, warned = _mean("elastic", 4.0)
    assert len(warned) == 1 and issubclass(warned[0].category, VibroWarning)
    assert "cuts off 0.0537" in str(warned[0].message) and "\n" not in str(warned[0].message)
    assert 0.05 < sd.mass_above_h_max < 0.06
    assert sd.mean_energy < ref.mean_energy


def test_tiny_h_max_warns_that_almost_everything_is_cut():
    sd, warned = _mean("paper", 1e-9, points=101)
    assert len(warned) == 1 and sd.mass_above_h_max > 0.999


def test_huge_noise_warns_instead_of_answering_silently():
    with pytest.warns(TruncationWarning, match="at least 0.99"):
        stationary_density(DuffingImpact(D=1e300), points=101)


@pytest.mark.parametrize("params", [dict(D=1e-300), dict(c=1e300)])
def test_density_scale_beyond_double_precision_is_refused(params):
    with pytest.raises(NormalisationError, match="energy scale") as info:
        stationary_density(DuffingImpact(**params), points=101)
    assert "\n" not in str(info.value)


def test_density_beyond_its_support_is_zero_and_consistent():
    sd, _ = _mean("paper", 1e8)
    assert sd.h_support < 100.0 and sd.p[-1] == 0.0
    assert float(sd.density([0.3, 1e7])[1]) == 0.0
    assert float(sd.density([0.3])[0]) == pytest.approx(float(_mean("paper", 1e3)[0].density([0.3])[0]), rel=1e-12)


# regression: nodes=3 returned p[0] = inf; points=[1, 2] gave a TypeError
@pytest.mark.parametrize("kwargs", [dict(nodes=3), dict(nodes=1.5), dict(points=[1, 2]), dict(points=None),
                                    dict(points=2.0), dict(points=10**9), dict(h_max="4"), dict(h_max=1j),
                                    dict(h_max=float("inf")), dict(h_max=-1.0)])
def test_bad_grid_arguments_are_parameter_errors(kwargs):
    with pytest.raises(ParameterError) as info:
        stationary_density(DuffingImpact(), **{"points": 101, **kwargs})
    assert "\n" not in str(info.value)


def test_defaults_are_unchanged_where_h_max_does_not_cover_the_mass():
    """h_max = 4 (the default) keeps its former answer: the range is h_max itself and the grid is the output one."""
    sd, _ = _mean("jump", 4.0)
    assert sd.h_support == 4.0 and np.all(np.isfinite(sd.log_p))
    assert sd.mean_energy == pytest.approx(0.5158129525464878, rel=1e-12)


# regression: solve --tol 1e-300 died with an OverflowError in the Monte Carlo cost estimate
@pytest.mark.parametrize("kwargs", [dict(tol=1e-300), dict(tol=0.0), dict(tol=float("nan")), dict(tol="0.02"),
                                    dict(max_cost=float("inf")), dict(max_cost=-1.0)])
def test_solver_request_beyond_double_precision_is_refused(kwargs):
    from vibro.solve import choose

    with pytest.raises(ParameterError) as info:
        choose(DuffingImpact(), **{"tol": 0.02, **kwargs}, mc_pilot=False)
    assert "\n" not in str(info.value)
