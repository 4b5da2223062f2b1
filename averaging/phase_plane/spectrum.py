r"""Power spectral density of an observable from the phase-plane generator, through its resolvent (method ``fpk``).

With the stationary density p, the forward equation M dp/dt = -A p of :mod:`averaging.phase_plane.passage` and
g = f - E f an observable centred, the correlation function C(tau) = E[g(Z_0) g(Z_tau)] has the Laplace transform

    C^(s) = int_0^inf e^{-s tau} C(tau) d tau = g . M (s M + A)^{-1} M (g p),

so one complex sparse solve per frequency gives the one-sided spectral density

    S(omega) = (2 / pi) Re C^(i omega),        int_0^inf S(omega) d omega = C(0) = Var f.

(S is twice the two-sided density of the Wiener-Khinchin pair C(tau) = int S2(omega) e^{i omega tau} d omega.)
At omega = 0 the matrix is singular (its null vector is p); g p has zero total mass, so the solve there is the
one of the stationary problem with the normalisation row set to zero mass.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
import sympy as sp

from hybrid.automaton import lambdify_numeric
from hybrid.errors import ParameterError
from models import X, Y

from .passage import H_SYMBOL
from .solver import stationary_density_xy

SPECTRUM_GRID = (80, 96)
"""Default (rings, angles): one complex LU of about 8 000 cells per frequency."""

SPECTRUM_STRETCH = 0.02
"""Width of the innermost ring over the uniform one (rings nearly uniform in radius sqrt(2 H)). The centre H = 0,
where the energy-angle coordinates are singular, puts a first-order error into the spectrum in proportion to the
innermost ring's width: on the free linear oscillator (c = 0.2, 80 x 96) the L1 error is 0.015 with the stationary
solver's 0.4 and 0.0027 with 0.02 (``benchmarks/spectrum_accuracy.py``)."""

SPECTRUM_ARC_END_ORDER = 2
"""The phase flux's order at the arcs' ends, where walls cut the rings (:func:`solve_phase_plane`'s
``arc_end_order``): the first-order upwind flux there smeared the phase and hence the harmonics; linear
reconstruction cuts the folded oscillator's L1 error from 0.010 to 0.0007 on 80 x 96
(``benchmarks/spectrum_accuracy.py``)."""

MAX_ORDER = 2.5
"""Highest convergence order the three-grid estimate and extrapolation accept (observed: 1.9 on the folded
oscillator, about 1.3-1.6 on the free one)."""


class Spectrum:
    """One-sided PSD S(omega) of an observable, with its variance check, peak and bandwidth.

    Attributes
    ----------
    method, observable : str
    omega, S : ndarray
        Frequencies (rad per unit time) and S, normalised so that int_0^inf S d omega = Var.
    variance : float
        Var of the observable under the stationary density (the exact C(0)).
    integral : float
        Trapezoid integral of S over the computed frequencies (0 to omega_max).
    variance_check : float
        integral / variance (1 up to the quadrature and the tail above omega_max).
    peak_omega, peak_S, bandwidth : float
        Frequency and height of the highest peak, and its full width at half height.
    mean : float
        E of the observable.
    details : dict
    """

    def __init__(self, method, observable, omega, S, variance, mean, details=None):
        self.method, self.observable = method, observable
        order = np.argsort(omega)
        self.omega = np.asarray(omega, dtype=float)[order]
        self.S = np.asarray(S, dtype=float)[order]
        self.variance, self.mean = float(variance), float(mean)
        self.integral = float(np.trapezoid(self.S, self.omega))
        self.variance_check = self.integral / self.variance if self.variance > 0 else float("nan")
        k = int(np.argmax(self.S))
        self.peak_S = float(self.S[k])
        self.peak_omega = _peak_location(self.omega, self.S, k)
        self.bandwidth = _half_power_width(self.omega, self.S, k)
        self.details = dict(details or {})

    def to_pandas(self):
        """DataFrame omega, S with :meth:`metadata` in ``.attrs``.

        Examples
        --------
        >>> s = Spectrum("fpk", "x", [0.0, 1.0, 2.0], [0.1, 1.0, 0.1], 1.1, 0.0)
        >>> list(s.to_pandas().columns), s.peak_omega
        (['omega', 'S'], 1.0)
        """
        import pandas as pd

        df = pd.DataFrame({"omega": self.omega, "S": self.S})
        df.attrs.update(self.metadata())
        return df

    def metadata(self) -> dict:
        """Method, observable and the summary figures (JSON-friendly)."""
        return {"method": self.method, "observable": self.observable, "variance": self.variance, "mean": self.mean,
                "integral": self.integral, "variance_check": self.variance_check, "peak_omega": self.peak_omega,
                "peak_S": self.peak_S, "bandwidth": self.bandwidth, "normalisation": "one-sided: int_0^inf S = Var",
                **{k: v for k, v in self.details.items() if isinstance(v, (int, float, str, list, type(None)))}}

    def __repr__(self):
        return (f"Spectrum(method={self.method!r}, observable={self.observable!r}, variance={self.variance:.6g}, "
                f"peak_omega={self.peak_omega:.6g}, bandwidth={self.bandwidth:.4g}, "
                f"variance_check={self.variance_check:.4f})")

    def _repr_html_(self):
        from hybrid.display import summary_html

        return summary_html(f"Spectrum of {self.observable} ({self.method})",
                            {"Var": self.variance, "int S": self.integral, "peak omega": self.peak_omega,
                             "bandwidth (half power)": self.bandwidth})


