"""``vibro pdf``: the stationary energy density p(H) (and optionally p(x, y)) by the method chosen for a default
tolerance, or by the one named with ``--method``."""

from __future__ import annotations

import argparse

from hybrid.errors import ParameterError
from hybrid.io import atomic_write_text

from .common import csv_text, phases_path


def register(subparsers) -> None:
    """Add the ``pdf`` subcommand.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["pdf", "--method", "jump", "--out", "p.csv"])
    >>> args.method, args.h_max, args.points, build_parser().parse_args(["pdf", "--out", "p.csv"]).method
    ('jump', 4.0, 2000, 'auto')
    """
    from .common import add_model_arguments
    from .names import DENSITY_METHODS

    p = subparsers.add_parser(
        "pdf", help="stationary p(H) (and p(x, y)) by the cheapest method that meets a default tolerance, or a "
                    "named one: averaging (paper, jump, chain), the phase-plane FPK solver (fpk) or the exact formula",
        description="Compute the stationary energy density p(H) on [0, h-max], normalised to 1 there, and print "
                    "E[H] and P(H < G(delta)). Without --method the method is chosen as by vibro solve at --tol "
                    f"(default {PDF_TOL}): the cheapest whose estimated L1 error of p(H) meets it, run, and its "
                    "estimate checked (a miss refines fpk's grid or moves to the next method). The methods: exact "
                    "(the elastic Gibbs density; exact for elastic impacts, linear damping, additive noise); paper "
                    "(energy-envelope averaging of eq. 30 with the impact loss of eq. 13 as a drift); "
                    "exact-two-impact (the same with the exact loss of two impacts per cycle); jump (impacts as "
                    "Poisson-timed jumps of the averaged energy); chain (the jumps once per flight, T(H)/walls: about "
                    "0.1 s); fpk (the full (x, y) Fokker-Planck equation with impacts as boundary conditions, on an "
                    "energy-angle grid, with a three-grid error estimate: 0.1-1 s). paper, jump and chain carry a "
                    "rating of their error measured against fpk over a sweep of models (benchmarks/method_ratings.py)"
                    "; where none covers the model and it is self-excited or strongly dissipative, they are refused "
                    "unless --force is given.",
    )
    add_model_arguments(p)
    p.add_argument("--method", choices=("auto", *DENSITY_METHODS, "fpk"), default="auto",
                   help="auto (default: the cheapest method whose estimated error meets --tol, the exact formula "
                        "included), paper, exact-two-impact, jump, chain or fpk (see above)")
    p.add_argument("--tol", type=float, default=PDF_TOL,
                   help=f"--method auto: target L1 distance of p(H) on 40 bins (default {PDF_TOL})")
    p.add_argument("--grid", type=int, nargs=2, default=None, metavar=("N1", "N2"),
                   help="--method fpk: energy rings and angle cells per ring (default 160 192), or with the "
                        "Cartesian scheme cells in x and in y (default 120 120; 64 128 for a forced model, which "
                        "uses Cartesian cells unless --scheme rings); cost ~ N1 x N2 (a sparse LU)")
    p.add_argument("--scheme", choices=("auto", "rings", "cartesian"), default="auto",
                   help="--method fpk: energy-angle rings (single well) or Cartesian cells (any number of wells, "
                        "e.g. a double-well Duffing with a < 0); auto (default) picks rings for a single well")
    p.add_argument("--filter", default=None, choices=("ou",),
                   help="drive the model by Ornstein-Uhlenbeck (coloured) noise of the same intensity, bandwidth "
                        "--param alpha=A (default 1): the density of (x, y, eta) by --method fpk on a 3-D grid "
                        "(averaging assumes white noise)")
    p.add_argument("--levels", type=int, default=None, metavar="NZ",
                   help="--filter: levels of the filter output eta (default 32); cells x levels cost ~ the product")
    p.add_argument("--phases", type=int, default=0, metavar="N",
                   help="--method fpk, forced models: also write p(H), p(x) and p(y) at the N phases k T / N of the "
                        "forcing period, in the columns of vibro mc --phases (--phases-out)")
    p.add_argument("--phases-out", default=None, metavar="FILE",
                   help="CSV of the phase-resolved densities (observable,phase,t_phase,lo,hi,density; default: OUT "
                        "with _phases before the suffix)")
    p.add_argument("--steps", type=int, default=64,
                   help="--method fpk, forced models: time steps per forcing period (Crank-Nicolson at this and twice "
                        "as many steps, combined: fourth order; rounded up to a multiple of --phases); cost ~ steps")
    p.add_argument("--extrapolate", action="store_true",
                   help="--method fpk, forced models: combine the grid with the grid twice coarser (Richardson, "
                        "second order): for --scheme rings, ~2.5x smaller error for ~1.3x the time")
    p.add_argument("--bins", type=int, default=400, help="--phases: bins of H on [0, h-max], as vibro mc")
    p.add_argument("--xy-bins", type=int, nargs=2, default=(80, 80), metavar=("NX", "NY"),
                   help="--phases: bins of x and y, as vibro mc")
    p.add_argument("--force", action="store_true",
                   help="compute an averaging density even where the diagnosis refuses averaging (warns instead)")
    p.add_argument("--h-max", type=float, default=4.0, dest="h_max", help="upper energy (default 4)")
    p.add_argument("--points", type=int, default=2000,
                   help="energy grid points (default 2000); cost ∝ points, well under a second at the default")
    p.add_argument("--out", required=True, metavar="FILE.csv",
                   help="CSV with columns H,p (written atomically; required)")
    p.add_argument("--joint", default=None, metavar="FILE.csv",
                   help="also write p(x, y) (eq. 31) as x,y,p (not written if absent)")
    p.add_argument("--joint-points", type=int, default=101, dest="joint_points",
                   help="grid points per axis of p(x, y) (default 101); cost ∝ joint-points squared")
    p.add_argument("--equations", choices=["text", "latex"], default=None,
                   help="also print the model's Itô and averaged equations (eqs. 16-26) as text or LaTeX (default: "
                        "not printed)")
    p.set_defaults(func=run)


