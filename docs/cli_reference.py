"""The ``vibro`` parser as ``vibro COMMAND --help`` prints it, for the command-line page (sphinx-argparse).

sphinx-argparse reads each option's raw ``help`` and adds its own "Default:" line; the command line's
:class:`vibro.cli.DefaultsFormatter` states every default in the help text itself, in its own number format. Here
each help becomes the text ``--help`` prints, and the page is built with ``:nodefault:``, so it shows the same
words as the terminal.
"""

from __future__ import annotations

import argparse


def printed_parser() -> argparse.ArgumentParser:
    """``vibro.cli.build_parser()`` with every option's help replaced by the text ``--help`` prints."""
    from vibro.cli import build_parser

    parser = build_parser()
    _print_helps(parser)
    return parser


def _print_helps(parser: argparse.ArgumentParser) -> None:
    formatter = parser._get_formatter()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _print_helps(sub)
        elif action.help and action.help is not argparse.SUPPRESS:
            action.help = formatter._expand_help(action).replace("%", "%%")  # sphinx-argparse applies % again
