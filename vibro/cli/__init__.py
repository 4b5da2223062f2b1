"""The ``vibro`` command line: one entry point, one module per subcommand.

Each module ``vibro/cli/cmd_<name>.py`` defines ``register(subparsers)``, which adds its parser and sets
``func`` to a callable ``func(args) -> int``. Bad input exits with status 2 and a one-line reason.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import warnings

from hybrid.errors import VibroError, VibroWarning
from vibro import __version__


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors in one line and exits with status 2."""

    def error(self, message):
        self.exit(2, f"vibro: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The full ``vibro`` parser, with every subcommand module found in this package.

    Examples
    --------
    >>> "orbit" in build_parser().format_help()
    True
    """
    parser = _Parser(prog="vibro", description="Stochastic vibro-impact systems: orbits, densities, Monte Carlo.")
    parser.add_argument("--version", action="version", version=f"vibro {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{info.name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``vibro`` with ``argv``; return the exit status (0 ok, 1 run failed, 2 bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", VibroWarning)
            previous = warnings.showwarning

            def one_line(message, category, filename, lineno, file=None, line=None):
                if issubclass(category, VibroWarning):  # ours: one line, no source location
                    print(f"vibro {args.command}: warning: {message}", file=sys.stderr)
                else:
                    previous(message, category, filename, lineno, file, line)

            warnings.showwarning = one_line
            status = args.func(args)
    except VibroError as exc:
        print(f"vibro {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vibro {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
