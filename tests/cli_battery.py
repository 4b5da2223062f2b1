"""An adversarial battery for the ``vibro`` command line: every numeric option against hostile values, every output
option against bad paths, and outputs that collide.

Each case runs ``vibro.cli.main`` in a forked child of one warm process (imports paid once), in a fresh folder,
with a time limit, and is classified by what it did:

- ``refused``: exit 2 with one line on stderr that says ``error:`` and nothing written;
- ``ok``: exit 0 or 1, and every number it printed or wrote is finite, and a density CSV integrates to 1 on its
  own grid (within 1 %) or the run printed a warning;
- ``crashed``: a traceback, an ``internal error`` line, or an exception escaping ``main``;
- ``hung``: still running at the time limit (killed);
- ``wrong``: exit 0 or 1 with a non-finite number printed or written, or an unnormalised density and no warning;
- ``unclear``: exit 2 with more than one line, or a refusal of an option's value that does not name the option.

``python tests/cli_battery.py [--limit N] [--timeout S]`` runs it and prints the table; the default test suite runs a
bounded sample of the same cases (``tests/test_cli_battery.py``).
"""

from __future__ import annotations

import itertools
import os
import re
import signal
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path

HOSTILE_NUMBERS = ["0", "-1", "nan", "inf", "-inf", "1e300", "1e-300", "", "abc", "1" + "0" * 30, str(2**63 - 1)]
"""The values every numeric option meets (1e30 written as an integer, and the largest 64-bit integer)."""

# cheap valid commands: each option is varied alone, the others keep these values (kernels are cached on disk)
BASE = {
    "orbit": ["orbit", "--t-end", "5", "--rows", "2", "--out", "o.csv"],
    "pdf": ["pdf", "--method", "jump", "--points", "300", "--out", "p.csv"],
    "pdf-fpk": ["pdf", "--method", "fpk", "--grid", "24", "32", "--points", "300", "--out", "p.csv"],
    "solve": ["solve", "--tol", "0.05", "--method", "jump", "--out", "s.csv"],
    "mc": ["mc", "--scheme", "splitting", "--dt", "0.01", "--paths", "8", "--t-end", "40", "--t-burn", "10",
           "--bins", "40", "--out", "h.csv"],
    "figure": ["figure", "2", "--no-mc", "--quick", "--out-dir", "fig"],
    "plot": ["plot", "in.csv", "--out", "pic.png"],
}
PLOT_INPUT = "H,p\n0,0\n0.5,1\n1,0.5\n2,0\n"

PARAMETERS = ("a", "c", "D", "delta")
"""Model parameters of the default model (Duffing between walls) met with the same values through ``--param``."""

PATH_OPTIONS = {
    "orbit": ["--out"], "pdf": ["--out", "--joint"], "solve": ["--out"], "mc": ["--out", "--joint", "--summary-json"],
    "figure": ["--out-dir"], "plot": ["--out"],
}
BAD_PATHS = ["/proc/x.csv", "", "adir", "fifo", "a" * 300 + ".csv", "missing/x.csv"]
"""``fifo`` is a named pipe made in the case's folder: a special file where the output goes. (Not ``/dev/null``: a
build that renames its output onto it, as root, replaces the system's device with a regular file.)"""

COLLISIONS = [
    ["pdf", "--method", "jump", "--points", "300", "--out", "p.csv", "--joint", "p.csv"],
    ["pdf", "--method", "jump", "--points", "300", "--out", "p.json"],
    ["mc", *BASE["mc"][1:-2], "--out", "h.csv", "--summary-json", "h.json"],
    ["mc", *BASE["mc"][1:-2], "--out", "h.csv", "--joint", "h.csv"],
    ["orbit", "--t-end", "5", "--out", "o.json"],
    ["solve", "--tol", "0.05", "--method", "jump", "--out", "s.json"],
    ["plot", "in.csv", "--out", "in.csv"],
    ["plot", "in.csv", "--out", "in.json"],
    ["pdf", "--model", "in.py:M", "--method", "jump", "--points", "300", "--out", "in.py"],
    ["mc", *BASE["mc"][1:-2], "--checkpoint", "adir", "--out", "adir/mc_checkpoint.npz"],
]


@dataclass
class Case:
    argv: list
    option: str = ""
    value: str = ""


