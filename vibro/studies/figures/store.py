"""Crash-safe outputs: temp names and atomic renames, the sidecar written last, and a Monte Carlo cache.

A figure counts as finished only when its sidecar JSON exists, carries the current spec hash, and every output it
lists exists with the recorded SHA-256. PNG and CSV are written to temporary names and renamed; the sidecar is
renamed last. An interrupted run therefore leaves either a finished figure or no sidecar at all.
"""

from __future__ import annotations

import hashlib
import json
import pickle
from pathlib import Path

from hybrid.io import atomic_write as _atomic_write


def atomic_write(path, write) -> Path:
    """:func:`hybrid.io.atomic_write`, creating the output folder first.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> atomic_write(d / "sub" / "a.txt", lambda p: pathlib.Path(p).write_text("hi")).read_text()
    'hi'
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return _atomic_write(path, write)


def sha256_file(path) -> str:
    """SHA-256 hex digest of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON, atomically.

    Examples
    --------
    >>> import tempfile, pathlib, json
    >>> p = write_json(pathlib.Path(tempfile.mkdtemp()) / "x.json", {"a": 1})
    >>> json.loads(p.read_text())
    {'a': 1}
    """
    text = json.dumps(data, indent=2, sort_keys=False, default=_jsonable, allow_nan=True)
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text + "\n", encoding="utf-8"))


def _jsonable(obj):
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    if isinstance(obj, Path):
        return str(obj)
    return str(obj)


def finished(sidecar, spec_hash: str) -> bool:
    """True when ``sidecar`` records ``spec_hash`` and all its outputs exist with matching hashes.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> finished(pathlib.Path(tempfile.mkdtemp()) / "missing.json", "abc")
    False
    """
    sidecar = Path(sidecar)
    try:
        data = json.loads(sidecar.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    if data.get("spec_hash") != spec_hash or data.get("status") != "finished":
        return False
    for name, digest in data.get("outputs", {}).items():
        f = sidecar.parent / name
        if not f.is_file() or sha256_file(f) != digest:
            return False
    return True


class MCCache:
    """A directory of pickled Monte Carlo results keyed by a hash of (model, settings, seed).

    Figures that simulate the same case with the same settings (Fig. 2 and Figs. 3-5) share one run.
    Entries are written atomically; an unreadable entry is treated as missing.

    Examples
    --------
    >>> import tempfile
    >>> c = MCCache(tempfile.mkdtemp())
    >>> c.get({"a": 1}) is None
    True
    >>> c.put({"a": 1}, [1, 2]); c.get({"a": 1})
    [1, 2]
    """

    def __init__(self, directory):
        self.directory = Path(directory)

    @staticmethod
    def key(payload: dict) -> str:
        """Hash of a JSON-serialisable payload."""
        return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:24]

    def _path(self, payload):
        return self.directory / f"mc-{self.key(payload)}.pkl"

    def get(self, payload):
        """The cached object for ``payload``, or None."""
        p = self._path(payload)
        if not p.is_file():
            return None
        try:
            with open(p, "rb") as fh:
                return pickle.load(fh)
        except Exception:  # a stale or foreign pickle: recompute
            return None

    def put(self, payload, obj) -> None:
        """Store ``obj`` for ``payload`` (silently skipped if the object cannot be pickled)."""
        try:
            blob = pickle.dumps(obj)
        except Exception:
            return
        atomic_write(self._path(payload), lambda tmp: Path(tmp).write_bytes(blob))
