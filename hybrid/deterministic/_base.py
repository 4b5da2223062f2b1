"""The backend interface shared by the deterministic simulators.

A backend integrates the flow of one mode until ``t_end`` or until a guard of that mode crosses zero, whichever
comes first, and stops exactly there. The driver (:func:`~hybrid.deterministic.simulate_orbit`) applies the reset,
logs the transition, watches for Zeno behaviour and restarts the backend. To add a backend, subclass
:class:`OrbitBackend`, implement ``start``, ``advance`` and ``restart``, and add it to ``BACKENDS``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.automaton import HybridAutomaton


@dataclass
class Advance:
    """What :meth:`OrbitBackend.advance` reports.

    ``fired`` is the index (into ``automaton.transitions``) of the transition whose guard stopped the integration,
    or None when ``t_end`` was reached; ``failed`` carries a message when the integrator gave up.
    """

    t: float
    state: np.ndarray
    fired: int | None
    steps: int
    failed: str | None = None


class OrbitBackend:
    """Base class of the deterministic backends.

    Parameters
    ----------
    automaton : HybridAutomaton
    params : dict
        Parameter values, in ``automaton.parameters`` order.
    rtol, atol : float or None
        Tolerances (the backend's defaults when None).
    dense : bool
        Record the state after every step in :attr:`samples`.
    options : dict
        Backend-specific options (``method`` for scipy).
    """

    name = "base"
    order: int | None = None

    def __init__(self, automaton: HybridAutomaton, params: dict, rtol=None, atol=None, dense=False, **options):
        self.automaton = automaton
        self.params = dict(params)
        self.rtol = rtol
        self.atol = atol
        self.dense = dense
        self.options = options
        self.samples: list[tuple[float, np.ndarray, str]] = []
        self.compile_time = 0.0

    def start(self, t0: float, state: np.ndarray, mode: str) -> None:
        """Set the initial time, state and mode."""
        raise NotImplementedError

    def advance(self, t_end: float) -> Advance:
        """Integrate until ``t_end`` or the first guard crossing of the current mode."""
        raise NotImplementedError

    def restart(self, t: float, state: np.ndarray, mode: str, fired: int | None = None) -> None:
        """Continue from a state just after the reset of transition ``fired`` (same time), maybe in another mode.

        A guard that is zero at the restart point is not a crossing; the guard of ``fired`` must not fire again
        because of the rounding of the event location (a cooldown).
        """
        raise NotImplementedError

    def settings(self) -> dict:
        """The options in effect (for the result's metadata)."""
        return {"rtol": self.rtol, "atol": self.atol}