@dataclass
class Outcome:
    case: Case
    kind: str
    status: int | None
    seconds: float
    detail: str = ""
    stderr: str = field(default="", repr=False)


def _numeric_options():
    """(command, option, nargs) of every option of the commands in BASE whose type is int or float."""
    import vibro.cli
    from vibro.cli import build_parser

    parser = build_parser()
    checked_int = getattr(vibro.cli, "checked_int", int)  # absent before issue 24: the battery also rates old builds
    checked_float = getattr(vibro.cli, "checked_float", float)
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    out = []
    for command in dict.fromkeys(k.split("-")[0] for k in BASE):
        for action in sub.choices[command]._actions:
            if action.type in (int, float, checked_int, checked_float) and action.option_strings:
                out.append((command, action.option_strings[0], action.nargs))
    return out


def _with(argv, option, values):
    """``argv`` with ``option`` set to ``values`` (replacing its old values, or appended)."""
    argv = list(argv)
    if option in argv:
        i = argv.index(option)
        j = i + 1
        while j < len(argv) and not (argv[j].startswith("--") and not _is_number(argv[j])):
            j += 1
        argv[i + 1:j] = values
    else:
        argv += [option, *values]
    return argv


def _is_number(text):
    try:
        float(text)
        return True
    except ValueError:
        return False


def cases() -> list[Case]:
    """Every case of the battery, in a fixed order."""
    out = []
    for command, option, nargs in _numeric_options():
        bases = [name for name in BASE if name.split("-")[0] == command]
        width = nargs if isinstance(nargs, int) else 1
        for base, value in itertools.product(bases, HOSTILE_NUMBERS):
            if option in ("--x0",) and command == "mc":
                continue  # the automaton route's state: covered through orbit's spelling
            out.append(Case(_with(BASE[base], option, [value] * width), option, value))
    for command, options in PATH_OPTIONS.items():
        for option, path in itertools.product(options, BAD_PATHS):
            out.append(Case(_with(BASE[command], option, [path]), option, path))
    for command, name, value in itertools.product(("orbit", "pdf", "solve", "mc"), PARAMETERS, HOSTILE_NUMBERS):
        out.append(Case(BASE[command] + ["--param", f"{name}={value}"], "--param", f"{name}={value}"))
    out += [Case(argv, "collision") for argv in COLLISIONS]
    return out


_NUMBER = re.compile(r"(?<![\w.])(nan|inf|-inf)(?![\w])", re.IGNORECASE)


def _files_bad(folder: Path) -> str:
    """Why a written file is wrong (non-finite numbers, an unnormalised p(H)), or ''."""
    import numpy as np
    import pandas as pd

    for path in folder.rglob("*.csv"):
        # a figure's table leaves the Monte Carlo columns empty (NaN) under --no-mc
        inputs_or_figures = path.name in ("in.csv", "in.py") or path.name.startswith(("fig", "."))
        if inputs_or_figures or not path.is_file():
            continue
        try:
            df = pd.read_csv(path)
        except Exception as exc:  # an unreadable output is wrong too
            return f"{path.name} unreadable: {exc}"
        numeric = df.select_dtypes("number")
        # a histogram's first and last rows count the samples outside its range: their edges are -inf and inf and
        # their density (per unit of an infinite width) is NaN by the file's definition
        lo_hi = [c for c in df.columns if str(c).endswith(("_lo", "_hi"))]
        if lo_hi:
            numeric = numeric[np.isfinite(df[lo_hi].to_numpy(dtype=float)).all(axis=1)]
        if not np.isfinite(numeric.to_numpy(dtype=float)).all():
            return f"{path.name} holds non-finite numbers"
        if list(df.columns) == ["H", "p"] and len(df) > 2:
            total = float(np.trapezoid(df["p"], df["H"]))
            if abs(total - 1.0) > 0.01:
                return f"{path.name} integrates to {total:.4g}"
    return ""


