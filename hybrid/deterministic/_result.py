"""Result types of the deterministic simulators: :class:`ImpactLog`, :class:`Trajectory`, :class:`OrbitResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybrid.io import write_csv_atomically

STATUSES = ("ok", "zeno", "chattering", "max_impacts", "max_steps", "left_admissible_set", "failed")
"""Possible values of :attr:`OrbitResult.status`."""


@dataclass
class ImpactLog:
    """Every transition (impact) of an orbit: time, which transition, state and observables before and after.

    Attributes
    ----------
    t : ndarray (n,)
        Transition times.
    transition : ndarray of str (n,)
        Transition names (for an impact oscillator: ``'right'`` or ``'left'``, the barrier).
    source, target : ndarray of str (n,)
        Modes before and after.
    before, after : ndarray (n, d)
        States just before and just after the reset.
    observables_before, observables_after : dict of str to ndarray (n,)
        The automaton's observables (for an impact oscillator, the energy ``H``).
    state_names : tuple of str
    oscillator : bool
        True when the log belongs to an impact oscillator: :meth:`to_pandas` then gives the columns
        ``t, x, v_minus, v_plus, e, H_minus, H_plus, barrier``.

    Examples
    --------
    >>> from models import DuffingImpact, Newton
    >>> from hybrid.deterministic import simulate_orbit
    >>> m = DuffingImpact(c=0, D=0, restitution=Newton(0.9))
    >>> log = simulate_orbit(m, x0=(0.0, 2.0), t_end=3.0).impacts
    >>> list(log.to_pandas().columns)
    ['t', 'x', 'v_minus', 'v_plus', 'e', 'H_minus', 'H_plus', 'barrier']
    """

    t: np.ndarray
    transition: np.ndarray
    source: np.ndarray
    target: np.ndarray
    before: np.ndarray
    after: np.ndarray
    observables_before: dict = field(default_factory=dict)
    observables_after: dict = field(default_factory=dict)
    state_names: tuple = ()
    oscillator: bool = False

    def __len__(self) -> int:
        return len(self.t)

    def __repr__(self) -> str:
        span = f", t={float(self.t[0]):.6g}..{float(self.t[-1]):.6g}" if len(self.t) else ""
        kinds = {str(k): int(n) for k, n in zip(*np.unique(self.transition, return_counts=True))}
        return f"ImpactLog({len(self.t)} transitions{span}, {kinds})"

    @property
    def x(self) -> np.ndarray:
        """Impact positions (first state variable)."""
        return self.before[:, 0]

    @property
    def v_minus(self) -> np.ndarray:
        """Velocity before each impact (second state variable)."""
        return self.before[:, 1]

    @property
    def v_plus(self) -> np.ndarray:
        """Velocity after each impact."""
        return self.after[:, 1]

    @property
    def e(self) -> np.ndarray:
        """Applied restitution coefficient -v_plus / v_minus (1 where v_minus = 0: a grazing contact)."""
        vm, vp = self.v_minus, self.v_plus
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(vm != 0.0, -vp / np.where(vm != 0.0, vm, 1.0), 1.0)

    def to_pandas(self):
        """The log as a DataFrame (impact-oscillator columns, or generic ``<state>_minus/_plus`` columns).

        Generic automata give ``t, transition, source, target``, then ``<name>_minus``, ``<name>_plus`` for every
        state and observable.
        """
        import pandas as pd

        if self.oscillator:
            cols = {"t": self.t, "x": self.x, "v_minus": self.v_minus, "v_plus": self.v_plus, "e": self.e}
            for k in self.observables_before:
                cols[f"{k}_minus"] = self.observables_before[k]
                cols[f"{k}_plus"] = self.observables_after[k]
            cols["barrier"] = self.transition
            return pd.DataFrame(cols)
        cols = {"t": self.t, "transition": self.transition, "source": self.source, "target": self.target}
        for i, name in enumerate(self.state_names):
            cols[f"{name}_minus"] = self.before[:, i]
            cols[f"{name}_plus"] = self.after[:, i]
        for k in self.observables_before:
            cols[f"{k}_minus"] = self.observables_before[k]
            cols[f"{k}_plus"] = self.observables_after[k]
        return pd.DataFrame(cols)

    def to_csv(self, path) -> Path:
        """Write :meth:`to_pandas` to ``path`` atomically (temporary file and rename)."""
        return write_csv_atomically(self.to_pandas(), path)


@dataclass
class Trajectory:
    """Orbit samples at every integrator step and on both sides of every transition.

    Attributes
    ----------
    t : ndarray (n,)
    y : ndarray (n, d)
    mode : ndarray of str (n,)
    state_names : tuple of str
    """

    t: np.ndarray
    y: np.ndarray
    mode: np.ndarray
    state_names: tuple = ()

    def __repr__(self) -> str:
        span = f", t={float(self.t[0]):.6g}..{float(self.t[-1]):.6g}" if len(self.t) else ""
        return f"Trajectory({len(self.t)} samples of {list(self.state_names)}{span})"

    def to_pandas(self):
        """DataFrame with columns ``t``, one per state, and ``mode``."""
        import pandas as pd

        cols = {"t": self.t}
        cols.update({name: self.y[:, i] for i, name in enumerate(self.state_names)})
        cols["mode"] = self.mode
        return pd.DataFrame(cols)

    def to_csv(self, path) -> Path:
        """Write :meth:`to_pandas` atomically."""
        return write_csv_atomically(self.to_pandas(), path)


@dataclass
class OrbitResult:
    """Outcome of :func:`~hybrid.deterministic.simulate_orbit`.

    Attributes
    ----------
    status : str
        ``'ok'`` (reached ``t_end``), ``'zeno'`` (impact times accumulate geometrically; see ``zeno_time``),
        ``'chattering'`` (two transitions closer than ``min_dwell``), ``'max_impacts'``, ``'max_steps'`` (the step
        budget ran out before ``t_end``), ``'left_admissible_set'`` (a step ended past a guard: the integrator
        missed an impact, and the run stopped there) or ``'failed'``.
    message : str
    t, state, mode : final time, state and mode
    impacts : ImpactLog
    n_steps, n_impacts : int
    zeno_time : float or None
        Predicted accumulation time t_k + dt_k r / (1 - r) when ``status == 'zeno'``.
    trajectory : Trajectory or None
        Only with ``dense=True``.
    backend : str
    settings : dict
        Every option used (tolerances, min_dwell, max_impacts, ...).
    compile_time, wall_time : float
        Seconds spent compiling (0 when cached) and in the whole call.

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> from hybrid.deterministic import simulate_orbit
    >>> res = simulate_orbit(DuffingImpact(c=0, D=0, restitution=Elastic()), x0=(0.0, 2.0), t_end=10.0)
    >>> res.status, res.n_impacts == len(res.impacts)
    ('ok', True)
    """

    status: str
    message: str
    t: float
    state: np.ndarray
    mode: str
    impacts: ImpactLog
    n_steps: int
    n_impacts: int
    zeno_time: float | None = None
    trajectory: Trajectory | None = None
    backend: str = ""
    settings: dict = field(default_factory=dict)
    compile_time: float = 0.0
    wall_time: float = 0.0

    @property
    def success(self) -> bool:
        """True when the orbit reached ``t_end``."""
        return self.status == "ok"

    def to_pandas(self):
        """The impact log as a DataFrame (see :meth:`ImpactLog.to_pandas`)."""
        return self.impacts.to_pandas()

    def to_csv(self, path) -> Path:
        """Write the impact log atomically."""
        return self.impacts.to_csv(path)

    def __repr__(self) -> str:
        return (f"OrbitResult(status={self.status!r}, t={self.t:.6g}, n_impacts={self.n_impacts}, "
                f"n_steps={self.n_steps}, backend={self.backend!r})")

    def _repr_html_(self) -> str:
        from hybrid.display import summary_html

        return summary_html(f"OrbitResult ({self.backend})", {
            "status": self.status, "message": self.message, "t": self.t, "impacts": self.n_impacts,
            "steps": self.n_steps, "wall time (s)": self.wall_time})
