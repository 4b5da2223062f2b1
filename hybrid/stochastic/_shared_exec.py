"""What the oscillator and the automaton ensemble runners share: checkpoint files and the Dask client.

A checkpoint is an ``.npz`` of per-chunk arrays with a ``format`` number and a SHA-256 ``checksum`` over every
array's name, dtype, shape and bytes, so that an edited or truncated file is refused in one line.
"""

from __future__ import annotations

import hashlib
import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from hybrid.errors import CheckpointError, ParameterError


def checksum(arrays: dict) -> str:
    """SHA-256 over every array's name, dtype, shape and bytes (an edited file with doubled counts is refused)."""
    h = hashlib.sha256()
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def prepare_directory(directory: Path) -> None:
    """Before any work: the checkpoint path must be a directory that can be created and written."""
    if directory.exists() and not directory.is_dir():
        raise CheckpointError(f"checkpoint {str(directory)!r} is a file, not a directory; give a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CheckpointError(f"cannot create the checkpoint directory {str(directory)!r} ({exc.strerror or exc})") \
            from None


def read_checked(path: Path, fmt: int, hint: str) -> dict:
    """The arrays of the checkpoint ``path`` (``checksum`` removed) after its format and checksum are verified."""
    try:
        with np.load(path, allow_pickle=False) as d:
            arrays = {k: d[k] for k in d.files}
    except Exception as exc:  # not a zip, truncated, bad member: numpy raises many types
        raise CheckpointError(f"checkpoint {path} cannot be read ({type(exc).__name__}): it is corrupt; {hint}") \
            from None
    stored = str(arrays.pop("checksum", ""))
    if "format" not in arrays or int(arrays["format"]) != fmt:
        raise CheckpointError(f"checkpoint {path} has an old or unknown format (need {fmt}); {hint}")
    if stored != checksum(arrays):
        raise CheckpointError(f"checkpoint {path} fails its checksum (edited or corrupt); {hint}")
    return arrays


@contextmanager
def dask_client(scheduler):
    """A ``distributed.Client`` for ``scheduler`` ("dask": a LocalCluster of this machine, "dask=ADDRESS", or a
    Client, which is used as it is); what it opened is closed on exit."""
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover
        raise ParameterError("scheduler='dask' needs dask.distributed: pip install 'dask[distributed]'") from exc
    if not isinstance(scheduler, str):
        yield scheduler
        return
    name, _, address = scheduler.partition("=")
    if name != "dask":
        raise ParameterError(f"unknown scheduler {scheduler!r}; use threads, dask, dask=ADDRESS or a Client")
    own = []
    try:
        if address:
            own.append(Client(address))
        else:
            own.append(LocalCluster(n_workers=min(2, os.cpu_count() or 1), threads_per_worker=1, processes=True,
                                    dashboard_address=None))
            own.append(Client(own[-1]))
        yield own[-1]
    finally:
        for obj in reversed(own):  # the client before its cluster
            obj.close()