PDF_TOL = 0.01
"""The L1 tolerance of p(H) that ``vibro pdf`` without ``--method`` meets (vibro solve's default is 0.02)."""
_MAX_POINTS = 10_000_000  # stationary_density's own limit
_BYTES_PER_POINT = 8 * 12  # the output arrays, the jump chain's grid arrays and the CSV text, about
_MAX_JOINT_CELLS = 10_000**2
_BYTES_PER_PHASE_ROW = 300  # a row of the --phases table (pandas, with its string column) and its CSV line, about
_BYTES_PER_CELL = 8 * 8 + 60  # meshgrid, energies, density, and one CSV line


def _check_resolved(args, sd, joint=None) -> None:
    """Warn unless the p(H) (or, with ``joint`` = (x, y, p), the p(x, y)) about to be written is resolved by its
    grid and integrates to 1 there (hybrid.resolution, the one check of every density writer)."""
    from hybrid.resolution import check_density

    if joint is None:
        def hint(spreads):
            return f"use --h-max {4.0 * spreads[0].hi:.3g} or --points {spreads[0].cells_needed()}"

        check_density(f"p(H) in {args.out}", [sd.H], sd.p, sampled_on=[sd.H], mass=1.0, mean=sd.mean_energy,
                      hint=hint, refine=f"use --points {4 * args.points}")
        return
    x, y, pxy = joint
    # p(x, y) jumps across the walls and the level h_max inside its box, so the trapezoid rule converges at first
    # order only (0.5 % off at 101 points per axis for fpk): a 1 % tolerance catches a grid that cannot hold the
    # density without flagging that first-order error
    check_density(f"p(x, y) in {args.joint}", [x, y], pxy.T, sampled_on=[x, y], mass=1.0, mass_tol=1e-2,
                  hint=lambda spreads: f"use --joint-points {max(s.cells_needed() for s in spreads.values())}",
                  refine=f"use --joint-points {4 * args.joint_points}")


