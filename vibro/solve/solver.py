"""``solve``: run the chosen method and return the density with the choice behind it and what it cost."""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from hybrid.errors import ModelError, ParameterError, VibroWarning

from .choice import Choice, averaging_cost, check_request, choose, fpk_grid_for, mc_choice, method_cost
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
        The L1 error estimated after the run: for fpk its three-grid (Richardson) estimate on the ``L1_BINS`` bins;
        for Monte Carlo the statistical error measured from two independent halves plus the bias model; for
        averaging its rating against fpk (raised when the a-posteriori check against the chain disagrees).
    result : object
        The underlying StationaryDensity, PhaseDensity or EnsembleStatistics.
    estimate_source : str
        How ``estimated_error`` was made.
    attempts : list of (method, settings, estimate)
        Every run, in order, when the first one's estimate missed the tolerance and ``solve`` escalated.
    """

    H: np.ndarray
    p: np.ndarray
    edges: np.ndarray
    masses: np.ndarray
    choice: Choice
    wall_time: float
    estimated_error: float
    result: object
    estimate_source: str = ""
    attempts: list = field(default_factory=list)

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
        out = self.choice.summary()
        if len(self.attempts) > 1:
            out += "\nescalated: " + " -> ".join(
                f"{m}{' ' + str(st['grid']) if 'grid' in st else ''}"
                f"{' ' + str(st['steps']) + ' steps' if 'steps' in st else ''} ({e:.3g})" for m, st, e in self.attempts)
        return (out + f"\nmeasured wall time: {self.wall_time:.3g} s"
                + f"\nestimated L1 error after the run: {self.estimated_error:.3g} ({self.estimate_source})")


METHODS = ("auto", "exact", "paper", "jump", "chain", "fpk", "monte-carlo")
"""What ``solve`` (and ``vibro solve --method``) accepts."""


def solve(model, tol: float = 0.02, *, method: str = "auto", max_cost: float = 600.0, seed: int = 1,
          h_max: float | None = None, progress: bool = False, points: int = 2000,
          monte_carlo: bool = True, phases: int | None = None) -> Solution:
    """Stationary p(H) by the cheapest method predicted to reach ``tol`` (L1), with the reason and the cost.

    Parameters
    ----------
    model : ImpactOscillator
    tol : float
        Target L1 distance of p(H).
    method : str
        ``auto`` (default) or force one of ``exact``, ``paper``, ``jump``, ``chain``, ``fpk``, ``monte-carlo``.
        With ``auto`` the chosen method is run and its estimate checked; when the estimate misses ``tol``, fpk's
        grid is refined, and an averaging method gives way to the next candidate (chain, then fpk).
    max_cost : float
        Wall-time budget for Monte Carlo (seconds).
    seed : int
    h_max : float, optional
        Energy range (default: from the diagnostics).
    progress : bool
    points : int
        Energies of the output p(H) of the deterministic methods.
    monte_carlo : bool
        False: raise :class:`~hybrid.errors.ModelError` instead of running Monte Carlo where no deterministic
        method applies (``vibro pdf``).
    phases : int, optional
        Forced models: hold ``tol`` for p(H | t) at each of the sections t = k T / phases (the worst of them), not
        only for the time-averaged p(H); the result (``Solution.result``, a
        :class:`~averaging.phase_plane.forced.PeriodicDensity`) stores the sections as steps.

    A forced model (``forcing=...``) gets the periodic density of the forced fpk
    (:func:`~averaging.phase_plane.periodic_density_xy`), and p(H) is its time average; an OU-filtered model
    (``models.excitation.ou_filter``) gets the coloured fpk on (x, y, eta). Both estimate their error after the run
    (the forced: cells plus time steps) and are refined while it misses ``tol``; a forced model outside their reach
    (several wells, no period) goes to Monte Carlo.

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
    if method not in METHODS:
        raise ParameterError(f"method={method!r}; use one of {', '.join(METHODS)}")
    from models.excitation import FilteredAutomaton

    filtered = isinstance(model, FilteredAutomaton)
    if phases is not None and (isinstance(phases, bool) or not isinstance(phases, (int, float, np.integer))
                               or not np.isfinite(phases) or int(phases) != phases or phases < 1):
        raise ParameterError(f"phases={phases!r} must be a whole number >= 1")
    if phases is not None and not getattr(model, "is_forced", False):
        raise ParameterError("phases applies to a forced model (a periodic density), not to this one")
    if filtered and method not in ("auto", "fpk"):
        raise ModelError(f"method={method!r} assumes white noise; a filtered model takes fpk (or vibro mc)")
    if filtered or (getattr(model, "is_forced", False) and method in ("auto", "fpk")):
        choice = choose(model, tol, max_cost=max_cost, seed=seed, mc_pilot=monte_carlo)
        if method == "fpk" and choice.method != "fpk":
            raise ModelError(f"method='fpk' does not apply here: {choice.reason}")
        if phases is not None:
            choice.settings["phases"] = int(phases)
    elif method == "monte-carlo":
        try:
            diag = diagnose(model, h_max)
        except ModelError:
            diag = None
        choice = mc_choice(model, tol, diag, "forced by method='monte-carlo'", {}, max_cost, True, seed)
    else:
        try:
            diag = diagnose(model, h_max)
        except ModelError:
            if forced:
                raise
            diag = None  # choose says why and plans Monte Carlo
        choice = choose(model, tol, max_cost=max_cost, diagnostics=diag, seed=seed, mc_pilot=monte_carlo)
        if forced and method != choice.method:
            pred = predict_averaging_error(method, diag)
            if method == "exact" and not (diag.linear_damping and diag.additive_noise):
                raise ModelError("the exact elastic formula needs linear damping h = c*y and additive noise")
            if math.isnan(pred):
                from .choice import UnmeasuredAccuracyWarning

                warnings.warn(f"method={method!r} on this model ({diag.geometry} walls): its accuracy is not measured "
                              "(no rating of benchmarks/method_ratings.py covers it); use method='fpk', which "
                              "carries its own error estimate", UnmeasuredAccuracyWarning, stacklevel=2)
            elif pred > tol:
                warnings.warn(f"method={method!r} is predicted to miss tol={tol:g} (expected L1 {pred:.3g})",
                              VibroWarning, stacklevel=2)
            settings = {"grid": fpk_grid_for(tol)} if method == "fpk" else {}
            choice = Choice(method, f"forced by method={method!r}", pred, averaging_cost(), settings,
                            choice.predictions, diag)
    if choice.method == "monte-carlo" and not monte_carlo and not forced:
        raise ModelError(f"no deterministic method applies to this model ({choice.reason}); use vibro solve or "
                         "vibro mc")
    if h_max is not None and choice.settings.get("scheme") in ("cartesian", "forced", "coloured"):
        choice.settings["h_max"] = float(h_max)  # the user's range (multiwell_choice saw no diagnostics)
    h_max = choice.settings.get("h_max", choice.diagnostics.h_max)
    edges = np.linspace(choice.settings.get("h_min", 0.0), h_max, L1_BINS + 1)  # h_min < 0 between two wells

    def run_monte_carlo(choice):
        """The planned Monte Carlo run of ``choice``, extended while its two halves miss tol."""
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
                          f"(halves of {a.paths} paths); raise max_cost", stacklevel=3)
        stats = a.merge(b)
        centres = 0.5 * (stats.h_edges[1:] + stats.h_edges[:-1])
        masses = rebin_counts(stats.h_counts, L1_BINS)
        masses = masses / masses.sum()
        p = np.asarray(stats.h_density(), dtype=float)
        est = stat + bias
        return Solution(centres, p, edges, masses, choice, time.perf_counter() - t0, est, stats,
                        f"half the L1 between two independent halves ({a.paths} paths each) plus the {s['scheme']} "
                        f"bias constant x dt**{scheme_order(s['scheme']):g}", [("monte-carlo", dict(s), est)])

    if choice.method == "monte-carlo":
        return run_monte_carlo(choice)
    from hybrid.sizes import SizeError

    attempts, last, parts = [], None, None
    while True:
        try:
            sd, estimated, source = _run_deterministic(model, choice, h_max, edges, points, warn=forced)
        except SizeError as exc:  # an escalated grid refused for its memory: keep the last run, say why
            if last is None and choice.settings.get("scheme") == "forced" and monte_carlo and not forced:
                # the forced fpk cannot hold this tolerance in memory: Monte Carlo instead
                return run_monte_carlo(mc_choice(model, tol, None, f"{choice.reason}; but {exc}", {}, max_cost, True,
                                                 seed))
            if last is None:
                raise
            warnings.warn(f"{choice.method} {choice.settings.get('grid')} refused ({exc}); kept the previous run",
                          VibroWarning, stacklevel=2)
            choice, sd, estimated, source, edges = last
            break
        if choice.settings.get("scheme") in ("forced", "coloured"):
            edges, parts = sd._solve_edges, getattr(sd, "_solve_parts", None)
        attempts.append((choice.method, dict(choice.settings), estimated))
        last = (choice, sd, estimated, source, edges)
        if forced or estimated <= tol or time.perf_counter() - t0 > max_cost:
            break
        nxt = _escalate(choice, estimated, tol, parts)
        if nxt is None:
            break
        choice = nxt
    if estimated > tol:
        warnings.warn(f"{choice.method}: estimated L1 error {estimated:.3g} > tol={tol:g} ({source})",
                      VibroWarning, stacklevel=2)
    density = sd.mean if choice.settings.get("scheme") == "forced" else sd  # the time-averaged p(H)
    H = np.asarray(density.H, dtype=float)
    p = np.asarray(density.p, dtype=float)
    masses = density.bin_masses(edges) if choice.method == "fpk" else bin_masses(H, p, edges)
    return Solution(H, p, edges, masses, choice, time.perf_counter() - t0, estimated, sd, source, attempts)


