"""``vibro passage``: first passage out of a domain: mean time, survival R(t), first-passage density.

    vibro passage --domain "H < 2.0" --method fpk --t-max 600 --out R.csv [--x0 X V | --from-stationary]
"""

from __future__ import annotations

import argparse
import json
import time

from hybrid.errors import ParameterError

PASSAGE_GRID = (120, 128)
"""averaging.phase_plane.passage.PASSAGE_GRID, spelt out: building the parser must not import scipy or sympy."""
DEFAULT_STEPS = 800
"""averaging.phase_plane.passage.DEFAULT_STEPS, likewise."""


def register(subparsers) -> None:
    """Add the ``passage`` subcommand.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["passage", "--domain", "H < 2", "--out", "R.csv"])
    >>> args.method, args.x0, args.grid
    ('fpk', [0.0, 0.0], (120, 128))
    """
    from .common import add_model_arguments

    p = subparsers.add_parser(
        "passage", help="first passage out of a domain: mean time, survival R(t), density (fpk, averaging, mc)",
        description="The time T at which the response first leaves a safe domain (one inequality in x, y, H and "
                    "the model's parameters, e.g. \"H < 2.0\" or \"abs(x) <= 0.8\"), from a state (default rest). "
                    "Writes t,R,density (R = P(T > t); R_lo,R_hi for mc; R_poisson, exp(-nu t) with Rice's "
                    "out-crossing rate nu, for domains of x alone) and prints the mean time.",
    )
    add_model_arguments(p)
    p.add_argument("--domain", required=True, metavar="INEQUALITY",
                   help="safe domain, e.g. \"H < 2.0\", \"abs(x) <= 0.8\", \"x < 0.5\" (required)")
    p.add_argument("--method", default="fpk", choices=["fpk", "mc", "splitting", "paper", "jump", "auto"],
                   help="fpk (the phase-plane generator: one sparse solve for the mean, ~0.5 s), paper or jump (the "
                        "averaged energy, H < H_c only; 15-18%% short at H_c = 2 on Example 1), mc (Monte Carlo with "
                        "the exit as a transition; needs --t-max), splitting (P(T <= t-max) by fixed-level "
                        "splitting, for small probabilities; needs --t-max), auto (fpk)")
    p.add_argument("--x0", type=float, nargs="+", default=[0.0, 0.0], metavar="X V",
                   help="start state: position and velocity (as in vibro orbit and mc)")
    p.add_argument("--from-stationary", action="store_true",
                   help="fpk: start from the stationary density restricted to the domain instead of --x0")
    p.add_argument("--t-max", type=float, default=None, dest="t_max",
                   help="end of R(t) (default: 5 mean times for fpk, paper, jump; required for mc)")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS, help="time steps of R(t) (rows of the CSV - 1)")
    p.add_argument("--grid", type=int, nargs=2, default=PASSAGE_GRID, metavar=("NH", "NPHI"),
                   help="fpk: rings and angle cells per ring; cost ~ NH x NPHI")
    p.add_argument("--h-max", type=float, default=4.0, dest="h_max",
                   help="fpk: top energy of the grid for domains other than H < H_c (choose it above the domain)")
    p.add_argument("--no-check", action="store_true",
                   help="fpk: skip the error estimate (from half the rings and half the angles)")
    p.add_argument("--points", type=int, default=2000, help="paper/jump: energy nodes on [0, H_c]")
    p.add_argument("--paths", type=int, default=2000, help="mc: paths; cost ∝ paths x t-max / dt")
    p.add_argument("--dt", type=float, default=0.002, help="mc: time step")
    p.add_argument("--scheme", default="baoab", choices=["baoab", "splitting", "symplectic", "em", "milstein"],
                   help="mc: scheme (crossings located inside the step in each)")
    p.add_argument("--seed", type=int, default=1, help="mc: root seed")
    p.add_argument("--out", required=True, metavar="FILE.csv", help="CSV t,R,density[,...] (atomically; required)")
    p.add_argument("--summary-json", default=None, help="also write the summary as JSON (not written if absent)")
    p.add_argument("--levels", type=int, default=10, help="splitting: levels from the start to the domain's edge")
    p.add_argument("--clones", type=int, default=1000, help="splitting: paths per level")
    p.add_argument("--replicas", type=int, default=8, help="splitting: independent repetitions (the CI)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="accepted for symmetry with the other commands (nothing to show)")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``vibro passage``; bad input raises a VibroError (exit status 2)."""
    import math

    from hybrid.io import atomic_write_text
    from vibro.passage import first_passage
    from vibro.provenance import record, sidecar_path, write_sidecar

    from .common import csv_text, model_from_args, output_plan

    if args.steps < 10 or args.steps > 10_000_000:
        raise ParameterError(f"--steps {args.steps} must lie in 10..1e7")
    if min(args.grid) < 8 or args.grid[0] * args.grid[1] > 4_000_000:
        raise ParameterError(f"--grid {args.grid[0]} {args.grid[1]}: use at least 8 and at most 4e6 cells in all")
    if len(args.x0) != 2:
        raise ParameterError(f"--x0 takes the position and the velocity (2 numbers), got {len(args.x0)}")
    if not all(math.isfinite(v) for v in args.x0):
        raise ParameterError(f"--x0 {args.x0[0]:g} {args.x0[1]:g} must be finite")
    plan = output_plan(args)
    plan.file(args.out, "--out", sidecar=True)
    if args.summary_json:
        plan.file(args.summary_json, "--summary-json")
    model = model_from_args(args)
    started = time.perf_counter()
    start = "stationary" if args.from_stationary else tuple(args.x0)
    method = "fpk" if args.method == "auto" else args.method
    if method == "fpk":
        options = {"grid": tuple(args.grid), "h_max": args.h_max, "t_max": args.t_max, "steps": args.steps,
                   "check": not args.no_check}
    elif method in ("paper", "jump"):
        options = {"points": args.points, "t_max": args.t_max, "steps": args.steps}
    elif method == "mc":
        options = {"paths": args.paths, "dt": args.dt, "t_max": args.t_max, "seed": args.seed,
                   "scheme": args.scheme, "points": args.steps}
    elif method == "splitting":
        options = {"dt": args.dt, "t_max": args.t_max, "seed": args.seed, "scheme": args.scheme,
                   "levels": args.levels, "clones": args.clones, "replicas": args.replicas}
    else:
        options = {}
    r = first_passage(model, args.domain, start, method=method, **options)
    columns = {"t": r.t, "R": r.R}
    if hasattr(r, "R_lo"):
        columns.update({"R_lo": r.R_lo, "R_hi": r.R_hi})
    columns["density"] = r.density
    if r.poisson is not None:
        columns["R_poisson"] = r.poisson
    atomic_write_text(args.out, csv_text(columns))
    results = {"mean_time": r.mean_time if math.isfinite(r.mean_time) else None, "error_estimate": r.error_estimate,
               "decay_rate": r.decay_rate if math.isfinite(r.decay_rate) else None}
    if "ci" in r.details:
        results["ci"] = r.details["ci"]
    for key in ("out_crossing_rate", "stationary_impact_rate", "censored", "mean_time_coarse_rings",
                "mean_time_coarse_angles", "probability", "speedup"):
        if key in r.details:
            results[key] = r.details[key]
    settings = {"method": method, "domain": args.domain, "start": start if isinstance(start, str) else list(start),
                **{k: (list(v) if isinstance(v, tuple) else v) for k, v in options.items()}}
    rec = record("passage", model=model, settings=settings, results=results, started=started)
    write_sidecar(args.out, rec)
    if args.summary_json:
        atomic_write_text(args.summary_json, json.dumps(rec, indent=1))
    print(f"model {model.name} {dict(model.params)} restitution {model.restitution.spec()} method {method}")
    print(f"domain {args.domain}   start {start if isinstance(start, str) else f'(x, y) = {start}'}")
    tail = ""
    if r.error_estimate is not None:
        tail = (f"   (95% CI ± {r.error_estimate:.3g})" if method == "mc"
                else f"   (estimated error {r.error_estimate:.2g})")
    if method == "splitting":  # a probability, not a mean time
        print(f"P(T <= {args.t_max:g}) = {r.details['probability']:.6g}   (95% CI ± {r.error_estimate:.3g} over "
              f"{r.details['replicas']} replicas; {r.details['cpu_seconds']:.3g} CPU s; {r.details['speedup']:.3g}x "
              "fewer path-steps than brute force, whose steps are cheaper (13-20x on the OU chain and Example 1: "
              "docs/results/rare-events.md)")
    else:
        print(f"mean time = {r.mean_time:.8g}{tail}")
    if math.isfinite(r.decay_rate):
        print(f"decay rate = {r.decay_rate:.6g}   (R(t) ~ exp(-rate t) for long t)")
    if "out_crossing_rate" in r.details:
        print(f"out-crossing rate (Rice) = {r.details['out_crossing_rate']:.6g}   (Poisson estimate in R_poisson)")
    print(f"wrote {args.out} ({len(r.t)} rows); provenance in {sidecar_path(args.out)}")
    return 0
