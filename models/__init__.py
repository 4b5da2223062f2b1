"""Impact models: restitution laws, the impact-oscillator base class and the paper's examples."""

from .builtin import MODELS, DuffingImpact, DuffingVanDerPolImpact, ForcedDuffingImpact, RayleighImpact, make_model
from .oscillator import ImpactOscillator, X, Y
from .restitution import (
    SPEED,
    CustomRestitution,
    Elastic,
    Ma,
    Newton,
    RestitutionLaw,
    parse_restitution,
)

__all__ = [
    "MODELS", "SPEED", "X", "Y", "CustomRestitution", "DuffingImpact", "DuffingVanDerPolImpact", "Elastic",
    "ForcedDuffingImpact", "ImpactOscillator", "Ma", "Newton", "RayleighImpact", "RestitutionLaw", "make_model",
    "parse_restitution",
]
