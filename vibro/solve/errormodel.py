"""The fitted error models: predicted L1 distance of p(H) for each method, from the diagnostics.

The constants are data, not code. ``benchmarks/method_ratings.py`` rates ``paper``, ``jump`` and ``chain``
against the phase-plane solver ``fpk`` over a sweep of models and writes the ratings into ``error_model.json``;
``vibro bench work-precision`` writes the Monte Carlo bias constants (``mc_bias.json``). Both are package data in
``vibro/solve/data``, which this module loads; each records how it was fitted.
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
L1_BINS = 40
"""Bins of the common H grid on which every L1 distance of p(H) is measured."""


RATED_METHODS = ("paper", "jump", "chain")
"""The averaging methods rated against fpk over the sweep of ``benchmarks/method_ratings.py``."""
RATING_FAMILIES = {"none": "symmetric", "symmetric": "symmetric", "asymmetric": "asymmetric",
                   "one-sided": "one-sided", "equilibrium": "equilibrium"}
"""The wall family whose rating applies to each barrier geometry (no walls: the symmetric family's)."""


RATING_FEATURES = ("log_r_imp", "log_r_damp", "self_excited", "linear_damping", "quasi_linear_log_r_imp",
                   "quasi_linear_log_r_damp")
"""What a rating's ``coef`` multiplies (:func:`rating_features`), after the family's ``log_scale``."""
RATING_SHIFT = 1e-4
"""Added to r_imp and r_damp before their logarithm (a ratio of 0 stays finite)."""


def rating_features(r_imp: float, r_damp: float, self_excited: bool, linear_damping: bool) -> tuple:
    """The features of :data:`RATING_FEATURES` (the quasi-linear class: linear damping, not self-excited).

    Parameters
    ----------
    r_imp, r_damp : float
        The model's impact and damping ratios (see :mod:`vibro.solve.diagnostics`).
    self_excited, linear_damping : bool
        The model's damping class.

    Returns
    -------
    tuple of float
        log(r_imp + shift), log(r_damp + shift), the two class flags, and the two logs again in the quasi-linear
        class (0 outside it).

    Examples
    --------
    >>> [round(v, 3) for v in rating_features(0.1, 0.2, False, True)]
    [-2.302, -1.609, 0.0, 1.0, -2.302, -1.609]
    """
    li, ld = math.log(r_imp + RATING_SHIFT), math.log(r_damp + RATING_SHIFT)
    quasi_linear = float(bool(linear_damping) and not self_excited)
    return li, ld, float(bool(self_excited)), float(bool(linear_damping)), quasi_linear * li, quasi_linear * ld


def _exponents(r: dict, diag: Diagnostics) -> tuple[float, float]:
    """The rating's power of (r_imp + shift) and of (r_damp + shift) for this model's class."""
    if "coef" not in r:  # the per-family power law of earlier ratings
        return r["exp_imp"], r["exp_damp"]
    c = r["coef"]
    quasi_linear = bool(diag.linear_damping) and not diag.self_excited
    return c[0] + (c[4] if quasi_linear else 0.0), c[1] + (c[5] if quasi_linear else 0.0)


def rating(method: str, diag: Diagnostics) -> dict | None:
    """The fitted rating of ``method`` that covers this model, or None where none does.

    None when the sweep has no rating for the wall family, when the noise is not additive (the sweep held additive
    noise only), or when the model's diagnostics (r_imp, r_damp) lie outside the box the sweep covered.

    Examples
    --------
    >>> from vibro.solve import diagnose
    >>> from models import DuffingImpact
    >>> rating("chain", diagnose(DuffingImpact()))["cases"] > 0
    True
    """
    fam = RATING_FAMILIES.get(getattr(diag, "geometry", "symmetric"))
    r = error_model().get("ratings", {}).get(method, {}).get(fam)
    if r is None or not diag.additive_noise:
        return None
    if _rated_features(r, diag) is None:
        return None
    return r


def _rated_features(r: dict, diag: Diagnostics):
    """(r_imp, r_damp) to evaluate the rating at, or None outside the rated box. Beyond the box on the side where
    the power law only grows with the distance (below the lowest r_imp for a positive exponent, ...), the box's
    edge is taken: the rating there bounds the model's from above."""
    out = []
    for name, exponent in zip(("r_imp", "r_damp"), _exponents(r, diag)):
        lo, hi = r["rated_box"][name]
        v = float(getattr(diag, name))
        if lo <= v <= hi:
            out.append(v)
        elif v < lo and exponent >= 0:
            out.append(lo)
        elif v > hi and exponent <= 0:
            out.append(hi)
        else:
            return None
    return out


def predict_averaging_error(method: str, diag: Diagnostics) -> float:
    """Predicted L1 error of p(H) (40 bins) of ``method`` for a model with these diagnostics.

    ``paper``, ``jump``, ``chain``: the rating fitted against fpk over the sweep (:func:`rating`: an upper quantile,
    exp(log_scale + coef . :func:`rating_features`)), NaN where no rating covers the model.
    ``exact``: the Gibbs formula's error from the neglected inelastic tail (inf without linear damping and additive
    noise). ``fpk``: the upper quantile of its own estimate at the default grid over the sweep (``solve`` reports
    the run's estimate). ``exact-two-impact``: the older fit against Monte Carlo on symmetric gaps (NaN elsewhere).

    Examples
    --------
    >>> from vibro.solve import diagnose
    >>> from models import DuffingImpact
    >>> d = diagnose(DuffingImpact())
    >>> predict_averaging_error("chain", d) < predict_averaging_error("paper", d)
    True
    """
    if method == "exact":
        m = error_model()["exact"]
        if not (diag.linear_damping and diag.additive_noise):
            return math.inf
        return m["floor"] + m["tail"] * diag.tail_impact_speed
    if method == "fpk":
        return error_model()["fpk"]["floor"]
    if method in RATED_METHODS:
        r = rating(method, diag)
        if r is None:
            return math.nan
        r_imp, r_damp = _rated_features(r, diag)
        if "coef" in r:
            x = rating_features(r_imp, r_damp, diag.self_excited, diag.linear_damping)
            return math.exp(r["log_scale"] + sum(c * v for c, v in zip(r["coef"], x)))
        return math.exp(r["log_scale"]) * (r_imp + r["shift"]) ** r["exp_imp"] * (r_damp + r["shift"]) ** r["exp_damp"]
    if getattr(diag, "geometry", "symmetric") not in AVERAGING_GEOMETRIES:
        return math.nan  # not measured on this geometry
    m = error_model()[method]
    damp = 0.0 if (diag.linear_damping and diag.additive_noise) else diag.r_damp
    return m["floor"] + m["slope"] * diag.r_imp + m["slope_damp"] * damp
