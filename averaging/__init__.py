"""Stochastic averaging of the energy envelope: symbolic coefficients, stationary and transient densities."""

from .methods import METHODS, ExactTwoImpactMethod, ImpactMethod, JumpMethod, PaperMethod, get_method, register
from .quadrature import action, orbit_integrals, period, turning_points
from .stationary import (
    AveragedCoefficients,
    StationaryDensity,
    averaged_coefficients,
    check_confinement,
    energy_table,
    stationary_density,
)
from .symbolic import AveragingEquations, averaging_equations
from .transient import TransientDensity, mean_first_passage_time, transient_density

__all__ = [
    "METHODS", "AveragedCoefficients", "AveragingEquations", "ExactTwoImpactMethod", "ImpactMethod", "JumpMethod",
    "PaperMethod", "StationaryDensity", "action", "averaged_coefficients", "averaging_equations",
    "check_confinement", "energy_table", "get_method", "orbit_integrals", "period", "register",
    "mean_first_passage_time", "stationary_density", "transient_density", "TransientDensity", "turning_points",
]
