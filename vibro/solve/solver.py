"""``solve``: run the chosen method and return the density with the choice behind it and what it cost."""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from hybrid.errors import ModelError, ParameterError, VibroWarning

from .choice import Choice, averaging_cost, check_request, choose, mc_choice
from .diagnostics import diagnose
from .errormodel import L1_BINS, bias_constants, predict_averaging_error
from .metrics import bin_masses, l1_between_histograms, rebin_counts
from .planner import scheme_order


@dataclass
class Solution:
    """Result of :func:`solve`: the density, the choice behind it and what it cost.

    Attributes
    ----------
    H, p : numpy arrays
        p(H), normalised on [0, h_max] (bin centres for Monte Carlo).
    edges, masses : numpy arrays
        p(H) as masses on the common ``L1_BINS``-bin grid (for L1 comparisons).
    choice : Choice
    wall_time : float
        Seconds spent computing the density (diagnostics included).
    estimated_error : float
        For Monte Carlo, the statistical error measured from two independent halves plus the bias model;
        for averaging, the predicted error.
    result : object
        The underlying StationaryDensity or EnsembleStatistics.
    """

    H: np.ndarray
    p: np.ndarray
    edges: np.ndarray
    masses: np.ndarray
    choice: Choice
    wall_time: float
    estimated_error: float
    result: object

    @property
    def method(self) -> str:
        return self.choice.method

    def to_pandas(self):
        """DataFrame with columns H, p."""
        import pandas as pd

        return pd.DataFrame({"H": self.H, "p": self.p})

    def __repr__(self) -> str:
        return (f"Solution(method={self.method!r}, points={len(self.H)}, "
                f"expected_error={self.choice.expected_error:.3g}, estimated_error={self.estimated_error:.3g}, "
                f"wall_time={self.wall_time:.3g})")

    def _repr_html_(self) -> str:
        from hybrid.display import summary_html

        return summary_html(f"Solution by {self.method}", {
            "reason": self.choice.reason, "points": len(self.H), "expected L1 error": self.choice.expected_error,
            "estimated L1 error": self.estimated_error, "wall time (s)": self.wall_time})

    def summary(self) -> str:
        """The choice, its reason, the wall time and the estimated error, as printed by ``vibro solve``."""
        return (self.choice.summary() + f"\nmeasured wall time: {self.wall_time:.3g} s"
                + f"\nestimated L1 error: {self.estimated_error:.3g}")


