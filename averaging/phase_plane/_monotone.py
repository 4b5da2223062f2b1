"""A shape-preserving piecewise cubic (Fritsch-Carlson slopes, Fritsch-Butland weights) for cumulative masses.

The phase-plane densities interpolate their cumulative ring masses with it: monotone data stay monotone, so bin
masses are never negative. scipy.interpolate has the same interpolant, but importing it costs 0.2-0.3 s (it imports
scipy.optimize), a large share of ``vibro solve``'s start-up; the algorithm is twenty lines of numpy.
"""

from __future__ import annotations

import numpy as np


class MonotoneCubic:
    """Piecewise cubic Hermite interpolant of (x, y) with shape-preserving slopes; ``derivative()`` gives its slope.

    Interior slopes: 0 where the neighbouring secants differ in sign or one is 0, else their weighted harmonic mean
    with weights 2 h_k + h_(k-1) and h_k + 2 h_(k-1). End slopes: the three-point one-sided formula, set to 0 when
    its sign differs from the first secant's and limited to three times that secant when the first two secants
    differ in sign. Outside [x_0, x_n] the end cubics continue.

    Parameters
    ----------
    x : array_like
        Strictly increasing abscissae (at least 2).
    y : array_like
        Values at ``x``.

    Examples
    --------
    >>> f = MonotoneCubic([0.0, 1.0, 2.0, 3.0], [0.0, 0.1, 0.9, 1.0])
    >>> [round(float(v), 4) for v in f([0.5, 1.5, 3.0])]
    [0.0278, 0.5, 1.0]
    >>> bool(np.all(np.diff(f(np.linspace(0, 3, 301))) >= 0))
    True
    """

    def __init__(self, x, y, _slopes=None, _order: int = 0):
        self.x = np.asarray(x, dtype=float)
        self.y = np.asarray(y, dtype=float)
        if self.x.ndim != 1 or len(self.x) < 2 or self.x.shape != self.y.shape or np.any(np.diff(self.x) <= 0):
            raise ValueError("MonotoneCubic needs at least 2 strictly increasing x and one y per x")
        self.d = self._slopes() if _slopes is None else _slopes
        self.order = _order  # 0: the interpolant, 1: its derivative

    def _slopes(self) -> np.ndarray:
        h = np.diff(self.x)
        delta = np.diff(self.y) / h
        d = np.empty_like(self.x)
        if len(h) == 1:
            d[:] = delta[0]
            return d
        w1 = 2.0 * h[1:] + h[:-1]
        w2 = h[1:] + 2.0 * h[:-1]
        same = (delta[:-1] * delta[1:]) > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            harmonic = (w1 + w2) / (w1 / delta[:-1] + w2 / delta[1:])
        d[1:-1] = np.where(same, harmonic, 0.0)
        d[0] = self._end(h[0], h[1], delta[0], delta[1])
        d[-1] = self._end(h[-1], h[-2], delta[-1], delta[-2])
        return d

    @staticmethod
    def _end(h0, h1, m0, m1) -> float:
        d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        if np.sign(d) != np.sign(m0):
            return 0.0
        if np.sign(m0) != np.sign(m1) and abs(d) > abs(3.0 * m0):
            return 3.0 * m0
        return float(d)

    def derivative(self) -> MonotoneCubic:
        """The slope of the interpolant, as a callable of the same kind."""
        return MonotoneCubic(self.x, self.y, self.d, 1)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        k = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        x0, h = self.x[k], self.x[k + 1] - self.x[k]
        s = (t - x0) / h
        y0, y1, d0, d1 = self.y[k], self.y[k + 1], self.d[k], self.d[k + 1]
        if self.order == 0:  # Hermite basis on [0, 1]
            h00 = (1.0 + 2.0 * s) * (1.0 - s) ** 2
            h10 = s * (1.0 - s) ** 2
            h01 = s * s * (3.0 - 2.0 * s)
            h11 = s * s * (s - 1.0)
            return h00 * y0 + h10 * h * d0 + h01 * y1 + h11 * h * d1
        dh00 = 6.0 * s * (s - 1.0) / h
        dh10 = (1.0 - s) * (1.0 - 3.0 * s)
        dh01 = -dh00
        dh11 = s * (3.0 * s - 2.0)
        return dh00 * y0 + dh10 * d0 + dh01 * y1 + dh11 * d1
