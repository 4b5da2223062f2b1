"""Arguments shared by subcommands: the model, its parameters and its restitution law."""

from __future__ import annotations

import argparse

from hybrid.errors import ParameterError


def add_model_arguments(parser: argparse.ArgumentParser, restitution_default: str | None = None) -> None:
    """Add ``--model``, ``--param NAME=VALUE`` (repeatable) and ``--restitution SPEC``."""
    from .names import MODELS

    parser.add_argument(
        "--model", default="duffing", metavar="NAME|FILE.py:NAME",
        help=f"built-in model ({', '.join(sorted(MODELS))}) or path/to/file.py:NAME, where NAME is an "
             "ImpactOscillator subclass or instance, a HybridAutomaton (vibro mc), or a function or class returning "
             "one; the command says which it found",
    )
    parser.add_argument(
        "--param", action="append", default=[], metavar="NAME=VALUE",
        help="set a model parameter, e.g. --param delta=1.0 (repeatable)",
    )
    parser.add_argument(
        "--restitution", default=restitution_default, metavar="SPEC",
        help="elastic | newton:e=0.8 | ma:vc=0.4 | custom:EXPR_IN_v (default: the model's own)",
    )


def output_plan(args: argparse.Namespace):
    """A :class:`hybrid.io.OutputPlan` for a command, with its inputs noted: the model file of ``--model
    FILE.py:NAME`` can then not be overwritten by an output.

    Examples
    --------
    >>> plan = output_plan(argparse.Namespace(model="my_model.py:Linear"))
    >>> plan.file("my_model.py", "--out")
    Traceback (most recent call last):
    ...
    hybrid.errors.OutputError: --out and the input --model are one file (my_model.py); give them different names
    """
    from hybrid.io import OutputPlan

    plan = OutputPlan()
    path, colon, _ = str(getattr(args, "model", "") or "").rpartition(":")
    if colon and path.endswith(".py"):
        plan.reads(path, "--model")
    return plan


def beside(out, name: str):
    """The file named after ``--out`` for the output ``name``: ``h.csv`` -> ``h_NAME.csv``.

    Examples
    --------
    >>> beside("runs/h.csv", "phases").as_posix()
    'runs/h_phases.csv'
    """
    from pathlib import Path

    out = Path(out)
    return out.with_name(f"{out.stem}_{name}{out.suffix or '.csv'}")


def csv_text(columns: dict) -> str:
    """Columns of numbers as CSV text, each number exact (17 significant digits), without pandas (whose import
    would double the start-up of a command that writes two columns).

    Examples
    --------
    >>> csv_text({"H": [0.5, 1.0], "p": [0.25, 1e-20]})
    'H,p\\n0.5,0.25\\n1,9.9999999999999995e-21\\n'
    """
    import numpy as np

    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], dtype=float).ravel() for k in names])
    return "\n".join([",".join(names)] + [",".join(f"{v:.17g}" for v in row) for row in data]) + "\n"


def phases_path(args: argparse.Namespace):
    """Where the phase-resolved histograms or densities go: ``--phases-out``, or OUT with ``_phases``."""
    from pathlib import Path

    return Path(args.phases_out) if args.phases_out else beside(args.out, "phases")


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


def _user_attribute(spec: str, what: str):
    """``NAME`` from ``path/to/file.py:NAME`` (the file run once per process), with one-line errors."""
    import importlib.util
    from pathlib import Path

    path, colon, name = spec.rpartition(":")
    if not colon or not path.endswith(".py"):
        raise ParameterError(f"unknown model {spec!r}; use {what} or path/to/file.py:NAME")
    if not Path(path).is_file():
        raise ParameterError(f"model file {path!r} does not exist")
    key = str(Path(path).resolve())
    module = _USER_MODULES.get(key)
    if module is None:
        module_spec = importlib.util.spec_from_file_location(f"vibro_user_model_{Path(path).stem}", path)
        module = importlib.util.module_from_spec(module_spec)
        try:
            module_spec.loader.exec_module(module)
        except SystemExit as exc:  # sys.exit() in the user's file would end vibro silently with its status
            raise ParameterError(f"could not import {path!r}: it called sys.exit({exc.code!r}); a model file must "
                                 "not exit (guard its script part with if __name__ == '__main__':)") from exc
        except Exception as exc:  # the user's file: report, do not trace back
            raise ParameterError(f"could not import {path!r}: {type(exc).__name__}: {exc}") from exc
        _USER_MODULES[key] = module
    return path, name, getattr(module, name, None)


_USER_MODULES: dict = {}


