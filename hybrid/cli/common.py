"""Arguments shared by subcommands: the model, its parameters and its restitution law."""

from __future__ import annotations

import argparse

from hybrid.errors import ParameterError


def add_model_arguments(parser: argparse.ArgumentParser, restitution_default: str | None = None) -> None:
    """Add ``--model``, ``--param NAME=VALUE`` (repeatable) and ``--restitution SPEC``."""
    from models import MODELS

    parser.add_argument("--model", default="duffing", choices=sorted(MODELS), help="built-in model (default duffing)")
    parser.add_argument(
        "--param", action="append", default=[], metavar="NAME=VALUE",
        help="set a model parameter, e.g. --param delta=1.0 (repeatable)",
    )
    parser.add_argument(
        "--restitution", default=restitution_default, metavar="SPEC",
        help="elastic | newton:e=0.8 | ma:vc=0.4 | custom:EXPR_IN_v (default: the model's own)",
    )


def parse_params(items: list[str]) -> dict[str, float]:
    """Turn ``["a=1", "delta=0.8"]`` into a dict of floats, with a clear error on bad items.

    Examples
    --------
    >>> parse_params(["a=1", "delta=0.8"])
    {'a': 1.0, 'delta': 0.8}
    """
    out: dict[str, float] = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name.strip():
            raise ParameterError(f"--param {item!r} must read NAME=VALUE, e.g. --param delta=1.0")
        try:
            out[name.strip()] = float(value)
        except ValueError as exc:
            raise ParameterError(f"--param {item!r}: {value!r} is not a number") from exc
    return out


def model_from_args(args: argparse.Namespace):
    """Build the model named by ``args.model`` with ``args.param`` and ``args.restitution``."""
    from models import make_model, parse_restitution

    law = parse_restitution(args.restitution) if args.restitution else None
    return make_model(args.model, parse_params(args.param), law)
