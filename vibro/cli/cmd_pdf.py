"""``vibro pdf``: the stationary energy density p(H) by stochastic averaging (and optionally p(x, y))."""

from __future__ import annotations

import argparse

from hybrid.errors import ParameterError
from hybrid.io import atomic_write_text


def register(subparsers) -> None:
    """Add the ``pdf`` subcommand.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["pdf", "--method", "jump", "--out", "p.csv"])
    >>> args.method, args.h_max, args.points, build_parser().parse_args(["pdf", "--out", "p.csv"]).method
    ('jump', 4.0, 2000, 'jump')
    """
    from .common import add_model_arguments
    from .names import DENSITY_METHODS

    p = subparsers.add_parser(
        "pdf", help="stationary p(H) (and p(x, y)) by energy-envelope averaging or the phase-plane FPK solver",
        description="Compute the stationary energy density p(H) of eq. 30 on [0, h-max], normalised to 1 there, "
                    "with the impact losses treated as in the paper (eq. 13 as a drift), as the exact two-impact "
                    "loss, or as jumps of the averaged energy. Prints E[H] and P(H < G(delta)).",
    )
    add_model_arguments(p)
    p.add_argument("--method", choices=(*DENSITY_METHODS, "fpk"), default="jump",
                   help="jump (default: impacts as jumps of the averaged energy, 3-4x closer to Monte Carlo than "
                        "paper), paper (eq. 13 drift), exact-two-impact, chain (the jumps once per flight T(H)/walls "
                        "instead of at Poisson times: ~0.05 s, median L1 0.0055 on the paper's cases against jump's "
                        "0.029), or fpk (the full (x, y) Fokker-Planck problem with impact boundary conditions: "
                        "about 0.5 s, within ~0.005 of Monte Carlo)")
    p.add_argument("--grid", type=int, nargs=2, default=None, metavar=("N1", "N2"),
                   help="--method fpk: energy rings and angle cells per ring (default 160 192), or with the Cartesian "
                        "scheme cells in x and in y (default 120 120); cost ~ N1 x N2 (a sparse LU)")
    p.add_argument("--scheme", choices=("auto", "rings", "cartesian"), default="auto",
                   help="--method fpk: energy-angle rings (single well) or Cartesian cells (any number of wells, "
                        "e.g. a double-well Duffing with a < 0); auto (default) picks rings for a single well")
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


_MAX_POINTS = 10_000_000  # stationary_density's own limit
_BYTES_PER_POINT = 8 * 12  # the output arrays, the jump chain's grid arrays and the CSV text, about
_MAX_JOINT_CELLS = 10_000**2
_BYTES_PER_CELL = 8 * 8 + 60  # meshgrid, energies, density, and one CSV line


def _csv(columns: dict) -> str:
    import numpy as np

    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], dtype=float).ravel() for k in names])
    lines = [",".join(names)] + [",".join(f"{v:.17g}" for v in row) for row in data]
    return "\n".join(lines) + "\n"


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
    model = model_from_args(args)
    if args.equations is not None:
        from averaging import averaging_equations

        eq = averaging_equations(model)
        print(eq.latex() if args.equations == "latex" else eq)
    started = time.perf_counter()
    refusal = None
    if args.method == "fpk":
        from averaging.phase_plane import stationary_density_xy

        if args.grid is not None and (min(args.grid) < 8 or args.grid[0] * args.grid[1] > 4_000_000):
            raise ParameterError(f"--grid {args.grid[0]} {args.grid[1]}: use at least 8 and at most 4e6 cells in all")
        sd = stationary_density_xy(model, grid=None if args.grid is None else tuple(args.grid), h_max=args.h_max,
                                   points=args.points, scheme=args.scheme)
    else:
        from vibro.solve import diagnose
        from vibro.solve.choice import averaging_refusal
        from vibro.solve.diagnostics import CALIBRATED_GEOMETRIES

        # the density first: its own checks (energy scale, confinement) give the more precise refusal
        sd = stationary_density(model, args.method, h_max=args.h_max, points=args.points)
        diag = diagnose(model)
        refusal = averaging_refusal(diag)
        if diag.geometry not in CALIBRATED_GEOMETRIES and not refusal:
            from vibro.solve.choice import UnmeasuredAccuracyWarning

            warnings.warn(f"{diag.geometry} walls: the accuracy of --method {args.method} is not rated by the error "
                          "model here (fitted on symmetric gaps); measured L1 against Monte Carlo is in "
                          "benchmarks/geometry_averaging.py", UnmeasuredAccuracyWarning, stacklevel=2)
        if refusal and not args.force:
            raise ModelError(f"{refusal}; use --method fpk or vibro mc, or --force to compute it anyway")
        if refusal:
            warnings.warn(f"--force: {refusal}", VibroWarning, stacklevel=2)
        if args.method != "chain":  # the a-posteriori check against the chain (warns outside validity)
            from vibro.solve.choice import averaging_cross_check
            from vibro.solve.errormodel import predict_averaging_error

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
    atomic_write_text(args.out, _csv({"H": sd.H, "p": sd.p}))
    if args.joint is not None:
        atomic_write_text(args.joint, _csv({"x": X, "y": Y, "p": pxy}))
    from averaging.quadrature import geometry

    Gd = geometry(model).G_delta  # the lowest impact level (inf without walls)
    walls = bool(np.isfinite(Gd))
    results = {"mean_energy": sd.mean_energy, "prob_below_barrier": sd.prob_below_barrier, "mean_x2": sd.mean_x2,
               "impact_rate": sd.impact_rate, "barrier_energy": Gd if walls else None, "averaging_refusal": refusal}
    settings = {"method": args.method, "h_max": args.h_max, "points": args.points, "force": args.force}
    if args.method == "fpk":
        settings["grid"] = sd.metadata()["grid"]
        settings["scheme"] = sd.scheme
    rec = record("pdf", model=model, settings=settings, results=results, started=started)
    write_sidecar(args.out, rec)
    if args.joint is not None:  # its own record, so that vibro plot finds the barriers beside the joint CSV too
        write_sidecar(args.joint, {**rec, "output": "joint",
                                   "settings": {**rec["settings"], "joint_points": args.joint_points}})
    print(f"model {model.name} {dict(model.params)} restitution {model.restitution.spec()} method {args.method}")
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