def run_case(case: Case, timeout: float = 30.0) -> Outcome:
    """Run one case in a forked child; classify it."""
    from vibro.cli import main

    folder = Path(tempfile.mkdtemp(prefix="vibro-battery-"))
    (folder / "adir").mkdir()
    os.mkfifo(folder / "fifo")
    (folder / "in.csv").write_text(PLOT_INPUT)
    (folder / "in.py").write_text("from models import DuffingImpact as M\n")
    err_path = folder / ".stderr"
    out_path = folder / ".stdout"
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # the child: run main, report its status through the exit code
        code = 98
        try:
            os.chdir(folder)
            with open(out_path, "w") as out, open(err_path, "w") as err, redirect_stdout(out), redirect_stderr(err):
                try:
                    code = main(case.argv)
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else 2
                except BaseException as exc:  # escaped main: a crash
                    import traceback

                    traceback.print_exc(file=err)
                    err.write(f"ESCAPED {type(exc).__name__}\n")
                    code = 97
        finally:
            os._exit(code if isinstance(code, int) and 0 <= code < 256 else 96)
    deadline = t0 + timeout
    status = None
    while time.perf_counter() < deadline:
        done, raw = os.waitpid(pid, os.WNOHANG)
        if done:
            status = os.waitstatus_to_exitcode(raw)
            break
        time.sleep(0.02)
    seconds = time.perf_counter() - t0
    if status is None:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        return Outcome(case, "hung", None, seconds, f"killed after {timeout:g} s")
    stderr = err_path.read_text(errors="replace") if err_path.exists() else ""
    stdout = out_path.read_text(errors="replace") if out_path.exists() else ""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if "Traceback" in stderr or "internal error" in stderr or status in (96, 97, 98) or status < 0:
        last = lines[-1] if lines else f"status {status}"
        return Outcome(case, "crashed", status, seconds, last, stderr)
    if status == 2:
        errors = [ln for ln in lines if "error:" in ln]
        written = [p.name for p in folder.rglob("*") if p.is_file() and p.name not in ("in.csv", "in.py",
                                                                                     ".stderr", ".stdout", "fifo")]
        if len(errors) != 1 or written:
            return Outcome(case, "unclear", status, seconds, f"{len(errors)} error lines, wrote {written}", stderr)
        # a refused option must be named; a refused --param may answer about the model it makes (its damping)
        if (case.option.startswith("--") and case.option != "--param" and case.option not in errors[0]
                and case.option.lstrip("-") not in errors[0]):
            return Outcome(case, "unclear", status, seconds, f"does not name {case.option}: {errors[0]}", stderr)
        return Outcome(case, "refused", status, seconds, errors[0], stderr)
    warned = "warning" in stderr.lower()
    if case.option == "--param":  # the model line echoes the value typed (delta=inf: no walls); not an answer
        name, _, value = case.value.partition("=")
        stdout = stdout.replace(case.value, "").replace(f"'{name}': {value}", "")
    if _NUMBER.search(stdout):
        line = next(ln for ln in stdout.splitlines() if _NUMBER.search(ln))
        return Outcome(case, "wrong", status, seconds, f"printed {line.strip()[:100]}", stderr)
    bad = _files_bad(folder)
    if bad and not (warned and "integrates" in bad):
        return Outcome(case, "wrong", status, seconds, bad, stderr)
    return Outcome(case, "ok", status, seconds, "", stderr)


KINDS = ("refused", "ok", "crashed", "hung", "wrong", "unclear")


def summarise(outcomes) -> str:
    counts = {k: sum(o.kind == k for o in outcomes) for k in KINDS}
    head = "| cases | " + " | ".join(KINDS) + " |"
    row = f"| {len(outcomes)} | " + " | ".join(str(counts[k]) for k in KINDS) + " |"
    return "\n".join([head, "|" + "---|" * (len(KINDS) + 1), row])


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, default=0, help="run only the first N cases (0: all)")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds before a case counts as hung")
    ap.add_argument("--only", default="", help="run only cases whose command line contains this text")
    ap.add_argument("--show", default="crashed,hung,wrong,unclear", help="which kinds to list")
    args = ap.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    todo = [c for c in cases() if args.only in " ".join(c.argv)]
    if args.limit:
        todo = todo[: args.limit]
    outcomes = []
    for case in todo:
        outcome = run_case(case, args.timeout)
        outcomes.append(outcome)
        if outcome.kind in args.show.split(","):
            shown = " ".join(repr(a) if not a or " " in a else a for a in case.argv)[:160]
            print(f"{outcome.kind:8} {outcome.seconds:6.1f}s vibro {shown}\n         {outcome.detail[:300]}",
                  flush=True)
    print(summarise(outcomes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
