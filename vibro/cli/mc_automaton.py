"""``vibro mc`` for automaton models: built-in or user automata, filtered (coloured-noise) models, observables.

Kept apart from ``cmd_mc.py`` (which calls :func:`add_arguments` and :func:`automaton_from_args`), so the
oscillator path and this one change independently. An automaton runs through
``hybrid.stochastic.simulate_automaton``:

    vibro mc --model impact_pair --scheme splitting --dt 0.01 --paths 64 --t-end 500 --range z=-0.2:0.2:20 --out h.csv
    vibro mc --model duffing --filter ou --param alpha=5 --scheme splitting --dt 0.01 --out h.csv
    vibro mc --model my.py:build --observable "rel=x2 - x1" --range rel=-1:1:40 --out h.csv --summary-json s.json

Files: ``--out`` holds the histogram of the energy ``H`` when the model declares one (``H_lo,H_hi,count,density``,
as for oscillators; otherwise of the first observable), each other observable NAME goes to ``STEM_NAME.csv``
(``NAME_lo,NAME_hi,count,density``), firings and rates per transition to ``STEM_transitions.csv``, and with
``--events K`` each path's first K firings to ``STEM_events.csv`` (``path,k,t,transition,speed``); the first and
last histogram rows count the samples below and above the range. Every file is written atomically.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

from hybrid.errors import ParameterError
from hybrid.sizes import check_size
from vibro.cli.common import beside

FILTERS = ("bandpass", "ou")
"""Names of ``models.excitation.FILTER_KINDS`` (kept here so that ``vibro --help`` imports no sympy)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of the automaton path of ``vibro mc``."""
    g = p.add_argument_group(
        "automaton models",
        "--model also takes impact_pair, vibrating_table, or path/to/file.py:NAME where NAME is a HybridAutomaton, "
        "or a function or class returning one; --filter, --observable or --range also send an oscillator model "
        "through the automaton engine (schemes em, milstein, splitting, symplectic, baoab; --param sets automaton "
        "and filter parameters).")
    g.add_argument("--filter", default=None, choices=FILTERS,
                   help="drive the model by coloured noise: ou (Ornstein-Uhlenbeck, --param alpha=BANDWIDTH) or "
                        "bandpass (--param zeta=... --param omega_f=...); the output tends to the white noise of the "
                        "same intensity as the bandwidth grows")
    g.add_argument("--observable", action="append", default=[], metavar="NAME=EXPR",
                   help="histogram and average EXPR (states, parameters, t), e.g. 'rel=x2 - x1' (repeatable; needs "
                        "--range NAME=...)")
    g.add_argument("--range", action="append", default=[], metavar="NAME=LO:HI:BINS",
                   help="histogram range of an observable, e.g. z=-0.2:0.2:40 (repeatable; H defaults to "
                        "0:h_max:bins; a declared observable is histogrammed when given a range)")
    g.add_argument("--x0", type=float, nargs="+", default=None, metavar="V",
                   help="initial state of every path, one value per state (default: zeros)")
    g.add_argument("--snapshots", type=int, default=0, metavar="N",
                   help="also record the ensemble at the N times t_j = j t_end / N from the start --x0 (E[obs](t_j) "
                        "with CIs in STEM_snapshots.csv, histograms in STEM_snapshot_histograms.csv; the run starts "
                        "recording at t = 0; default 0: none)")
    g.add_argument("--events", type=int, default=0, metavar="K",
                   help="keep each path's first K firings from t = 0 (time, transition, speed) in STEM_events.csv; "
                        "the summary gives each transition's mean first-passage time (default 0: none)")


def automaton_from_args(args):
    """The automaton to simulate, or None when ``simulate_ensemble`` (the oscillator front end) runs the request.

    Parameters split in two: those of an oscillator model go to ``with_params`` (its own checks), the rest (filter
    parameters) become overrides that the automaton checks when the run resolves them.
    """
    from hybrid.automaton import HybridAutomaton
    from models import ImpactOscillator, parse_restitution
    from vibro.cli.common import _call_user, announce_model, load_model, parse_params

    obj, found = load_model(args.model)
    params = parse_params(args.param)
    automaton_options = (args.filter or args.observable or args.range or args.x0 is not None or args.events
                         or args.snapshots)
    oscillator = isinstance(obj, ImpactOscillator) or (isinstance(obj, type) and issubclass(obj, ImpactOscillator))
    if oscillator and not automaton_options:  # the oscillator route, whether the file holds a class or an instance
        return None
    announce_model(args.model, found)
    if isinstance(obj, type):  # an ImpactOscillator subclass
        obj = _call_user(obj, obj.__name__)
    if isinstance(obj, ImpactOscillator):
        if args.restitution:
            obj = obj.with_restitution(parse_restitution(args.restitution))
        own = {k: v for k, v in params.items() if k in obj.params}
        obj = obj.with_params(**own) if own else obj
        params = {k: v for k, v in params.items() if k not in own}
        description = obj.describe()
    else:
        if args.restitution:
            raise ParameterError("--restitution applies to oscillator models; an automaton's impact law is in its "
                                 "resets: set its parameters with --param (e.g. --param r=0.8)")
        description = None
    if args.filter:
        from models.excitation import attach_filter

        automaton = attach_filter(obj, args.filter)
    elif isinstance(obj, ImpactOscillator):
        automaton = obj.to_automaton()
    else:
        automaton = obj
    if not isinstance(automaton, HybridAutomaton):  # pragma: no cover - load_model_object already checks
        raise ParameterError(f"--model {args.model!r} is not an automaton")
    automaton.resolve_parameters(params)  # unknown names and bad values, before anything runs
    return automaton, params, description


def parse_ranges(items: list[str]) -> dict[str, tuple[float, float, int]]:
    """``["z=-1:1:40"]`` -> ``{"z": (-1.0, 1.0, 40)}``, with one-line errors.

    Examples
    --------
    >>> parse_ranges(["z=-0.2:0.2:20"])
    {'z': (-0.2, 0.2, 20)}
    """
    out = {}
    for item in items:
        name, eq, spec = item.partition("=")
        parts = spec.split(":")
        try:
            if not eq or not name.strip().isidentifier() or len(parts) != 3:
                raise ValueError
            lo, hi, bins = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise ParameterError(f"--range {item!r} must read NAME=LO:HI:BINS, e.g. --range z=-0.2:0.2:40") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo and 1 <= bins <= 10**7):
            raise ParameterError(f"--range {item!r}: need finite LO < HI and 1 <= BINS <= 1e7")
        out[name.strip()] = (lo, hi, bins)
    return out


def parse_observables(items: list[str], automaton) -> dict:
    """``["rel=x2 - x1"]`` -> ``{"rel": expression}``; names must be identifiers, symbols states/parameters/t."""
    from hybrid.automaton import _as_expr
    from hybrid.errors import ModelError

    known = {s.name for s in automaton.states} | set(automaton.parameters) | {"t"}
    out = {}
    for item in items:
        name, eq, text = item.partition("=")
        name = name.strip()
        if not eq or not name.isidentifier() or not text.strip():
            raise ParameterError(f"--observable {item!r} must read NAME=EXPR, e.g. --observable 'rel=x2 - x1'")
        try:
            expr = _as_expr(text, f"--observable {name}")
        except ModelError as exc:
            raise ParameterError(str(exc)) from None
        unknown = sorted({str(s) for s in expr.free_symbols} - known)
        if unknown:
            raise ParameterError(f"--observable {item!r} uses unknown names {unknown}; the model has states "
                                 f"{[s.name for s in automaton.states]} and parameters {sorted(automaton.parameters)}")
        out[name] = expr
    return out


def _choose_observables(args, automaton):
    """Observables and their ranges: H (declared energy), declared ones given a --range, then --observable."""
    ranges = parse_ranges(args.range)
    extra = parse_observables(args.observable, automaton)
    obs, hist = {}, {}
    declared = dict(automaton.observables)
    if "H" in declared and "H" not in extra:
        obs["H"] = declared["H"]
        hist["H"] = ranges.get("H", (0.0, float(args.h_max), int(args.bins)))
        if not (hist["H"][1] > 0 and hist["H"][2] >= 1):
            raise ParameterError("--h-max must be > 0 and --bins >= 1")
    for name, expr in declared.items():
        if name != "H" and name in ranges and name not in extra:
            obs[name], hist[name] = expr, ranges[name]
    for name, expr in extra.items():
        if name not in ranges:
            raise ParameterError(f"--observable {name}: give its histogram range, --range {name}=LO:HI:BINS")
        obs[name], hist[name] = expr, ranges[name]
    unused = sorted(set(ranges) - set(obs))
    if unused:
        raise ParameterError(f"--range for {unused}: no such observable; the model declares {sorted(declared)}, add "
                             "others with --observable NAME=EXPR")
    if not obs:
        raise ParameterError(f"nothing to histogram: the model declares no energy H (observables {sorted(declared)});"
                             " give --range NAME=LO:HI:BINS for one of them or --observable NAME=EXPR")
    return obs, hist


def _histogram_frame(ens, name):
    import pandas as pd

    df = ens.to_pandas(name)
    return pd.DataFrame({f"{name}_lo": df["lo"], f"{name}_hi": df["hi"], "count": df["count"],
                         "density": df["density"]})


def scheme_for(args, automaton, oscillator: bool) -> str:
    """The automaton scheme that runs ``--scheme``: for an oscillator model (not filtered) milstein and splitting
    mean what they mean on the oscillator path, the automaton's symplectic and baoab, where the model admits them
    (else the automaton's own milstein and splitting run; ``settings['scheme']`` says which ran). Forced oscillator
    models (``cmd_mc``) take the same rule."""
    from hybrid.errors import ModelError
    from hybrid.stochastic import AUTOMATON_SCHEME_OF, AUTOMATON_SCHEMES
    from hybrid.stochastic._auto_codegen import analyse

    mapped = AUTOMATON_SCHEME_OF.get(args.scheme) if oscillator else None
    if mapped is None:
        return args.scheme
    try:
        AUTOMATON_SCHEMES[mapped].check(analyse(automaton))
    except ModelError:
        return args.scheme
    return mapped


def run(args, resolved, plan) -> int:
    """Simulate the automaton, print the summary, write the CSV files, the sidecar and ``--summary-json``."""
    import numpy as np

    from hybrid.stochastic import default_chunk_paths, simulate_automaton
    from hybrid.stochastic._auto_codegen import analyse
    from models.automata import describe_automaton
    from vibro.provenance import noise_assumption, record

    from .density_check import check_observable_histogram
    from .mc_outputs import common_results, transitions_frame, write_outputs

    automaton, params, base = resolved
    scheme = scheme_for(args, automaton, base is not None and not args.filter)
    if args.joint:
        raise ParameterError("--joint is for oscillator models; automaton models write their observables' "
                             "histograms (--observable, --range)")
    if getattr(args, "phases", 0):
        # an automaton declares no forcing period: sections at a guessed period would be silently wrong
        raise ParameterError("--phases needs a forced oscillator model (duffing-forced, or forcing= in a model file); "
                             "for an automaton call simulate_automaton(..., phases=N, period=T) from Python")
    obs, hist = _choose_observables(args, automaton)
    out = Path(args.out)
    first = "H" if "H" in obs else next(iter(obs))
    extra = {name: beside(out, name) for name in obs if name != first}
    if automaton.transitions:
        extra["transitions"] = beside(out, "transitions")
    if args.events:
        extra["events"] = beside(out, "events")
    if args.snapshots:
        for name in ("snapshots", "snapshot_histograms"):
            extra[name] = beside(out, name)
    for name, path in extra.items():  # the files named after --out, checked before the run
        plan.file(path, f"the {name} file of --out", sidecar=True)
    n = len(automaton.states)
    x0 = tuple(args.x0) if args.x0 is not None else (0.0,) * n
    if len(x0) != n:
        raise ParameterError(f"--x0 gives {len(x0)} values for the {n} states {[s.name for s in automaton.states]}")
    steps = args.t_end / args.dt if args.dt > 0 and math.isfinite(args.t_end / args.dt) else None
    chunk = args.chunk_paths or default_chunk_paths(args.paths, steps)
    if isinstance(chunk, int) and chunk >= 1 and args.paths >= 1:  # bad values: simulate_automaton says why
        cells = -(-args.paths // chunk) * len(obs) * (max(b for _, _, b in hist.values()) + 2)
        # one int64 histogram row per chunk and observable
        check_size("the run", memory=cells * 8.0, max_memory=args.max_memory_gb * 1e9,
                   detail=f"histograms of {cells:.3g} counters over the chunks",
                   fix=f"use fewer bins or larger --chunk-paths, or raise --max-memory-gb {args.max_memory_gb:g}")
    started = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:  # printed as one line each below
        warnings.simplefilter("always")
        ens = simulate_automaton(automaton, scheme, dt=args.dt, paths=args.paths, t_end=args.t_end,
                                 t_burn=args.t_burn, x0=x0, params=params, seed=args.seed, observables=obs,
                                 histograms=hist, stride=args.stride, chunk_paths=chunk,
                                 max_path_steps=args.max_path_steps, scheduler=args.scheduler,
                                 checkpoint=args.checkpoint, resume=args.resume,
                                 checkpoint_every=args.checkpoint_every, events=args.events,
                                 **({"precision": args.precision, "threads_per_block": args.threads_per_block}
                                    if args.scheduler == "cuda" else {}),
                                 **({"phases": args.snapshots, "period": args.t_end} if args.snapshots else {}))
    notes = [f"{w.category.__name__}: {w.message}" for w in caught]
    if scheme not in ("splitting", "symplectic", "baoab"):
        try:
            from hybrid.stochastic import AUTOMATON_SCHEMES

            AUTOMATON_SCHEMES["splitting"].check(analyse(automaton))
            notes.append(f"scheme {scheme!r} is explicit in the drift and pumps energy into lightly damped "
                         "oscillations (a bias ~ stiffness x dt / damping); this model admits --scheme symplectic or "
                         "splitting (or baoab where its damping is linear)")
        except Exception:  # splitting does not apply: nothing better to suggest
            pass
    for text in dict.fromkeys(notes):
        print(f"vibro mc: warning: {text}", file=sys.stderr)

    names = list(ens.names)
    for name in names:  # the one check of every density written (hybrid.resolution)
        if name in ens.counts:
            where = out if name == first else extra[name]
            check_observable_histogram(where, name, ens.density(name)[0], ens.counts[name][1:-1],
                                       ens.mean(name).value)
    files = [(out, _histogram_frame(ens, first), None, None)]
    files += [(extra[name], _histogram_frame(ens, name), name, None) for name in names if name != first]
    if ens.transitions:
        files.append((extra["transitions"], transitions_frame(ens.transitions, ens.events,
                                                              [ens.rate(t) for t in ens.transitions]),
                      "transitions", None))
    if args.events:
        files.append((extra["events"], ens.events_to_pandas(), "events", None))
    snap = None
    if args.snapshots:
        from hybrid.stochastic._snapshots import snapshots_of

        snap = snapshots_of(ens)  # every path seen once at every time, or a one-line error
        for name in ens.phase_counts or {}:  # the density check at every time; one line per observable
            with warnings.catch_warnings(record=True) as unresolved:
                warnings.simplefilter("always")
                for j in range(len(snap.times)):
                    edges, _ = snap.density(name, j)
                    check_observable_histogram(extra["snapshot_histograms"], name, edges,
                                               ens.phase_counts[name][snap._slot(j)][1:-1], snap.mean(name, j).value)
            if unresolved:
                print(f"vibro mc: warning: {len(unresolved)} of the {len(snap.times)} snapshot histograms of {name} "
                      f"do not resolve the density; the first: {unresolved[0].message}", file=sys.stderr)
        for name, frame in (("snapshots", snap.to_pandas()), ("snapshot_histograms", snap.histograms_to_pandas())):
            files.append((extra[name], frame, name, None))

    results = common_results(ens)
    if args.events:  # first-passage times: the mean over the paths whose kept firings include the transition
        results["first_event_time"] = {}
        for t in ens.transitions:
            first = ens.first_event_times(t)
            hit = first[np.isfinite(first)]
            results["first_event_time"][t] = {"mean": float(hit.mean()) if hit.size else None,
                                              "paths": int(hit.size)}
    if snap is not None:
        results["snapshots"] = {name: [{"t": float(t), "mean": snap.mean(name, j).value, "ci": snap.mean(name, j).ci}
                                       for j, t in enumerate(snap.times)] for name in names}
    settings = {**{k: v for k, v in ens.settings.items() if k != "automaton"}, "scheme_requested": args.scheme,
                "x0": list(x0),
                "observables": {k: str(v) for k, v in obs.items()}, "engine": "simulate_automaton",
                "reproducible_as": "the same seed and chunk_paths give the same numbers on any number of threads"
                if args.scheduler != "cuda" else "the same seed gives the same numbers on any launch configuration"}
    description = automaton.describe() if hasattr(automaton, "describe") else describe_automaton(automaton)
    if base is not None and not args.filter:  # a filtered model carries its base model already
        description["oscillator"] = base
    rec = record("mc", model=_Described(description), settings=settings, results=results, started=started,
                 noise=noise_assumption(automaton))
    written = write_outputs(files, rec, args.summary_json)

    print(f"vibro mc: automaton {scheme} dt={args.dt:g} paths={args.paths} seed={args.seed} "
          f"states={[s.name for s in automaton.states]}")
    print(f"  noise           {rec['noise']['text']}")
    print(f"  wall            {ens.wall_time:.2f} s")
    for name in names:
        est = ens.mean(name)
        print(f"  E[{name}]{' ' * max(1, 12 - len(name))}{est:.6g}   (95% batch-means CI; "
              f"{ens.outside_fraction(name):.3g} outside the range)")
    for t in ens.transitions:
        print(f"  rate {t:<10} {ens.rate(t):.6g} per unit time ({int(ens.events[ens.transitions.index(t)])} firings)")
    if snap is not None:
        name = first
        shown = np.unique(np.linspace(0, len(snap.times) - 1, min(len(snap.times), 8)).round().astype(int))
        print(f"  E[{name}](t) from the start x0 = {list(x0)} (95% batch-means CI), {len(shown)} of "
              f"{len(snap.times)} times:")
        for j in shown:
            print(f"    t = {snap.times[j]:<10.5g} {snap.mean(name, int(j)):.6g}")
    print(f"  wrote {', '.join(str(f) for f in written)}")
    return 1 if ens.flags["outside"] else 0


class _Described:
    """Gives ``record`` a ``describe()`` for a plain description."""

    def __init__(self, description: dict):
        self._d = description

    def describe(self) -> dict:
        return self._d