def _peak_location(omega, S, k):
    """The vertex of the parabola through the highest sample and its neighbours (the sample itself at an end)."""
    if 0 < k < len(S) - 1:
        w0, w1, w2 = omega[k - 1:k + 2]
        s0, s1, s2 = S[k - 1:k + 2]
        den = (w0 - w1) * (w0 - w2) * (w1 - w2)
        a = (w2 * (s1 - s0) + w1 * (s0 - s2) + w0 * (s2 - s1)) / den
        b = (w2 * w2 * (s0 - s1) + w1 * w1 * (s2 - s0) + w0 * w0 * (s1 - s2)) / den
        if a < 0:
            return float(np.clip(-b / (2 * a), w0, w2))
    return float(omega[k])


def fitted_peak(omega, S, level: float = 0.85) -> float:
    """The vertex of the least-squares parabola through the samples above ``level`` times the highest, around it.

    Less sensitive to the sampling than the three-point vertex of ``Spectrum.peak_omega``: the same estimator
    compares a Monte Carlo spectrum's bins with fpk's values at the same frequencies.

    Examples
    --------
    >>> w = np.linspace(0.0, 2.0, 201)
    >>> round(fitted_peak(w, 1.0 / ((1 - w**2) ** 2 + 0.04 * w**2)), 2)  # the exact peak: 0.98995
    0.99
    """
    k = int(np.argmax(S))
    lo, hi = k, k
    while lo > 0 and S[lo - 1] > level * S[k]:
        lo -= 1
    while hi < len(S) - 1 and S[hi + 1] > level * S[k]:
        hi += 1
    if hi - lo < 2:  # fewer than three samples above the level (a sharp peak, or one at an end): a parabola through
        return _peak_location(omega, S, k)  # the highest sample and its neighbours
    a, b, _ = np.polyfit(omega[lo:hi + 1], S[lo:hi + 1], 2)
    vertex = -b / (2 * a)
    return float(vertex) if a < 0 and omega[lo] <= vertex <= omega[hi] else _peak_location(omega, S, k)


def _half_power_width(omega, S, k):
    """Full width at half height of the peak at sample k (linear interpolation; to the end of the range where S
    stays above half height there)."""
    half = 0.5 * S[k]
    lo = k
    while lo > 0 and S[lo] > half:
        lo -= 1
    hi = k
    while hi < len(S) - 1 and S[hi] > half:
        hi += 1

    def cross(a, b):
        if S[a] == S[b]:
            return omega[a]
        return omega[a] + (half - S[a]) * (omega[b] - omega[a]) / (S[b] - S[a])

    left = cross(lo, lo + 1) if S[lo] <= half else omega[lo]
    right = cross(hi - 1, hi) if S[hi] <= half else omega[hi]
    return float(right - left)


def observable_values(model, observable, x, y):
    """An observable (text in x, y, H and the model's parameters) at the states (x, y).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> observable_values(DuffingImpact(), "y**2", np.array([0.0]), np.array([2.0])).tolist()
    [4.0]
    """
    names = {"x": X, "y": Y, "H": H_SYMBOL}
    try:
        expr = sp.sympify(observable, locals=names) if isinstance(observable, str) else sp.sympify(observable)
    except (sp.SympifyError, SyntaxError, TypeError, ValueError) as exc:
        raise ParameterError(f"observable {observable!r} is not an expression in x, y, H") from exc
    boolean = (sp.core.relational.Relational, sp.logic.boolalg.BooleanFunction, sp.logic.boolalg.BooleanAtom)
    if isinstance(expr, boolean):
        raise ParameterError(f"observable {observable!r} must be an expression, not a condition")
    expr = model.substitute(expr)
    extra = expr.free_symbols - {X, Y, H_SYMBOL}
    if extra:
        raise ParameterError(f"observable {observable!r}: unknown names {sorted(map(str, extra))}; use x, y, H and "
                             "the model's parameters")
    f = lambdify_numeric((X, Y, H_SYMBOL), expr)
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    with np.errstate(all="ignore"):
        v = np.broadcast_to(np.asarray(f(x, y, model.energy(x, y)), dtype=float), x.shape).copy()
    if not np.all(np.isfinite(v)):
        raise ParameterError(f"observable {observable!r} is not finite on the grid")
    return v


