"""``vibro solve --tol 0.02``: p(H) by the cheapest method whose estimated error meets the tolerance, with the
reason and the estimate after the run."""

from __future__ import annotations

import argparse
import math
import sys
import time


def register(subparsers) -> None:
    """Add the ``solve`` subcommand.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["solve", "--tol", "0.05", "--param", "delta=0.8"])
    >>> args.tol, args.method, args.param
    (0.05, 'auto', ['delta=0.8'])
    """
    from .common import add_model_arguments
    from .names import SOLVE_METHODS

    p = subparsers.add_parser(
        "solve", help="stationary p(H) by the cheapest method whose estimated error meets --tol (exact, paper, jump, "
                      "chain, fpk or Monte Carlo), with the estimate after the run",
        description="Consider, cheapest first: exact (the elastic Gibbs density, when impacts are elastic at every "
                    "reachable speed, the damping linear and the noise additive); chain, paper and jump (energy-"
                    "envelope averaging: the impact loss as jumps once per flight, as a drift, or as Poisson-timed "
                    "jumps; milliseconds to 0.1 s; paper and jump are checked against the chain after the run, so "
                    "the chain comes first), each with a rating of its L1 error measured against the phase-"
                    "plane solver over a sweep of models (benchmarks/method_ratings.py; not rated outside it); fpk "
                    "(the full (x, y) Fokker-Planck equation with impacts as boundary conditions, 0.1-2 s, on the "
                    "coarsest grid predicted to meet --tol, with its own three-grid error estimate; on Cartesian "
                    "cells for a potential with several wells, linear damping and additive noise, with a two-grid "
                    "estimate, L1 then on [min G, h_max]); for a forced model the fpk of its periodic density "
                    "(the time-averaged p(H); --phases N: each section's), for --filter ou the fpk on (x, y, eta), "
                    "both with their own estimates; Monte Carlo only where none of these applies (forced "
                    "models with several wells, several wells with nonlinear damping; dt and paths planned from the "
                    "scheme's bias constant and a pilot run). Runs the cheapest one predicted to meet --tol, then "
                    "reports the error estimated after the run and how it was made; when that misses --tol it "
                    "escalates (a finer fpk grid, or the next method). L1 is measured on 40 bins of [0, h_max].",
    )
    add_model_arguments(p)
    p.add_argument("--tol", type=float, default=0.02, help="target L1 distance of p(H) (default 0.02)")
    p.add_argument("--method", default="auto", choices=list(SOLVE_METHODS),
                   help="force a method (default: auto, the choice above); a forced method is run once, "
                        "without escalation, and warns when its estimate misses --tol")
    p.add_argument("--h-max", type=float, default=None, dest="h_max",
                   help="upper energy of p(H) (default: chosen from the model, where the density's tail is "
                        "negligible; raise it where a warning says the tail is cut)")
    p.add_argument("--max-cost", type=float, default=600.0, dest="max_cost",
                   help="wall-time budget of Monte Carlo in seconds (default 600)")
    p.add_argument("--seed", type=int, default=1,
                   help="root seed of the Monte Carlo pilot and runs (same seed, same numbers)")
    p.add_argument("--filter", default=None, choices=("ou",),
                   help="drive the model by Ornstein-Uhlenbeck (coloured) noise of the same intensity, bandwidth "
                        "--param alpha=A (default 1): solved by the fpk on (x, y, eta), its grid refined while its "
                        "two-grid estimate misses --tol")
    p.add_argument("--phases", type=int, default=None, metavar="N",
                   help="forced models: hold --tol for p(H | t) at each of the N phases k T / N (the worst), not "
                        "only for the time-averaged p(H); with --out also write them (OUT with _phases, the "
                        "columns of vibro mc --phases)")
    p.add_argument("--dry-run", action="store_true", help="only print the choice; compute nothing expensive")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="Monte Carlo progress bars; --no-progress: silent (default: bars on a terminal, otherwise "
                        "one line per stage on stderr)")
    p.add_argument("--out", default=None, metavar="FILE.csv", help="write p(H) (columns H, p; not written if absent)")
    p.set_defaults(func=run)