COLOURED_ORDER = 1.5
"""The grid order ``solve`` assumes for the coloured fpk's two-grid (Richardson) estimate, below the orders measured
(1.7-2.3 between the grids of the ladder): on the coarsest grids the grid twice coarser is pre-asymptotic, and at
order 1.8 the estimate missed the true L1 of example 10 at (24, 24, 12) (0.0147 against 0.0181 from Monte Carlo)."""
LADDER = ("paper", "jump", "chain", "fpk")
"""The order in which ``solve`` escalates when a method's estimate misses the tolerance."""


def _escalate(choice: Choice, estimated: float, tol: float, parts=None) -> Choice | None:
    """The next run after a miss: a finer fpk grid (for a forced model, finer cells or more time steps, whichever
    part of the estimate, ``parts`` = (cells, time), misses half of tol), or the next method of :data:`LADDER`
    (None: nothing left)."""
    from .choice import (
        COLOURED_GRIDS,
        FORCED_GRIDS,
        FORCED_STEPS,
        FPK_GRIDS,
        coloured_cost,
        forced_cost,
        fpk_cost,
        fpk_grid_for,
    )

    preds = choice.predictions
    scheme = choice.settings.get("scheme")
    if scheme == "forced":
        grid, steps = tuple(choice.settings["grid"]), int(choice.settings["steps"])
        cells, in_time = parts
        finer_cells = cells > tol / 2.0 or (in_time <= tol / 2.0 and cells >= in_time)
        finer_steps = in_time > tol / 2.0 or not finer_cells
        if finer_cells:
            # the cells' estimate falls about as the square of the cells (docs/results/fpk-forced.md)
            want = grid[0] * math.sqrt(cells / (0.4 * tol))
            nxt = next((g for g in FORCED_GRIDS if g[0] > grid[0] and g[0] >= want),
                       FORCED_GRIDS[-1] if grid != FORCED_GRIDS[-1] else None)
            grid = nxt if nxt is not None else grid
            finer_cells = nxt is not None
        if finer_steps:
            nxt = next((k for k in FORCED_STEPS if k > steps), None)
            steps = nxt if nxt is not None else steps
            finer_steps = nxt is not None
        if not (finer_cells or finer_steps):
            return None
        what = " and ".join(w for w, on in ((f"cells {grid}", finer_cells), (f"{steps} steps", finer_steps)) if on)
        return Choice("fpk", choice.reason + f"; the estimate {estimated:.3g} (cells {cells:.2g}, time steps "
                      f"{in_time:.2g}) missed tol, so {what}", math.nan, forced_cost(grid, steps),
                      {**choice.settings, "grid": grid, "steps": steps}, preds, choice.diagnostics)
    if scheme == "coloured":
        grid = tuple(choice.settings["grid"])
        finer = next((g for g in COLOURED_GRIDS if g[2] * g[0] > grid[2] * grid[0]), None)
        if finer is None:
            return None
        return Choice("fpk", choice.reason + f"; the estimate {estimated:.3g} on grid {grid} missed tol, refined",
                      math.nan, coloured_cost(finer), {**choice.settings, "grid": finer}, preds, choice.diagnostics)
    if choice.method == "fpk":
        grid = tuple(choice.settings["grid"])
        if grid == FPK_GRIDS[-1]:
            return None
        # the estimate falls at least like the grid to the power ESTIMATE_ORDER = 1.3: the rings needed, and more
        want = grid[0] * (estimated / (0.7 * tol)) ** (1.0 / 1.3)
        finer = next((g for g in FPK_GRIDS if g[0] > grid[0] and g[0] >= want), FPK_GRIDS[-1])
        return Choice("fpk", choice.reason + f"; the estimate {estimated:.3g} on grid {grid} missed tol, refined",
                      estimated * (grid[0] / finer[0]) ** 1.3, fpk_cost(finer), {**choice.settings, "grid": finer},
                      preds, choice.diagnostics)
    if choice.method not in LADDER:
        return None
    for name in LADDER[LADDER.index(choice.method) + 1:]:
        if name == "fpk":
            grid = fpk_grid_for(tol)
            return Choice("fpk", choice.reason + f"; {choice.method}'s estimate {estimated:.3g} missed tol, so fpk",
                          preds.get("fpk", math.nan), fpk_cost(grid), {"grid": grid}, preds, choice.diagnostics)
        if preds.get(name, math.nan) <= tol:
            return Choice(name, choice.reason + f"; {choice.method}'s estimate {estimated:.3g} missed tol",
                          preds[name], method_cost(name), {}, preds, choice.diagnostics)
    return None


