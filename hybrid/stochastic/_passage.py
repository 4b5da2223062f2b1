"""First passage out of a safe domain, by event-exact Monte Carlo of any automaton.

The safe domain is a set of inequalities in the states, parameters, observables and t (``"H < 2.0"``,
``"abs(x) <= 0.8"``). Each one becomes a transition of the automaton, guarded by the inequality's slack and fired
on its upward crossing: every scheme locates it inside the step, as it locates an impact (velocity-dependent guards
included). The transition leads to an absorbing mode ``passed_`` where the path is parked: its velocities are set to
zero, so its positions no longer move, and its first position is set to ``-(MARK + t)``, t being the located
instant of the exit. One histogrammed observable, ``-q - MARK``, then reads the exit time of every path that has
left, and sends every path that has not to the underflow bin. Recorded on the kernel's sections at t_j = j T / n
(as :mod:`._snapshots` does), it gives the survival R(t_j) = P(T_exit > t_j) with every path counted, and at
t = T the histogram of the exit times. No second kernel, no change of the engine: the statistics stream, merge
across chunks, threads and Dask workers, and are reproducible from the seed like every automaton run.

Censoring is at T only (all paths start at t = 0), so the Kaplan-Meier estimate is the empirical survival, and
its 95 % interval is the Wilson score interval of a binomial proportion.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import sympy as sp

from hybrid.errors import ModelError, ParameterError, VibroWarning

from ._statistics import Estimate

MARK = 1.0e6
"""Offset of the parked position: far beyond the coordinates of a model, yet the exit time keeps ~1e-10 resolution."""

PASSED_MODE = "passed_"
_ROUNDING = 1e-6  # the mark's rounding (~1e-10) can put an exit in the last step a hair above t_max


class CensoredWarning(VibroWarning):
    """Some paths had not left the domain by the end of the run: the mean exit time is a lower bound."""


def exit_guards(automaton, domain) -> list[sp.Expr]:
    """The guards g (exit when g crosses zero upward) of a safe domain written as inequalities.

    Parameters
    ----------
    automaton : HybridAutomaton
    domain : str or sympy relational or sequence of them
        Inequalities joined by ``&`` (or given as a list), in the automaton's states, parameters, observables and
        t: ``"H < 2.0"``, ``"abs(x) <= 0.8"``, ``"x > -0.5 & y < 1"``.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> exit_guards(DuffingImpact().to_automaton(), "H < 2")
    [a*x**2/2 + b*x**4/4 + y**2/2 - 2]
    """
    from hybrid.automaton import _LOCALS, canonical

    parts = domain
    if isinstance(domain, str):
        parts = [p for p in domain.split("&") if p.strip()]
    elif not isinstance(domain, (list, tuple)):
        parts = [domain]
    if not parts:
        raise ParameterError(f"domain {domain!r} has no inequality; write it as e.g. 'H < 2.0'")
    names = {str(s) for s in automaton.states} | set(automaton.parameters) | {"t"}
    observables = {k: canonical(v) for k, v in automaton.observables.items()}
    guards = []
    for part in parts:
        try:
            rel = (sp.sympify(part, locals={**_LOCALS, "abs": sp.Abs}) if isinstance(part, str)
                   else sp.sympify(part))
        except Exception as exc:  # the user's text: any failure is a bad domain, said in one line
            raise ParameterError(f"cannot read the domain {str(part).strip()!r}: write an inequality such as "
                                 "'H < 2.0' or 'abs(x) <= 0.8'") from exc
        if not isinstance(rel, (sp.StrictLessThan, sp.LessThan, sp.StrictGreaterThan, sp.GreaterThan)):
            raise ParameterError(f"the domain {str(part).strip()!r} is not an inequality (<, <=, >, >=): write "
                                 "e.g. 'H < 2.0'")
        slack = rel.lhs - rel.rhs if isinstance(rel, (sp.StrictLessThan, sp.LessThan)) else rel.rhs - rel.lhs
        slack = canonical(slack)  # symbols compare by name, as in the automaton
        slack = slack.xreplace({s: observables[s.name] for s in slack.free_symbols if s.name in observables})
        unknown = sorted({s.name for s in slack.free_symbols} - names)
        if unknown:
            raise ParameterError(f"the domain {str(part).strip()!r} uses {unknown}, which are not states, "
                                 f"parameters or observables of the model ({sorted(names - {'t'})}, "
                                 f"{sorted(observables)}, t)")
        guards.append(sp.expand(slack))
    return guards


def passage_automaton(automaton, domain):
    """The automaton with its exit transitions into the absorbing mode ``passed_`` (see the module's text).

    Returns
    -------
    (HybridAutomaton, sympy.Symbol)
        The automaton and the position that carries the parked path's mark.
    """
    from hybrid.automaton import HybridAutomaton, Mode, Transition

    from ._auto_codegen import analyse

    if any(m.name == PASSED_MODE for m in automaton.modes):
        raise ModelError(f"the automaton already has a mode named {PASSED_MODE!r}")
    guards = exit_guards(automaton, domain)
    pairs = dict(analyse(automaton).pairs)  # position index -> velocity index
    velocities = set(pairs.values())
    marked = min(pairs) if pairs else 0
    t = sp.Symbol("t")
    reset = tuple(-(MARK + t) if i == marked else (sp.Integer(0) if i in velocities else s)
                  for i, s in enumerate(automaton.states))
    # parked: positions move at their (zero) velocities, every other state is still; no noise, no transition
    flow = tuple(automaton.states[pairs[i]] if i in pairs else sp.Integer(0) for i in range(len(automaton.states)))
    parked = Mode(PASSED_MODE, flow, tuple(sp.Integer(0) for _ in automaton.states))
    exits = [Transition(f"exit{k}_" if len(guards) > 1 else "exit_", mode.name, PASSED_MODE, guard=g, direction=1,
                        reset=reset)
             for mode in automaton.modes for k, g in enumerate(guards)]
    out = HybridAutomaton(automaton.states, automaton.parameters, (*automaton.modes, parked),
                          (*automaton.transitions, *exits), automaton.initial_mode, automaton.observables,
                          automaton.positive, automaton.nonnegative)
    return out, automaton.states[marked], guards


def _wilson(k: np.ndarray, n: int, z: float = 1.959963984540054) -> tuple[np.ndarray, np.ndarray]:
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    # the interval holds p (at p = 0 or 1 rounding can put an end a hair inside) and lies in [0, 1]
    return np.clip(np.minimum(centre - half, p), 0, 1), np.clip(np.maximum(centre + half, p), 0, 1)


@dataclass
class PassageEnsemble:
    """First passage out of a safe domain by Monte Carlo: the survival, the exit-time histogram, the mean time.

    Attributes
    ----------
    times : ndarray (n,)
        t_j = j T / n, where the survival is recorded.
    survivors : ndarray (n,) of int
        Paths still inside the domain at t_j.
    paths : int
    time_edges, time_counts : ndarray
        Histogram of the located exit times on [0, T] (the paths that left).
    ensemble : AutomatonEnsemble
        The run (settings, counters).
    """

    times: np.ndarray
    survivors: np.ndarray
    paths: int
    time_edges: np.ndarray
    time_counts: np.ndarray
    ensemble: object

    @property
    def survival(self) -> np.ndarray:
        """R(t_j) = P(T_exit > t_j): the share of the paths still inside."""
        return self.survivors / self.paths

    def survival_interval(self) -> tuple[np.ndarray, np.ndarray]:
        """95 % Wilson interval of R(t_j) (binomial: the paths are independent)."""
        return _wilson(self.survivors.astype(float), self.paths)

    @property
    def censored(self) -> int:
        """Paths still inside the domain at the end T."""
        return int(self.survivors[-1])

    def mean_time(self) -> Estimate:
        """The mean exit time with a 95 % interval (normal, from the sample variance of the binned times).

        With censored paths it is the mean of min(T_exit, T), a lower bound of the mean exit time, and a
        :class:`CensoredWarning` says so. The exit times are binned on [0, T]: the binning moves the mean by at most
        half a bin width (``time_edges``), far below the interval at the default 20,000 bins.
        """
        mid = 0.5 * (self.time_edges[1:] + self.time_edges[:-1])
        t_end = float(self.time_edges[-1])
        n = self.paths
        total = float(self.time_counts @ mid + self.censored * t_end)
        square = float(self.time_counts @ mid**2 + self.censored * t_end**2)
        mean = total / n
        var = max(square / n - mean * mean, 0.0) * n / max(n - 1, 1)
        if self.censored:
            warnings.warn(f"{self.censored} of {n} paths had not left the domain by t = {t_end:g}: the mean exit "
                          "time is at least the printed mean of min(T_exit, t_end); raise t_max", CensoredWarning,
                          stacklevel=2)
        return Estimate(mean, 1.959963984540054 * math.sqrt(var / n), n)

    def density(self) -> tuple[np.ndarray, np.ndarray]:
        """(edges, f) of the exit time: the first-passage density on [0, T], normalised by all paths."""
        return self.time_edges, self.time_counts / self.paths / np.diff(self.time_edges)

    def to_pandas(self):
        """The survival curve: columns t, R, R_lo, R_hi, inside (t = 0 first, R = 1)."""
        import pandas as pd

        lo, hi = self.survival_interval()
        return pd.DataFrame({"t": np.concatenate([[0.0], self.times]),
                             "R": np.concatenate([[1.0], self.survival]),
                             "R_lo": np.concatenate([[1.0], lo]), "R_hi": np.concatenate([[1.0], hi]),
                             "inside": np.concatenate([[self.paths], self.survivors]).astype(int)})

    def __repr__(self) -> str:
        return (f"PassageEnsemble({self.paths} paths, {self.paths - self.censored} left by t = {self.times[-1]:g}, "
                f"R(t) at {len(self.times)} times)")


def simulate_first_passage(automaton, domain, scheme: str = "splitting", *, dt: float, paths: int, t_max: float,
                           x0, seed: int = 1, snapshots: int = 200, time_bins: int = 20_000,
                           **options) -> PassageEnsemble:
    """First passage out of ``domain`` from ``x0`` by event-exact Monte Carlo.

    Parameters
    ----------
    automaton : HybridAutomaton or ImpactOscillator
    domain : str or sympy relational or sequence
        The safe domain, e.g. ``"H < 2.0"`` (see :func:`exit_guards`); ``x0`` must lie inside it.
    scheme, dt, paths, seed :
        As in :func:`simulate_automaton`.
    t_max : float
        End of the run: paths still inside then are censored (counted, and reported).
    snapshots : int
        Times t_j = j t_max / snapshots at which R(t_j) is recorded.
    time_bins : int
        Bins of the exit-time histogram on [0, t_max].
    **options
        ``params``, ``chunk_paths``, ``scheduler``, ``checkpoint``, ``resume`` of :func:`simulate_automaton`.

    Returns
    -------
    PassageEnsemble

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> run = simulate_first_passage(DuffingImpact(restitution=Ma(0.4)), "H < 1.0", dt=0.01, paths=256,
    ...                              t_max=400.0, x0=(0.0, 0.0), chunk_paths=16)   # doctest: +SKIP
    >>> run.mean_time()                                                           # doctest: +SKIP
    """
    from ._auto_runner import simulate_automaton

    for name in ("t_burn", "phases", "period", "observables", "histograms", "t_end", "stride"):
        if name in options:
            raise ParameterError(f"simulate_first_passage sets {name} itself")
    if isinstance(snapshots, bool) or not isinstance(snapshots, (int, np.integer)) or not 1 <= snapshots <= 10**5:
        raise ParameterError(f"snapshots={snapshots!r} must be an integer in 1..1e5")
    if isinstance(time_bins, bool) or not isinstance(time_bins, (int, np.integer)) or not 1 <= time_bins <= 10**7:
        raise ParameterError(f"time_bins={time_bins!r} must be an integer in 1..1e7")
    if hasattr(automaton, "to_automaton"):  # an oscillator model (models sits above hybrid: no import)
        automaton = automaton.to_automaton()
    passage, mark, guards = passage_automaton(automaton, domain)
    values = automaton.resolve_parameters(options.get("params") or {})
    start = {s: float(v) for s, v in zip(automaton.states, np.atleast_1d(np.asarray(x0, dtype=float)))}
    subs = {**{str(k): v for k, v in start.items()}, **values, "t": 0.0}
    for g in guards:
        slack = (float(g.xreplace({s: subs[s.name] for s in g.free_symbols}))
                 if len(start) == len(automaton.states) else -1.0)
        if not slack < 0:
            raise ParameterError(f"the start x0 = {list(start.values())} is not inside the domain {domain!r} "
                                 f"({g} = {slack:g} must be < 0 there)")
    t_max = float(t_max)
    with warnings.catch_warnings():  # the paths still inside are in the underflow bin by design, and counted
        warnings.filterwarnings("ignore", message=".*samples of 'exit_time' fall outside its histogram range")
        ens = simulate_automaton(passage, scheme, dt=dt, paths=paths, t_end=t_max, t_burn=0.0, x0=x0, seed=seed,
                                 observables={"exit_time": -mark - MARK},
                                 histograms={"exit_time": (0.0, t_max + _ROUNDING, int(time_bins))},
                                 phases=int(snapshots),
                                 period=t_max, stride=max(1, int(t_max / dt)), **options)
    counts = ens.phase_counts["exit_time"]  # section k holds t = k T / n, section 0 the end T
    order = [(j + 1) % snapshots for j in range(snapshots)]
    seen = counts.sum(axis=1)
    n = ens.settings["paths"]
    if not np.all(seen == n):
        raise ParameterError(f"the paths were seen {seen.tolist()} times at the {snapshots} times, not once each "
                             f"({n}); choose t_max and dt so that t_max / (snapshots dt) is close to an integer")
    left = np.array([counts[k][1:].sum() for k in order])  # inside [0, T] or above it: left the domain
    final = counts[0]
    if final[-1]:  # an exit time above T: impossible unless a path reached the mark by its own motion
        raise ParameterError(f"{int(final[-1])} paths reached the parking mark by their own motion; the model's "
                             f"first position must stay far below {MARK:g} in size")
    return PassageEnsemble(times=np.arange(1, snapshots + 1) * (t_max / snapshots), survivors=n - left, paths=n,
                           time_edges=ens.edges["exit_time"], time_counts=final[1:-1].copy(), ensemble=ens)
