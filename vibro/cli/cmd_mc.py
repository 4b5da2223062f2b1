"""``vibro mc``: a Monte Carlo ensemble; writes the histogram of H (and optionally of (x, y)) as CSV.

    vibro mc --model duffing --param delta=1.0 --restitution ma:vc=0.4 --scheme milstein --dt 1e-3 --paths 256 \\
             --t-end 2200 --t-burn 200 --seed 1 --h-max 4 --bins 400 --out h.csv [--joint joint.csv] \\
             [--checkpoint DIR] [--resume] [--scheduler dask[=ADDRESS]|cuda] [--precision f64|f32]

A forced model (``ImpactOscillator(..., forcing="A*cos(Omega*t)")``) runs through its automaton
(``hybrid.stochastic.simulate_automaton``, with checkpoints and every scheduler); ``--phases N`` then also writes the
histograms of H, x and y at N phases of the forcing period (one long CSV with a ``phase`` column, ``--phases-out``).
Every route writes its files through :mod:`vibro.cli.mc_outputs` (the same CSV shapes, sidecars and summary); a
model with walls or transitions also gets ``STEM_transitions.csv`` (firings and rate of each).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings

from hybrid.errors import ParameterError
from vibro.cli.common import add_model_arguments, model_from_args, phases_path
from vibro.cli.density_check import check_energy_histogram, check_xy_histogram
from vibro.cli.mc_automaton import add_arguments as add_automaton_arguments
from vibro.cli.mc_automaton import automaton_from_args, scheme_for
from vibro.cli.mc_automaton import run as run_automaton
from vibro.cli.mc_outputs import beside, common_results, transitions_frame, wall_transitions, write_outputs
from vibro.cli.names import AUTOMATON_ONLY_SCHEMES, SCHEMES


def register(subparsers) -> None:
    """Add the ``mc`` subcommand."""
    p = subparsers.add_parser(
        "mc", help="Monte Carlo ensemble: histogram of H, moments, impact rate (compiled, parallel, reproducible)",
        description="Simulate an ensemble with a compiled scheme and write the histogram of H as CSV "
                    "(H_lo,H_hi,count,density; the first and last rows count the samples below 0 and above h_max, and "
                    "the density is normalised by every sample). Cost: paths x t_end / dt path-steps; the defaults "
                    "make 5.6e8, about 30 s on 2 cores (~20 M path-steps/s), plus a few seconds to compile the kernel "
                    "the first time a model and scheme are run.",
    )
    add_model_arguments(p)
    p.add_argument("--scheme", default="milstein", choices=SCHEMES + AUTOMATON_ONLY_SCHEMES,
                   help="time-stepping scheme (symplectic and baoab: automaton models; for an oscillator model, "
                        "forced or not, milstein and splitting are those schemes)")
    p.add_argument("--dt", type=float, default=1e-3, help="time step; cost ∝ 1/dt")
    p.add_argument("--paths", type=int, default=256,
                   help="number of paths; cost ∝ paths x t_end / dt: the defaults are 5.6e8 path-steps, ~30 s on 2 "
                        "cores")
    p.add_argument("--t-end", type=float, default=2200.0, help="end time of every path; cost ∝ t_end")
    p.add_argument("--t-burn", type=float, default=None,
                   help="burn-in before statistics (part of t_end, so it costs nothing extra; default 200, and 0 with "
                        "--snapshots)")
    p.add_argument("--seed", type=int, default=1, help="root seed (numpy SeedSequence)")
    p.add_argument("--h-max", type=float, default=4.0, help="upper end of the H histogram")
    p.add_argument("--bins", type=int, default=400, help="bins of the H histogram")
    p.add_argument("--stride", type=int, default=1, help="statistics every STRIDE steps")
    p.add_argument("--out", required=True, help="CSV file for the H histogram (required)")
    p.add_argument("--joint", default=None,
                   help="CSV file for the (x, y) histogram (long form: x_lo,x_hi,y_lo,y_hi,count,density; not "
                        "written if absent)")
    p.add_argument("--xy-bins", type=int, nargs=2, default=(80, 80), metavar=("NX", "NY"), help="(x, y) bins")
    p.add_argument("--chunk-paths", type=int, default=None, help="paths per chunk (default: from paths and steps)")
    p.add_argument("--checkpoint", default=None, metavar="DIR", help="write a checkpoint in DIR")
    p.add_argument("--checkpoint-every", type=int, default=4, metavar="N",
                   help="checkpoint every N chunks (cuda: N launches)")
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint in DIR")
    p.add_argument("--scheduler", default=None, metavar="threads|dask[=ADDRESS]|cuda",
                   help="where chunks run (cuda: an NVIDIA GPU, one thread per path; pip install -e '.[cuda]')")
    p.add_argument("--precision", default="f64", choices=["f64", "f32"], help="floating point of --scheduler cuda")
    p.add_argument("--threads-per-block", type=int, default=128, metavar="N",
                   help="--scheduler cuda: block size (changes no number)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar (default: when stderr is a terminal)")
    p.add_argument("--summary-json", default=None, help="also write the summary as JSON (not written if absent)")
    p.add_argument("--max-path-steps", type=float, default=1e13, help="refuse runs of more paths x steps")
    p.add_argument("--max-memory-gb", type=float, default=4.0, help="refuse histograms needing more memory")
    p.add_argument("--phases", type=int, default=0, metavar="N",
                   help="forced models: also histogram H, x and y at N phases of the forcing period (Poincaré "
                        "sections); dt is lowered so that the period is a whole number of steps per phase")
    p.add_argument("--phases-out", default=None, metavar="FILE",
                   help="CSV of the phase-resolved histograms (observable,phase,t_phase,lo,hi,count,density; "
                        "default: OUT with _phases before the suffix)")
    add_automaton_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Run the ensemble described by ``args``; print the summary; write the CSV files."""

    from hybrid.stochastic import simulate_ensemble
    from vibro.provenance import record

    plan = plan_outputs(args)  # every path checked before the run, not after it
    if not (0 < args.max_memory_gb < float("inf")):
        raise ParameterError(f"--max-memory-gb {args.max_memory_gb:g} must be a positive number of GB")
    if not (32 <= args.threads_per_block <= 1024 and args.threads_per_block % 32 == 0):
        raise ParameterError(f"--threads-per-block {args.threads_per_block} must be a multiple of 32 in [32, 1024] "
                             "(whole warps of a CUDA block)")
    if args.resume and args.checkpoint is None:
        raise ParameterError("--resume needs --checkpoint DIR")
    if args.snapshots:  # the ensemble at fixed times from the start: recorded from t = 0
        if args.t_burn not in (None, 0.0):
            raise ParameterError(f"--snapshots records the ensemble from the start at t = 0: drop --t-burn "
                                 f"{args.t_burn:g} (or give --t-burn 0)")
        if args.phases:
            raise ParameterError("--snapshots and --phases both record sections of the run; give one of them")
    args.t_burn = (0.0 if args.snapshots else 200.0) if args.t_burn is None else args.t_burn
    resolved = automaton_from_args(args)  # None: an oscillator model without automaton options
    if resolved is not None:
        return run_automaton(args, resolved, plan)
    model = model_from_args(args)
    if wall_transitions(model.barriers):  # firings and rates of the walls, as an automaton's transitions
        plan.file(beside(args.out, "transitions"), "the transitions file of --out", sidecar=True)
    started = time.perf_counter()
    if getattr(model, "is_forced", False) or args.phases:
        return _run_forced(args, model, started, plan)
    if args.scheme in AUTOMATON_ONLY_SCHEMES:
        same = {"symplectic": "milstein runs the same step (velocity first, then the exact free flight)",
                "baoab": "splitting runs the same step (kick, half flight, exact OU step, half flight, kick)"}
        raise ParameterError(f"--scheme {args.scheme} is a scheme of automaton models; for {model.name!r} "
                             f"--scheme {same[args.scheme]}")
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    with warnings.catch_warnings(record=True) as caught:  # printed as one line each below
        warnings.simplefilter("always")
        stats = simulate_ensemble(
            model, scheme=args.scheme, dt=args.dt, paths=args.paths, t_end=args.t_end, t_burn=args.t_burn,
            seed=args.seed, h_max=args.h_max, bins=args.bins, xy_bins=tuple(args.xy_bins) if args.joint else None,
            stride=args.stride, progress=progress, checkpoint=args.checkpoint, resume=args.resume,
            scheduler=args.scheduler, chunk_paths=args.chunk_paths, checkpoint_every=args.checkpoint_every,
            max_path_steps=args.max_path_steps, max_memory=args.max_memory_gb * 1e9,
            precision=args.precision, threads_per_block=args.threads_per_block,
        )
    for text in dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in caught):
        print(f"vibro mc: warning: {text}", file=sys.stderr)
    check_energy_histogram(args.out, stats.h_edges, stats.h_counts, stats.mean_energy.value)
    if args.joint:
        check_xy_histogram(args.joint, *stats.xy_edges, stats.xy_counts, stats.mean_energy.value)
    settings = {**stats.settings, "scheduler": args.scheduler or "threads",
                "reproducible_as": "the same seed and chunk_paths give the same numbers on any number of threads, "
                                   "workers or launches"}
    rec = record("mc", model=model, settings=settings, results={**stats.summary(), **common_results(stats)},
                 started=started)
    files = [(args.out, stats.to_pandas(), None, None)]
    if args.joint:
        files.append((args.joint, stats.joint_to_pandas(), "joint", {"xy_bins": list(args.xy_bins)}))
    walls = wall_transitions(model.barriers)
    if walls:
        files.append((beside(args.out, "transitions"), transitions_frame(
            walls, [stats.total(f"impacts_{w}") for w in walls],
            [getattr(stats, f"impact_rate_{w}").value for w in walls]), "transitions", None))
    written = write_outputs(files, rec, args.summary_json)
    g = stats.settings["g_barrier"]
    print(f"vibro mc: {stats.settings['scheme']} dt={stats.settings['dt']:g} paths={stats.paths} "
          f"seed={stats.seed} path-steps={stats.path_steps:.4g}")
    print(f"  noise           {rec['noise']['text']}")
    print(f"  throughput      {stats.throughput / 1e6:.1f} M path-steps/s  (wall {stats.wall_time:.2f} s, "
          f"compile/load {stats.compile_time:.2f} s)")
    print(f"  E[H]            {stats.mean_energy:.6g}   (± = 95% batch-means CI)")
    if math.isfinite(g):
        print(f"  P(H < G(delta)) {stats.prob_below_barrier:.6g}   G(delta) = {g:.6g}")
    else:  # no impact level: the probability is 1 by definition and G(delta) has no finite value to print
        print("  no walls        no impacts, P(H < G(delta)) = 1")
    print(f"  impacts/time    {stats.impact_rate:.6g}   ({stats.impacts} impacts)")
    print(f"  E[x^2]          {stats.mean_x2:.6g}")
    out = stats.outside()
    h = out["H"]
    print(f"  H outside bins  {h['fraction']:.4g} uncounted  ({h['below']} below 0, {h['above']} above "
          f"h_max={stats.settings['h_max']:g}, of {h['total']} samples)")
    for name in ("xy", "speed"):
        if name in out and out[name]["outside"]:
            print(f"  {name + ' outside':<15} {out[name]['fraction']:.4g}  ({out[name]['outside']} of "
                  f"{out[name]['total']})")
    if stats.violations:
        print(f"  WARNING: {stats.violations} steps ended outside the barriers", file=sys.stderr)
        return 1
    print("  wrote " + ", ".join(str(w) for w in written))
    return 0