def _run_deterministic(model, choice: Choice, h_max: float, edges, points: int, warn: bool = False):
    """(density, estimated L1 error on ``edges``, how it was estimated) of the chosen deterministic method; ``warn``:
    a forced averaging method outside its validity warns (an automatic choice escalates instead)."""
    from averaging import stationary_density
    from models import Elastic

    if choice.method == "fpk" and choice.settings.get("scheme") in ("forced", "coloured"):
        return _run_forced_or_coloured(model, choice, h_max, points)
    if choice.method == "fpk":
        from averaging.phase_plane import stationary_density_xy

        grid = tuple(choice.settings.get("grid", (160, 192)))
        if choice.settings.get("scheme") == "cartesian":  # several wells (multiwell_choice)
            from averaging.phase_plane import GridWarning
            from averaging.phase_plane.cartesian import stationary_density_cartesian

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GridWarning)  # its 100-bin warning is not solve's tolerance
                sd = stationary_density_cartesian(model, grid=grid, h_max=h_max, points=points, tol=2.0)
            return sd, sd.estimate_error(edges), f"fpk on Cartesian cells {grid}: " + sd.error_method
        with warnings.catch_warnings():
            # solve checks the estimate on its own bins and escalates; the 100-bin GridWarning is not its tolerance
            from averaging.phase_plane import GridWarning

            warnings.simplefilter("ignore", GridWarning)
            sd = stationary_density_xy(model, grid=grid, h_max=h_max, points=points, tol=2.0)
        return sd, sd.estimate_error(edges), f"fpk on {grid}: " + sd.error_method
    if choice.method == "exact":
        sd = stationary_density(model.with_restitution(Elastic()), method="paper", h_max=h_max, points=points)
        return sd, choice.expected_error, "the Gibbs density's error from the impact-speed tail above V_C"
    sd = stationary_density(model, method=choice.method, h_max=h_max, points=points)
    estimated = choice.expected_error
    source = "its rating against fpk over the sweep of benchmarks/method_ratings.py"
    if math.isnan(estimated):
        source = "not rated for this model"
    if choice.method in ("paper", "jump"):
        # a-posteriori check against the impact-to-impact chain: warns outside the method's validity, and the
        # measured distance less the chain's own rated error bounds the error from below
        from .choice import averaging_cross_check

        chain_err = predict_averaging_error("chain", choice.diagnostics)
        cross = averaging_cross_check(model, sd, choice.expected_error, warn=warn,
                                      remedy="use method fpk (or vibro pdf --method chain)")
        if cross is not None and not cross.valid:
            floor = cross.l1 - (chain_err if math.isfinite(chain_err) else 0.0)
            if not floor <= estimated:
                estimated = floor
                source = "the L1 distance to the impact-to-impact chain less the chain's rating"
    return sd, estimated, source


