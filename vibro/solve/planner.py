"""Monte Carlo planning: the scheme, dt from its declared weak order and the fitted bias constant (capped by the
step rule), and the path count from a pilot run that measures the statistical constant."""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from hybrid.errors import ModelError

from .errormodel import L1_BINS, MC_SCHEMES, bias_constants
from .metrics import l1_between_histograms


def scheme_order(scheme: str) -> float:
    """The declared weak order with barriers of a Monte Carlo scheme (falls back to its weak order)."""
    from hybrid.stochastic import SCHEMES

    s = SCHEMES[scheme]
    return float(getattr(s, "weak_order_barriers", s.weak_order))


def pick_scheme(model) -> str:
    """The first scheme of ``MC_SCHEMES`` that accepts ``model``."""
    from hybrid.stochastic import SCHEMES

    for name in MC_SCHEMES:
        try:
            SCHEMES[name].check(model)
        except ModelError:
            continue
        return name
    raise ModelError(f"no Monte Carlo scheme among {MC_SCHEMES} accepts this model")


def step_limit(model, h_max) -> float:
    """Largest dt the Monte Carlo step rule accepts without a coarse-step warning (halving from 0.05)."""
    from hybrid.stochastic import StepSizeWarning, check_step

    dt = 0.05
    for _ in range(12):
        with warnings.catch_warnings():
            warnings.simplefilter("error", StepSizeWarning)
            try:
                check_step(model, dt, h_max)
                return dt
            except (StepSizeWarning, ValueError):
                dt /= 2.0
    return dt


NOMINAL_STAT_CONST = 3.0
"""Statistical constant C' (L1 ~ C' / sqrt(paths x time)) assumed before the pilot measures it."""
NOMINAL_RATE = 5e7
"""Path-steps per second assumed before the pilot measures the throughput."""
PLAN_PATHS = 64
PILOT_PATH_RUNS = 4 * 8  # pilot_run's groups x paths


def check_plan(tol, dt, t_burn, t_pilot_sample, max_cost) -> None:
    """Refuse, before the pilot runs, a tolerance whose Monte Carlo work is beyond :data:`MAX_PATH_STEPS`, or whose
    pilot alone would take longer than ``max_cost`` (both at the nominal constants, with the step ``dt`` that the
    tolerance's bias budget gives)."""
    from hybrid.sizes import MAX_PATH_STEPS, check_size

    need = (NOMINAL_STAT_CONST / tol) ** 2  # paths x sampled time for the statistical error alone
    t_sample = max(need / PLAN_PATHS, 200.0)
    work = PLAN_PATHS * (t_sample + t_burn) / dt
    check_size(f"Monte Carlo to tol={tol:g}", work=work, work_unit="path-steps", max_work=MAX_PATH_STEPS,
               seconds_per_unit=1.0 / NOMINAL_RATE, max_memory=None,
               detail=f"{PLAN_PATHS} paths x {t_sample + t_burn:.3g} time units at dt={dt:.3g}, at "
                      f"{NOMINAL_RATE:.0e} path-steps per second",
               fix="raise the tolerance (--tol)")
    if t_pilot_sample:
        pilot = PILOT_PATH_RUNS * (t_pilot_sample + t_burn) / dt
        check_size(f"the Monte Carlo pilot for tol={tol:g}", work=pilot, work_unit="path-steps",
                   max_work=max_cost * NOMINAL_RATE, seconds_per_unit=1.0 / NOMINAL_RATE, max_memory=None,
                   detail=f"{PILOT_PATH_RUNS} paths x {t_pilot_sample + t_burn:.3g} time units at dt={dt:.3g}",
                   fix="raise the tolerance (--tol) or the budget (--max-cost)")


