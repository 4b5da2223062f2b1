"""Atomic file output: a reader sees either the old file (or none) or the complete new one, never half of it.

Every command and result type writes through :func:`atomic_write`, so an interrupted run leaves no partial file
that looks complete.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Callable
from pathlib import Path

from .errors import ParameterError


def atomic_write(path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it onto ``path``.

    Parameters
    ----------
    path : str or Path
        The destination; its folder must exist.
    write : callable
        Writes the complete content to the temporary path it is given.

    Raises
    ------
    ParameterError
        When the destination folder does not exist.

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> p = atomic_write(os.path.join(d, "a.txt"), lambda tmp: open(tmp, "w").write("hi"))
    >>> p.read_text()
    'hi'
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ParameterError(f"cannot write {str(path)!r}: folder {str(folder)!r} does not exist")
    # a unique hidden name created with open(.., "x"): the file gets the usual permissions (0666 minus the umask),
    # which mkstemp's 0600 would not give
    tmp = str(folder / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.part{path.suffix}")
    open(tmp, "x").close()
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically.

    Examples
    --------
    >>> import tempfile, os
    >>> atomic_write_text(os.path.join(tempfile.mkdtemp(), "a.csv"), "H,p\\n").read_text()
    'H,p\\n'
    """

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())

    return atomic_write(path, write)


def write_csv_atomically(frame, path) -> Path:
    """Write a pandas DataFrame to ``path`` atomically (no index column).

    Examples
    --------
    >>> import pandas as pd, tempfile, os
    >>> p = write_csv_atomically(pd.DataFrame({"a": [1]}), os.path.join(tempfile.mkdtemp(), "x.csv"))
    >>> p.read_text().splitlines()
    ['a', '1']
    """

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            frame.to_csv(fh, index=False)  # streamed: a large frame is never held as one string

    return atomic_write(path, write)
