"""Ensemble statistics at fixed times from a given start: E[obs](t_j) and p(obs, t_j), j = 1 .. n.

The automaton kernel already records its observables on sections taken every ``phase_steps`` steps (the
Poincaré sections of a forced model). With the burn-in at zero, ``t_end = T`` and the "period" T cut into n
sections, section j holds exactly the ensemble at t_j = j T / n (section 0 the one at t = T), one sample per path:
the ensemble at fixed times, with no second kernel. The statistics are sums and histograms per chunk, so they stream,
merge across chunks, threads and Dask workers, and resume from checkpoints like every other automaton statistic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.errors import ParameterError

from ._statistics import Estimate


@dataclass
class SnapshotEnsemble:
    """The ensemble at the times ``times`` (from the start x0 at t = 0): means with CIs and histograms.

    Attributes
    ----------
    times : ndarray (n,)
        t_j = j T / n, j = 1 .. n.
    ensemble : AutomatonEnsemble
        The run itself (its time averages cover [0, T]; its settings, counters and provenance).
    """

    times: np.ndarray
    ensemble: object

    @property
    def names(self) -> tuple:
        """The observables recorded."""
        return self.ensemble.names

    def _slot(self, j: int) -> int:
        n = len(self.times)
        if isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 <= j < n:
            raise ParameterError(f"time index {j!r} must be an integer in [0, {n})")
        return (int(j) + 1) % n  # section k holds t = k T / n; section 0 the end time T

    def mean(self, name: str, j: int) -> Estimate:
        """E[name](t_j) with a 95 % batch-means interval over the chunks of paths."""
        return self.ensemble.phase_mean(name, self._slot(j))

    def density(self, name: str, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(edges, density) of an observable at t_j, normalised by all paths (mass outside the range is lost)."""
        return self.ensemble.phase_density(name, self._slot(j))

    def means(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(E[name](t_j), CI half-width) for every j."""
        est = [self.mean(name, j) for j in range(len(self.times))]
        return np.array([e.value for e in est]), np.array([e.ci for e in est])

    def to_pandas(self):
        """Long DataFrame of the means: observable, t, mean, ci, samples (one per path at every time)."""
        import pandas as pd

        rows = []
        for name in self.names:
            for j, t in enumerate(self.times):
                est = self.mean(name, j)
                rows.append({"observable": name, "t": float(t), "mean": est.value, "ci": est.ci,
                             "samples": int(self.ensemble.phase_samples[:, self._slot(j)].sum())})
        return pd.DataFrame(rows)

    def histograms_to_pandas(self):
        """Long DataFrame of the histograms: observable, t, lo, hi, count, density (outside rows first and last)."""
        import pandas as pd

        frames = []
        for name in self.ensemble.phase_counts or {}:
            long = self.ensemble.phase_to_pandas(name)
            slot_time = {self._slot(j): t for j, t in enumerate(self.times)}
            long.insert(0, "t", long.pop("phase").map(slot_time))
            frames.append(long.drop(columns="t_phase").assign(observable=name))
        if not frames:
            return pd.DataFrame(columns=["observable", "t", "lo", "hi", "count", "density"])
        out = pd.concat(frames, ignore_index=True)
        return out[["observable", "t", "lo", "hi", "count", "density"]].sort_values(["observable", "t"],
                                                                                    kind="stable")

    def __repr__(self) -> str:
        return (f"SnapshotEnsemble({len(self.times)} times up to t = {self.times[-1]:g}, "
                f"{self.ensemble.settings['paths']} paths, observables {list(self.names)})")


def simulate_snapshots(automaton, scheme: str = "splitting", *, dt: float, paths: int, t_end: float, snapshots: int,
                       x0, seed: int = 1, **options) -> SnapshotEnsemble:
    """Monte Carlo statistics at the fixed times t_j = j t_end / snapshots from the start ``x0`` at t = 0.

    Parameters
    ----------
    automaton : HybridAutomaton or ImpactOscillator
        An oscillator model runs through its automaton.
    scheme, dt, paths, seed :
        As in :func:`simulate_automaton` (``dt`` is lowered so that every t_j falls on a step).
    t_end : float
        The last time; the ensemble is recorded at ``snapshots`` equally spaced times up to it.
    snapshots : int
        Number of times (at least 1).
    x0 : sequence of float
        The start of every path.
    **options
        ``observables``, ``histograms``, ``params``, ``chunk_paths``, ``scheduler``, ``checkpoint`` ... of
        :func:`simulate_automaton` (not ``t_burn``, ``phases`` or ``period``, which this function sets).

    Returns
    -------
    SnapshotEnsemble
        Means with CIs and histograms at each t_j; every path contributes exactly one sample per time (checked).

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> m = DuffingImpact(restitution=Ma(0.4))
    >>> snap = simulate_snapshots(m, "splitting", dt=0.01, paths=64, t_end=20.0, snapshots=4, x0=(0.0, 0.0),
    ...                           histograms={"H": (0.0, 4.0, 40)}, chunk_paths=8)  # doctest: +SKIP
    >>> snap.means("H")  # doctest: +SKIP
    """
    from ._auto_runner import simulate_automaton

    for name in ("t_burn", "phases", "period"):
        if name in options:
            raise ParameterError(f"simulate_snapshots sets {name} itself (the ensemble is recorded from t = 0)")
    if isinstance(snapshots, bool) or not isinstance(snapshots, (int, np.integer)) or snapshots < 1:
        raise ParameterError(f"snapshots={snapshots!r} must be a positive integer")
    if hasattr(automaton, "to_automaton"):  # an oscillator model (models sits above hybrid: no import)
        automaton = automaton.to_automaton()
    ens = simulate_automaton(automaton, scheme, dt=dt, paths=paths, t_end=t_end, t_burn=0.0, x0=x0, seed=seed,
                             phases=int(snapshots), period=t_end, **options)
    return snapshots_of(ens)


def snapshots_of(ens) -> SnapshotEnsemble:
    """The fixed-time view of an automaton run made with ``t_burn=0``, ``phases=n`` and ``period=t_end``.

    Checks that every path was seen exactly once at each of the n times (no silently missing section).
    """
    settings = ens.settings
    n = int(settings["phases"] or 0)
    if not n or settings["t_burn"] != 0 or not np.isclose(settings["period"], settings["t_end"], rtol=1e-12):
        raise ParameterError("snapshots need a run from t = 0 with phases=n and period=t_end")
    times = np.arange(1, n + 1) * (float(settings["t_end"]) / n)
    seen = ens.phase_samples.sum(axis=0)
    if not np.all(seen == settings["paths"]):
        raise ParameterError(f"the ensemble was seen {seen.tolist()} times at the {n} times, not once per path "
                             f"({settings['paths']}); choose t_end and dt so that t_end / (snapshots dt) is "
                             "close to an integer")
    return SnapshotEnsemble(times=times, ensemble=ens)
