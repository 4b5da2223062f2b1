"""The fitted error models: predicted L1 distance of p(H) for each method, from the diagnostics.

The constants are data, not code. ``vibro bench validity`` fits the averaging error model and ``vibro bench
work-precision`` the Monte Carlo bias constants; both write ``vibro/solve/data/*.json`` (package data), which this
module loads. Each file records how it was fitted.
"""

from __future__ import annotations

import json
import math
from functools import cache
from importlib import resources
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .diagnostics import Diagnostics

DATA_PACKAGE = "vibro.solve.data"
ERROR_MODEL_FILE = "error_model.json"
BIAS_FILE = "mc_bias.json"


@cache
def load_constants(name: str) -> dict:
    """The fitted constants stored as package data file ``name`` (a JSON object).

    Examples
    --------
    >>> sorted(load_constants(ERROR_MODEL_FILE))[1:3]
    ['exact', 'exact-two-impact']
    """
    with resources.files(DATA_PACKAGE).joinpath(name).open("r", encoding="utf-8") as fh:
        return json.load(fh)


def error_model() -> dict:
    """Averaging error model: L1 ~ floor + slope * r_imp + slope_damp * r_damp, per method (fitted)."""
    return load_constants(ERROR_MODEL_FILE)


def bias_constants() -> dict:
    """Monte Carlo bias of L1(p(H)) ~ C[scheme] * dt**weak_order (fitted on the elastic Duffing oracle)."""
    return {k: float(v) for k, v in load_constants(BIAS_FILE)["bias_constant"].items()}


MAX_DAMPING_RATIO = 0.6
"""Refuse averaging when the 90th-percentile energy level loses more than this share of H per cycle to the damping
force: the energy is then not slowly varying over a cycle (the quasi-conservative assumption of the paper breaks).
Impact losses are not counted here: the jump method treats large impact losses as jumps."""
MAX_IMPACT_RATIO = 0.9
"""Refuse averaging when the 90th-percentile energy loses more than this share to impacts in one quasi-period."""
MC_SCHEMES = ("splitting", "milstein")
"""Monte Carlo schemes in order of preference (splitting needs damping linear in y and noise free of y)."""
AVERAGING_GEOMETRIES = ("none", "symmetric")
"""Wall geometries on which the averaging error model was fitted (the paper's symmetric gaps, no walls)."""
FPK_GEOMETRIES = ("none", "symmetric", "equilibrium")
"""Wall geometries on which the fpk floor was measured: the paper's cases and the linear oscillator against a wall
at its equilibrium (benchmarks/density_accuracy.py: E[H] within 0.08 % and 0.69 % of Monte Carlo at r = 0.8, 0.6)."""
L1_BINS = 40
"""Bins of the common H grid on which every L1 distance of p(H) is measured."""


def predict_averaging_error(method: str, diag: Diagnostics) -> float:
    """Predicted L1 distance of an averaging method from converged Monte Carlo (the fitted error model).

    NaN (not measured) for ``paper``, ``jump`` and ``exact-two-impact`` on a barrier geometry other than a symmetric
    gap (or none): the constants were fitted there only. ``fpk`` is rated on those and on a wall at the equilibrium
    (:data:`FPK_GEOMETRIES`). ``exact`` holds for any walls (it is the elastic Gibbs density).

    Examples
    --------
    >>> from vibro.solve.diagnostics import Diagnostics
    >>> d = Diagnostics(True, True, False, 0.4, 0.9, 0.0, 0.01, 0.05, 0.0, 20.0, 0.55)
    >>> predict_averaging_error("paper", d) == error_model()["paper"]["floor"]
    True
    """
    rated = FPK_GEOMETRIES if method == "fpk" else AVERAGING_GEOMETRIES
    if method != "exact" and getattr(diag, "geometry", "symmetric") not in rated:
        return math.nan  # not measured on this geometry
    if method == "exact":
        m = error_model()["exact"]
        if not (diag.linear_damping and diag.additive_noise):
            return math.inf
        return m["floor"] + m["tail"] * diag.tail_impact_speed
    if method == "fpk":
        return error_model()["fpk"]["floor"]
    m = error_model()[method]
    damp = 0.0 if (diag.linear_damping and diag.additive_noise) else diag.r_damp
    return m["floor"] + m["slope"] * diag.r_imp + m["slope_damp"] * damp