def plan_monte_carlo(model, tol, h_max, relaxation_time, max_cost, pilot, seed):
    """Settings, expected L1 error and expected cost of a Monte Carlo run that aims at ``tol``.

    Returns
    -------
    settings : dict
        scheme, dt, paths, t_end, t_burn, h_max.
    expected : float
    cost : float
        Seconds, the pilot included.
    capped : bool
        True when ``max_cost`` cut the run short of the tolerance.
    """
    # the largest step any scheme's bias budget allows bounds the work from below: an impossible tolerance is
    # refused before the schemes are checked against the model (symbolic, seconds)
    best_dt = min(0.05, max((tol / 3.0 / c) ** (1.0 / scheme_order(s)) for s, c in bias_constants().items()
                            if s in MC_SCHEMES))
    check_plan(tol, best_dt, 200.0, 0.0, max_cost)
    scheme = pick_scheme(model)
    p = scheme_order(scheme)
    bias_c = bias_constants()[scheme]
    # bias budget tol/3 from the declared weak order; never beyond the step rule's warning limit
    dt = (tol / 3.0 / bias_c) ** (1.0 / p)
    dt = float(min(dt, step_limit(model, h_max)))
    relax = relaxation_time if np.isfinite(relaxation_time) else 40.0
    # paths start at rest: burn in for several relaxation times (a fixed 200 biased slow limit-cycle models)
    t_burn = float(min(max(200.0, 8.0 * relax), 20000.0))
    t_pilot_sample = float(min(max(1000.0, 20.0 * relax), 20000.0))
    check_plan(tol, dt, t_burn, t_pilot_sample if pilot else 0.0, max_cost)
    t_pilot = time.perf_counter()
    stat_const, rate = (pilot_run(model, scheme, dt, h_max, seed, t_burn=t_burn, t_sample=t_pilot_sample) if pilot
                        else (NOMINAL_STAT_CONST, NOMINAL_RATE))
    t_pilot = time.perf_counter() - t_pilot
    # statistical budget: what remains of tol after the bias
    budget = max(tol - bias_c * dt**p, tol / 3.0)
    need = (stat_const / budget) ** 2  # paths * sampled time
    paths = PLAN_PATHS
    t_sample = max(need / paths, 200.0)
    steps = paths * (t_sample + t_burn) / dt
    cost = steps / rate
    capped = cost > max_cost
    if capped:
        t_sample = max((max_cost * rate * dt / paths) - t_burn, 100.0)
        cost = max_cost
    cost += t_pilot
    expected = bias_c * dt**p + stat_const / math.sqrt(paths * t_sample)
    settings = {"scheme": scheme, "dt": round(dt, 6), "paths": paths, "t_end": round(t_sample + t_burn, 1),
                "t_burn": t_burn, "h_max": h_max}
    return settings, expected, cost, capped


def pilot_run(model, scheme, dt, h_max, seed, groups: int = 4, paths: int = 8, t_sample: float = 1000.0,
           t_burn: float = 200.0):
    """Statistical constant C' (L1 ~ C'/sqrt(paths * time)) and throughput (path-steps/s), measured.

    ``groups`` independent small ensembles (``paths`` paths, ``t_sample`` time units each): the mean pairwise L1
    distance of their histograms over sqrt(2) is the error of one group, so C' = that * sqrt(paths * t_sample).
    The estimate is multiplied by 1.4 to cover its own sampling error. (Batch-means intervals of E[H] were tried
    first and over-estimated C' by a factor of about 5 at the Fig. 2 parameters; this estimate was within 20 % of
    the spread of 6 independent 64-path runs there.)
    """
    from itertools import combinations

    from hybrid.stochastic import simulate_ensemble

    runs = [simulate_ensemble(model, scheme=scheme, dt=dt, paths=paths, t_end=t_sample + t_burn, t_burn=t_burn,
                              h_max=h_max, bins=L1_BINS, xy_bins=None, seed=seed + 1000 + k) for k in range(groups)]
    d = [l1_between_histograms(a.h_counts, b.h_counts) for a, b in combinations(runs, 2)]
    # 1.4: the mean of 6 correlated pairwise distances from 4 groups is itself uncertain by about +-30 %
    stat_const = 1.4 * float(np.mean(d)) / math.sqrt(2.0) * math.sqrt(paths * t_sample)
    rate = sum(r.path_steps for r in runs) / max(sum(r.wall_time for r in runs), 1e-6)
    return stat_const, rate

