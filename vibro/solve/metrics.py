"""One definition of the distance between densities of H (and of (x, y)), used by every study and by ``solve``.

An analytic density is turned into **probability masses** per bin by the exact integral of its piecewise-linear
interpolant; a Monte Carlo histogram into masses by dividing its counts by the *total* number of samples (overflow
included). Neither is renormalised over the bins, so mass that a method puts outside the bins counts as error.
The L1 distance is the sum of absolute differences of masses.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import NormalisationError, ParameterError


def _cumulative(x, p):
    return np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(x))])


def bin_masses(x, p, edges) -> np.ndarray:
    """Mass of the piecewise-linear interpolant of (x, p) in each bin of ``edges`` (exact; 0 outside [x0, x-1]).

    Examples
    --------
    >>> H = np.linspace(0, 1, 1001); edges = np.linspace(0, 1, 5)
    >>> bin_masses(H, np.ones_like(H), edges).round(6).tolist()
    [0.25, 0.25, 0.25, 0.25]
    """
    x = np.asarray(x, dtype=float)
    p = np.asarray(p, dtype=float)
    edges = np.asarray(edges, dtype=float)
    if not np.all(np.isfinite(p)):
        raise NormalisationError("the density has non-finite values; it cannot be compared")
    cum = _cumulative(x, p)

    def F(t):
        # integral of the interpolant from x[0] to t; exact for piecewise-linear p
        t = np.clip(t, x[0], x[-1])
        k = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(x) - 2)
        s = t - x[k]
        slope = (p[k + 1] - p[k]) / (x[k + 1] - x[k])
        return cum[k] + p[k] * s + 0.5 * slope * s * s

    m = np.diff(F(edges))
    if not m.sum() > 0:
        raise NormalisationError("the density has no mass on the comparison grid")
    return m


def bin_average(x, p, edges):
    """Mean of the piecewise-linear interpolant of (x, p) over each bin: :func:`bin_masses` over the widths.

    Examples
    --------
    >>> x = np.linspace(0.0, 2.0, 201)
    >>> bin_average(x, x, [0.0, 1.0, 2.0]).round(12).tolist()
    [0.5, 1.5]
    """
    return bin_masses(x, p, edges) / np.diff(np.asarray(edges, dtype=float))


def histogram_masses(counts, total=None) -> np.ndarray:
    """Counts as probability masses: divided by ``total`` (all samples, overflow included; default: their sum)."""
    counts = np.asarray(counts, dtype=float)
    total = counts.sum() if total is None else float(total)
    if not total > 0:
        raise NormalisationError("the histogram holds no samples")
    return counts / total


def l1_masses(a, b) -> float:
    """L1 distance between two vectors of probability masses on the same bins: sum |a - b|.

    Examples
    --------
    >>> l1_masses([0.5, 0.5], [0.25, 0.75])
    0.5
    """
    return float(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)).sum())


def l1_between_histograms(a, b, total_a=None, total_b=None) -> float:
    """L1 distance between two histograms of equal bins, each divided by its total (default: its own sum).

    Examples
    --------
    >>> l1_between_histograms([1, 1, 0], [0, 1, 1])
    1.0
    """
    return l1_masses(histogram_masses(a, total_a), histogram_masses(b, total_b))


def l1_on_bins(p_a, p_b, edges) -> float:
    """L1 distance between two densities given as bin averages on ``edges``: sum |p_a - p_b| * width.

    Examples
    --------
    >>> l1_on_bins([1.0, 0.0], [0.0, 1.0], [0.0, 0.5, 1.0])
    1.0
    """
    w = np.diff(np.asarray(edges, dtype=float))
    return l1_masses(np.asarray(p_a, dtype=float) * w, np.asarray(p_b, dtype=float) * w)


def rebin_counts(counts, n_out: int) -> np.ndarray:
    """Merge a histogram of ``len(counts)`` bins into ``n_out`` bins (n_out must divide len(counts))."""
    counts = np.asarray(counts, dtype=float)
    if len(counts) % n_out:
        raise ParameterError(f"cannot merge {len(counts)} bins into {n_out}")
    return counts.reshape(n_out, -1).sum(axis=1)


def halves_noise_l1(p_a, p_b, widths) -> float:
    """Expected L1 of the merged histogram's noise, from two independent half-batches: L1(a, b) / 2.

    With a and b independent of equal variance s², |a − b| has mean s·sqrt(2)·sqrt(2/π) and the merged mean
    (a + b)/2 has mean absolute error (s/sqrt(2))·sqrt(2/π): half of it.

    Examples
    --------
    >>> halves_noise_l1([1.0, 0.0], [0.0, 1.0], [0.5, 0.5])
    0.5
    """
    w = np.asarray(widths, dtype=float)
    return 0.5 * l1_masses(np.asarray(p_a, dtype=float) * w, np.asarray(p_b, dtype=float) * w)


def l1_joint(p_a, p_b, x_edges, y_edges) -> float:
    """L1 = Σ |p_a − p_b| ΔxΔy for densities of shape (ny, nx) on the same bins.

    Examples
    --------
    >>> l1_joint(np.ones((2, 2)), np.zeros((2, 2)), [0, 0.5, 1], [0, 0.5, 1])
    1.0
    """
    area = np.outer(np.diff(np.asarray(y_edges, float)), np.diff(np.asarray(x_edges, float)))
    return l1_masses(np.asarray(p_a, dtype=float) * area, np.asarray(p_b, dtype=float) * area)


def joint_bin_average(joint, x_edges, y_edges, sub: int = 4):
    """Average of ``joint(x, y) -> (ny, nx)`` over each cell, by ``sub`` x ``sub`` midpoints per cell.

    Examples
    --------
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
