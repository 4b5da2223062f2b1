"""One size estimator for every request: refuse work or memory above a limit before anything starts.

Each entry point (Monte Carlo ensembles, event-exact orbits, energy grids, the phase-plane grid, the planner of
``vibro solve``) states what its request costs, in its own unit of work and in bytes, and calls
:func:`check_size`. Above a limit the request is refused at once with a :class:`SizeError` whose one-line message
gives the estimate, the limit and how to get under it; nothing has been computed or allocated yet.

Examples
--------
>>> check_size("the grid", work=1e6, work_unit="cells", max_work=1e7, memory=8e6)
>>> try:
...     check_size("the grid", work=1e10, work_unit="cells", max_work=1e7, fix="use fewer cells")
... except SizeError as exc:
...     print(exc)
the grid needs about 1e+10 cells, above the limit 1e+07; use fewer cells
"""

from __future__ import annotations

import math
import numbers

from hybrid.errors import ParameterError

MAX_MEMORY = 4e9
"""Default memory limit of one request, in bytes (``vibro mc --max-memory-gb 4``)."""

MAX_PATH_STEPS = 1e13
"""Default work limit of a Monte Carlo request, in path-steps (``vibro mc --max-path-steps``)."""


class SizeError(ParameterError):
    """A request whose estimated work or memory is above its limit; refused before it starts."""


def _gb(n: float) -> str:
    return f"{n / 1e9:.3g} GB"


def _duration(seconds: float) -> str:
    """A readable duration: seconds, hours, or years for the absurd ones."""
    if not math.isfinite(seconds):
        return "forever"
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 3.156e7:.3g} years"


def check_limit(name: str, value) -> float:
    """``value`` as a positive float limit, or a :class:`ParameterError` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not float(value) > 0:  # also NaN
        raise ParameterError(f"{name}={value!r} must be a positive number")
    return float(value)


def check_size(what: str, *, work: float = 0.0, work_unit: str = "steps", max_work: float | None = None,
               memory: float = 0.0, max_memory: float | None = MAX_MEMORY, seconds_per_unit: float | None = None,
               detail: str = "", fix: str = "", work_fix: str | None = None, memory_fix: str | None = None) -> None:
    """Refuse a request whose estimated work or memory is above its limit, with the estimate in one line.

    Parameters
    ----------
    what : str
        The request, as the message starts: "the orbit up to t_end=1e12".
    work : float
        Estimated work in ``work_unit`` (steps, path-steps, cells); may be inf.
    max_work : float, optional
        Work limit; None: no work limit.
    memory : float
        Estimated peak memory in bytes; may be inf.
    max_memory : float, optional
        Memory limit in bytes (default :data:`MAX_MEMORY`); None: no memory limit.
    seconds_per_unit : float, optional
        Typical cost of one unit of work; adds the expected duration to the message.
    detail : str
        How the estimate was made (appended in parentheses).
    fix, work_fix, memory_fix : str
        How to get under the limit (``work_fix``/``memory_fix`` override ``fix`` for that limit).

    Raises
    ------
    SizeError
        When ``work > max_work`` or ``memory > max_memory`` (NaN counts as above).
    """
    work, memory = float(work), float(memory)
    note = f" ({detail})" if detail else ""
    if max_work is not None and not work <= max_work:
        time = f", about {_duration(work * seconds_per_unit)}" if seconds_per_unit else ""
        hint = work_fix if work_fix is not None else fix
        raise SizeError(f"{what} needs about {work:.3g} {work_unit}{time}{note}, above the limit {max_work:.6g}"
                        + (f"; {hint}" if hint else ""))
    if max_memory is not None and not memory <= max_memory:
        hint = memory_fix if memory_fix is not None else fix
        raise SizeError(f"{what} needs about {_gb(memory)} of memory{note}, above the limit {_gb(max_memory)}"
                        + (f"; {hint}" if hint else ""))


__all__ = ["MAX_MEMORY", "MAX_PATH_STEPS", "SizeError", "check_limit", "check_size"]
