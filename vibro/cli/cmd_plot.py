"""``vibro plot FILE [FILE ...] --out PNG``: draw the CSV files that the other subcommands write."""

from __future__ import annotations


def register(subparsers) -> None:
    """Add the ``plot`` subcommand.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["plot", "a.csv", "b.csv", "--out", "ab.png"])
    >>> args.files, args.out, args.dpi
    (['a.csv', 'b.csv'], 'ab.png', 100)
    """
    p = subparsers.add_parser(
        "plot", help="draw your own results: p(H), joint densities, impact logs (PNG)",
        description="Draw CSV files written by vibro pdf, mc, solve and orbit, recognised by their columns: "
                    "p(H) (H,p from pdf/solve; H_lo,H_hi,count,density from mc), several files compared on a "
                    "linear and a log panel with G(delta) marked; joint densities (x,y,p from pdf --joint; "
                    "x_lo,x_hi,y_lo,y_hi,count,density from mc --joint) as filled contours with the barriers; "
                    "impact logs (orbit --out) as H against time and impact speeds; sample paths (t,x,y[,path]). "
                    "G(delta) and the barriers are read from a JSON sidecar beside a CSV (name.json) when there "
                    "is one; the options below override it. Unknown columns exit with status 2.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="CSV files of one kind (energy, joint, impacts or paths)")
    p.add_argument("--out", required=True, metavar="PNG",
                   help="the picture to write (atomically; required), with its provenance in PNG.json (PNG with "
                        ".json appended: what it draws and the records of the files drawn)")
    p.add_argument("--label", action="append", default=None, dest="labels", metavar="TEXT",
                   help="legend label, once per file in order (default: the file names)")
    p.add_argument("--barrier-energy", type=float, default=None, metavar="G",
                   help="mark H = G(delta) at G (default: from the sidecar; not drawn if unknown)")
    p.add_argument("--barriers", type=float, nargs=2, default=None, metavar=("LEFT", "RIGHT"),
                   help="barrier positions for joint densities (default: from the sidecar; not drawn if unknown)")
    p.add_argument("--title", default=None, help="figure title (default: the file names)")
    p.add_argument("--dpi", type=int, default=100, help="PNG resolution; a 10-inch-wide figure is 10 x dpi pixels")
    p.set_defaults(func=run)


def run(args) -> int:
    """Draw the files; bad input raises a VibroError (exit status 2)."""
    import json
    import time
    from pathlib import Path

    from hybrid.io import OutputPlan, atomic_write_text
    from vibro.provenance import record, sidecar_path
    from vibro.studies.plots import plot_files

    plan = OutputPlan()  # the picture must not replace a file it draws (or the sidecar it reads)
    for name in dict.fromkeys(args.files):
        plan.reads(name, repr(name))
        if sidecar_path(name) != Path(name):
            plan.reads(sidecar_path(name), f"sidecar {str(sidecar_path(name))!r}")
    plan.file(args.out, "--out")
    # PNG.png.json: the picture's own record, apart from the sidecar NAME.json of a CSV named like the picture
    picture_record = plan.file(f"{args.out}.json", "the provenance sidecar of --out")

    started = time.perf_counter()
    plot_files(args.files, args.out, labels=args.labels, barrier_energy=args.barrier_energy,
               barriers=None if args.barriers is None else tuple(args.barriers), title=args.title, dpi=args.dpi)
    # the picture's provenance: what it draws, and the records of the files it drew (where they have one)
    inputs = {}
    for name in dict.fromkeys(args.files):
        side = sidecar_path(name)
        try:
            inputs[name] = json.loads(side.read_text(encoding="utf-8")) if side != Path(name) else None
        except (OSError, ValueError):
            inputs[name] = None
    settings = {"files": list(args.files), "labels": args.labels, "barrier_energy": args.barrier_energy,
                "barriers": args.barriers, "title": args.title, "dpi": args.dpi}
    atomic_write_text(picture_record, json.dumps(record("plot", settings=settings, results={"inputs": inputs},
                                                        started=started), indent=2) + "\n")
    print(f"wrote {args.out} and {picture_record}")
    return 0
