"""Hybrid automata (flows, guards, resets) and their simulators.

Names load on first use (sympy is imported only when an automaton is needed), so that light users such as the
command-line parser and ``hybrid.errors`` start fast.
"""

from __future__ import annotations

import importlib

from .errors import (
    ModelError,
    NormalisationError,
    ParameterError,
    RestitutionError,
    StepSizeError,
    VibroError,
)

_LAZY = {"HybridAutomaton": ".automaton", "Mode": ".automaton", "Transition": ".automaton",
         "real_symbol": ".automaton"}

__all__ = [
    "HybridAutomaton", "Mode", "Transition", "real_symbol", "ModelError", "NormalisationError", "ParameterError",
    "RestitutionError", "StepSizeError", "VibroError",
]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'hybrid' has no attribute {name!r}")