def solve(model, tol: float = 0.02, *, method: str = "auto", max_cost: float = 600.0, seed: int = 1,
          h_max: float | None = None, progress: bool = False) -> Solution:
    """Stationary p(H) by the cheapest method predicted to reach ``tol`` (L1), with the reason and the cost.

    Parameters
    ----------
    model : ImpactOscillator
    tol : float
        Target L1 distance of p(H).
    method : str
        ``auto`` (default) or force one of ``exact``, ``paper``, ``jump``, ``monte-carlo``.
    max_cost : float
        Wall-time budget for Monte Carlo (seconds).
    seed : int
    h_max : float, optional
        Energy range (default: from the diagnostics).
    progress : bool

    Returns
    -------
    Solution

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> sol = solve(DuffingImpact(restitution=Elastic()), tol=0.02)    # doctest: +SKIP
    >>> sol.method                                                     # doctest: +SKIP
    'exact'
    """
    check_request(tol, max_cost)  # also for method='monte-carlo', which does not go through choose
    t0 = time.perf_counter()
    forced = method != "auto"
    if method not in ("auto", "exact", "paper", "jump", "fpk", "monte-carlo"):
        raise ParameterError(f"method={method!r}; use auto, exact, paper, jump, fpk or monte-carlo")
    if method == "monte-carlo":
        try:
            diag = diagnose(model, h_max)
        except ModelError:
            diag = None
        choice = mc_choice(model, tol, diag, "forced by method='monte-carlo'", {}, max_cost, True, seed)
    else:
        diag = diagnose(model, h_max)
        choice = choose(model, tol, max_cost=max_cost, diagnostics=diag, seed=seed)
        if forced and method != choice.method:
            pred = predict_averaging_error(method, diag)
            if method == "exact" and not (diag.linear_damping and diag.additive_noise):
                raise ModelError("the exact elastic formula needs linear damping h = c*y and additive noise")
            if math.isnan(pred):
                from .choice import UnmeasuredAccuracyWarning

                warnings.warn(f"method={method!r} on {diag.geometry} walls: its accuracy is not measured by the error "
                              "model (fitted on symmetric gaps); see benchmarks/geometry_averaging.py",
                              UnmeasuredAccuracyWarning, stacklevel=2)
            elif pred > tol:
                warnings.warn(f"method={method!r} is predicted to miss tol={tol:g} (expected L1 {pred:.3g})",
                              VibroWarning, stacklevel=2)
            choice = Choice(method, f"forced by method={method!r}", pred, averaging_cost(), {},
                            choice.predictions, diag)
    h_max = choice.settings.get("h_max", choice.diagnostics.h_max)
    edges = np.linspace(0.0, h_max, L1_BINS + 1)
    if choice.method == "monte-carlo":
        from hybrid.stochastic import simulate_ensemble

        s = choice.settings
        half = max(s["paths"] // 2, 1)
        kw = dict(scheme=s["scheme"], dt=s["dt"], t_end=s["t_end"], t_burn=s["t_burn"], h_max=h_max,
                  bins=L1_BINS * 10, xy_bins=None, progress=progress)
        a = simulate_ensemble(model, paths=half, seed=seed, **kw)
        b = simulate_ensemble(model, paths=half, seed=seed + 7919, **kw)
        bias = bias_constants()[s["scheme"]] * s["dt"] ** scheme_order(s["scheme"])
        extensions = 0
        # a-posteriori check: the two independent halves measure the statistical error; extend while it misses
        while True:
            stat = l1_between_histograms(rebin_counts(a.h_counts, L1_BINS), rebin_counts(b.h_counts, L1_BINS)) / 2
            spent = time.perf_counter() - t0
            if stat + bias <= tol or extensions >= 3 or spent > max_cost:
                break
            factor = min((stat / max(tol - bias, tol / 3.0)) ** 2, 8.0)
            extra = max(int(math.ceil((factor - 1.0) * a.paths)), half)
            extensions += 1
            a = a.merge(simulate_ensemble(model, paths=extra, seed=seed + 101 * extensions, **kw))
            b = b.merge(simulate_ensemble(model, paths=extra, seed=seed + 7919 + 101 * extensions, **kw))
        if extensions:
            choice.settings["paths"] = int(a.paths + b.paths)
            choice.settings["extensions"] = extensions
            choice.reason += f"; extended {extensions}x after the two halves measured a larger error"
        if stat + bias > tol:
            warnings.warn(f"Monte Carlo measured L1 error {stat + bias:.3g} > tol={tol:g} within max_cost "
                          f"(halves of {a.paths} paths); raise max_cost", stacklevel=2)
        stats = a.merge(b)
        centres = 0.5 * (stats.h_edges[1:] + stats.h_edges[:-1])
        masses = rebin_counts(stats.h_counts, L1_BINS)
        masses = masses / masses.sum()
        p = np.asarray(stats.h_density(), dtype=float)
        est = stat + bias
        return Solution(centres, p, edges, masses, choice, time.perf_counter() - t0, est, stats)
    from averaging import stationary_density
    from models import Elastic

    if choice.method == "exact":
        sd = stationary_density(model.with_restitution(Elastic()), method="paper", h_max=h_max, points=2000)
    elif choice.method == "fpk":
        from averaging.phase_plane import stationary_density_xy

        sd = stationary_density_xy(model, h_max=h_max, points=2000)
    else:
        sd = stationary_density(model, method=choice.method, h_max=h_max, points=2000)
    estimated = choice.expected_error
    if choice.method in ("paper", "jump"):
        # a-posteriori check against the impact-to-impact chain: warns outside the method's validity, and the
        # measured distance (less the chain's own error) bounds the error from below
        from .choice import CHAIN_L1_ERROR, averaging_cross_check

        cross = averaging_cross_check(model, sd, choice.expected_error,
                                      remedy="use method fpk (or vibro pdf --method chain)")
        if cross is not None and not cross.valid:
            estimated = max(estimated, cross.l1 - CHAIN_L1_ERROR) if math.isfinite(estimated) else cross.l1
    H = np.asarray(sd.H, dtype=float)
    p = np.asarray(sd.p, dtype=float)
    return Solution(H, p, edges, bin_masses(H, p, edges), choice, time.perf_counter() - t0, estimated, sd)

