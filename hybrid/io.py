"""Output files: checked before the work starts, written atomically, refused in one line.

Every command and result type writes through :func:`atomic_write`: a reader sees either the old file (or none) or
the complete new one, never half of it, and a failed write (read-only folder, full disk) leaves nothing behind and
raises :class:`~hybrid.errors.OutputError` in one line.

A command first lists what it will write in an :class:`OutputPlan`. The plan refuses, before any work, an empty
name, a name too long for the file system, a missing folder, a directory or a special file where a file is to go,
a folder in which no file can be created (read-only, ``/proc``), and two outputs (or an output and an input) that
are one file, such as ``--out h.json`` and its own provenance sidecar ``h.json``. A ten-minute run then cannot die
at its end on a path it could have checked at its start; only a full disk remains, and that is reported in one
line with the partial file removed.
"""

from __future__ import annotations

import errno
import os
import secrets
import stat
from collections.abc import Callable
from pathlib import Path

from .errors import OutputError

_NAME_MAX_FALLBACK = 255


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return _NAME_MAX_FALLBACK


def _temporary_name(path: Path) -> str:
    """A unique hidden name beside ``path`` that fits the file system's name limit (the stem is shortened)."""
    tag = f".{os.getpid()}.{secrets.token_hex(4)}.part{path.suffix[:16]}"  # a suffix keeps the writer's format
    room = _name_max(path.parent if str(path.parent) else Path(".")) - len(os.fsencode(tag)) - 1
    stem = os.fsencode(path.name)[: max(room, 1)].decode(errors="ignore") or "out"
    return f".{stem}{tag}"


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _shown(path) -> str:
    """A path as a message shows it: a very long one is cut in its middle, so that the reason after it survives."""
    text = str(path)
    return repr(text) if len(text) <= 100 else repr(f"{text[:40]}...{text[-40:]}")


def _describe(path, label: str | None) -> str:
    return f"{label} {_shown(path)}" if label else _shown(path)


def check_output_file(path, label: str | None = None) -> Path:
    """Check that ``path`` can be written as a file, before any work; return it as a Path.

    Refused with :class:`~hybrid.errors.OutputError`: an empty name, a name longer than the file system allows, a
    missing folder, an existing directory or special file (``/dev/null``: the atomic rename would replace the device),
    and a folder in which no file can be created (read-only, ``/proc``). The check creates and removes one empty
    temporary file, the kind the atomic write will use.

    Parameters
    ----------
    path : str or Path
        The destination.
    label : str, optional
        How the user named it (``"--out"``), for the message.

    Examples
    --------
    >>> import tempfile, os
    >>> check_output_file(os.path.join(tempfile.mkdtemp(), "p.csv")).name
    'p.csv'
    >>> check_output_file("", "--out")
    Traceback (most recent call last):
    ...
    hybrid.errors.OutputError: --out '': give a file name
    """
    text = os.fspath(path) if path is not None else ""
    if not str(text).strip():
        raise OutputError(f"{label or 'output'} {str(text)!r}: give a file name")
    if text == "-":
        raise OutputError(f"{label or 'output'} '-': standard output is not a file this command can write; give a "
                          "file name")
    path = Path(text)
    where = _describe(path, label)
    folder = path.parent if str(path.parent) else Path(".")
    if text.endswith(os.sep) or path.name in ("", ".", ".."):
        raise OutputError(f"{where} names a directory; give a file name")
    limit = _name_max(folder) if folder.is_dir() else _NAME_MAX_FALLBACK
    if len(os.fsencode(path.name)) > limit:
        raise OutputError(f"{where}: the name is {len(os.fsencode(path.name))} bytes long, above the file system's "
                          f"limit of {limit}; give a shorter name")
    if not folder.is_dir():
        raise OutputError(f"{where}: folder {_shown(folder)} does not exist; create it first")
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise OutputError(f"{where} cannot be written: {_reason(exc)}") from exc
    if mode is not None and stat.S_ISDIR(mode):
        raise OutputError(f"{where} is a directory; give a file name inside it")
    if mode is not None and not stat.S_ISREG(mode):
        raise OutputError(f"{where} is not a regular file (a device, pipe or socket); give a file path")
    if mode is not None and not os.access(path, os.W_OK):  # the rename would replace it all the same: ask first
        raise OutputError(f"{where} exists and is read-only; remove it or choose another path")
    _probe_folder(folder, path, where)
    return path


def _probe_folder(folder: Path, path: Path, where: str) -> None:
    probe = folder / _temporary_name(path)
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise OutputError(f"{where}: no file can be created in {_shown(folder)} ({_reason(exc)}); choose a writable "
                          "folder") from exc
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass


