"""How a result was made: the record written beside every output of the command line and of the studies.

A sidecar ``FILE.json`` next to ``FILE.csv`` holds the command line, the model (expressions, parameters at full
precision, restitution law), the method or scheme and its settings, seeds and chunking, package versions, the git
commit and the wall time. Writing goes through :mod:`hybrid.io`, so a sidecar is never left half written.
"""

from __future__ import annotations

import json
import math
import platform
import subprocess
import sys
import time
from pathlib import Path

PROVENANCE_VERSION = 1


def _installed_version(name: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def versions() -> dict:
    """Versions of Python, the scientific stack and this package (and the git commit when available).

    Examples
    --------
    >>> sorted(k for k in versions() if k in ("numpy", "python"))
    ['numpy', 'python']
    """
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("numpy", "scipy", "sympy", "numba", "heyoka", "matplotlib", "pandas"):
        module = sys.modules.get(name)
        # a module this run did not import is read from the installed metadata (importing it would cost start-up)
        out[name] = getattr(module, "__version__", None) if module is not None else _installed_version(name)
    from vibro import __version__

    out["vibro-impact"] = __version__
    try:
        here = Path(__file__).resolve().parent
        out["git_commit"] = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True,
                                           timeout=5).stdout.strip() or None
    except Exception:  # not a git checkout, or no git: the version above still identifies the code
        out["git_commit"] = None
    return out


def _jsonable(value):
    """Numbers at full precision (repr), non-finite floats as strings, containers recursively."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item") and callable(value.item) and getattr(value, "ndim", 1) == 0:
        value = value.item()  # numpy scalar
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def noise_assumption(model) -> dict | None:
    """How many noises and states ``model`` has, and how its noise is read (the convention, said for every run).

    The Monte Carlo kernels, the averaging methods and fpk all read the noise as Stratonovich (physical white noise:
    the Itô drift gains the Wong-Zakai term). With additive noise (no f_k depends on the state) Itô and Stratonovich
    agree, so the convention does not matter; with multiplicative noise it changes the answer.

    Parameters
    ----------
    model : ImpactOscillator or HybridAutomaton
        Anything else gives None.

    Returns
    -------
    dict or None
        ``noises``, ``states``, ``convention``, ``multiplicative``, ``depends_on`` (the states the noise
        coefficients depend on) and ``text``, a one-line summary.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> noise_assumption(ImpactOscillator("x", "c*y", noise=("1", "y"), parameters={"c": 0.1, "D": 0.05},
    ...                                   barriers=None))["text"]
    '2 noises, 2 states, Stratonovich (multiplicative: f depends on y)'
    >>> noise_assumption(ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.05},
    ...                                   barriers=None))["text"]
    '1 noise, 2 states, additive (Itô and Stratonovich agree)'
    """
    from hybrid.automaton import HybridAutomaton
    from models import ImpactOscillator

    if isinstance(model, ImpactOscillator):
        from models.oscillator import X, Y

        states = (X, Y)
        coefficients = [model.substitute(f) for f in model.f]
        noises = len(coefficients)
    elif isinstance(model, HybridAutomaton):
        from hybrid.stochastic._auto_codegen import noise_matrix

        states = tuple(model.states)
        matrices = [noise_matrix(mode, len(states)) for mode in model.modes]
        coefficients = [e for G in matrices for e in G]
        noises = max((G.shape[1] for G in matrices if any(e != 0 for e in G)), default=0)
    else:
        return None
    symbols = set().union(*(getattr(e, "free_symbols", set()) for e in coefficients)) if coefficients else set()
    depends_on = [s.name for s in states if s in symbols]
    head = f"{noises} noise{'' if noises == 1 else 's'}, {len(states)} state{'' if len(states) == 1 else 's'}"
    if noises == 0:
        text = f"{head} (deterministic)"
    elif depends_on:
        text = f"{head}, Stratonovich (multiplicative: f depends on {', '.join(depends_on)})"
    else:
        text = f"{head}, additive (Itô and Stratonovich agree)"
    return {"noises": noises, "states": len(states), "convention": "stratonovich", "multiplicative": bool(depends_on),
            "depends_on": depends_on, "text": text}


def record(kind: str, *, model=None, settings: dict | None = None, results: dict | None = None,
           started: float | None = None, argv: list[str] | None = None, noise: dict | None = None) -> dict:
    """The provenance record of one output.

    Parameters
    ----------
    kind : str
        What was computed: ``pdf``, ``mc``, ``solve``, ``orbit``, ...
    model : ImpactOscillator, optional
        Its ``describe()`` is stored (expressions, parameters, restitution law).
    settings : dict, optional
        Method or scheme and every setting that changes the numbers (dt, seed, chunk size, grid, ...).
    results : dict, optional
        Summary numbers of the output (mean energy and its CI, counts, ...).
    started : float, optional
        ``time.perf_counter()`` at the start; the wall time is measured from it.
    argv : list of str, optional
        The command line (default: ``sys.argv``).
    noise : dict, optional
        The noise and its convention (default: :func:`noise_assumption` of ``model``).

    Examples
    --------
    >>> r = record("pdf", settings={"method": "jump", "h_max": 4.0})
    >>> r["kind"], r["settings"]["method"], "versions" in r
    ('pdf', 'jump', True)
    """
    out = {
        "provenance_version": PROVENANCE_VERSION,
        "kind": kind,
        "command": list(sys.argv if argv is None else argv),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "model": model.describe() if model is not None else None,
        "noise": noise if noise is not None else (noise_assumption(model) if model is not None else None),
        "settings": settings or {},
        "results": results or {},
        "wall_time_s": None if started is None else time.perf_counter() - started,
        "versions": versions(),
    }
    return _jsonable(out)


def sidecar_path(output) -> Path:
    """``FILE.json`` beside ``FILE.csv`` (or ``FILE.png``).

    Examples
    --------
    >>> sidecar_path("out/p.csv").as_posix()
    'out/p.json'
    """
    return Path(output).with_suffix(".json")


def write_sidecar(output, rec: dict) -> Path:
    """Write ``rec`` as JSON beside ``output`` (atomically); return the sidecar's path."""
    from hybrid.io import atomic_write_text

    path = sidecar_path(output)
    atomic_write_text(path, json.dumps(rec, indent=2, sort_keys=False) + "\n")
    return path
