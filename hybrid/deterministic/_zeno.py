"""Detection of Zeno behaviour: impact times that accumulate like a geometric series."""

from __future__ import annotations

from collections import deque


class ZenoDetector:
    """Watch transition times; flag a geometric accumulation t_k + dt_k r / (1 - r).

    The ratios of successive intervals r_i = dt_{i+1} / dt_i must stay below ``max_ratio`` and agree within
    ``rtol`` (relative spread) over ``window`` ratios. The prediction is the sum of the remaining geometric series.

    Parameters
    ----------
    window : int
        Number of successive ratios that must agree (needs ``window + 2`` transitions).
    rtol : float
        Allowed relative spread (max - min) / mean of those ratios.
    max_ratio : float
        Ratios at or above this are not an accumulation (intervals converging to a period have ratio -> 1).

    Examples
    --------
    >>> z = ZenoDetector(window=4)
    >>> [z.add(t) for t in (1.0, 1.5, 1.75, 1.875, 1.9375)]
    [None, None, None, None, None]
    >>> z.add(1.96875)
    2.0
    """

    def __init__(self, window: int = 6, rtol: float = 1e-3, max_ratio: float = 0.99):
        if window < 2:
            raise ValueError(f"zeno window must be >= 2, got {window}")
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
        mean = sum(ratios) / len(ratios)
        if not (0.0 < max(ratios) < self.max_ratio):
            return None
        if (max(ratios) - min(ratios)) > self.rtol * mean:
            return None
        r = ratios[-1]
        self.ratio = r
        return times[-1] + dts[-1] * r / (1.0 - r)
