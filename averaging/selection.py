"""Choose the cheapest method that is predicted to reach a tolerance in the L1 distance of p(H), and run it.

``solve(model, tol=0.02)`` looks at the model before computing anything expensive:

1. **exact**: the impacts are elastic at every *reachable* impact speed (law elastic, or V_C so high that the
   stationary impact-speed tail P(|v| > V_C) under the elastic density is below tol/10), the damping is linear
   (h = c*y) and the noise additive. Then p(H) is proportional to T(H) exp(-2cH/sigma**2), exactly (NOTES.md).
2. **paper** averaging (eq. 30 with the drift loss delta H / T) when the energy lost per cycle is small.
3. **jump** averaging (impacts as jumps of the averaged energy) when impacts dominate the dissipation but each
   cycle still loses a small share of the energy between impacts.
4. **Monte Carlo** otherwise, with dt from the declared weak order (bias ~ C dt**p) and the path count from the
   measured statistical error (~ C' / sqrt(paths * time), C' measured by a pilot run).

The predicted error of each averaging method is an error model fitted, in ``vibro bench validity``, to the L1
distance from converged Monte Carlo over a calibration grid; its inputs are the stationary means of

* ``r_imp``: impact energy loss per quasi-period over H, (1 - e1**2 e2**2)(H - G(delta)) / H,
* ``r_damp``: work of the damping force over one cycle over H, |oint h dx| / H,

both computed here by quadrature from the model (no averaging or simulation code is involved). Averaging is
refused when the 90th-percentile energy level loses more than ``MAX_DAMPING_RATIO`` of its energy per cycle to
the damping force, or more than ``MAX_IMPACT_RATIO`` to impacts: the quasi-conservative assumption is broken there.

Examples
--------
>>> from models import DuffingImpact, Ma
>>> d = diagnose(DuffingImpact(restitution=Ma(vc=50.0)))
>>> d.linear_damping, d.tail_impact_speed < 1e-10
(True, True)
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from hybrid.errors import ModelError, NormalisationError, ParameterError
from models import Elastic

# ----------------------------------------------------------------------------- error-model constants
# Fitted by ``vibro bench validity`` (averaging/validity.py, ``fit_error_model``) on the calibration grids of the
# Duffing model (c, D), (V_C, delta) and constant e; see README "Which method when". The verification cases in
# ``vibro bench solve-verify`` are not part of that grid.
ERROR_MODEL = {
    # L1(method, MC) ~ floor + slope * r_imp + slope_damp * r_damp (r_damp only for nonlinear damping or
    # multiplicative noise). From ``vibro bench validity --quick`` (docs/charts/error_model.json): slope = 90 %
    # quantile of (L1 - floor) / r_imp over the 20 quasi-conservative linear-damping cells (Duffing grids (c, D),
    # (V_C, delta), Newton e); slope_damp = 90 % quantile of the remainder / r_damp over the 5 quasi-conservative
    # cells of the Rayleigh (c + k3 y^2) y grid with elastic walls; floor = median MC noise of all cells.
    "paper": {"slope": 1.55, "slope_damp": 0.009, "floor": 0.0026},
    "exact-two-impact": {"slope": 1.76, "slope_damp": 0.009, "floor": 0.0026},
    "jump": {"slope": 0.64, "slope_damp": 0.009, "floor": 0.0026},
    # exact formula: the neglected inelastic tail changes p(H) by about this many times the tail flux share
    "exact": {"tail": 2.0, "floor": 0.001},
}
MAX_DAMPING_RATIO = 0.6
"""Refuse averaging when the 90th-percentile energy level loses more than this share of H per cycle to the damping
force: the energy is then not slowly varying over a cycle (the quasi-conservative assumption of the paper breaks).
Impact losses are not counted here: the jump method treats large impact losses as jumps."""
MAX_IMPACT_RATIO = 0.9
"""Refuse averaging when the 90th-percentile energy loses more than this share to impacts in one quasi-period."""

# Monte Carlo error model: bias of L1(p(H)) ~ BIAS_CONSTANT[scheme] * dt**weak_order_barriers, fitted by
# ``averaging.workprecision.fit_bias_constants`` on ``vibro bench work-precision --quick`` (elastic Duffing c = D = 0.1,
# 512 paths; docs/charts/workprecision_mc.csv). The statistical part is measured per model by a pilot run.
MC_SCHEMES = ("splitting", "milstein")
"""Monte Carlo schemes in order of preference (splitting needs damping linear in y and noise free of y)."""
BIAS_CONSTANT = {"naive": 0.22, "em": 4.9, "milstein": 0.11, "splitting": 0.40}
DEFAULT_WEAK_ORDER = {"naive": 0.5, "em": 1.0, "milstein": 1.0, "splitting": 2.0}
L1_BINS = 40
"""Bins of the common H grid on which every L1 distance of p(H) is measured."""


# ----------------------------------------------------------------------------- diagnostics

@dataclass
class Diagnostics:
    """What the chooser knows about a model before running anything expensive.

    Attributes
    ----------
    linear_damping : bool
        h = c*y with a constant c (and constant epsilon).
    additive_noise : bool
        sigma**2 does not depend on x or y.
    elastic_law : bool
        e = 1 at every speed.
    elastic_below : float
        Speed below which impacts are elastic (V_C for Ma's law).
    tail_impact_speed : float
        P(|v_impact| > elastic_below), flux-weighted, under the stationary density of the elastic model.
    r_imp, r_damp : float
        Stationary means of the impact loss per quasi-period / H and the damping work per cycle / H.
    r_damp_p90, r_imp_p90 : float
        |damping work| / H and impact loss / H per cycle at the 90th percentile of H.
    h_max : float
        Energy above which the stationary mass is below 1e-5.
    barrier_energy : float
    notes : list of str
    relaxation_time : float
        1 / E_p[(damping work + impact loss) / (T H)]: how long the energy takes to forget its start (sets the
        Monte Carlo burn-in).
    self_excited : bool
        The damping force feeds energy in somewhere (h * y < 0, e.g. van der Pol): outside the domain where the
        averaging error model was calibrated.
    """

    linear_damping: bool
    additive_noise: bool
    elastic_law: bool
    elastic_below: float
    tail_impact_speed: float
    r_imp: float
    r_damp: float
    r_damp_p90: float
    r_imp_p90: float
    h_max: float
    barrier_energy: float
    notes: list = field(default_factory=list)
    relaxation_time: float = math.nan
    self_excited: bool = False


def _linear_damping_constant(model) -> float | None:
    """c when eps*h = c*y with constant c, else None."""
    from models import X, Y

    h = sp.expand(model.substitute(model.epsilon * model.h))
    c = sp.diff(h, Y)
    if c.free_symbols & {X, Y} or sp.simplify(h - c * Y) != 0:
        return None
    return float(c)


def _sigma2_constant(model) -> float | None:
    from models import X, Y

    s2 = model.substitute(model.diffusion_squared)
    if s2.free_symbols & {X, Y}:
        return None
    return float(s2)


def _check_averagable(model) -> None:
    """The energy-envelope methods need one confining single well and symmetric barriers."""
    model.check_single_well()
    if model.has_barriers:
        _ = model.barrier_energy  # raises ModelError for asymmetric barriers




def cycle_quantities(model, H):
    """Damping work per cycle W(H) = |oint h dx|, the period or quasi-period T(H), and the impact loss per cycle.

    A diagnostic, on the orbit nodes of :class:`averaging.quadrature.OrbitNodes` (no turning-point singularity,
    accurate as H -> G(delta)+). The impact loss per quasi-period is (1 - e1**2 e2**2)(H - G(delta)) with
    e2 = e(e1 v) (the exact two-impact loss of NOTES.md).

    Parameters
    ----------
    model : ImpactOscillator
    H : array_like
        Energies > 0.

    Returns
    -------
    W, T, loss : numpy arrays shaped like H

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.0}, barriers=None)
    >>> W, T, loss = cycle_quantities(m, [0.5])
    >>> round(float(T[0]), 9), round(float(W[0]), 9), float(loss[0])   # T = 2 pi, W = c * pi * A**2
    (6.283185307, 0.314159265, 0.0)
    """
    from models import X, Y

    from .quadrature import OrbitNodes

    H = np.atleast_1d(np.asarray(H, dtype=float))
    h = sp.lambdify((X, Y), model.substitute(model.epsilon * model.h), "numpy")
    Gd = model.barrier_energy if model.has_barriers else np.inf
    orbit = OrbitNodes(model, H)  # the averaging's singularity-free nodes (int w/s dx over the level)
    x, s = orbit.x, orbit.s
    hp = np.broadcast_to(np.asarray(h(x, s), dtype=float), x.shape)
    hm = np.broadcast_to(np.asarray(h(x, -s), dtype=float), x.shape)
    W = np.abs(orbit.integral((hp - hm) * s))  # oint h dx: the y > 0 branch forwards, y < 0 backwards
    T = orbit.integral(2.0)
    loss = np.zeros_like(H)
    if model.has_barriers:
        above = H > Gd
        v = np.where(above, np.sqrt(2.0 * np.maximum(H - Gd, 0.0)), 1.0)  # dummy speed where no impact
        e1 = np.asarray(model.restitution.coefficient(v), dtype=float)
        e2 = np.asarray(model.restitution.coefficient(e1 * v), dtype=float)
        loss = np.where(above, (1.0 - e1**2 * e2**2) * (H - Gd), 0.0)
    return W, T, loss


def _reference_density(model, h_max, points=600):
    """A cheap p(H) to weight the diagnostics: the paper's averaged density of the *elastic* model.

    For linear damping and additive noise this is the exact elastic density T(H) exp(-beta H).
    """
    H = np.linspace(h_max / points, h_max, points)
    W, T, _ = cycle_quantities(model, H)
    c = _linear_damping_constant(model)
    s2 = _sigma2_constant(model)
    if c is not None and s2 is not None:
        if c <= 0 or s2 <= 0:
            raise NormalisationError(
                f"damping c={c:g} and sigma^2={s2:g}: with c <= 0 or no noise there is no stationary density; "
                "use c > 0 and D > 0"
            )
        logp = np.log(T) - 2.0 * c / s2 * H
    else:
        # elastic energy-envelope density: m = s2bar/2-type noise input minus damping work rate; for the weights we
        # only need the shape, so use the averaged FPK with drift D_eff - W/T and diffusion from the model.
        from averaging import stationary_density
        from models import Elastic

        sd = stationary_density(model.with_restitution(Elastic()), method="paper", h_max=h_max, points=points)
        return np.asarray(sd.H, dtype=float)[1:], np.asarray(sd.p, dtype=float)[1:]  # drop H = 0 (ratios / H)
    logp -= logp.max()
    p = np.exp(logp)
    p /= _trapz(p, H)
    return H, p


def _trapz(y, x):
    return float(np.trapezoid(y, x)) if hasattr(np, "trapezoid") else float(np.trapz(y, x))


def _feeds_energy(model, h_top: float) -> bool:
    """True when h(x, y) * y < 0 somewhere on the orbits up to energy ``h_top`` (negative damping)."""
    from models import X, Y

    h = sp.lambdify((X, Y), model.substitute(model.epsilon * model.h), "numpy")
    right = min(float(model.amplitude(h_top)), model.barriers[1])
    left = max(-right, model.barriers[0])
    x = np.linspace(left, right, 101)
    y = np.linspace(-math.sqrt(2.0 * h_top), math.sqrt(2.0 * h_top), 101)
    xx, yy = np.meshgrid(x, y)
    power = np.broadcast_to(np.asarray(h(xx, yy), dtype=float), xx.shape) * yy
    return bool(np.any(power < -1e-12 * max(1.0, float(np.max(np.abs(power))))))


def _choose_h_max(model, elastic: bool = True) -> float:
    """An energy above which the stationary mass is negligible (< 1e-5).

    From the density of the elastic model (``elastic=True``) or of the model itself by the paper's averaging.
    """
    c = _linear_damping_constant(model)
    s2 = _sigma2_constant(model)
    if elastic and c is not None and s2 is not None and c > 0 and s2 > 0:
        return 14.0 * s2 / (2.0 * c)  # exp(-beta H) T(H): tail mass ~ e^-14 times a polynomial
    h_max = 4.0
    for _ in range(8):
        if elastic:
            H, p = _reference_density(model, h_max)
        else:
            from averaging import stationary_density

            sd = stationary_density(model, method="paper", h_max=h_max, points=600)
            H, p = np.asarray(sd.H, dtype=float), np.asarray(sd.p, dtype=float)
        tail = _trapz(p[-len(p) // 10:], H[-len(H) // 10:])
        if tail < 1e-5:
            return h_max
        h_max *= 2.0
    raise NormalisationError(
        f"the stationary p(H) still has mass {tail:.3g} near H = {h_max:g}: energy grows without bound, "
        "so there is no stationary density to approximate (check the damping sign and the noise intensity)"
    )


def diagnose(model, h_max: float | None = None) -> Diagnostics:
    """Loss ratios, impact-speed tail and model structure: the inputs of the method choice.

    Parameters
    ----------
    model : ImpactOscillator
    h_max : float, optional
        Energy range; by default chosen so that the stationary tail beyond it is below 1e-5.

    Returns
    -------
    Diagnostics

    Examples
    --------
    >>> from models import DuffingImpact
    >>> d = diagnose(DuffingImpact())
    >>> 0 < d.r_imp < 1, round(d.tail_impact_speed, 3)    # exp(-c V_C**2 / (2 D)) for linear damping
    (True, 0.961)
    """
    _check_averagable(model)
    c = _linear_damping_constant(model)
    s2 = _sigma2_constant(model)
    notes: list[str] = []
    law = model.restitution
    vc = float(law.elastic_below()) if model.has_barriers else math.inf
    elastic = bool(law.is_elastic) or not model.has_barriers
    try:
        h_el = _choose_h_max(model)
        He, pe = _reference_density(model, h_el)
    except NormalisationError:
        if elastic:
            raise
        # the elastic model has no stationary density (energy input beats the damping): impacts must dissipate,
        # so every reachable speed matters; the energy range comes from the model itself
        notes.append("the elastic version of the model has no stationary density")
        h_el = _choose_h_max(model, elastic=False)
        He = pe = None
    if elastic or not np.isfinite(vc):
        tail = 0.0
    elif He is None:
        tail = 1.0
    elif c is not None and s2 is not None:
        # elastic density ~ exp(-beta H): the wall flux of speeds is Rayleigh, P(v > V_C) = exp(-beta V_C^2 / 2)
        tail = math.exp(-(2.0 * c / s2) * vc * vc / 2.0)
    else:
        # flux density of impact speeds: v p(delta, v) dv = p(H) / T(H) dH above G(delta)
        # Rice: the impact-speed flux density at the wall is v p(delta, v), with p(x, y) = p(H)/T(H) (eq. 31)
        from averaging import stationary_density

        sd_el = stationary_density(model.with_restitution(Elastic()), method="paper", h_max=h_el, points=2000)
        right = model.barriers[1]
        v = np.linspace(0.0, math.sqrt(2.0 * (h_el - model.barrier_energy)), 4001)
        flux = v * sd_el.joint(np.array([right]), v)[:, 0]
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (flux[1:] + flux[:-1]) * np.diff(v))])
        at_vc = np.interp(vc, v, cum)
        tail = float((cum[-1] - at_vc) / cum[-1]) if cum[-1] > 0 else 0.0
    if tail < 1e-4:
        H, p = He, pe
    else:
        # weights from the paper's averaged density of the model itself (cheap; its tail is on the heavy side)
        from averaging import stationary_density

        sd = stationary_density(model, method="paper", h_max=h_el, points=800)
        H, p = np.asarray(sd.H, dtype=float)[1:], np.asarray(sd.p, dtype=float)[1:]
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(H))])
    cdf /= cdf[-1]
    if h_max is None:
        h_max = float(min(h_el, 1.15 * H[min(int(np.searchsorted(cdf, 1.0 - 1e-5)), len(H) - 1)]))
    h_max = float(h_max)
    W, T, loss = cycle_quantities(model, H)
    r_imp = _trapz(p * loss / H, H)
    r_damp = _trapz(p * W / H, H)
    i90 = min(int(np.searchsorted(cdf, 0.9)), len(H) - 1)
    rate = (W + loss) / (T * H)
    relax = 1.0 / max(_trapz(p * rate, H), 1e-12)
    rd90 = float(W[i90] / H[i90])
    self_excited = _feeds_energy(model, H[-1])
    ri90 = float(loss[i90] / H[i90])
    if c is None:
        notes.append("nonlinear damping: the elastic formula is not exact")
    if s2 is None:
        notes.append("multiplicative noise")
    return Diagnostics(
        linear_damping=c is not None, additive_noise=s2 is not None, elastic_law=elastic, elastic_below=vc,
        tail_impact_speed=float(tail), r_imp=float(r_imp), r_damp=float(r_damp), r_damp_p90=rd90, r_imp_p90=ri90,
        h_max=h_max,
        barrier_energy=float(model.barrier_energy) if model.has_barriers else math.inf, notes=notes,
        relaxation_time=float(relax), self_excited=bool(self_excited),
    )


# ----------------------------------------------------------------------------- choice

@dataclass
class Choice:
    """The chosen method, why, its predicted L1 error of p(H) and its predicted cost (seconds).

    Attributes
    ----------
    method : str
        ``exact``, ``paper``, ``jump`` or ``monte-carlo``.
    reason : str
    expected_error : float
    expected_cost : float
    settings : dict
        For Monte Carlo: scheme, dt, paths, t_end, t_burn.
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
        s = [f"method: {self.method}", f"why: {self.reason}",
             f"expected L1 error of p(H): {self.expected_error:.3g}", f"expected cost: {self.expected_cost:.3g} s"]
        if self.settings:
            s.append("settings: " + ", ".join(f"{k}={v}" for k, v in self.settings.items()))
        return "\n".join(s)


