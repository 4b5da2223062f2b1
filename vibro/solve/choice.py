"""Choose the cheapest method whose estimated L1 error of p(H) meets a tolerance.

``choose(model, tol)`` looks at the model before computing anything expensive and considers, cheapest first:

1. **exact**: the impacts are elastic at every *reachable* impact speed (law elastic, or V_C so high that the
   stationary impact-speed tail P(|v| > V_C) under the elastic density is below tol/10), the damping is linear
   (h = c*y) and the noise additive. Then p(H) is proportional to T(H) exp(-2cH/sigma**2), exactly.
2. **chain**, **paper**, **jump** (energy-envelope averaging; milliseconds, about 0.1 s for chain; paper and jump
   are checked against the chain after the run, so the chain, the most accurate, is also the cheapest): their error is
   rated against the phase-plane solver over a sweep of models (``benchmarks/method_ratings.py``, per wall
   family: symmetric, asymmetric, one-sided, equilibrium; self-excited damping included). A method is a candidate
   where a rating covers the model (:func:`~vibro.solve.errormodel.rating`), and chosen when its rating meets tol.
3. **fpk**, the phase-plane solver of the full (x, y) problem, on the coarsest grid of :data:`FPK_GRIDS` predicted
   to meet tol; it carries its own a-posteriori estimate (three grids), so it is the method for models no rating
   covers, and :func:`~vibro.solve.solve` refines its grid when the estimate misses. A potential with several
   wells (linear damping, additive noise) gets fpk on Cartesian cells (:func:`multiwell_choice`).
4. **Monte Carlo** only where no deterministic method applies (a forced model, several wells with nonlinear
   damping or multiplicative noise), planned by
   :mod:`vibro.solve.planner`.

Averaging is refused only where no rating covers the model and the 90th-percentile energy loses more than
``MAX_DAMPING_RATIO`` of its energy per cycle to the damping force or more than ``MAX_IMPACT_RATIO`` to impacts, or
the damping feeds energy in: the quasi-conservative assumption is unverified there. Forcing an unrated method warns
with :class:`UnmeasuredAccuracyWarning`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

from hybrid.errors import ModelError, ParameterError, VibroWarning

from .diagnostics import Diagnostics, diagnose
from .errormodel import MAX_DAMPING_RATIO, MAX_IMPACT_RATIO, error_model, predict_averaging_error
from .planner import plan_monte_carlo


class UnmeasuredAccuracyWarning(VibroWarning):
    """An averaging density is asked for on a geometry where its error has not been measured."""


class OutsideValidityWarning(VibroWarning):
    """An averaging method's result fails its a-posteriori check: it is outside the method's validity."""


MEAN_GAP_WARN = 0.10
"""Relative gap between an averaging method's E[H] and the impact-to-impact chain's above which the result is
outside the method's validity. The chain is within 0.5 % of Monte Carlo on the paper's 21 cases and 3 % at a wall
at the equilibrium with r = 0.6, so a 10 % gap is an error of at least 7 % in the printed E[H]."""
CHAIN_L1_ERROR = 0.015
"""The chain's own L1 distance from Monte Carlo on the paper's 21 cases (40 bins; at most 0.013 measured)."""


@dataclass(frozen=True)
class CrossCheck:
    """An averaging density against the impact-to-impact chain: E[H] gap (relative) and L1 distance of p(H)."""

    method: str
    mean_gap: float
    l1: float
    chain_mean: float
    predicted: float

    @property
    def valid(self) -> bool:
        over = math.isfinite(self.predicted) and self.l1 > self.predicted + CHAIN_L1_ERROR
        return abs(self.mean_gap) <= MEAN_GAP_WARN and not over


def averaging_cross_check(model, sd, predicted: float = math.nan, warn: bool = True,
                          remedy: str = "use --method chain or fpk") -> CrossCheck | None:
    """Check an averaging density (``paper``, ``exact-two-impact``, ``jump``) a posteriori against ``chain``.

    ``paper`` and ``jump`` treat impacts as a drift or as Poisson-timed jumps of the averaged energy; when one
    impact takes a large share of the energy (a wall at the equilibrium, Newton r <= 0.6, strong noise with large
    losses) that clock is wrong and E[H] comes out 10-35 % high. The chain (impacts at the end of each flight,
    about 0.05 s) is the reference: an :class:`OutsideValidityWarning` is issued when the E[H] gap exceeds
    :data:`MEAN_GAP_WARN`, or when the L1 distance of p(H) exceeds the method's ``predicted`` L1 error plus
    :data:`CHAIN_L1_ERROR`; it names the better methods (``remedy``). None when the chain cannot be computed.

    Examples
    --------
    >>> from averaging import stationary_density
    >>> from models import DuffingImpact
    >>> averaging_cross_check(DuffingImpact(), stationary_density(DuffingImpact(), "jump")).valid
    True
    """
    import numpy as np

    from averaging.chain import chain_density

    from .errormodel import L1_BINS
    from .metrics import bin_masses

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its truncation, if any, is the density's own (already reported)
            ref = chain_density(model, h_max=sd.h_max, check=False)
    except (ValueError, ArithmeticError):  # VibroError is a ValueError: no reference, no claim
        return None
    # both densities from their own accurate interpolants (not the output grid, however coarse), on L1_BINS bins
    # of the energies that carry the mass (bins over all of a huge h_max would put it into the first)
    top = min(sd.h_max, max(sd.h_support, ref.h_support))
    edges = np.linspace(0.0, top, L1_BINS + 1)
    H = np.linspace(0.0, top, 100 * L1_BINS + 1)
    H[0] = 1e-9 * top  # p(H) may diverge (integrably) at 0
    l1 = float(np.abs(bin_masses(H, sd.density(H), edges) - bin_masses(H, ref.density(H), edges)).sum())
    out = CrossCheck(sd.method, sd.mean_energy / ref.mean_energy - 1.0, l1, ref.mean_energy, float(predicted))
    if warn and not out.valid:
        rated = f" (its predicted L1 error is {predicted:.3g})" if math.isfinite(predicted) else ""
        # what each method approximates: paper folds the impacts' loss into the drift of the averaged energy, jump
        # (and exact-two-impact) lets them arrive as Poisson-timed jumps
        why = {"paper": "the paper's method averages the impacts' loss into a drift of the energy, which is "
                        "biased here",
               }.get(out.method, "impacts that take a large share of the energy are not Poisson-timed jumps of the "
                                 "averaged energy")
        warnings.warn(f"--method {out.method} is outside its validity here: its E[H] {sd.mean_energy:.4g} is "
                      f"{out.mean_gap:+.1%} off the impact-to-impact chain's {ref.mean_energy:.4g}, L1 {l1:.3f} "
                      f"between the two p(H){rated}; {why}: {remedy}",
                      OutsideValidityWarning,
                      stacklevel=2)
    return out


@dataclass
class Choice:
    """The chosen method, why, its predicted L1 error of p(H) and its predicted cost (seconds).

    Attributes
    ----------
    method : str
        ``exact``, ``paper``, ``jump``, ``chain``, ``fpk`` or ``monte-carlo``.
    reason : str
    expected_error : float
    expected_cost : float
    settings : dict
        For fpk: grid. For Monte Carlo: scheme, dt, paths, t_end, t_burn.
    predictions : dict
        Predicted L1 error of every candidate (inf when refused).
    diagnostics : Diagnostics
    """

    method: str
    reason: str
    expected_error: float
    expected_cost: float
    settings: dict
    predictions: dict
    diagnostics: Diagnostics

    def summary(self) -> str:
        """Human-readable lines: method, why, expected error and cost."""
        err = "not rated for this model" if math.isnan(self.expected_error) else f"{self.expected_error:.3g}"
        s = [f"method: {self.method}", f"why: {self.reason}",
             f"expected L1 error of p(H): {err}", f"expected cost: {self.expected_cost:.3g} s"]
        if self.settings:
            s.append("settings: " + ", ".join(f"{k}={v}" for k, v in self.settings.items()))
        return "\n".join(s)


MIN_TOL = 1e-10
"""Smallest L1 tolerance accepted: the densities themselves are accurate to about 1e-12, and Monte Carlo cost
estimates (paths ~ 1 / tol**2) overflow long before."""


def check_request(tol, max_cost) -> None:
    """Refuse a tolerance outside [MIN_TOL, 2) or a budget that is not a finite positive time."""
    import numpy as np

    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)) or \
            not (MIN_TOL <= tol < 2.0):
        raise ParameterError(f"tol={tol!r}: an L1 distance between densities lies in (0, 2), and below "
                             f"{MIN_TOL:g} double precision cannot deliver it; use e.g. tol=0.02")
    if isinstance(max_cost, bool) or not isinstance(max_cost, (int, float, np.integer, np.floating)) or \
            not (0 < max_cost < np.inf):
        raise ParameterError(f"max_cost={max_cost!r} must be a finite positive wall time in seconds, e.g. 600")


FPK_GRIDS = ((48, 64), (64, 80), (80, 96), (120, 144), (160, 192), (240, 288), (320, 384))
"""The grids (rings, angles) ``choose`` and ``solve`` take fpk on, coarsest first."""
FPK_PREDICT_ORDER = 1.75
"""Order by which fpk's estimate is predicted to fall with the grid (fitted on Fig. 2, benchmarks/fpk_convergence.py);
the run's own estimate decides, and a miss refines the grid."""
COSTS = {"exact": 0.02, "paper": 0.05, "jump": 0.05, "chain": 0.15}
"""Wall time (s) of each averaging density at 2000 points (the diagnostics already spent)."""
CROSS_CHECKED = ("paper", "jump")
"""Averaging methods whose result ``solve`` checks against the chain after the run (so they cost the chain too)."""


