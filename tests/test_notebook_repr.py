"""Results in a notebook: a one-line repr with the key numbers (never whole arrays), a small HTML table, and
``to_pandas()`` on every result."""

from __future__ import annotations

import warnings

import pandas as pd
import pytest

from averaging import stationary_density
from averaging.phase_plane import stationary_density_xy
from hybrid.deterministic import simulate_orbit
from hybrid.stochastic import simulate_automaton, simulate_ensemble
from models import DuffingImpact, Elastic
from models.automata import AUTOMATA
from vibro.solve import solve


def _results():
    model = DuffingImpact()
    orbit = simulate_orbit(DuffingImpact(c=0, D=0), (0.0, 2.2), 10.0, dense=True)
    pair = AUTOMATA["impact_pair"]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # short runs: the chunk-count and resolution warnings are not the point here
        ens = simulate_ensemble(model, "splitting", dt=0.02, paths=16, t_end=40.0, t_burn=5.0, seed=1)
        auto = simulate_automaton(pair, "splitting", dt=0.01, paths=16, t_end=50.0, t_burn=5.0, x0=(0.0,) * 4,
                                  seed=1, observables={"H": pair.observables["H"], "z": pair.observables["z"]},
                                  histograms={"H": (0.0, 4.0, 400), "z": (-0.2, 0.2, 20)}, chunk_paths=2)
        sol = solve(DuffingImpact(restitution=Elastic()), 0.05)
    return {
        "StationaryDensity": (stationary_density(model, "jump", h_max=4.0, points=300), "E[H]=0.51"),
        "PhaseDensity": (stationary_density_xy(model, grid=(40, 48), h_max=4.0, points=300), "E[H]="),
        "EnsembleStatistics": (ens, f"paths=16, E[H]={ens.mean_energy}"),
        "AutomatonEnsemble": (auto, "E[z]="),
        "OrbitResult": (orbit, "n_impacts=7"),
        "ImpactLog": (orbit.impacts, "7 transitions"),
        "Trajectory": (orbit.trajectory, "samples of ['x', 'y']"),
        "Solution": (sol, "Solution(method='exact', points="),
    }


@pytest.fixture(scope="module")
def results():
    return _results()


def test_reprs_are_one_short_line_with_the_key_numbers(results):
    for name, (obj, needle) in results.items():
        text = repr(obj)
        assert text.startswith(name) and needle in text, (name, text)
        assert "\n" not in text and len(text) < 250 and "array(" not in text, (name, text)


def test_html_tables_where_they_help(results):
    for name in ("StationaryDensity", "PhaseDensity", "EnsembleStatistics", "AutomatonEnsemble", "OrbitResult",
                 "Solution"):
        obj = results[name][0]
        page = obj._repr_html_()
        assert page.startswith("<table><caption>") and page.endswith("</table>") and len(page) < 3000, name
    assert "<td>exact" not in results["Solution"][0]._repr_html_()  # the method is the caption, the reason a row
    assert "Solution by exact" in results["Solution"][0]._repr_html_()


def test_every_result_converts_to_pandas(results):
    for name, (obj, _) in results.items():
        frame = obj.to_pandas()
        assert isinstance(frame, pd.DataFrame) and len(frame) > 0, name
    # an automaton ensemble's default table is its first histogrammed observable
    auto = results["AutomatonEnsemble"][0]
    assert auto.to_pandas().equals(auto.to_pandas("H"))