def predict_averaging_error(method: str, diag: Diagnostics) -> float:
    """Predicted L1 distance of an averaging method from converged Monte Carlo (the fitted error model).

    Examples
    --------
    >>> d = Diagnostics(True, True, False, 0.4, 0.9, 0.0, 0.01, 0.05, 0.0, 20.0, 0.55)
    >>> predict_averaging_error("paper", d) == ERROR_MODEL["paper"]["floor"]
    True
    """
    if method == "exact":
        m = ERROR_MODEL["exact"]
        if not (diag.linear_damping and diag.additive_noise):
            return math.inf
        return m["floor"] + m["tail"] * diag.tail_impact_speed
    m = ERROR_MODEL[method]
    damp = 0.0 if (diag.linear_damping and diag.additive_noise) else diag.r_damp
    return m["floor"] + m["slope"] * diag.r_imp + m["slope_damp"] * damp


MIN_TOL = 1e-10
"""Smallest L1 tolerance accepted: the densities themselves are accurate to about 1e-12, and Monte Carlo cost
estimates (paths ~ 1 / tol**2) overflow long before."""


def _check_request(tol, max_cost) -> None:
    if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)) or \
            not (MIN_TOL <= tol < 2.0):
        raise ParameterError(f"tol={tol!r}: an L1 distance between densities lies in (0, 2), and below "
                             f"{MIN_TOL:g} double precision cannot deliver it; use e.g. tol=0.02")
    if isinstance(max_cost, bool) or not isinstance(max_cost, (int, float, np.integer, np.floating)) or \
            not (0 < max_cost < np.inf):
        raise ParameterError(f"max_cost={max_cost!r} must be a finite positive wall time in seconds, e.g. 600")