def method_cost(name: str) -> float:
    """Wall time (s) of averaging method ``name`` in ``solve``: its density, plus the chain's for the a-posteriori
    cross-check of ``paper`` and ``jump``; so the chain, the most accurate of the three, is never the dearer.

    Examples
    --------
    >>> method_cost("chain") < method_cost("jump")
    True
    """
    return COSTS[name] + (COSTS["chain"] if name in CROSS_CHECKED else 0.0)


AVERAGING_ORDER = tuple(sorted(("paper", "jump", "chain"), key=method_cost))
"""The averaging methods, cheapest (in ``solve``, cross-check included) first."""


def fpk_grid_for(tol: float, start=None) -> tuple[int, int]:
    """The coarsest grid of :data:`FPK_GRIDS` whose predicted estimate meets half of ``tol`` (a margin).

    The prediction scales the sweep's median estimate at the default grid (160, 192) by (160 / rings)**1.75: a
    start, not a promise (``solve`` refines the grid when the run's own estimate misses); ``start`` (a grid) gives
    a lower bound.

    Examples
    --------
    >>> fpk_grid_for(0.02)
    (48, 64)
    """
    floor = fpk_typical()
    for g in FPK_GRIDS:
        if start is not None and g[0] < start[0]:
            continue
        if floor * (160.0 / g[0]) ** FPK_PREDICT_ORDER <= tol / 2.0:
            return g
    return FPK_GRIDS[-1]


