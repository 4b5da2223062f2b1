"""vibro: stochastic vibro-impact and other hybrid dynamical systems, from one declaration to every engine.

The application layer over the libraries ``hybrid`` (automata, orbits, Monte Carlo), ``models`` (what a user
declares) and ``averaging`` (energy-envelope densities). ``import vibro`` is enough for the quickstart; the names
below load their modules on first use, so the command line starts fast.

Examples
--------
>>> import vibro
>>> model = vibro.DuffingImpact(restitution=vibro.Ma(vc=0.4))
>>> round(vibro.stationary_density(model, method="jump", h_max=4.0).mean_energy, 2)
0.52
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"

_EXPORTS = {
    # models
    "ImpactOscillator": "models", "DuffingImpact": "models", "DuffingVanDerPolImpact": "models",
    "RayleighImpact": "models", "Elastic": "models", "Newton": "models", "Ma": "models",
    "CustomRestitution": "models", "parse_restitution": "models",
    # engines
    "HybridAutomaton": "hybrid", "Mode": "hybrid", "Transition": "hybrid",
    "simulate_orbit": "hybrid.deterministic", "simulate_ensemble": "hybrid.stochastic",
    "sample_paths": "hybrid.stochastic", "EnsembleStatistics": "hybrid.stochastic",
    # densities
    "stationary_density": "averaging", "transient_density": "averaging",
    "mean_first_passage_time": "averaging",
    # first passage and spectra
    "first_passage": "vibro.passage", "spectrum": "vibro.passage",
    # method choice
    "solve": "vibro.solve", "choose": "vibro.solve", "diagnose": "vibro.solve",
    # errors and warnings
    "VibroError": "hybrid.errors", "ModelError": "hybrid.errors", "ParameterError": "hybrid.errors",
}

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'vibro' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__():
    return __all__