def check_output_dir(path, label: str | None = None) -> Path:
    """Check that ``path`` is, or can be made, a folder to write files in, before any work; return it as a Path.

    A folder that does not exist yet is fine when its nearest existing ancestor is a writable folder (it is created
    with its parents when the first file is written). Refused with :class:`~hybrid.errors.OutputError` otherwise.

    Examples
    --------
    >>> import tempfile, os
    >>> check_output_dir(os.path.join(tempfile.mkdtemp(), "new", "sub")).name
    'sub'
    """
    text = os.fspath(path) if path is not None else ""
    if not str(text).strip():
        raise OutputError(f"{label or 'output folder'} {str(text)!r}: give a folder name")
    path = Path(text)
    where = _describe(path, label)
    for part in path.parts:
        if len(os.fsencode(part)) > _NAME_MAX_FALLBACK:
            raise OutputError(f"{where}: the name {part[:20]!r}... is {len(os.fsencode(part))} bytes long, above "
                              f"the file system's limit of {_NAME_MAX_FALLBACK}")
    existing = path
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent if str(existing.parent) else Path(".")
    if existing.exists() and not existing.is_dir():
        raise OutputError(f"{where}: {str(existing)!r} is a file, not a folder; choose another folder")
    _probe_folder(existing, path / "probe", where)
    return path


class OutputPlan:
    """The files a command will write (and the ones it reads), checked together before any work starts.

    :meth:`file` checks one destination and, with ``sidecar=True``, the ``.json`` provenance sidecar beside it;
    :meth:`folder` checks an output folder; :meth:`reads` notes an input that no output may overwrite. Two entries
    on one file (after resolving links and ``..``) are refused with both names.

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> plan = OutputPlan()
    >>> _ = plan.file(os.path.join(d, "h.csv"), "--out", sidecar=True)
    >>> plan.file(os.path.join(d, "h.json"), "--summary-json")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hybrid.errors.OutputError: --summary-json and the provenance sidecar of --out are one file (h.json); give ...
    """

    def __init__(self):
        self._claims: dict[str, tuple[str, bool]] = {}

    def _claim(self, path: Path, label: str, is_input: bool = False) -> None:
        key = os.path.realpath(path)
        if key in self._claims:
            other, other_is_input = self._claims[key]
            if is_input and other_is_input:  # one file read twice is fine
                return
            raise OutputError(f"{label} and {other} are one file ({path.name}); give them different names")
        self._claims[key] = (label, is_input)

    def claim(self, path, label: str) -> None:
        """Claim a file that the command writes without checking it now (it goes inside a claimed folder)."""
        self._claim(Path(path), label)

    def file(self, path, label: str, sidecar: bool = False) -> Path:
        """Check and claim an output file (and its ``.json`` sidecar); return its Path."""
        path = check_output_file(path, label)
        self._claim(path, label)
        if sidecar:
            side = path.with_suffix(".json")
            if os.path.realpath(side) == os.path.realpath(path):
                raise OutputError(f"{label} {_shown(path)} would be overwritten by its own provenance sidecar "
                                  f"{side.name}; give it another suffix, e.g. .csv")
            check_output_file(side, f"the provenance sidecar of {label}")
            self._claim(side, f"the provenance sidecar of {label}")
        return path

    def folder(self, path, label: str) -> Path:
        """Check and claim an output folder; return its Path."""
        path = check_output_dir(path, label)
        self._claim(path, label)
        return path

    def reads(self, path, label: str = "input") -> None:
        """Note an input file, so that no output of the same plan replaces it."""
        self._claim(Path(path), f"the input {label}", is_input=True)


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
    OutputError
        When the folder does not exist, or the file cannot be created, written or renamed (read-only folder, full
        disk, name too long); the temporary file is removed and an existing ``path`` is left as it was.

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
        raise OutputError(f"cannot write {_shown(path)}: folder {_shown(folder)} does not exist")
    if path.is_dir():
        raise OutputError(f"cannot write {_shown(path)}: it is a directory")
    # a unique hidden name created with O_EXCL: the file gets the usual permissions (0666 minus the umask), which
    # mkstemp's 0600 would not give
    tmp = str(folder / _temporary_name(path))
    try:
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except OSError as exc:
        raise OutputError(f"cannot write {_shown(path)}: {_reason(exc)}") from exc
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) or _is_disk_error(exc):
            raise OutputError(f"cannot write {_shown(path)}: {_disk_reason(exc)}; nothing was written") from exc
        raise
    return path


_DISK_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG}


def _is_disk_error(exc: BaseException) -> bool:
    # pandas and PIL wrap the OSError of a full disk in errors of their own; only a file-system errno counts, so that
    # a defect raised while some other OSError was handled is not reported as a write failure
    seen = exc.__cause__ or exc.__context__
    return isinstance(seen, OSError) and seen.errno in _DISK_ERRNOS


def _disk_reason(exc: BaseException) -> str:
    inner = exc if isinstance(exc, OSError) else (exc.__cause__ or exc.__context__)
    if isinstance(inner, OSError) and inner.errno == errno.ENOSPC:
        return "no space left on the device"
    return _reason(inner) if isinstance(inner, OSError) else str(exc)


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
