"""``vibro figure N|all|list``: reproduce the paper's Figures 2-16 (averaging beside Monte Carlo)."""

from __future__ import annotations

import argparse
import sys
import time

from hybrid.errors import ParameterError
from vibro.references import PAPER, READINGS


def register(subparsers) -> None:
    """Add the ``figure`` subcommand."""
    p = subparsers.add_parser(
        "figure", help="reproduce a paper figure (2-16) or all of them: PNG + CSV + JSON sidecar",
        description=f"Reproduce Figures 2-16 of the paper {PAPER}. Each figure shows the analytic p(H) or p(x, y) "
                    "by the paper's averaging, the jump method and the phase-plane Fokker-Planck solver (fpk), beside "
                    "Monte Carlo. How we read the paper's "
                    f"typos and ambiguities: {READINGS}. Finished figures (sidecar JSON with the same spec hash) "
                    "are reused; use --force to recompute.",
    )
    p.add_argument("number", metavar="N|all|list", help="figure number 2-16, 'all', or 'list' (print the table)")
    p.add_argument("--out-dir", default="figures", help="output directory (default: ./figures)")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_const", dest="preset", const="quick",
                      help="small Monte Carlo (smoke tests; noisy); the default size takes 7-9 s for Fig. 2 and "
                           "~25 s for all figures on 2 cores")
    size.add_argument("--full", action="store_const", dest="preset", const="full",
                      help="8x the default Monte Carlo paths (about 8x the time)")
    p.add_argument("--no-mc", action="store_true",
                   help="analytic curves only (no Monte Carlo: about a second per figure)")
    p.add_argument("--force", action="store_true", help="recompute even if a finished figure exists")
    p.add_argument("--dpi", type=int, default=110, help="PNG resolution (default 110)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bars; --no-progress: silent (default: bars on a terminal, otherwise one line "
                        "per stage on stderr)")
    p.set_defaults(func=run, preset="default")


def _targets(token: str):
    from vibro.studies.figures import FIGURES

    if token == "all":
        return sorted(FIGURES)
    try:
        n = int(token)
    except ValueError:
        n = None
    if n not in FIGURES:
        raise ParameterError(f"figure {token!r} is not reproduced: choose a number from 2 to 16, 'all' or 'list'")
    return [n]


def _print_table() -> int:
    from vibro.studies.figures import FIGURES

    for n, spec in FIGURES.items():
        cases = "; ".join(c.label for c in spec.cases)
        print(f"{n:>2}  {spec.kind:<6}  {spec.title}  [{cases}]")
        for choice in spec.choices:
            print(f"      - {choice}")
    return 0


def run(args) -> int:
    """Run the subcommand; exit 0 when every figure finished, 1 when one failed at run time."""
    if args.number == "list":
        return _print_table()
    targets = _targets(args.number)
    if args.dpi < 20 or args.dpi > 600:
        raise ParameterError(f"--dpi {args.dpi} is outside 20-600")
    from hybrid.io import check_output_dir
    from vibro.cli import progress_mode

    check_output_dir(args.out_dir, "--out-dir")
    from vibro.studies.figures import run_figure

    mode = progress_mode(args.progress)
    log = (lambda line: print(line, file=sys.stderr, flush=True)) if mode == "lines" else None
    failures = 0
    for n in targets:
        t0 = time.perf_counter()
        try:
            res = run_figure(n, args.out_dir, preset=args.preset, with_mc=not args.no_mc, force=args.force,
                             progress=mode == "bars", dpi=args.dpi, log=log)
        except (KeyboardInterrupt, ParameterError):
            raise
        except Exception as exc:  # one failed figure must not stop 'all'; report it in one line
            failures += 1
            print(f"figure {n}: FAILED: {type(exc).__name__}: {exc}", file=sys.stderr)
            continue
        print(_summary(res, time.perf_counter() - t0))
    return 1 if failures else 0


def _summary(res, wall) -> str:
    side = res.sidecar
    if res.status == "reused":
        return f"figure {res.number}: reused finished outputs in {res.paths['png'].parent} ({res.paths['png'].name})"
    parts = []
    for label, m in side.get("cases", {}).items():
        l1 = m.get("l1_joint") or m.get("l1_energy")
        if l1:
            parts.append(f"{label}: L1 paper {l1.get('paper_vs_mc', float('nan')):.3f} jump "
                         f"{l1.get('jump_vs_mc', float('nan')):.3f} fpk {l1.get('fpk_vs_mc', float('nan')):.3f} "
                         f"noise {l1.get('mc_noise', float('nan')):.3f}")
    tail = ("  [" + "; ".join(parts) + "]") if parts else ""
    return f"figure {res.number}: wrote {res.paths['png']} (+csv, json) in {wall:.1f} s{tail}"
