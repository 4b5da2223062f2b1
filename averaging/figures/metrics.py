"""Distances between an analytic density and a Monte Carlo histogram, on the histogram's own bins.

The analytic density is averaged over each Monte Carlo bin (exact integral of its piecewise-linear interpolant),
so that a coarse histogram is compared with what it estimates, not with point values at bin centres.
"""

from __future__ import annotations

import numpy as np


def bin_average(x, p, edges):
    """Mean of the piecewise-linear interpolant of (x, p) over each bin [edges[i], edges[i+1]].

    Outside [x[0], x[-1]] the density is taken as 0.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.linspace(0.0, 2.0, 201)
    >>> bin_average(x, x, [0.0, 1.0, 2.0]).round(12).tolist()
    [0.5, 1.5]
    """
    x = np.asarray(x, dtype=float)
    p = np.asarray(p, dtype=float)
    edges = np.asarray(edges, dtype=float)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(x))])

    def F(t):
        # integral of the interpolant from x[0] to t; exact for piecewise-linear p
        t = np.clip(t, x[0], x[-1])
        k = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(x) - 2)
        s = t - x[k]
        slope = (p[k + 1] - p[k]) / (x[k + 1] - x[k])
        return cum[k] + p[k] * s + 0.5 * slope * s * s

    return np.diff(F(edges)) / np.diff(edges)


def l1_on_bins(p_analytic_binavg, p_mc, edges) -> float:
    """L1 = Σ |p_analytic_binavg − p_mc| · ΔH over the Monte Carlo bins.

    Examples
    --------
    >>> l1_on_bins([1.0, 0.0], [0.0, 1.0], [0.0, 0.5, 1.0])
    1.0
    """
    d = np.abs(np.asarray(p_analytic_binavg, dtype=float) - np.asarray(p_mc, dtype=float))
    return float(np.sum(d * np.diff(np.asarray(edges, dtype=float))))


def l1_joint(p_a, p_b, x_edges, y_edges) -> float:
    """L1 = Σ |p_a − p_b| ΔxΔy for densities of shape (ny, nx) on the same bins.

    Examples
    --------
    >>> import numpy as np
    >>> l1_joint(np.ones((2, 2)), np.zeros((2, 2)), [0, 0.5, 1], [0, 0.5, 1])
    1.0
    """
    area = np.outer(np.diff(np.asarray(y_edges, float)), np.diff(np.asarray(x_edges, float)))
    return float(np.sum(np.abs(np.asarray(p_a) - np.asarray(p_b)) * area))


def joint_bin_average(joint, x_edges, y_edges, sub: int = 4):
    """Average of ``joint(x, y) -> (ny, nx)`` over each cell, by ``sub`` x ``sub`` midpoints per cell.

    Examples
    --------
    >>> import numpy as np
    >>> f = lambda x, y: np.add.outer(np.asarray(y), np.asarray(x))
    >>> joint_bin_average(f, [0.0, 1.0], [0.0, 2.0]).round(12).tolist()
    [[1.5]]
    """
    x_edges = np.asarray(x_edges, dtype=float)
    y_edges = np.asarray(y_edges, dtype=float)
    offs = (np.arange(sub) + 0.5) / sub
    xs = (x_edges[:-1, None] + np.diff(x_edges)[:, None] * offs).ravel()
    ys = (y_edges[:-1, None] + np.diff(y_edges)[:, None] * offs).ravel()
    fine = np.asarray(joint(xs, ys), dtype=float)
    ny, nx = len(y_edges) - 1, len(x_edges) - 1
    return fine.reshape(ny, sub, nx, sub).mean(axis=(1, 3))


def halves_noise_l1(p_a, p_b, widths) -> float:
    """Expected L1 of the merged histogram's noise, from two independent half-batches: L1(a, b) / 2.

    With a and b independent of equal variance s², |a − b| has mean s·sqrt(2)·sqrt(2/π) and the merged mean
    (a + b)/2 has mean absolute error (s/sqrt(2))·sqrt(2/π): half of it.

    Examples
    --------
    >>> halves_noise_l1([1.0, 0.0], [0.0, 1.0], [0.5, 0.5])
    0.5
    """
    d = np.abs(np.asarray(p_a, dtype=float) - np.asarray(p_b, dtype=float))
    return float(0.5 * np.sum(d * np.asarray(widths, dtype=float)))