def fpk_typical() -> float:
    """The sweep's median fpk estimate (40 bins) at the default grid (160, 192)."""
    m = error_model()["fpk"]
    return m.get("median", m["floor"])


def fpk_cost(grid) -> float:
    """Seconds of one fpk solve with its estimate on ``grid`` (about 1e-5 s per cell with the coarse solve on
    2 shared cores, plus the set-up)."""
    return 0.05 + 1.0e-5 * 1.25 * grid[0] * grid[1]


def choose(model, tol: float = 0.02, *, max_cost: float = 600.0, diagnostics: Diagnostics | None = None,
           mc_pilot: bool = True, seed: int = 1) -> Choice:
    """Pick the cheapest method whose estimated L1 error of p(H) meets ``tol``.

    Parameters
    ----------
    model : ImpactOscillator
    tol : float
        Target L1 distance of p(H) (on a common grid of ``L1_BINS`` bins) from the true stationary density.
    max_cost : float
        Wall-time budget for Monte Carlo in seconds; a longer run is capped and the expected error raised.
    diagnostics : Diagnostics, optional
        Reuse a :func:`diagnose` result.
    mc_pilot : bool
        Measure the Monte Carlo statistical constant with a short pilot run (otherwise use a default).
    seed : int

    Returns
    -------
    Choice

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> choose(DuffingImpact(restitution=Elastic())).method
    'exact'
    """
    check_request(tol, max_cost)
    from models.excitation import FilteredAutomaton

    if isinstance(model, FilteredAutomaton):
        picked = coloured_choice(model, tol)
        if isinstance(picked, str):
            raise ModelError(f"no deterministic method applies to this filtered model ({picked}); solve's Monte Carlo "
                             "takes oscillators only: use vibro mc (hybrid.stochastic.simulate_automaton)")
        return picked
    if getattr(model, "is_forced", False):
        picked = forced_choice(model, tol)
        if not isinstance(picked, str):
            return picked
        return mc_choice(model, tol, None, f"no deterministic method applies (forced model: {picked})", {}, max_cost,
                         mc_pilot, seed)
    try:
        diag = diagnostics if diagnostics is not None else diagnose(model)
    except ModelError as exc:
        several = multiwell_choice(model, tol, str(exc))
        if several is not None:
            return several
        return mc_choice(model, tol, None, f"no deterministic method applies ({exc})", {}, max_cost, mc_pilot, seed)
    preds = {}
    reasons = []
    elastic_enough = diag.elastic_law or diag.tail_impact_speed < tol / 10.0
    preds["exact"] = predict_averaging_error("exact", diag) if elastic_enough else math.inf
    if preds["exact"] <= tol:
        why = ("there are no walls, so no impacts" if diag.geometry == "none" else
               "impacts are elastic" if diag.elastic_law else
               f"impacts faster than V_C={diag.elastic_below:g} are rare: P(|v| > V_C) = "
               f"{diag.tail_impact_speed:.2g} < tol/10 under the elastic density")
        return Choice("exact", why + "; linear damping and additive noise make p(H) ~ T(H) exp(-beta H) exact",
                      preds["exact"], COSTS["exact"], {}, preds, diag)
    refusal = averaging_refusal(diag)
    for name in ("paper", "jump", "chain"):
        preds[name] = math.inf if refusal else predict_averaging_error(name, diag)
    if refusal:
        reasons.append(refusal)
    elif all(math.isnan(preds[n]) for n in ("paper", "jump", "chain")):
        reasons.append("no rating of the averaging methods covers this model (its wall family, noise or loss "
                       "ratios lie outside the sweep of benchmarks/method_ratings.py)")
    else:
        for name in AVERAGING_ORDER:  # cheapest first
            if preds[name] <= tol:  # False for NaN (not rated)
                why = (f"its rating against fpk ({_family(diag)} walls, impacts lose {diag.r_imp:.3f} H and damping "
                       f"{diag.r_damp:.3f} H per cycle) is {preds[name]:.3g} <= tol")
                return Choice(name, why, preds[name], method_cost(name), {}, preds, diag)
        rated = ", ".join(f"{n} {preds[n]:.3f}" for n in ("paper", "jump", "chain") if math.isfinite(preds[n]))
        reasons.append(f"no averaging method is rated within tol={tol:g} ({rated})")
    grid = fpk_grid_for(tol)
    preds["fpk"] = fpk_typical() * (160.0 / grid[0]) ** FPK_PREDICT_ORDER
    if grid == FPK_GRIDS[-1] and preds["fpk"] > 2.0 * tol:
        # even the finest grid is predicted well above tol: only Monte Carlo is left, planned for tol (and refused
        # with its size estimate where that is absurd), rather than a run that is known to miss
        reasons.append(f"fpk's finest grid {grid} is predicted at {preds['fpk']:.2g}, above tol={tol:g}")
        return mc_choice(model, tol, diag, "; ".join(reasons), preds, max_cost, mc_pilot, seed)
    why = "; ".join(reasons) + (f"; the phase-plane FPK solver (impacts as boundary conditions) on grid {grid} "
                                "carries its own three-grid error estimate")
    return Choice("fpk", why, preds["fpk"], fpk_cost(grid), {"grid": grid}, preds, diag)