def _grid(args, default):
    grid = tuple(args.grid) if args.grid is not None else default
    if min(grid) < 8 or grid[0] * grid[1] > 4_000_000:
        raise ParameterError(f"--grid {grid[0]} {grid[1]}: use at least 8 cells in each direction and at most 4e6 "
                             "in all")
    return grid


def _run_forced(args, model, plan) -> int:
    """A forced model by ``fpk``: the periodic density, its time average in OUT and, with --phases, the sections."""
    import math
    import time

    import numpy as np

    from averaging.phase_plane.forced import PLANES, periodic_density_xy
    from vibro.provenance import noise_assumption, record, sidecar_path, write_sidecar

    started = time.perf_counter()
    if args.phases < 0:
        raise ParameterError(f"--phases {args.phases}: give a number of phases >= 1")
    if args.bins < 1 or min(args.xy_bins) < 1:
        raise ParameterError(f"--bins {args.bins} and --xy-bins {args.xy_bins[0]} {args.xy_bins[1]} must be >= 1")
    if args.phases:
        from hybrid.sizes import check_size

        # the phases table is built in memory, then written as CSV text: refuse a huge one before the solve
        rows = float(args.phases) * (args.bins + args.xy_bins[0] + args.xy_bins[1])
        check_size(f"--phases {args.phases} with --bins {args.bins} and --xy-bins {args.xy_bins[0]} "
                   f"{args.xy_bins[1]}", memory=rows * _BYTES_PER_PHASE_ROW,
                   detail=f"{rows:.3g} rows of the phases table, about {_BYTES_PER_PHASE_ROW} bytes each with its CSV "
                          "text", fix="use fewer phases or bins")
        plan.file(phases_path(args), "--phases-out", sidecar=True)
    cells = "rings" if args.scheme == "rings" else "cartesian"
    grid = _grid(args, PLANES[cells][1])
    sol = periodic_density_xy(model, grid=grid, h_max=args.h_max, cells=cells, steps=args.steps,
                              phases=args.phases or None, points=args.points, extrapolate=args.extrapolate)
    sd = sol.mean
    _check_resolved(args, sd)
    if args.joint is not None:
        from averaging.phase_plane.forced import unforced
        from averaging.quadrature import turning_points

        left, right = model.barriers
        # the box of the unforced energy levels up to h_max (turning points are those of g, not of the forcing)
        lo, hi = (float(v[0]) for v in turning_points(unforced(model), args.h_max))
        x = np.linspace(max(left, lo), min(right, hi), args.joint_points)
        ymax = np.sqrt(2.0 * args.h_max)
        y = np.linspace(-ymax, ymax, args.joint_points)
        pxy = sd.joint(x, y)
        _check_resolved(args, sd, (x, y, pxy))
        X, Y = np.meshgrid(x, y)
    phase_table = None
    if args.phases:
        # the bins of vibro mc --phases: x between the walls (or +-2 sqrt(2 h_max)), y within +-sqrt(2 h_max)
        lo, hi = model.barriers
        span = 2.0 * math.sqrt(2.0 * args.h_max)
        y_hi = math.sqrt(2.0 * args.h_max)
        bins = {"H": (0.0, args.h_max, args.bins), "x": (lo if math.isfinite(lo) else -span,
                                                         hi if math.isfinite(hi) else span, args.xy_bins[0]),
                "y": (-y_hi, y_hi, args.xy_bins[1])}
        phase_table = sol.phase_to_pandas(args.phases, bins)
    atomic_write_text(args.out, csv_text({"H": sd.H, "p": sd.p}))
    written = [args.out]
    if args.joint is not None:
        atomic_write_text(args.joint, csv_text({"x": X, "y": Y, "p": pxy}))
        written.append(args.joint)
    if phase_table is not None:
        atomic_write_text(phases_path(args), phase_table.to_csv(index=False, float_format="%.17g"))
        written.append(str(phases_path(args)))
    results = {"mean_energy": sol.mean_energy, "impact_rate": sol.impact_rate, "mean_x2": sd.mean_x2,
               "prob_below_barrier": sd.prob_below_barrier, "periodicity": sol.periodicity,
               "conservation": sol.conservation, "gmres_iterations": sol.iterations,
               "error_estimate": sol.error_estimate, "grid_estimate": sol.grid_estimate,
               "time_estimate": sol.time_estimate, "time_correction": sol.time_correction}
    if args.phases:
        times = sol.phase_times(args.phases)
        results["phase_mean_energy"] = [{"t_phase": float(t), "value": float(v)}
                                        for t, v in zip(times, sol.mean_energy_at(times))]
        results["phase_impact_rate"] = [{"t_phase": float(t), "value": float(v)}
                                        for t, v in zip(times, sol.impact_rate_at(times))]
    settings = {"method": "fpk", "cells": cells, "h_max": args.h_max, "points": args.points, "grid": list(grid),
                "steps": len(sol.times), "period": sol.period, "forcing": str(model.forcing), "phases": args.phases,
                "extrapolate": args.extrapolate}
    rec = record("pdf", model=model, settings=settings, results=results, started=started)
    write_sidecar(args.out, rec)
    if args.joint is not None:
        write_sidecar(args.joint, {**rec, "output": "joint",
                                   "settings": {**rec["settings"], "joint_points": args.joint_points}})
    if phase_table is not None:  # every file written carries its provenance, as vibro mc's phases file does
        write_sidecar(phases_path(args), {**rec, "output": "phases"})
    print(f"model {model.name} {dict(model.params)} restitution {model.restitution.spec()} method fpk (forced, "
          f"period {sol.period:.10g}, {len(sol.times)} steps, {sol.iterations} period maps)")
    print(f"noise: {noise_assumption(model)['text']}")
    print(f"time-averaged E[H] = {sol.mean_energy:.8g}   impact rate = {sol.impact_rate:.8g}")
    time_part = ("" if sol.time_estimate is None else
                 f" + time steps {sol.time_estimate:.2g} (the grid twice coarser at {len(sol.times)} and at "
                 f"{len(sol.times) // 2} steps, over 3)")
    print(f"estimated L1 error of p(H | t), worst phase: {sol.error_estimate:.2g} = cells {sol.grid_estimate:.2g} "
          f"(grid {tuple(grid)} against the grid twice coarser, over 3){time_part}")
    if args.phases:
        print("   phase   t_phase     E[H | t]     impact rate at t")
        for k, (t, e, r) in enumerate(zip(times, sol.mean_energy_at(times), sol.impact_rate_at(times))):
            print(f"   {k:5d}   {t:9.6f}   {e:10.6f}   {r:10.6f}")
    print("wrote " + ", ".join(str(w) for w in written) + f"; provenance in {sidecar_path(args.out)}")
    return 0


