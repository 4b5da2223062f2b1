"""The one writer of ``vibro mc`` outputs: oscillator, forced and automaton runs write their files here.

Every route writes the same shapes: the histogram CSV of ``--out`` (``NAME_lo,NAME_hi,count,density`` with an
underflow and an overflow row), ``STEM_transitions.csv`` (``transition,firings,rate``) for a model with walls or
transitions, the joint histogram of ``--joint`` (``x_lo,x_hi,y_lo,y_hi,count,density`` and a last row counting the
samples outside it), a provenance sidecar beside every file (the run's record; beside each file but ``--out`` it
says which output it describes), and ``--summary-json``. The record's ``results`` carry the same keys on every
route (:func:`common_results`), besides each route's own figures.
"""

from __future__ import annotations

import json
from pathlib import Path

from vibro.cli.common import beside  # noqa: F401  (the extra files' names: STEM_NAME.csv)

CSV_FLOATS = "%.17g"
"""Every float of every CSV in full precision."""


def transitions_frame(names, firings, rates):
    """Firings and rate (per unit time and path, after burn-in) of each transition or wall."""
    import pandas as pd

    return pd.DataFrame({"transition": list(names), "firings": [int(k) for k in firings], "rate": list(rates)})


def wall_transitions(barriers) -> list[str]:
    """The walls of an oscillator as the transitions of its automaton: 'left' and 'right' where finite.

    Examples
    --------
    >>> wall_transitions((0.0, float("inf")))
    ['left']
    """
    import math

    return [name for name, b in zip(("left", "right"), barriers) if b is not None and math.isfinite(float(b))]


def common_results(ens) -> dict:
    """The summary every route's record carries, from an :class:`~hybrid.stochastic.EnsembleStatistics` or an
    :class:`~hybrid.stochastic.AutomatonEnsemble`: paths, samples, wall_time, per observable its mean, CI and the
    share outside its histogram, rates and firings per transition, the counters, and ``mean_energy`` where H is
    an observable."""
    if hasattr(ens, "flags"):  # an automaton ensemble
        out = {"paths": ens.settings["paths"], "samples": ens.flags["samples"], "wall_time": ens.wall_time,
               "observables": {}, "rates": {t: ens.rate(t) for t in ens.transitions},
               "firings": {t: int(k) for t, k in zip(ens.transitions, ens.events)},
               "counters": {k: v for k, v in ens.flags.items() if k != "samples"}}
        for name in ens.names:
            est = ens.mean(name)
            out["observables"][name] = {"mean": est.value, "ci": est.ci,
                                        "outside": ens.outside_fraction(name) if name in ens.counts else None}
        if "H" in ens.names:
            est = ens.mean("H")
            out["mean_energy"] = {"value": est.value, "ci": est.ci}
        return out
    outside = ens.outside()
    walls = {"left": ens.impact_rate_left, "right": ens.impact_rate_right}
    sides = wall_transitions(ens.settings["model"]["barriers"])
    out = {"paths": ens.paths, "samples": ens.total("samples"), "wall_time": ens.wall_time,
           "observables": {"H": {"mean": ens.mean_energy.value, "ci": ens.mean_energy.ci,
                                 "outside": outside["H"]["fraction"]},
                           "x2": {"mean": ens.mean_x2.value, "ci": ens.mean_x2.ci, "outside": None},
                           "y2": {"mean": ens.mean_y2.value, "ci": ens.mean_y2.ci, "outside": None}},
           "rates": {t: walls[t].value for t in sides},
           "firings": {t: ens.total(f"impacts_{t}") for t in sides},
           # the automaton's counters under their names (the oscillator runs its automaton)
           "counters": {"event_overflow": ens.total("stuck"), "outside": ens.total("violations"),
                        "nonfinite": ens.total("nonfinite"), "joint_outside": ens.total("xy_out"),
                        "bad_reset": ens.total("bad_e")},
           "mean_energy": {"value": ens.mean_energy.value, "ci": ens.mean_energy.ci}}
    return out


def write_outputs(files: list, rec: dict, summary_json=None) -> list[Path]:
    """Write every output of a run: ``files`` is a list of ``(path, frame, label, settings)``; the first is
    ``--out`` and carries the record ``rec`` as its sidecar, each other one ``rec`` with ``output: label`` and its
    own extra ``settings`` (None: none). Then ``--summary-json`` (the record) when given. Every write is atomic.
    Returns the paths written (CSV files)."""
    from hybrid.stochastic import atomic_write_text
    from vibro.provenance import write_sidecar

    written = []
    for path, frame, _, _ in files:
        atomic_write_text(path, frame.to_csv(index=False, float_format=CSV_FLOATS))
        written.append(Path(path))
    for i, (path, _, label, extra) in enumerate(files):
        if i == 0:
            write_sidecar(path, rec)
        else:
            write_sidecar(path, {**rec, "output": label, "settings": {**rec["settings"], **(extra or {})}})
    if summary_json:
        atomic_write_text(summary_json, json.dumps(rec, indent=1))
    return written
