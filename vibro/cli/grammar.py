"""One grammar for the command line: the options that several subcommands share, written down once.

Every subcommand that takes one of these options takes it with this spelling, type, arity and destination, so
that ``--h-max 4`` or ``--x0 0 1.2`` mean one thing in ``orbit``, ``pdf``, ``solve`` and ``mc`` alike. Spellings
that users reach for by habit (``--output``, ``--hmax``, ``--nbins``, ``--state``) are not offered anywhere: one
name for one thing. :func:`grammar_problems` walks a parser and lists every departure; a test runs it on ``vibro``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass


@dataclass(frozen=True)
class SharedOption:
    """How a shared option reads: its destination, value type (``None``: a string), arity and meaning."""

    dest: str
    type: type | None
    nargs: object
    meaning: str
    action: type | None = None


SHARED_OPTIONS: dict[str, SharedOption] = {
    "--model": SharedOption("model", None, None, "built-in name or FILE.py:NAME (one meaning: vibro.cli.common."
                                                 "load_model)"),
    "--param": SharedOption("param", None, None, "NAME=VALUE, repeatable", argparse._AppendAction),
    "--restitution": SharedOption("restitution", None, None, "impact law, e.g. ma:vc=0.4"),
    "--seed": SharedOption("seed", int, None, "root seed; same seed, same numbers on any number of threads"),
    "--h-max": SharedOption("h_max", float, None, "upper end of the energy range"),
    "--bins": SharedOption("bins", int, None, "bins of the energy histogram or density"),
    "--x0": SharedOption("x0", float, "+", "initial state: one value per state (X [V] for an oscillator)"),
    "--t-end": SharedOption("t_end", float, None, "end time of an orbit or of every path"),
    "--dt": SharedOption("dt", float, None, "time step"),
    "--paths": SharedOption("paths", int, None, "number of Monte Carlo paths"),
    "--phases": SharedOption("phases", int, None, "phases of the forcing period resolved"),
    "--tol": SharedOption("tol", float, None, "target L1 distance of p(H)"),
    "--grid": SharedOption("grid", int, 2, "phase-plane grid: energy rings and angle cells per ring"),
    "--out": SharedOption("out", None, None, "the main file written (atomically, with a provenance sidecar)"),
    "--out-dir": SharedOption("out_dir", None, None, "the folder written into"),
    "--joint": SharedOption("joint", None, None, "also write the (x, y) density to this file"),
    "--summary-json": SharedOption("summary_json", None, None, "also write the printed summary as JSON"),
    "--progress": SharedOption("progress", None, 0, "progress bars (--no-progress: silent)",
                               argparse.BooleanOptionalAction),
}
"""The shared options of ``vibro``: each row is the one way the option reads, wherever it appears."""

AVOIDED_SPELLINGS: dict[str, str] = {
    "--output": "--out", "-o": "--out", "--outfile": "--out", "--output-dir": "--out-dir", "--outdir": "--out-dir",
    "--hmax": "--h-max", "--H-max": "--h-max", "--h_max": "--h-max", "--energy-max": "--h-max",
    "--nbins": "--bins", "--n-bins": "--bins", "--num-bins": "--bins",
    "--random-seed": "--seed", "--rng-seed": "--seed",
    "--state": "--x0", "--initial-state": "--x0", "--y0": "--x0 X V", "--init": "--x0",
    "--tend": "--t-end", "--t_end": "--t-end", "--n-paths": "--paths", "--npaths": "--paths",
    "--tolerance": "--tol", "--params": "--param",
}
"""Spellings no subcommand offers, with the option that means it."""


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _reads_as(action, numeric: type) -> bool:
    """Whether an action's type reads numbers of ``numeric`` type (the checked readers of vibro.cli included)."""
    kind = action.type
    return kind is numeric or getattr(kind, "__name__", "") == f"checked_{numeric.__name__}"


def grammar_problems(parser: argparse.ArgumentParser) -> list[str]:
    """Every departure of a subcommand from :data:`SHARED_OPTIONS` and :data:`AVOIDED_SPELLINGS`, one line each.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> grammar_problems(build_parser())
    []
    """
    problems = []
    for command, sub in sorted(_subcommands(parser).items()):
        for action in sub._actions:
            for flag in action.option_strings:
                if flag in AVOIDED_SPELLINGS:
                    problems.append(f"vibro {command} {flag}: spell it {AVOIDED_SPELLINGS[flag]}")
                rule = SHARED_OPTIONS.get(flag)
                if rule is None:
                    continue
                where = f"vibro {command} {flag}"
                if action.dest != rule.dest:
                    problems.append(f"{where}: destination {action.dest!r}, the grammar says {rule.dest!r}")
                if rule.type is None and action.type is not None:
                    problems.append(f"{where}: reads {action.type}, the grammar says a string")
                if rule.type is not None and not _reads_as(action, rule.type):
                    problems.append(f"{where}: reads {action.type}, the grammar says {rule.type.__name__}")
                if action.nargs != rule.nargs:
                    problems.append(f"{where}: nargs {action.nargs!r}, the grammar says {rule.nargs!r}")
                if rule.action is not None and not isinstance(action, rule.action):
                    problems.append(f"{where}: action {type(action).__name__}, the grammar says {rule.action.__name__}")
    return problems