FORCED_GRIDS = ((30, 60), (40, 80), (60, 120), (64, 128), (80, 160))
"""The Cartesian grids (cells in x, cells in y) ``solve`` takes the forced fpk on, coarsest first."""
FORCED_STEPS = (16, 32, 64, 128)
"""The time steps per forcing period (the result's; Crank-Nicolson also runs twice as many) ``solve`` escalates."""
COLOURED_GRIDS = ((24, 24, 12), (32, 32, 16), (48, 48, 24), (48, 48, 32), (48, 48, 48), (64, 64, 48))
"""The grids (x, y, eta) ``solve`` takes the coloured fpk on, coarsest first (docs/results/fpk-coloured.md)."""


def _first_meeting(ladder, predicted, tol):
    """The first entry of ``ladder`` whose ``predicted`` L1 (a dict) is at most ``tol``, else the last."""
    return next((g for g in ladder if predicted[g] <= tol), ladder[-1])


def forced_choice(model, tol: float) -> Choice | str:
    """fpk for a harmonically forced model (the periodic density, its time-averaged p(H)), or why not (a str).

    The forced solver (:func:`averaging.phase_plane.periodic_density_xy`) applies to a forced single-well
    oscillator with noise and a periodic forcing. Its estimate has two parts, measured after the run: the cells'
    (the grid twice coarser) and the time steps' (half the steps); :func:`~vibro.solve.solve` refines the part that
    misses. The start is predicted from example 08 (docs/results/fpk-forced.md): the cells' estimate is about
    0.02 at (30, 60) and falls as the square of the cells; the time estimate is about 0.02, 0.005 and 0.0006 at 16,
    32 and 64 steps. Each part gets half of ``tol``.

    Examples
    --------
    >>> from models import ForcedDuffingImpact
    >>> ch = forced_choice(ForcedDuffingImpact(), 0.05)
    >>> ch.method, ch.settings["scheme"], ch.settings["grid"], ch.settings["steps"]
    ('fpk', 'forced', (30, 60), 16)
    """
    from averaging.phase_plane.forced import unforced
    from averaging.phase_plane.solver import is_single_well

    if model.forcing_period is None:
        return f"the forcing F = {model.forcing} has no period, so no periodic density"
    free = unforced(model)
    if not is_single_well(free):
        return "the forced fpk needs a single-well potential"
    if model.substitute(model.diffusion_squared) == 0:
        return "the model has no noise"
    grid_pred = {g: 0.02 * (30.0 / g[0]) ** 2 for g in FORCED_GRIDS}
    time_pred = {16: 0.02, 32: 0.005, 64: 6e-4, 128: 4e-5}
    grid = _first_meeting(FORCED_GRIDS, grid_pred, tol / 2.0)
    steps = _first_meeting(FORCED_STEPS, time_pred, tol / 2.0)
    from averaging.phase_plane.forced import BYTES_PER_CELL_FACTOR
    from hybrid.sizes import MAX_MEMORY

    def memory(g, k):  # the forced solver's own estimate (check included)
        return g[0] * g[1] * BYTES_PER_CELL_FACTOR["cartesian"] * (k // 2 + 1) * 3 * 1.25

    while memory(grid, steps) > MAX_MEMORY and grid != FORCED_GRIDS[0]:  # start where it fits; solve escalates
        grid = FORCED_GRIDS[FORCED_GRIDS.index(grid) - 1]
    expected = grid_pred[grid] + time_pred[steps]
    why = (f"the model is forced (F = {model.forcing}): the averaging methods need a model without time dependence, "
           f"so the phase-plane FPK solver of the periodic density (Cartesian cells {grid}, Crank-Nicolson at "
           f"{steps} and {2 * steps} steps per period, combined) gives the time-averaged p(H), with its own estimate "
           "of the cells' error (grid twice coarser) and of the time steps' (half the steps)")
    preds = {"exact": math.inf, "paper": math.inf, "jump": math.inf, "chain": math.inf, "fpk": expected}
    return Choice("fpk", why, expected, forced_cost(grid, steps),
                  {"scheme": "forced", "grid": grid, "steps": steps}, preds, _no_diagnostics(4.0, "forced"))


def forced_cost(grid, steps) -> float:
    """Seconds of one forced fpk solve with its check: about 4e-5 s per cell and LU factor (K / 2 + 1 factors at K
    steps, 3 runs of them, a quarter more for the check)."""
    return 1.0 + 4e-5 * grid[0] * grid[1] * (steps // 2 + 1) * 3 * 1.3


def coloured_choice(model, tol: float) -> Choice | str:
    """fpk on (x, y, eta) for an OU-filtered model (:func:`averaging.phase_plane.stationary_density_coloured`), or
    why not (a str: a band-pass filter's density is 4-D, a filter not built by ``ou_filter``).

    The start is the coarsest grid of :data:`COLOURED_GRIDS` whose L1 against Monte Carlo on the benchmark of
    docs/results/fpk-coloured.md was below half of ``tol``; the run's own two-grid estimate decides.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> from models.excitation import ou_filter
    >>> ch = coloured_choice(ou_filter(DuffingImpact(), alpha=1.0), 0.02)
    >>> ch.method, ch.settings["scheme"], ch.settings["grid"]
    ('fpk', 'coloured', (32, 32, 16))
    """
    from averaging.phase_plane.coloured import ALPHA_CHECKED, _parts

    try:
        _osc, alpha, *_ = _parts(model, None)
    except ModelError as exc:
        return str(exc)
    if alpha > ALPHA_CHECKED:
        return (f"alpha = {alpha:g} is above the bandwidths the coloured fpk was checked at ({ALPHA_CHECKED:g}): "
                "the white-noise density (solve on the oscillator itself) approximates it")
    measured = dict(zip(COLOURED_GRIDS, (0.0147, 0.0077, 0.0034, 0.0018, 0.0011, 0.0010)))
    grid = _first_meeting(COLOURED_GRIDS, measured, tol / 2.0)
    why = (f"the noise is OU-filtered (alpha = {alpha:g}): the phase-plane FPK solver on (x, y, eta) (grid {grid}) "
           "gives the stationary p(H) of the (x, y)-marginal, with its own two-grid estimate")
    preds = {"exact": math.inf, "paper": math.inf, "jump": math.inf, "chain": math.inf, "fpk": measured[grid]}
    return Choice("fpk", why, measured[grid], coloured_cost(grid), {"scheme": "coloured", "grid": grid}, preds,
                  _no_diagnostics(4.0, "coloured noise"))


def coloured_cost(grid) -> float:
    """Seconds of one coloured fpk solve with its check (about 2.5e-4 s per cell on 2 shared cores)."""
    return 1.0 + 2.5e-4 * grid[0] * grid[1] * grid[2]


def _no_diagnostics(h_max: float, what: str) -> Diagnostics:
    return Diagnostics(True, True, False, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, h_max, math.nan,
                       [f"{what}: no averaging"], geometry=what)


def multiwell_choice(model, tol: float, why: str) -> Choice | None:
    """fpk on Cartesian cells for an autonomous model whose potential has several wells, or None.

    The energy-envelope methods and fpk's rings need one well (one closed orbit per energy); the Cartesian
    discretisation of :mod:`averaging.phase_plane.cartesian` does not. It is chosen where the damping is linear and
    the noise additive (then exp(-beta H), beta = 2c/sigma**2, bounds the tail, so the energy range is known before
    the run: up to 14/beta, fitted down to the mass by the solver); its two-grid estimate is checked after the run
    and the grid refined while it misses. Energies start at min G (negative between the wells of a double well),
    so the L1 bins cover [min G, h_max]. None (Monte Carlo) for other models, e.g. nonlinear damping.

    Parameters
    ----------
    model : ImpactOscillator
        The model (None for a single well, a forced model, or damping or noise not of the form above).
    tol : float
        The L1 accuracy asked of p(H).
    why : str
        Why the single-well methods do not apply (kept in the choice's reasons).

    Returns
    -------
    Choice or None

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> bistable = ImpactOscillator("-x + x**3/4", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
    >>> ch = multiwell_choice(bistable, 0.01, "not a single well")
    >>> ch.method, ch.settings["scheme"], round(ch.settings["h_min"], 6)
    ('fpk', 'cartesian', -1.0)
    """
    if model.is_forced:
        return None
    from averaging.phase_plane._cartesian import confining_range
    from averaging.phase_plane.solver import is_single_well

    c = model.linear_damping_constant()
    s2 = model.constant_noise_intensity()
    if is_single_well(model) or c is None or s2 is None or not (c > 0 and s2 > 0):
        return None
    h_max = 14.0 * s2 / (2.0 * c)
    walls = [float(b) if math.isfinite(b) else None for b in model.barriers]
    try:
        _, _, g_min = confining_range(model.potential, h_max, *walls)
    except ModelError:
        return None
    grid = fpk_grid_for(tol)
    expected = fpk_typical() * (160.0 / grid[0]) ** FPK_PREDICT_ORDER
    diag = Diagnostics(True, True, bool(model.restitution.is_elastic), math.nan, math.nan, math.nan, math.nan,
                       math.nan, math.nan, h_max, math.nan, ["several wells: no averaging"], geometry="several wells")
    reason = (f"the averaging methods and fpk's rings do not apply ({why}); the phase-plane FPK solver on Cartesian "
              f"cells (any number of wells) on grid {grid} carries its own two-grid error estimate")
    preds = {"exact": math.inf, "paper": math.inf, "jump": math.inf, "chain": math.inf, "fpk": expected}
    return Choice("fpk", reason, expected, fpk_cost(grid),
                  {"grid": grid, "scheme": "cartesian", "h_min": float(g_min), "h_max": h_max}, preds, diag)


def _family(diag) -> str:
    from .errormodel import RATING_FAMILIES

    return RATING_FAMILIES.get(diag.geometry, diag.geometry)


def averaging_refusal(diag: Diagnostics) -> str | None:
    """Why energy-envelope averaging must not be trusted for this model, or None when it may be.

    The one rule behind ``choose`` and ``vibro pdf``. Where a rating of the averaging methods covers the model
    (:func:`~vibro.solve.errormodel.rating` for ``chain``), their error is measured there, so they are not
    refused. Otherwise refused when the 90th-percentile energy loses more than ``MAX_DAMPING_RATIO`` of H per cycle
    to damping or ``MAX_IMPACT_RATIO`` to impacts (not quasi-conservative), or when the damping feeds energy in
    somewhere (self-excited).

    Examples
    --------
    >>> from models import DuffingImpact, ImpactOscillator, Ma
    >>> averaging_refusal(diagnose(DuffingImpact().with_params(c=-0.1))) is None    # self-excited, rated
    True
    >>> unrated = ImpactOscillator("x + b*x**3", "c*y", noise=("sqrt(1 + x**2)",), restitution=Ma(0.4),
    ...                            parameters={"b": 0.2, "c": -0.1, "D": 0.05, "delta": 1.0})
    >>> "self-excited" in averaging_refusal(diagnose(unrated))     # multiplicative noise: outside the sweep
    True
    """
    from .errormodel import rating

    if rating("chain", diag) is not None:
        return None
    if diag.r_damp_p90 > MAX_DAMPING_RATIO or diag.r_imp_p90 > MAX_IMPACT_RATIO:
        return (f"averaging refused: the 90th-percentile energy loses {diag.r_damp_p90:.2f} of H per cycle to damping "
                f"(limit {MAX_DAMPING_RATIO}) and {diag.r_imp_p90:.2f} to impacts (limit {MAX_IMPACT_RATIO}), "
                "so the system is not quasi-conservative, and no rating covers it")
    if diag.self_excited:
        return ("averaging not trusted: the damping feeds energy in somewhere (self-excited, e.g. van der Pol or "
                "negative damping) and no rating of the sweep covers this model")
    return None


def averaging_cost() -> float:
    """Wall time (s) of one averaging density at 2000 points (the diagnostics already spent)."""
    return COSTS["paper"]


def mc_choice(model, tol, diag, reason, preds, max_cost, pilot, seed) -> Choice:
    """A Monte Carlo :class:`Choice` planned for ``tol`` (``diag`` may be None when averaging does not apply)."""
    h_max = diag.h_max if diag is not None else 20.0
    relax = diag.relaxation_time if diag is not None else math.nan
    settings, expected, cost, capped = plan_monte_carlo(model, tol, h_max, relax, max_cost, pilot, seed)
    if capped:
        reason += f"; Monte Carlo capped at max_cost={max_cost:g} s, so the tolerance is not reached"
        warnings.warn(f"Monte Carlo capped at max_cost={max_cost:g} s: expected L1 {expected:.3g} > tol={tol:g}",
                      stacklevel=3)
    preds = dict(preds)
    preds["monte-carlo"] = expected
    if diag is None:
        diag = Diagnostics(False, False, False, 0.0, math.nan, math.nan, math.nan, math.nan, math.nan, h_max, math.nan,
                           ["averaging does not apply"])
    return Choice("monte-carlo", reason or "Monte Carlo", expected, cost, settings, preds, diag)