def plan_outputs(args):
    """The files and folder ``vibro mc`` writes, checked together (writable, no two on one file) before the run."""
    from pathlib import Path

    from hybrid.stochastic._auto_exec import CHECKPOINT_FILE, ENSEMBLE_CHECKPOINT_FILE
    from vibro.cli.common import output_plan

    plan = output_plan(args)
    plan.file(args.out, "--out", sidecar=True)
    if args.joint:
        plan.file(args.joint, "--joint", sidecar=True)
    if args.summary_json:
        plan.file(args.summary_json, "--summary-json")
    if args.checkpoint is not None:
        plan.folder(args.checkpoint, "--checkpoint")
        for name in (CHECKPOINT_FILE, ENSEMBLE_CHECKPOINT_FILE):  # the files it may hold
            plan.claim(Path(args.checkpoint) / name, "the checkpoint file in --checkpoint")
    return plan


def _run_forced(args, model, started, plan) -> int:
    """A forced model: Monte Carlo of its automaton (simulate_automaton), time-averaged and phase-resolved."""
    import pandas as pd

    from hybrid.errors import ModelError
    from hybrid.stochastic import AUTOMATON_SCHEME_OF, AUTOMATON_SCHEMES, simulate_automaton
    from vibro.provenance import record

    period = model.forcing_period
    if args.phases:
        if args.phases < 0:
            raise ParameterError(f"--phases {args.phases}: give a number of phases >= 1")
        if period is None:
            raise ParameterError(f"--phases needs a model with a periodic forcing (model {model.name!r} has "
                                 f"{'none' if not model.is_forced else 'F = ' + str(model.forcing)}); declare "
                                 "forcing='A*cos(Omega*t)'")
        plan.file(phases_path(args), "--phases-out", sidecar=True)
    if args.scheme not in set(AUTOMATON_SCHEMES) | set(AUTOMATON_SCHEME_OF):
        raise ParameterError(f"--scheme {args.scheme}: a forced model runs through its automaton, with the schemes "
                             f"{sorted(set(AUTOMATON_SCHEMES) | set(AUTOMATON_SCHEME_OF))}")
    if model.energy_expr is None:
        raise ModelError("the Monte Carlo of a forced model needs G(x) in closed form for H; sympy cannot "
                         f"integrate g = {model.g}")
    if not (math.isfinite(args.h_max) and args.h_max > 0):
        raise ParameterError(f"--h-max {args.h_max!r} must be a finite energy > 0")
    automaton = model.to_automaton()
    # an oscillator's scheme names mean the same forced or not, on the same rule as the automaton route
    scheme = scheme_for(args, automaton, True)
    lo, hi = model.barriers
    x_span = math.sqrt(2.0 * args.h_max) * 2.0
    x_lo = lo if math.isfinite(lo) else -x_span
    x_hi = hi if math.isfinite(hi) else x_span
    y_hi = math.sqrt(2.0 * args.h_max)
    nx, ny = args.xy_bins
    histograms = {"H": (0.0, args.h_max, args.bins), "x": (x_lo, x_hi, nx), "y": (-y_hi, y_hi, ny)}
    joint = ("x", "y", (x_lo, x_hi, nx), (-y_hi, y_hi, ny)) if args.joint else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ens = simulate_automaton(
            automaton, scheme, dt=args.dt, paths=args.paths, t_end=args.t_end, t_burn=args.t_burn,
            x0=(0.0, 0.0), seed=args.seed, observables={"H": model.energy_expr, "x": "x", "y": "y"},
            histograms=histograms, joint=joint, stride=args.stride,
            chunk_paths=args.chunk_paths, max_path_steps=args.max_path_steps,
            phases=args.phases, period=period if args.phases else None, scheduler=args.scheduler,
            checkpoint=args.checkpoint, resume=args.resume, checkpoint_every=args.checkpoint_every,
            **({"precision": args.precision, "threads_per_block": args.threads_per_block}
               if args.scheduler == "cuda" else {}),
        )
    for text in dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in caught):
        print(f"vibro mc: warning: {text}", file=sys.stderr)
    edges, _ = ens.density("H")
    check_energy_histogram(args.out, edges, ens.counts["H"][1:-1], ens.mean("H").value)
    if args.joint:
        check_xy_histogram(args.joint, ens.joint[2], ens.joint[3], ens.joint[4], ens.mean("H").value)
    H = ens.mean("H")
    rates = {tr: ens.rate(tr) for tr in ens.transitions}
    results = {**ens.summary(), **common_results(ens), "impact_rate": sum(rates.values()), "engine": "automaton"}
    if args.phases:
        results["phase_mean_x"] = [{"t_phase": float(tk), "value": ens.phase_mean("x", k).value,
                                    "ci": ens.phase_mean("x", k).ci} for k, tk in enumerate(ens.phase_times())]
    settings = {**{k: v for k, v in ens.settings.items() if k != "automaton"}, "engine": "simulate_automaton",
                "scheme": args.scheme, "automaton_scheme": scheme,
                "forcing": str(model.forcing), "scheduler": args.scheduler or "threads",
                "reproducible_as": "the same seed and chunk_paths give the same numbers on any number of threads"
                if args.scheduler != "cuda" else "the same seed gives the same numbers on any launch configuration"}
    rec = record("mc", model=model, settings=settings, results=results, started=started)
    files = [(args.out, ens.to_pandas("H").rename(columns={"lo": "H_lo", "hi": "H_hi"}), None, None)]
    if args.joint:
        files.append((args.joint, ens.joint_to_pandas(), "joint", {"xy_bins": list(args.xy_bins)}))
    if args.phases:
        long = pd.concat([ens.phase_to_pandas(nm).assign(observable=nm) for nm in ens.names], ignore_index=True)
        files.append((phases_path(args), long[["observable", "phase", "t_phase", "lo", "hi", "count", "density"]],
                      "phases", {"phases": args.phases}))
    if ens.transitions:
        files.append((beside(args.out, "transitions"), transitions_frame(ens.transitions, ens.events, rates.values()),
                      "transitions", None))
    written = write_outputs(files, rec, args.summary_json)
    steps = ens.settings["paths"] * ens.settings["t_end"] / ens.settings["dt"]
    dt_note = (f" (lowered from {ens.settings['dt_requested']:g} so that T = {args.phases} x "
               f"{ens.settings['phase_steps']} steps)" if args.phases else "")
    print(f"vibro mc: {args.scheme} ({scheme}) dt={ens.settings['dt']:.10g}{dt_note} paths={args.paths} "
          f"seed={args.seed} path-steps={steps:.4g}  (forced model: automaton kernel)")
    print(f"  noise           {rec['noise']['text']}")
    print(f"  forcing         F = {model.forcing}" + (f", period {period:.10g}" if period else ""))
    print(f"  throughput      {steps / max(ens.wall_time, 1e-9) / 1e6:.1f} M path-steps/s  (wall "
          f"{ens.wall_time:.2f} s)")
    print(f"  E[H]            {H:.6g}   (± = 95% batch-means CI)")
    print(f"  impacts/time    {sum(rates.values()):.6g}   ({int(ens.events.sum())} impacts)")
    if ens.flags["outside"]:
        print(f"  WARNING: {ens.flags['outside']} samples lay outside the barriers", file=sys.stderr)
        return 1
    print("  wrote " + ", ".join(str(w) for w in written))
    return 0
