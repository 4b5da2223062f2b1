"""Deterministic, event-exact orbits of hybrid automata and impact oscillators.

Two backends share one driver and one result type: ``'heyoka'`` (Taylor integration with terminal events,
compiled once per automaton structure) and ``'scipy'`` (DOP853 or another ``OdeSolver``, events located on the
dense output).

Examples
--------
>>> from models import DuffingImpact, Elastic
>>> from hybrid.deterministic import simulate_orbit
>>> res = simulate_orbit(DuffingImpact(c=0, D=0, restitution=Elastic()), x0=(0.0, 2.0), t_end=10.0)
>>> res.status
'ok'
"""

from ._base import Advance, OrbitBackend
from ._core import BACKENDS, simulate_orbit
from ._heyoka import HeyokaBackend
from ._result import STATUSES, ImpactLog, OrbitResult, Trajectory, write_csv_atomically
from ._scipy import METHODS, ScipyBackend
from ._zeno import ZenoDetector

__all__ = [
    "BACKENDS", "METHODS", "STATUSES", "Advance", "HeyokaBackend", "ImpactLog", "OrbitBackend", "OrbitResult",
    "ScipyBackend", "Trajectory", "ZenoDetector", "simulate_orbit", "write_csv_atomically",
]