def _filtered_model(args):
    """The OU-filtered oscillator of ``--filter``: --param sets the oscillator's parameters and the filter's alpha."""
    from models.excitation import ou_filter

    from .common import model_from_args, parse_params

    params = parse_params(args.param)
    plain = argparse.Namespace(**{**vars(args), "param": []})
    osc = model_from_args(plain)
    if getattr(osc, "is_forced", False):
        raise ParameterError(f"--filter: {osc.name!r} is forced; the coloured-noise density is for autonomous models")
    own = {k: v for k, v in params.items() if k in osc.params}
    osc = osc.with_params(**own) if own else osc
    rest = {k: v for k, v in params.items() if k not in own}
    unknown = sorted(set(rest) - {"alpha"})
    if unknown:
        raise ParameterError(f"--param {unknown[0]}: not a parameter of {osc.name!r} {sorted(osc.params)} nor of the "
                             "OU filter (alpha)")
    return ou_filter(osc, alpha=rest.get("alpha", 1.0))


def _run_filtered(args, model, plan) -> int:
    """An OU-filtered model by ``fpk``: the (x, y)-marginal's p(H) in OUT, p(x, y) with --joint."""
    import time

    import numpy as np

    from averaging.phase_plane.coloured import COLOURED_GRID, stationary_density_coloured
    from vibro.provenance import record, sidecar_path, write_sidecar

    started = time.perf_counter()
    grid = tuple(args.grid) if args.grid is not None else COLOURED_GRID[:2]
    grid = (*grid, COLOURED_GRID[2] if args.levels is None else args.levels)
    sd = stationary_density_coloured(model, grid=grid, h_max=args.h_max, points=args.points)
    _check_resolved(args, sd)
    if args.joint is not None:
        (lo, hi), ymax = sd.box()
        x = np.linspace(lo, hi, args.joint_points)
        y = np.linspace(-ymax, ymax, args.joint_points)
        pxy = sd.joint(x, y)
        _check_resolved(args, sd, (x, y, pxy))
        X, Y = np.meshgrid(x, y)
    atomic_write_text(args.out, csv_text({"H": sd.H, "p": sd.p}))
    written = [args.out]
    if args.joint is not None:
        atomic_write_text(args.joint, csv_text({"x": X, "y": Y, "p": pxy}))
        written.append(args.joint)
    results = {"mean_energy": sd.mean_energy, "prob_below_barrier": sd.prob_below_barrier, "mean_x2": sd.mean_x2,
               "impact_rate": sd.impact_rate, "eta_variance": sd.eta_variance, "mean_eta2": sd.mean_eta2,
               "error_estimate": sd.error_estimate, "gmres_iterations": sd.iterations}
    settings = {"method": "fpk", "scheme": sd.scheme, "filter": "ou", "alpha": sd.alpha, "h_max": args.h_max,
                "points": args.points, "grid": list(grid)}
    noise = {"text": f"OU-filtered noise, alpha = {sd.alpha:g}, Var eta = alpha D = {sd.eta_variance:.6g}"}
    rec = record("pdf", model=model, settings=settings, results=results, started=started, noise=noise)
    write_sidecar(args.out, rec)
    if args.joint is not None:
        write_sidecar(args.joint, {**rec, "output": "joint",
                                   "settings": {**rec["settings"], "joint_points": args.joint_points}})
    osc = model.oscillator
    print(f"model {osc.name} {dict(osc.params)} restitution {osc.restitution.spec()} method fpk (OU-filtered noise, "
          f"alpha {sd.alpha:g}, grid {grid[0]} x {grid[1]} x {grid[2]} levels of eta, {sd.iterations} GMRES "
          "iterations)")
    print(f"noise: {noise['text']}")
    print(f"E[H] = {sd.mean_energy:.8g}   E[x^2] = {sd.mean_x2:.8g}   impact rate = {sd.impact_rate:.8g}")
    print(f"estimated L1 error of p(H): {sd.error_estimate:.3g} ({sd.error_method})")
    print("wrote " + ", ".join(str(w) for w in written) + f"; provenance in {sidecar_path(args.out)}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Run ``vibro pdf``; bad input raises a VibroError (exit status 2)."""
    import time
    import warnings

    import numpy as np

    from averaging import stationary_density
    from averaging.quadrature import turning_points
    from hybrid.errors import ModelError, VibroWarning
    from vibro.provenance import noise_assumption, record, sidecar_path, write_sidecar

    from .common import model_from_args

    if not (np.isfinite(args.h_max) and args.h_max > 0):
        raise ParameterError(f"--h-max {args.h_max!r} must be a finite positive energy")
    if args.points < 3:
        raise ParameterError(f"--points {args.points} must be at least 3")
    if args.points > _MAX_POINTS:
        raise ParameterError(f"--points {args.points} needs about {args.points * _BYTES_PER_POINT / 2**30:.3g} GiB "
                             f"(~{_BYTES_PER_POINT} bytes per point); use at most {_MAX_POINTS}")
    if args.joint is not None and args.joint_points < 2:
        raise ParameterError(f"--joint-points {args.joint_points} must be at least 2")
    if args.joint is not None and args.joint_points**2 > _MAX_JOINT_CELLS:
        raise ParameterError(f"--joint-points {args.joint_points} makes a {args.joint_points}^2 grid needing about "
                             f"{args.joint_points**2 * _BYTES_PER_CELL / 2**30:.3g} GiB plus a CSV line per cell; use "
                             f"at most {int(_MAX_JOINT_CELLS**0.5)}")
    from .common import output_plan

    plan = output_plan(args)  # checked before the work: a bad path costs nothing
    plan.file(args.out, "--out", sidecar=True)
    if args.joint is not None:
        plan.file(args.joint, "--joint", sidecar=True)
    if args.filter:  # coloured noise: only the fpk solver on (x, y, eta)
        if args.method not in ("fpk", "auto"):
            raise ParameterError(f"--filter {args.filter}: --method {args.method} assumes white noise; use --method "
                                 "fpk (the density of the filtered model) or vibro mc --filter")
        if args.phases:
            raise ParameterError("--phases needs a forced model, not --filter")
        args.method = "fpk"
        return _run_filtered(args, _filtered_model(args), plan)
    if args.levels is not None:
        raise ParameterError("--levels applies to a filtered model (--filter ou)")
    model = model_from_args(args)
    forced = bool(getattr(model, "is_forced", False))
    if args.phases and not (forced and args.method in ("fpk", "auto")):
        raise ParameterError("--phases needs --method fpk and a forced model (forcing='A*cos(Omega*t)'), "
                             f"not --method {args.method} on {model.name!r}" + ("" if forced else " (unforced)"))
    if forced and args.method in ("fpk", "auto"):  # the only density method for a forced model: the periodic fpk
        args.method = "fpk"
        return _run_forced(args, model, plan)
    if args.equations is not None:
        from averaging import averaging_equations

        eq = averaging_equations(model)
        print(eq.latex() if args.equations == "latex" else eq)
    started = time.perf_counter()
    refusal = None
    chosen = None
    if args.method == "auto":
        from vibro.solve import solve
        from vibro.solve.choice import check_request

        check_request(args.tol, 600.0)
        if args.force:
            raise ParameterError("--force applies to a named averaging --method, not to the automatic choice")
        sol = solve(model, args.tol, h_max=args.h_max, points=args.points, monte_carlo=False)
        sd, chosen = sol.result, sol
    elif args.method == "fpk":
        from averaging.phase_plane import stationary_density_xy

        if args.grid is not None:
            _grid(args, None)  # the size check
        sd = stationary_density_xy(model, grid=None if args.grid is None else tuple(args.grid), h_max=args.h_max,
                                   points=args.points, scheme=args.scheme)
    else:
        from vibro.solve import diagnose
        from vibro.solve.choice import averaging_refusal
        from vibro.solve.errormodel import predict_averaging_error

        # the density first: its own checks (energy scale, confinement) give the more precise refusal
        sd = stationary_density(model, args.method, h_max=args.h_max, points=args.points)
        diag = diagnose(model)
        refusal = averaging_refusal(diag)
        if np.isnan(predict_averaging_error(args.method, diag)) and not refusal:
            from vibro.solve.choice import UnmeasuredAccuracyWarning

            warnings.warn(f"the accuracy of --method {args.method} is not rated for this model ({diag.geometry} "
                          "walls; no rating of benchmarks/method_ratings.py covers it): use --method fpk, which "
                          "carries its own error estimate", UnmeasuredAccuracyWarning, stacklevel=2)
        if refusal and not args.force:
            raise ModelError(f"{refusal}; use --method fpk or vibro mc, or --force to compute it anyway")
        if refusal:
            warnings.warn(f"--force: {refusal}", VibroWarning, stacklevel=2)
        if args.method != "chain":  # the a-posteriori check against the chain (warns outside validity)
            from vibro.solve.choice import averaging_cross_check

            averaging_cross_check(model, sd, predict_averaging_error(args.method, diag))
    _check_resolved(args, sd)
    if args.joint is not None:
        # the box of the energies that carry the mass (h_support <= h_max), not of all of [0, h_max]
        h_box = min(args.h_max, sd.h_support)
        left, right = model.barriers
        if args.method == "fpk":  # the solver's own box (with several wells, G(x) = h has more than two roots)
            (lo, hi), ymax = sd.box()
        else:
            lo, hi = (float(v[0]) for v in turning_points(model, h_box))
            ymax = np.sqrt(2.0 * h_box)
        x = np.linspace(max(left, lo), min(right, hi), args.joint_points)
        y = np.linspace(-ymax, ymax, args.joint_points)
        pxy = sd.joint(x, y)
        _check_resolved(args, sd, (x, y, pxy))
        X, Y = np.meshgrid(x, y)
    atomic_write_text(args.out, csv_text({"H": sd.H, "p": sd.p}))
    if args.joint is not None:
        atomic_write_text(args.joint, csv_text({"x": X, "y": Y, "p": pxy}))
    from averaging.quadrature import geometry

    Gd = geometry(model).G_delta  # the lowest impact level (inf without walls)
    walls = bool(np.isfinite(Gd))
    results = {"mean_energy": sd.mean_energy, "prob_below_barrier": sd.prob_below_barrier, "mean_x2": sd.mean_x2,
               "impact_rate": sd.impact_rate, "barrier_energy": Gd if walls else None, "averaging_refusal": refusal}
    settings = {"method": args.method, "h_max": args.h_max, "points": args.points, "force": args.force}
    if chosen is not None:
        settings["tol"] = args.tol
        results.update(chosen_method=chosen.method, reason=chosen.choice.reason,
                       estimated_error=chosen.estimated_error, estimate_source=chosen.estimate_source)
    if args.method == "fpk":
        settings["grid"] = sd.metadata()["grid"]
        settings["scheme"] = sd.scheme
    elif chosen is not None and "grid" in chosen.choice.settings:
        settings["grid"] = list(chosen.choice.settings["grid"])
    rec = record("pdf", model=model, settings=settings, results=results, started=started)
    write_sidecar(args.out, rec)
    if args.joint is not None:  # its own record, so that vibro plot finds the barriers beside the joint CSV too
        write_sidecar(args.joint, {**rec, "output": "joint",
                                   "settings": {**rec["settings"], "joint_points": args.joint_points}})
    method = args.method if chosen is None else f"auto -> {chosen.method}"
    print(f"model {model.name} {dict(model.params)} restitution {model.restitution.spec()} method {method}")
    if chosen is not None:
        print(f"chosen for --tol {args.tol:g}: {chosen.choice.reason}")
        print(f"estimated L1 error of p(H): {chosen.estimated_error:.3g} ({chosen.estimate_source})")
    print(f"noise: {noise_assumption(model)['text']}")
    print(f"E[H] = {sd.mean_energy:.8g}")
    if walls:
        print(f"P(H < G(delta)) = {sd.prob_below_barrier:.8g}   (G(delta) = {Gd:.8g})")
    else:  # no impact level: the probability is 1 by definition and G(delta) has no finite value to print
        print("no walls: no impacts, P(H < G(delta)) = 1")
    print(f"E[x^2] = {sd.mean_x2:.8g}   impact rate = {sd.impact_rate:.8g}")
    print(f"wrote {args.out} ({len(sd.H)} rows)" + (f" and {args.joint}" if args.joint else "")
          + f"; provenance in {sidecar_path(args.out)}" + (f" and {sidecar_path(args.joint)}" if args.joint else ""))
    return 0
