"""``vibro bench``: work-precision charts, validity/failure maps and the verification of ``vibro solve``."""

from __future__ import annotations


def register(subparsers) -> None:
    """Add the ``bench`` subcommand with its three tasks.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["bench", "work-precision", "--out-dir", "wp", "--quick"])
    >>> args.task, args.quick, args.out_dir
    ('work-precision', True, 'wp')
    """
    p = subparsers.add_parser(
        "bench", help="work-precision charts, validity maps, verification of 'vibro solve'",
        description="work-precision: error against wall time for the Monte Carlo schemes, the averaging methods "
                    "and the orbit backends (CSV + PNG). validity: where each averaging method, Monte Carlo scheme "
                    "and orbit backend fails (heatmaps, CSV). solve-verify: run 'vibro solve' on cases not used to "
                    "fit its rules and compare with converged Monte Carlo.",
    )
    p.add_argument("task", choices=["work-precision", "validity", "solve-verify"], help="which study to run")
    p.add_argument("--out-dir", default="bench", dest="out_dir", help="output directory (default ./bench)")
    p.add_argument("--quick", action="store_true",
                   help="small sizes: a few minutes on 2 cores (default: the full sizes, several times longer)")
    p.add_argument("--parts", default=None,
                   help="comma-separated subset: work-precision mc,averaging,deterministic; validity "
                        "averaging,mc,orbits (default: every part)")
    p.add_argument("--tol", type=float, default=0.02, help="solve-verify: the tolerance (default 0.02)")
    p.set_defaults(func=run)


def run(args) -> int:
    """Dispatch to the benchmark task."""
    import time

    from hybrid.errors import ParameterError
    from hybrid.io import check_output_dir

    check_output_dir(args.out_dir, "--out-dir")
    t0 = time.perf_counter()
    parts = tuple(s.strip() for s in args.parts.split(",")) if args.parts else None
    if args.task == "work-precision":
        from vibro.studies.workprecision import work_precision

        work_precision(args.out_dir, quick=args.quick, **({"parts": parts} if parts else {}))
    elif args.task == "validity":
        from vibro.studies.validity import validity_maps

        validity_maps(args.out_dir, quick=args.quick, **({"parts": parts} if parts else {}))
    else:
        if parts:
            raise ParameterError("--parts applies to work-precision and validity only")
        from vibro.studies.validity import solve_verification

        df = solve_verification(args.out_dir, tol=args.tol, quick=args.quick)
        print(df.to_string(index=False))
    print(f"done in {time.perf_counter() - t0:.1f} s; outputs in {args.out_dir}")
    return 0
