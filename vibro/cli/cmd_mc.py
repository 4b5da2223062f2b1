"""``vibro mc``: a Monte Carlo ensemble; writes the histogram of H (and optionally of (x, y)) as CSV.

    vibro mc --model duffing --param delta=1.0 --restitution ma:vc=0.4 --scheme milstein --dt 1e-3 --paths 256 \\
             --t-end 2200 --t-burn 200 --seed 1 --h-max 4 --bins 400 --out h.csv [--joint joint.csv] \\
             [--checkpoint DIR] [--resume] [--scheduler dask[=ADDRESS]|cuda] [--precision f64|f32]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

from hybrid.errors import ParameterError
from vibro.cli.common import add_model_arguments, model_from_args
from vibro.cli.mc_automaton import add_arguments as add_automaton_arguments
from vibro.cli.mc_automaton import automaton_from_args
from vibro.cli.mc_automaton import run as run_automaton
from vibro.cli.names import SCHEMES


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
    p.add_argument("--scheme", default="milstein", choices=SCHEMES, help="time-stepping scheme")
    p.add_argument("--dt", type=float, default=1e-3, help="time step; cost ∝ 1/dt")
    p.add_argument("--paths", type=int, default=256,
                   help="number of paths; cost ∝ paths x t_end / dt: the defaults are 5.6e8 path-steps, ~30 s on 2 "
                        "cores")
    p.add_argument("--t-end", type=float, default=2200.0, help="end time of every path; cost ∝ t_end")
    p.add_argument("--t-burn", type=float, default=200.0,
                   help="burn-in before statistics (part of t_end, so it costs nothing extra)")
    p.add_argument("--seed", type=int, default=1, help="root seed (numpy SeedSequence)")
    p.add_argument("--h-max", type=float, default=4.0, help="upper end of the H histogram")
    p.add_argument("--bins", type=int, default=400, help="bins of the H histogram")
    p.add_argument("--stride", type=int, default=1, help="statistics every STRIDE steps")
    p.add_argument("--out", required=True, help="CSV file for the H histogram (required)")
    p.add_argument("--joint", default=None,
                   help="CSV file for the (x, y) histogram (long form: x_lo,x_hi,y_lo,y_hi,count,density; not "
                        "written if absent)")
    p.add_argument("--xy-bins", type=int, nargs=2, default=(80, 80), metavar=("NX", "NY"), help="(x, y) bins")
    p.add_argument("--chunk-paths", type=int, default=None, help="paths per chunk (default: 8, fewer for few paths)")
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
    add_automaton_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Run the ensemble described by ``args``; print the summary; write the CSV files."""
    from pathlib import Path

    from hybrid.stochastic import atomic_write_text, simulate_ensemble
    from vibro.provenance import record, write_sidecar

    for name in ("out", "joint", "summary_json"):
        target = getattr(args, name)
        if target is not None and not Path(target).resolve().parent.is_dir():
            raise ParameterError(f"--{name.replace('_', '-')} {target!r}: the directory does not exist")
        if target is not None and Path(target).is_dir():  # found before the run, not after it
            raise ParameterError(f"--{name.replace('_', '-')} {target!r} is a directory; give a file name")
    if args.resume and args.checkpoint is None:
        raise ParameterError("--resume needs --checkpoint DIR")
    resolved = automaton_from_args(args)  # None: an oscillator model without automaton options
    if resolved is not None:
        return run_automaton(args, resolved)
    model = model_from_args(args)
    started = time.perf_counter()
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
    stats.to_csv(args.out)
    if args.joint:
        atomic_write_text(args.joint, stats.joint_to_pandas().to_csv(index=False, float_format="%.17g"))
    settings = {**stats.settings, "scheduler": args.scheduler or "threads",
                "reproducible_as": "the same seed and chunk_paths give the same numbers on any number of threads, "
                                   "workers or launches"}
    rec = record("mc", model=model, settings=settings, results=stats.summary(), started=started)
    write_sidecar(args.out, rec)
    if args.summary_json:
        atomic_write_text(args.summary_json, json.dumps(rec, indent=1))
    g = stats.settings["g_barrier"]
    print(f"vibro mc: {stats.settings['scheme']} dt={stats.settings['dt']:g} paths={stats.paths} "
          f"seed={stats.seed} path-steps={stats.path_steps:.4g}")
    print(f"  throughput      {stats.throughput / 1e6:.1f} M path-steps/s  (wall {stats.wall_time:.2f} s, "
          f"compile/load {stats.compile_time:.2f} s)")
    print(f"  E[H]            {stats.mean_energy:.6g}   (± = 95% batch-means CI)")
    print(f"  P(H < G(delta)) {stats.prob_below_barrier:.6g}   G(delta) = {g:.6g}")
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
    print(f"  wrote {args.out}" + (f" and {args.joint}" if args.joint else ""))
    return 0