def load_model(spec: str):
    """What ``--model`` names, and in words what was found there: one meaning for every command.

    ``spec`` is a built-in name (an oscillator such as ``duffing``, or an automaton such as ``impact_pair``) or
    ``path/to/file.py:NAME``, where ``NAME`` is an ``ImpactOscillator`` subclass, an ``ImpactOscillator`` instance,
    a ``HybridAutomaton`` instance, or a function or class that returns one of these when called without arguments.

    Returns
    -------
    obj : type or ImpactOscillator or HybridAutomaton
        An ``ImpactOscillator`` subclass (not yet built, so that ``--param`` and ``--restitution`` apply to its
        defaults), an ``ImpactOscillator`` instance, or a ``HybridAutomaton``.
    found : str
        What ``NAME`` turned out to be, e.g. ``"an ImpactOscillator subclass (built with its defaults)"``.

    Examples
    --------
    >>> obj, found = load_model("impact_pair")
    >>> obj.transitions[0].name, found
    ('hit_right', 'the built-in automaton impact_pair')
    >>> load_model("duffing")[1]
    'the built-in oscillator model duffing (DuffingImpact)'
    """
    from hybrid.automaton import HybridAutomaton
    from models import MODELS, ImpactOscillator
    from models.automata import AUTOMATA

    if spec in MODELS:
        return MODELS[spec], f"the built-in oscillator model {spec} ({MODELS[spec].__name__})"
    if spec in AUTOMATA:
        return AUTOMATA[spec](), f"the built-in automaton {spec}"
    path, name, obj = _user_attribute(spec, f"one of {sorted(MODELS) + sorted(AUTOMATA)}")
    if obj is None:
        raise ParameterError(f"{path!r} has no object named {name!r}")
    if isinstance(obj, type) and issubclass(obj, ImpactOscillator):
        return obj, "an ImpactOscillator subclass (built with its defaults)"
    if isinstance(obj, ImpactOscillator):
        return obj, "an ImpactOscillator instance"
    if isinstance(obj, HybridAutomaton):
        return obj, "a HybridAutomaton instance"
    if callable(obj):
        kind = "class" if isinstance(obj, type) else "function"
        built = _call_user(obj, name)
        if isinstance(built, ImpactOscillator):
            return built, f"a {kind} returning an ImpactOscillator"
        if isinstance(built, HybridAutomaton):
            return built, f"a {kind} returning a HybridAutomaton"
        raise ParameterError(f"{path}:{name}() returned {type(built).__name__!r}, not a model: it must return an "
                             "ImpactOscillator or a HybridAutomaton")
    raise ParameterError(f"{path}:{name} is not a model: give an ImpactOscillator subclass or instance, a "
                         f"HybridAutomaton, or a function or class returning one (got {type(obj).__name__})")


def load_model_object(spec: str):
    """What ``--model`` names (see :func:`load_model`), without the words.

    Examples
    --------
    >>> load_model_object("impact_pair").transitions[0].name
    'hit_right'
    """
    return load_model(spec)[0]


def announce_model(spec: str, found: str) -> None:
    """Say what a user file's ``NAME`` was found to be (built-in names need no note)."""
    if ":" in str(spec):
        print(f"model: {spec} is {found}")


def _call_user(factory, name: str):
    """``factory()`` with the user's errors turned into one line."""
    from hybrid.errors import VibroError

    try:
        return factory()
    except VibroError:
        raise
    except TypeError as exc:  # required arguments, or a type error in the body
        raise ParameterError(f"{name} cannot be built without arguments ({exc}); give its parameters defaults and "
                             "set them with --param NAME=VALUE") from exc
    except SystemExit as exc:  # would end vibro silently with the user's status
        raise ParameterError(f"{name}() called sys.exit({exc.code!r}); a model must be built without exiting") from exc
    except Exception as exc:  # the user's code failed: report it, do not trace back
        raise ParameterError(f"{name}() raised {type(exc).__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else ''}") from exc


def model_from_args(args: argparse.Namespace):
    """Build the oscillator model named by ``args.model`` with ``args.param`` and ``args.restitution``.

    Parameters not given keep the model's defaults. ``--model`` has the meaning of :func:`load_model`; commands that
    need an oscillator (``orbit``, ``pdf``, ``solve``) refuse an automaton in one line, naming ``vibro mc``.
    """
    from hybrid.automaton import HybridAutomaton
    from models import parse_restitution

    law = parse_restitution(args.restitution) if args.restitution else None
    obj, found = load_model(args.model)
    if isinstance(obj, HybridAutomaton):
        command = getattr(args, "command", None) or "this command"
        raise ParameterError(f"--model {args.model}: {found}; vibro {command} needs an ImpactOscillator model "
                             "(vibro mc runs automata)")
    announce_model(args.model, found)
    model = _call_user(obj, f"model class {obj.__name__}") if isinstance(obj, type) else obj
    if law is not None:
        model = model.with_restitution(law)
    params = parse_params(args.param)
    return model.with_params(**params) if params else model