def run(args) -> int:
    """Choose, (optionally) run, and report."""
    from hybrid.errors import ParameterError
    from vibro.solve import choose, solve
    from vibro.solve.choice import check_request

    from .common import model_from_args

    check_request(args.tol, args.max_cost)  # before any output: bad input gives one line
    if args.h_max is not None and not (math.isfinite(args.h_max) and args.h_max > 0):
        raise ParameterError(f"--h-max {args.h_max:g} must be a finite positive energy")
    if args.out is not None:
        from .common import output_plan

        plan = output_plan(args)
        plan.file(args.out, "--out", sidecar=True)
        if args.phases:
            from .common import beside

            plan.file(beside(args.out, "phases"), "--out (its _phases file)")
    if args.filter:
        from .cmd_pdf import _filtered_model

        model = _filtered_model(args)
        if args.phases is not None:
            raise ParameterError("--phases needs a forced model, not --filter")
    else:
        model = model_from_args(args)
    if args.phases is not None and (args.phases < 1 or not getattr(model, "is_forced", False)):
        raise ParameterError(f"--phases {args.phases}: give a number of phases >= 1, for a forced model")
    osc = model.oscillator if args.filter else model
    if args.filter:
        alpha = model.resolve_parameters()[model.filter["parameters"]["alpha"]]
        print(f"model: {osc!r} under an OU filter, alpha = {alpha:g}")
    else:
        print(f"model: {osc!r}")
    from vibro.provenance import noise_assumption

    print(f"noise: {noise_assumption(model)['text']}")
    if not any(math.isfinite(v) for v in osc.barriers):  # e.g. --param delta=inf: say what the inf means
        print("walls: none (barriers at infinity: no impacts)")
    if args.dry_run:
        if args.method != "auto":
            raise ParameterError("--dry-run reports the automatic choice; drop --method")
        from hybrid.errors import ModelError
        from vibro.solve import diagnose

        try:
            diag = None if args.filter else diagnose(model, args.h_max)
        except ModelError:  # no averaging (several wells, forcing): choose says what applies instead
            diag = None
        print(choose(model, args.tol, max_cost=args.max_cost, seed=args.seed, mc_pilot=False,
                     diagnostics=diag).summary())
        return 0
    from vibro.cli import progress_mode

    mode = progress_mode(args.progress)
    if mode == "lines":
        print(f"vibro solve: choosing and running a method for tol {args.tol:g} (Monte Carlo budget "
              f"{args.max_cost:g} s)", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    sol = solve(model, args.tol, method=args.method, max_cost=args.max_cost, seed=args.seed, h_max=args.h_max,
                progress=mode == "bars", phases=args.phases)
    if mode == "lines":
        print(f"vibro solve: {sol.method} done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    print(sol.summary())
    # inf: the method does not apply to this model; NaN: its accuracy is not rated here (said in words, not numbers)
    words = {math.inf: "not applicable"}
    preds = ", ".join(f"{k} {v:.3g}" if math.isfinite(v) else f"{k} {words.get(v, 'not rated')}"
                      for k, v in sol.choice.predictions.items())
    print(f"predicted L1 of the candidates: {preds}")
    if args.out is not None:
        from hybrid.io import atomic_write_text
        from hybrid.resolution import check_density
        from vibro.provenance import record, write_sidecar

        # the one check of every density written (hybrid.resolution): Monte Carlo writes a histogram's densities
        if sol.method == "monte-carlo":
            check_density(f"p(H) in {args.out}", [sol.result.h_edges], sol.result.h_counts,
                          hint=lambda spreads: "its energy range comes from the diagnostics; use vibro mc --h-max")
        else:
            check_density(f"p(H) in {args.out}", [sol.H], sol.p, sampled_on=[sol.H], mass=1.0,
                          hint=lambda spreads: "", refine="use vibro pdf with more --points")

        from .common import csv_text

        phased = args.phases and sol.choice.settings.get("scheme") == "forced"
        if phased:  # the sections, as vibro pdf --method fpk --phases writes them (before OUT: no partial pair)
            from .common import beside

            table = sol.result.phase_to_pandas(args.phases, {"H": (sol.edges[0], sol.edges[-1], len(sol.edges) - 1)})
            phases_file = atomic_write_text(beside(args.out, "phases"), table.to_csv(index=False, float_format="%.17g"))
        path = atomic_write_text(args.out, csv_text({"H": sol.H, "p": sol.p}))
        results = {"method": sol.method, "reason": sol.choice.reason, "expected_error": sol.choice.expected_error,
                   "estimated_error": sol.estimated_error, "estimate_source": sol.estimate_source,
                   "predictions": sol.choice.predictions,
                   "attempts": [{"method": m, "settings": st, "estimate": e} for m, st, e in sol.attempts]}
        settings = {"tol": args.tol, "h_max_requested": args.h_max, "max_cost": args.max_cost, "seed": args.seed,
                    "forced_method": args.method,
                    **sol.choice.settings}
        side = write_sidecar(path, record("solve", model=model, settings=settings, results=results, started=t0))
        print(f"wrote {path} and {side}" + (f" and {phases_file}" if phased else ""))
    return 0