def _run_forced_or_coloured(model, choice: Choice, h_max: float, points: int):
    """The forced fpk (periodic density) or the coloured fpk (x, y, eta) of ``choice``, with its estimated L1 on
    :data:`L1_BINS` bins of the energies its solver fitted to the mass (stored as ``_solve_edges``)."""
    from averaging.phase_plane import GridWarning

    st = choice.settings
    grid = tuple(st["grid"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GridWarning)  # its own 100-bin warning is not solve's tolerance
        if st["scheme"] == "forced":
            from averaging.phase_plane.forced import periodic_density_xy

            sd = periodic_density_xy(model, grid=grid, h_max=h_max, steps=int(st["steps"]), phases=st.get("phases"),
                                     points=points)
            sd._solve_edges = np.linspace(sd.mean.h_min, sd.grid.h_max, L1_BINS + 1)
            phases = st.get("phases")
            cells, in_time = sd.estimate_parts(sd._solve_edges, phases=phases, average=phases is None)
            sd._solve_parts = (cells, in_time)
            where = f"p(H | t) at the worst of {phases} phases" if phases else "the time-averaged p(H)"
            return sd, cells + in_time, (f"forced fpk on {grid}, Crank-Nicolson at {st['steps']} + {2 * st['steps']} "
                                         f"steps, for {where}: cells {cells:.2g} (the grid twice coarser, over 3) + "
                                         f"time steps {in_time:.2g} (half the steps, over 3)")
        from averaging.phase_plane.coloured import stationary_density_coloured

        # Richardson at a safe order, not 2: at 2 the estimate was 0.0235 where the true L1 was 0.0264 (OU linear
        # oscillator, (32, 32, 16)), at 1.8 0.0147 where it was 0.0181 (example 10, (24, 24, 12))
        sd = stationary_density_coloured(model, grid=grid, h_max=h_max, points=points, order=COLOURED_ORDER)
    sd._solve_edges = np.linspace(sd.h_min, sd.h_support, L1_BINS + 1)
    est = sd.estimate_error(sd._solve_edges) + sd.tail_mass
    return sd, est, f"coloured fpk on {grid}: " + sd.error_method
