"""Method choice: diagnose a model, predict each method's error from fitted constants, choose the cheapest one that
reaches the tolerance, and run it. Every L1 distance in the project comes from :mod:`vibro.solve.metrics`.

Examples
--------
>>> from models import DuffingImpact, Elastic
>>> choose(DuffingImpact(restitution=Elastic())).method
'exact'
"""

from .choice import Choice, choose
from .diagnostics import Diagnostics, cycle_quantities, diagnose
from .errormodel import (
    L1_BINS,
    MAX_DAMPING_RATIO,
    MAX_IMPACT_RATIO,
    MC_SCHEMES,
    bias_constants,
    error_model,
    predict_averaging_error,
)
from .metrics import bin_masses, l1_between_histograms, l1_masses, rebin_counts
from .planner import pick_scheme
from .solver import Solution, solve

__all__ = [
    "Choice", "Diagnostics", "L1_BINS", "MAX_DAMPING_RATIO", "MAX_IMPACT_RATIO", "MC_SCHEMES", "Solution",
    "bias_constants", "bin_masses", "choose", "cycle_quantities", "diagnose", "error_model", "l1_between_histograms",
    "l1_masses", "pick_scheme", "predict_averaging_error", "rebin_counts", "solve",
]
