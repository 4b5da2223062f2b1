"""Crash-safe outputs: temp names and atomic renames, the sidecar written last, and a Monte Carlo cache.

The cache holds numbers only (``.npz`` read with ``allow_pickle=False``, and JSON): the output folder may be shared,
and unpickling a file runs whatever code it names, so a pickle planted there would run as the user.

A figure counts as finished only when its sidecar JSON exists, carries the current spec hash, and every output it
lists exists with the recorded SHA-256. PNG and CSV are written to temporary names and renamed; the sidecar is
renamed last. An interrupted run therefore leaves either a finished figure or no sidecar at all.
"""

from __future__ import annotations

import hashlib
import json
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
    """A directory of Monte Carlo results (tuples of ``EnsembleStatistics``) keyed by a hash of (model, settings, seed).

    Figures that simulate the same case with the same settings (Fig. 2 and Figs. 3-5) share one run. Each entry is
    ``mc-KEY.npz`` (the arrays of every run, loaded with ``allow_pickle=False``) beside ``mc-KEY.json`` (the payload
    it was made for and the number of runs; written last, so an entry without it is incomplete). Entries are written
    atomically; an unreadable or mismatching entry is treated as missing.

    Examples
    --------
    >>> import tempfile
    >>> from hybrid.stochastic import EnsembleStatistics
    >>> s = EnsembleStatistics.empty({"h_max": 4.0, "bins": 4, "xy_bins": None, "v_max": 2.0, "v_bins": 2,
    ...                               "seed": 1, "t_sample": 1.0, "chunk_paths": 1})
    >>> c = MCCache(tempfile.mkdtemp())
    >>> c.get({"a": 1}) is None
    True
    >>> c.put({"a": 1}, (s, s)); [r.h_counts.tolist() for r in c.get({"a": 1})]
    [[0, 0, 0, 0], [0, 0, 0, 0]]
    """

    FORMAT = 1
    """Version of the entry layout; an entry of another version is ignored."""

    def __init__(self, directory):
        self.directory = Path(directory)

    @staticmethod
    def key(payload: dict) -> str:
        """Hash of a JSON-serialisable payload."""
        return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:24]

    def _paths(self, payload):
        stem = self.directory / f"mc-{self.key(payload)}"
        return stem.with_suffix(".npz"), stem.with_suffix(".json")

    def get(self, payload):
        """The cached tuple of ``EnsembleStatistics`` for ``payload``, or None."""
        import numpy as np

        from hybrid.stochastic import EnsembleStatistics

        npz, meta = self._paths(payload)
        try:
            info = json.loads(meta.read_text(encoding="utf-8"))
            expected = json.loads(json.dumps(payload, sort_keys=True, default=str))
            if info.get("format") != self.FORMAT or info.get("payload") != expected:
                return None
            with np.load(npz, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
            runs = []
            for i in range(int(info["runs"])):
                prefix = f"run{i}__"
                runs.append(EnsembleStatistics.from_arrays(
                    {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}))
            return tuple(runs)
        except Exception:  # missing, stale, truncated or foreign entry: recompute
            return None

    def put(self, payload, runs) -> None:
        """Store the tuple ``runs`` of ``EnsembleStatistics`` for ``payload``."""
        import numpy as np

        npz, meta = self._paths(payload)
        arrays = {f"run{i}__{k}": np.asarray(v) for i, r in enumerate(runs) for k, v in r.to_arrays().items()}
        info = {"format": self.FORMAT, "runs": len(runs),
                "payload": json.loads(json.dumps(payload, sort_keys=True, default=str))}
        atomic_write(npz, lambda tmp: np.savez(tmp, **arrays))
        write_json(meta, info)  # last: the entry is complete
