"""The ``vibro`` command line: one entry point, one module per subcommand.

Each module ``vibro/cli/cmd_<name>.py`` defines ``register(subparsers)``, which adds its parser and sets
``func`` to a callable ``func(args) -> int``. Bad input exits with status 2 and a one-line reason.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import re
import sys
import warnings

from hybrid.errors import VibroError, VibroWarning
from vibro import __version__


class DefaultsFormatter(argparse.HelpFormatter):
    """Help that states every option's default, unless its text already names one.

    ``argparse.ArgumentDefaultsHelpFormatter`` would repeat a default that the help already gives ("(default 0)
    (default: 0.0)") and says nothing for an option without help; here every option has help (a test checks) and
    gets "(default: ...)" appended once. Flags (``store_true``) and ``--help``/``--version`` get none.

    Examples
    --------
    >>> p = argparse.ArgumentParser(prog="x", formatter_class=DefaultsFormatter)
    >>> _ = p.add_argument("--dt", type=float, default=0.01, help="time step")
    >>> "time step (default: 0.01)" in p.format_help()
    True
    """

    def _get_help_string(self, action):
        text = action.help or ""
        if ("(default" in text or action.default is argparse.SUPPRESS or not action.option_strings
                or action.required):
            return text
        if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction, argparse._StoreConstAction)):
            return text
        default = action.default
        if isinstance(default, (list, tuple)):
            default = " ".join(format_number(v) for v in default) if default else "none"
        return f"{text} (default: {'none' if default is None else format_number(default)})"


def format_number(value) -> str:
    """A default as a user would type it: whole numbers without '.0', large ones as '1e13', others exactly.

    Examples
    --------
    >>> format_number(1e13), format_number(2200.0), format_number(0.001), format_number(0.1 + 0.2), format_number(8)
    ('1e13', '2200', '0.001', '0.30000000000000004', '8')
    """
    if not isinstance(value, float) or value != value or value in (float("inf"), float("-inf")):
        return str(value)
    short = f"{value:g}"
    return short.replace("e+", "e") if float(short) == value else repr(value)


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors in one line, exits with status 2, and shows every default in its help."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", DefaultsFormatter)
        super().__init__(*args, **kwargs)

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
    for command in sub.choices.values():  # every number on the command line is read by one rule
        for action in command._actions:
            if action.type is int:
                action.type = checked_int
            elif action.type is float:
                action.type = checked_float
    return parser


LARGEST_INT = 2**63 - 1
"""Integer options beyond a signed 64-bit integer are refused when read: numpy, numba and heyoka overflow (or crash)
on them, and no count, seed or size needs more (each command refuses the sizes it cannot run, with its estimate)."""


def checked_int(text: str) -> int:
    """An integer option: digits only (no ``1e3``, no ``2.5``), within a signed 64-bit integer.

    Examples
    --------
    >>> checked_int("64")
    64
    >>> checked_int("1" + "0" * 30)
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: 1000000000000000000000000000000 is beyond a 64-bit integer (at most 2^63 - 1)
    """
    try:
        value = int(text.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if abs(value) > LARGEST_INT:
        raise argparse.ArgumentTypeError(f"{text} is beyond a 64-bit integer (at most 2^63 - 1)")
    return value


def checked_float(text: str) -> float:
    """A real option: NaN is refused when read (every range check downstream would pass it silently); infinities
    reach the command, which says whether it takes them.

    Examples
    --------
    >>> checked_float("1e-3"), checked_float("inf")
    (0.001, inf)
    >>> checked_float("nan")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: 'nan' is not a number
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if value != value:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number")
    return value


EXIT_BROKEN_PIPE = 141
"""Exit status when the reader of stdout went away (``vibro orbit ... | head -1``): 128 + SIGPIPE, what a C tool
killed by SIGPIPE reports, so a shell pipeline with ``set -o pipefail`` still sees that the output was cut short."""


def _stdout_gone() -> int:
    # Python flushes stdout again at exit and would print a second BrokenPipeError; point fd 1 at devnull first
    # (the way the Python docs recommend), then report the conventional status without a traceback.
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout without a file descriptor (captured in a test)
        pass
    return EXIT_BROKEN_PIPE


def progress_mode(flag: bool | None, stream=None) -> str:
    """How a command reports progress: ``'bars'``, ``'lines'`` or ``'off'``.

    ``--progress`` (True) asks for tqdm bars, ``--no-progress`` (False) for silence; without either, bars go to a
    terminal and a log file gets one line per stage instead (a bar redrawn into a file is dozens of lines).

    Examples
    --------
    >>> import io
    >>> progress_mode(None, io.StringIO()), progress_mode(True, io.StringIO()), progress_mode(False)
    ('lines', 'bars', 'off')
    """
    if flag is not None:
        return "bars" if flag else "off"
    stream = sys.stderr if stream is None else stream
    try:
        return "bars" if stream.isatty() else "lines"
    except (AttributeError, ValueError):  # closed or replaced stream
        return "lines"


COMPILE_LOGGER = "hybrid.stochastic.compile"
"""The library's record of a kernel being compiled (not loaded from the disk cache); see :func:`compile_notices`."""


class _CompileNotice(logging.Handler):
    """Each compile record as one line on stderr (read at each record: a test or a caller may swap stderr)."""

    def emit(self, record):
        print(f"vibro: {record.getMessage()}", file=sys.stderr, flush=True)


class compile_notices:
    """While active, a Monte Carlo kernel compiled rather than loaded from the cache prints one line on stderr
    ("vibro: compiling the Monte Carlo kernel for duffing/milstein (first run only, ~10 s)"), whether stderr is a
    terminal, a pipe or a log: a first run's wait of seconds then does not look like a hang.

    Examples
    --------
    >>> import contextlib, io
    >>> err = io.StringIO()
    >>> with contextlib.redirect_stderr(err), compile_notices():
    ...     logging.getLogger(COMPILE_LOGGER).info("compiling the Monte Carlo kernel for m/s (first run only, ~1 s)")
    >>> err.getvalue().splitlines()
    ['vibro: compiling the Monte Carlo kernel for m/s (first run only, ~1 s)']
    """

    def __enter__(self):
        self._logger = logging.getLogger(COMPILE_LOGGER)
        self._level, self._handler = self._logger.level, _CompileNotice()
        self._logger.addHandler(self._handler)
        self._logger.setLevel(logging.INFO)
        return self

    def __exit__(self, *exc):
        self._logger.removeHandler(self._handler)
        self._logger.setLevel(self._level)
        return False


def main(argv: list[str] | None = None) -> int:
    """Run ``vibro`` with ``argv``; return the exit status.

    0 ok, 1 run failed, 2 bad input, 130 interrupted, 141 (= 128 + SIGPIPE) when stdout was closed by its reader.
    """
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
            with compile_notices():
                status = args.func(args)
            sys.stdout.flush()  # a closed pipe shows up here, inside the handler, not at interpreter exit
    except BrokenPipeError:
        return _stdout_gone()
    except VibroError as exc:
        print(f"vibro {args.command}: error: {flag_names(_one_line(exc), parser, args.command)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vibro {args.command}: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"vibro {args.command}: error: not enough memory for this request; make it smaller (fewer points, "
              "paths or bins)", file=sys.stderr)
        return 2
    except OSError as exc:  # a file that vanished or a disk that filled while the command ran
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"vibro {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except Exception as exc:  # a defect of ours: one line for the user, the traceback on request
        if os.environ.get("VIBRO_DEBUG"):
            raise
        print(f"vibro {args.command}: internal error: {type(exc).__name__}: {_one_line(exc)} (this is a bug; "
              "VIBRO_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1
    return int(status or 0)


def flag_names(message: str, parser: argparse.ArgumentParser, command: str) -> str:
    """``message`` with the API's argument names (``max_steps=0``) spelt as the command's flags (``--max-steps=0``),
    so that a refusal names what the user typed.

    Examples
    --------
    >>> flag_names("max_impacts=0 must be an integer >= 1", build_parser(), "orbit")
    '--max-impacts=0 must be an integer >= 1'
    """
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for action in sub.choices[command]._actions:
        longest = max(action.option_strings, key=len, default="")
        if longest.startswith("--") and action.dest not in ("help", "param"):
            # only 'name=value': a hint that already gives both spellings ("max_memory=, --max-memory-gb") stays
            message = re.sub(rf"(?<![\w.-]){re.escape(action.dest)}=(?=[^\s,;)])", f"{longest}=", message)
    return message


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 600 else f"{text[:300]} ... {text[-290:]}"


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
