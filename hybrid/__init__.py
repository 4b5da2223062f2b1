"""Hybrid automata (flows, guards, resets) and their simulators."""

from .automaton import HybridAutomaton, Mode, Transition, real_symbol
from .errors import (
    ModelError,
    NormalisationError,
    ParameterError,
    RestitutionError,
    StepSizeError,
    VibroError,
)

__all__ = [
    "HybridAutomaton", "Mode", "Transition", "real_symbol", "ModelError", "NormalisationError", "ParameterError",
    "RestitutionError", "StepSizeError", "VibroError",
]
