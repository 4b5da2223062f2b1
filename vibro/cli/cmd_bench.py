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
                   help="comma-separated subset: work-precision mc,averaging,deterministic,forced,coloured; validity "
                        "averaging,mc,orbits (default: every part)")
    p.add_argument("--tol", type=float, default=0.02, help="solve-verify: the tolerance (default 0.02)")
    p.set_defaults(func=run)


PARTS = {"work-precision": ("mc", "averaging", "deterministic", "forced", "coloured"),
         "validity": ("averaging", "mc", "orbits")}
"""The parts of each task that --parts may name."""


def parse_parts(task: str, text: str | None) -> tuple[str, ...] | None:
    """The parts named by ``--parts`` (None: every part), checked before anything runs.

    An empty list would run nothing (or, read as absent, every full-size part for hours): refused, as are unknown
    and repeated names.

    Examples
    --------
    >>> parse_parts("validity", "mc, orbits")
    ('mc', 'orbits')
    """
    from hybrid.errors import ParameterError

    if text is None:
        return None
    if task not in PARTS:
        raise ParameterError("--parts applies to work-precision and validity only")
    names = tuple(s.strip() for s in text.split(","))
    known = PARTS[task]
    if not any(names) or "" in names:
        raise ParameterError(f"--parts {text!r} names an empty part; give a comma-separated subset of "
                             f"{','.join(known)}, or omit --parts for every part")
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ParameterError(f"--parts: unknown {task} part(s) {unknown}; choose from {','.join(known)}")
    if len(set(names)) != len(names):
        raise ParameterError(f"--parts {text!r} repeats a part; name each once")
    return names


def run(args) -> int:
    """Dispatch to the benchmark task."""
    import time

    from hybrid.io import check_output_dir

    check_output_dir(args.out_dir, "--out-dir")
    t0 = time.perf_counter()
    parts = parse_parts(args.task, args.parts)
    if args.task == "work-precision":
        from vibro.studies.workprecision import work_precision

        work_precision(args.out_dir, quick=args.quick, **({"parts": parts} if parts else {}))
    elif args.task == "validity":
        from vibro.studies.validity import validity_maps

        validity_maps(args.out_dir, quick=args.quick, **({"parts": parts} if parts else {}))
    else:
        from vibro.studies.validity import solve_verification

        df = solve_verification(args.out_dir, tol=args.tol, quick=args.quick)
        print(df.to_string(index=False))
    print(f"done in {time.perf_counter() - t0:.1f} s; outputs in {args.out_dir}")
    return 0