def choose(model, tol: float = 0.02, *, max_cost: float = 600.0, diagnostics: Diagnostics | None = None,
           mc_pilot: bool = True, seed: int = 1) -> Choice:
    """Pick the cheapest method predicted to reach ``tol`` in the L1 distance of p(H).

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
    _check_request(tol, max_cost)
    try:
        diag = diagnostics if diagnostics is not None else diagnose(model)
    except ModelError as exc:
        return _mc_choice(model, tol, None, f"averaging does not apply ({exc})", {}, max_cost, mc_pilot, seed)
    preds = {}
    reasons = []
    elastic_enough = diag.elastic_law or diag.tail_impact_speed < tol / 10.0
    preds["exact"] = predict_averaging_error("exact", diag) if elastic_enough else math.inf
    heavy = diag.r_damp_p90 > MAX_DAMPING_RATIO or diag.r_imp_p90 > MAX_IMPACT_RATIO
    outside = diag.self_excited
    for name in ("paper", "jump"):
        preds[name] = math.inf if (heavy or outside) else predict_averaging_error(name, diag)
    if preds["exact"] <= tol:
        why = ("impacts are elastic" if diag.elastic_law else
               f"impacts faster than V_C={diag.elastic_below:g} are rare: P(|v| > V_C) = "
               f"{diag.tail_impact_speed:.2g} < tol/10 under the elastic density")
        return Choice("exact", why + "; linear damping and additive noise make p(H) ~ T(H) exp(-beta H) exact",
                      preds["exact"], _averaging_cost(), {}, preds, diag)
    if outside and not heavy:
        reasons.append(
            "averaging not trusted: the damping feeds energy in somewhere (self-excited, e.g. van der Pol), outside "
            "the dissipative models on which the averaging error model was calibrated"
        )
    elif heavy:
        reasons.append(
            f"averaging refused: the 90th-percentile energy loses {diag.r_damp_p90:.2f} of H per cycle to damping "
            f"(limit {MAX_DAMPING_RATIO}) and {diag.r_imp_p90:.2f} to impacts (limit {MAX_IMPACT_RATIO}), "
            "so the system is not quasi-conservative"
        )
    if not (heavy or outside):
        for name in ("paper", "jump"):  # cheapest first
            if preds[name] <= tol:
                why = (f"energy lost per cycle is small (impacts {diag.r_imp:.3f} H, damping {diag.r_damp:.3f} H "
                       "on average)") if name == "paper" else (
                       f"impact losses ({diag.r_imp:.3f} H per cycle) are too large for a drift but well described "
                       "as jumps of the averaged energy")
                return Choice(name, why, preds[name], _averaging_cost(), {}, preds, diag)
        reasons.append(
            f"no averaging method is predicted within tol={tol:g} (paper {preds['paper']:.3f}, "
            f"jump {preds['jump']:.3f})"
        )
    return _mc_choice(model, tol, diag, "; ".join(reasons), preds, max_cost, mc_pilot, seed)


def _averaging_cost() -> float:
    # one density on a 2000-point grid: 0.01-0.03 s in the work-precision bench, plus the diagnostics already spent
    return 0.05


def _scheme_order(scheme: str) -> float:
    """The declared weak order with barriers of a Monte Carlo scheme."""
    try:
        from hybrid.stochastic import SCHEMES

        s = SCHEMES[scheme]
        for attr in ("weak_order_barriers", "weak_order"):
            if hasattr(s, attr):
                return float(getattr(s, attr))
    except (ImportError, KeyError):
        pass
    return DEFAULT_WEAK_ORDER[scheme]


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


def _step_limit(model, h_max) -> float:
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


def _mc_choice(model, tol, diag, reason, preds, max_cost, pilot, seed) -> Choice:
    scheme = pick_scheme(model)
    p = _scheme_order(scheme)
    h_max = diag.h_max if diag is not None else 20.0
    # bias budget tol/3 from the declared weak order; never beyond the step rule's warning limit
    dt = (tol / 3.0 / BIAS_CONSTANT[scheme]) ** (1.0 / p)
    dt = float(min(dt, _step_limit(model, h_max)))
    relax = diag.relaxation_time if diag is not None and np.isfinite(diag.relaxation_time) else 40.0
    # paths start at rest: burn in for several relaxation times (a fixed 200 biased slow limit-cycle models)
    t_burn = float(min(max(200.0, 8.0 * relax), 20000.0))
    t_pilot = time.perf_counter()
    stat_const, rate = (_pilot(model, scheme, dt, h_max, seed, t_burn=t_burn,
                               t_sample=float(min(max(1000.0, 20.0 * relax), 20000.0))) if pilot else (3.0, 5e7))
    t_pilot = time.perf_counter() - t_pilot
    # statistical budget: what remains of tol after the bias
    budget = max(tol - BIAS_CONSTANT[scheme] * dt**p, tol / 3.0)
    need = (stat_const / budget) ** 2  # paths * sampled time
    paths = 64
    t_sample = max(need / paths, 200.0)
    steps = paths * (t_sample + t_burn) / dt
    cost = steps / rate
    capped = cost > max_cost
    if capped:
        t_sample = max((max_cost * rate * dt / paths) - t_burn, 100.0)
        cost = max_cost
    cost += t_pilot
    stat = stat_const / math.sqrt(paths * t_sample)
    expected = BIAS_CONSTANT[scheme] * dt**p + stat
    if capped:
        reason += f"; Monte Carlo capped at max_cost={max_cost:g} s, so the tolerance is not reached"
        warnings.warn(f"Monte Carlo capped at max_cost={max_cost:g} s: expected L1 {expected:.3g} > tol={tol:g}",
                      stacklevel=3)
    preds = dict(preds)
    preds["monte-carlo"] = expected
    settings = {"scheme": scheme, "dt": round(dt, 6), "paths": paths, "t_end": round(t_sample + t_burn, 1),
                "t_burn": t_burn, "h_max": h_max}
    if diag is None:
        diag = Diagnostics(False, False, False, 0.0, math.nan, math.nan, math.nan, math.nan, math.nan, h_max, math.nan,
                           ["averaging does not apply"])
    return Choice("monte-carlo", reason or "Monte Carlo", expected, cost, settings, preds, diag)


def _pilot(model, scheme, dt, h_max, seed, groups: int = 4, paths: int = 8, t_sample: float = 1000.0,
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


# ----------------------------------------------------------------------------- L1 on a common grid

def bin_masses(H, p, edges) -> np.ndarray:
    """Probability mass of a density p(H) (sampled on a grid H) in each bin of ``edges``, renormalised.

    Examples
    --------
    >>> H = np.linspace(0, 1, 1001); edges = np.linspace(0, 1, 5)
    >>> bin_masses(H, np.ones_like(H), edges).round(6).tolist()
    [0.25, 0.25, 0.25, 0.25]
    """
    H = np.asarray(H, dtype=float)
    p = np.asarray(p, dtype=float)
    if not np.all(np.isfinite(p)):
        raise NormalisationError("the density has non-finite values; it cannot be compared")
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(H))])
    at = np.interp(edges, H, cum, left=0.0, right=cum[-1])
    m = np.diff(at)
    total = m.sum()
    if not total > 0:
        raise NormalisationError("the density has no mass on the comparison grid")
    return m / total


def rebin_counts(counts, n_out: int) -> np.ndarray:
    """Merge a histogram of ``len(counts)`` bins into ``n_out`` bins (n_out must divide len(counts))."""
    counts = np.asarray(counts, dtype=float)
    if len(counts) % n_out:
        raise ParameterError(f"cannot merge {len(counts)} bins into {n_out}")
    return counts.reshape(n_out, -1).sum(axis=1)


def l1_between_histograms(a, b) -> float:
    """L1 distance between two histograms of equal bins, each normalised to mass 1.

    Examples
    --------
    >>> l1_between_histograms([1, 1, 0], [0, 1, 1])
    1.0
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return float(np.abs(a / a.sum() - b / b.sum()).sum())