class _Resolvent:
    """C^(i omega) for one centred observable on one discretisation."""

    def __init__(self, sd, g):
        disc = sd.discretisation
        self.A = disc.A.tocsc()
        self.m = disc.mass_weight
        self.M = sps.diags(self.m)
        self.g = g
        self.rhs = g * sd.cell_mass  # M (g p)

    def laplace(self, omega):
        if omega == 0.0:
            return self._at_zero()
        # the complex system (A + i omega M) w = b as the real one [[A, -omega M], [omega M, A]]: SuperLU's real
        # factorisation of twice the size is 10-20x faster here than its complex one
        n = len(self.m)
        K = sps.bmat([[self.A, -omega * self.M], [omega * self.M, self.A]]).tocsc()
        rhs = np.concatenate([self.rhs, np.zeros(n)])
        try:
            w = spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1).solve(rhs)
        except RuntimeError:
            w = spla.spsolve(K, rhs, permc_spec="COLAMD")
        return complex(self.g @ (self.m * w[:n]), self.g @ (self.m * w[n:]))

    def _at_zero(self):
        A = self.A
        n = A.shape[0]
        k = int(np.argmax(np.abs(A.diagonal())))
        keep = np.ones(n)
        keep[k] = 0.0
        B = (sps.diags(keep) @ A + sps.csr_matrix((self.m, (np.full(n, k), np.arange(n))), shape=(n, n))).tocsc()
        rhs = self.rhs.copy()
        rhs[k] = 0.0
        w = spla.splu(B, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1).solve(rhs)
        return complex(self.g @ (self.m * w))


