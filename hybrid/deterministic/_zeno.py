"""Detection of Zeno behaviour: impact times that accumulate like a geometric series."""

from __future__ import annotations

import math
from collections import deque

from hybrid.errors import ParameterError


class ZenoDetector:
    """Watch transition times; flag a geometric accumulation t_k + dt_k r / (1 - r).

    The ratios of successive intervals r_i = dt_{i+1} / dt_i must lie in (0, ``max_ratio``) and their deficits
    1 - r_i must agree within ``rtol`` (relative spread) over ``window`` ratios. Comparing the deficits rather than
    the ratios is what separates an accumulation at any ratio below 1 (constant deficit) from intervals that
    converge to a period (the deficit itself decays to 0). The prediction is the sum of the remaining series.

    Parameters
    ----------
    window : int
        Number of successive ratios that must agree (needs ``window + 2`` transitions).
    rtol : float
        Allowed relative spread (max - min) / mean of the deficits 1 - r_i.
    max_ratio : float
        Ratios at or above this are not an accumulation (default 1: any ratio below 1 counts).

    Raises
    ------
    ParameterError
        ``window`` outside [2, 10000], a negative or non-finite ``rtol``, or ``max_ratio`` outside (0, 1].

    Examples
    --------
    >>> z = ZenoDetector(window=4)
    >>> [z.add(t) for t in (1.0, 1.5, 1.75, 1.875, 1.9375)]
    [None, None, None, None, None]
    >>> z.add(1.96875)
    2.0
    """

    def __init__(self, window: int = 6, rtol: float = 1e-3, max_ratio: float = 1.0):
        if isinstance(window, bool) or not isinstance(window, int) or not 2 <= window <= 10_000:
            raise ParameterError(f"zeno window={window!r} must be an integer in [2, 10000]")
        if not (isinstance(rtol, (int, float)) and math.isfinite(rtol) and rtol >= 0):
            raise ParameterError(f"zeno rtol={rtol!r} must be a finite relative spread >= 0, e.g. 1e-3")
        if not (isinstance(max_ratio, (int, float)) and 0.0 < max_ratio <= 1.0):
            raise ParameterError(f"zeno max_ratio={max_ratio!r} must lie in (0, 1]")
        self.window = int(window)
        self.rtol = float(rtol)
        self.max_ratio = float(max_ratio)
        self._times: deque = deque(maxlen=self.window + 2)
        self.ratio: float | None = None

    def add(self, t: float) -> float | None:
        """Record a transition at time ``t``; return the predicted accumulation time, or None."""
        self._times.append(float(t))
        if len(self._times) < self._times.maxlen:
            return None
        times = list(self._times)
        dts = [b - a for a, b in zip(times[:-1], times[1:])]
        if min(dts) <= 0.0:
            return None
        ratios = [b / a for a, b in zip(dts[:-1], dts[1:])]
        if not (0.0 < max(ratios) < self.max_ratio):
            return None
        deficits = [1.0 - r for r in ratios]
        mean = sum(deficits) / len(deficits)
        if (max(deficits) - min(deficits)) > self.rtol * mean:
            return None
        r = ratios[-1]
        self.ratio = r
        return times[-1] + dts[-1] * r / (1.0 - r)