# ----------------------------------------------------------------------------- solve

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

    def summary(self) -> str:
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
    _check_request(tol, max_cost)  # also for method='monte-carlo', which does not go through choose
    t0 = time.perf_counter()
    forced = method != "auto"
    if method not in ("auto", "exact", "paper", "jump", "monte-carlo"):
        raise ParameterError(f"method={method!r}; use auto, exact, paper, jump or monte-carlo")
    if method == "monte-carlo":
        try:
            diag = diagnose(model, h_max)
        except ModelError:
            diag = None
        choice = _mc_choice(model, tol, diag, "forced by method='monte-carlo'", {}, max_cost, True, seed)
    else:
        diag = diagnose(model, h_max)
        choice = choose(model, tol, max_cost=max_cost, diagnostics=diag, seed=seed)
        if forced and method != choice.method:
            pred = predict_averaging_error(method, diag)
            if method == "exact" and not (diag.linear_damping and diag.additive_noise):
                raise ModelError("the exact elastic formula needs linear damping h = c*y and additive noise")
            if pred > tol:
                warnings.warn(f"method={method!r} is predicted to miss tol={tol:g} (expected L1 {pred:.3g})",
                              stacklevel=2)
            choice = Choice(method, f"forced by method={method!r}", pred, _averaging_cost(), {},
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
        bias = BIAS_CONSTANT[s["scheme"]] * s["dt"] ** _scheme_order(s["scheme"])
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
    else:
        sd = stationary_density(model, method=choice.method, h_max=h_max, points=2000)
    H = np.asarray(sd.H, dtype=float)
    p = np.asarray(sd.p, dtype=float)
    return Solution(H, p, edges, bin_masses(H, p, edges), choice, time.perf_counter() - t0,
                    choice.expected_error, sd)


__all__ = [
    "BIAS_CONSTANT", "Choice", "Diagnostics", "ERROR_MODEL", "L1_BINS", "MAX_DAMPING_RATIO", "MAX_IMPACT_RATIO",
    "Solution", "bin_masses",
    "choose", "cycle_quantities", "diagnose", "l1_between_histograms", "predict_averaging_error", "rebin_counts",
    "solve",
]