def spectrum_fpk(model, observable="x", *, omega=None, omega_max: float = 3.0, points: int = 150,
                 refine: int = 100, grid=SPECTRUM_GRID, h_max: float = 4.0, walls="model",
                 restitution=None, check: bool = False, extrapolate: bool = False,
                 stretch: float = SPECTRUM_STRETCH, arc_end_order: int = SPECTRUM_ARC_END_ORDER) -> Spectrum:
    """One-sided PSD of ``observable`` from the phase-plane generator (one complex sparse solve per frequency).

    Parameters
    ----------
    model : ImpactOscillator
    observable : str
        Expression in x, y, H and the model's parameters.
    omega : array, optional
        Frequencies to use (overrides ``omega_max``, ``points`` and ``refine``).
    omega_max, points : float, int
        A uniform grid of ``points`` frequencies on [0, omega_max].
    refine : int
        Further frequencies spread over five half-power widths either side of the peak (a narrow peak needs them
        for the peak, the bandwidth and the variance check).
    grid, h_max, walls, restitution
        As in :func:`averaging.phase_plane.stationary_density_xy`.
    check : bool
        Also compute S on grids twice and four times coarser at the same frequencies: ``error_estimate`` is the
        L1 distance of S and S_coarse over the integral of S, divided by 2**p - 1, p the order observed from the
        three grids (the ratio of the successive L1 differences), within [1, :data:`MAX_ORDER`]; ``order`` in
        ``details``. Costs about 30 % more.
    extrapolate : bool
        Return the Richardson extrapolation S + (S - S_coarse) / (2**p - 1) at that observed order (implies
        ``check``; ``error_estimate`` stays the estimate for the unextrapolated S, an upper bound in the measured
        cases: folded oscillator on 160 x 192, 0.0024 unextrapolated and 0.0007 extrapolated).
    stretch : float
        Innermost ring width over the uniform one (:data:`SPECTRUM_STRETCH`; see :func:`solve_phase_plane`).
    arc_end_order : {1, 2}
        The phase flux's order where walls end the arcs (:data:`SPECTRUM_ARC_END_ORDER`; see
        :func:`solve_phase_plane`).

    Returns
    -------
    Spectrum

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.05}, barriers=None)
    >>> s = spectrum_fpk(lin, "x", omega_max=4.0, points=25, refine=10, grid=(20, 32), h_max=3.0)
    >>> round(s.peak_omega, 2), round(s.variance, 2)        # exact: 0.99 and the variance D / c = 0.25
    (0.99, 0.25)
    """
    model.require_autonomous()
    if omega is None:
        if not (np.isfinite(omega_max) and omega_max > 0):
            raise ParameterError(f"omega_max={omega_max!r} must be a finite positive frequency")
        if int(points) != points or points < 3 or points > 100_000:
            raise ParameterError(f"points={points!r} must be an integer in 3..100000")
        if int(refine) != refine or refine < 0 or refine > 100_000:
            raise ParameterError(f"refine={refine!r} must be an integer in 0..100000")
        freqs = np.linspace(0.0, float(omega_max), int(points))
    else:
        freqs = np.unique(np.asarray(omega, dtype=float))
        refine = 0
        if freqs.size == 0 or not np.all(np.isfinite(freqs)) or freqs[0] < 0:
            raise ParameterError("omega must hold finite frequencies >= 0")
    t0 = time.perf_counter()
    sd = stationary_density_xy(model, grid=grid, h_max=h_max, walls=walls, restitution=restitution, check=False,
                               stretch=stretch, arc_end_order=arc_end_order)
    f = observable_values(model, observable, sd.cell_x, sd.cell_y)
    mean = float(sd.cell_mass @ f)
    g = f - mean
    var = float(sd.cell_mass @ (g * g))
    res = _Resolvent(sd, g)
    S = np.array([2.0 / np.pi * res.laplace(w).real for w in freqs])
    if refine and var > 0:
        k = int(np.argmax(S))
        width = _half_power_width(freqs, S, k)
        width = max(width, 2 * (freqs[1] - freqs[0]) if len(freqs) > 1 else width)
        extra = np.linspace(max(0.0, freqs[k] - 5 * width), min(freqs[-1], freqs[k] + 5 * width), int(refine))
        extra = np.setdiff1d(extra, freqs)
        S = np.concatenate([S, [2.0 / np.pi * res.laplace(w).real for w in extra]])
        freqs = np.concatenate([freqs, extra])
        # then the vertex of the parabola through the highest three samples, twice, and its neighbours at a tenth
        # of the spacing: the peak frequency to a small fraction of the peak's width
        for _ in range(2):
            order = np.argsort(freqs)
            k = int(np.argmax(S[order]))
            vertex = _peak_location(freqs[order], S[order], k)
            step = 0.1 * np.min(np.abs(np.diff(freqs[order][max(k - 1, 0):k + 2]))) if len(freqs) > 2 else 0.0
            new = np.setdiff1d([w for w in (vertex - step, vertex, vertex + step) if w >= 0], freqs)
            S = np.concatenate([S, [2.0 / np.pi * res.laplace(w).real for w in new]])
            freqs = np.concatenate([freqs, new])
    details = {"grid": [int(grid[0]), int(grid[1])], "cells": int(sd.grid.n), "frequencies": int(len(freqs)),
               "h_support": float(sd.h_support), "error_estimate": None, "extrapolated": bool(extrapolate)}
    if check or extrapolate:
        order = np.argsort(freqs)

        def coarser(factor):
            g = (max(8, int(grid[0]) // factor), max(16, int(grid[1]) // factor))
            sdc = stationary_density_xy(model, grid=g, h_max=h_max, walls=walls, restitution=restitution,
                                        check=False, stretch=stretch, arc_end_order=arc_end_order)
            fc = observable_values(model, observable, sdc.cell_x, sdc.cell_y)
            gc = fc - float(sdc.cell_mass @ fc)
            resc = _Resolvent(sdc, gc)
            return g, np.array([2.0 / np.pi * resc.laplace(w).real for w in freqs]), float(sdc.cell_mass @ (gc * gc))

        def l1(a, b):
            return float(np.trapezoid(np.abs(a - b)[order], freqs[order]))

        half_grid, Sc, var_c = coarser(2)
        quarter_grid, Sq, _ = coarser(4)
        diff = l1(S, Sc)
        p = 1.0
        if quarter_grid != half_grid and diff > 0:
            p = float(np.clip(np.log2(max(l1(Sc, Sq), 1e-300) / diff), 1.0, MAX_ORDER))
        factor = 1.0 / (2.0**p - 1.0)
        details["error_estimate"] = float(diff * factor / max(np.trapezoid(S[order], freqs[order]), 1e-300))
        details["order"] = p
        details["check_grids"] = [list(half_grid), list(quarter_grid)]
        if extrapolate:
            unextrapolated = S
            S = S + factor * (S - Sc)
            var = var + factor * (var - var_c)
    details["seconds"] = time.perf_counter() - t0
    out = Spectrum("fpk", str(observable), freqs, S, var, mean, details)
    out.phase_density = sd
    if extrapolate:  # the finest grid's own S at out.omega (sorted as out.S), for comparison
        out.unextrapolated = unextrapolated[np.argsort(freqs)]
    return out
