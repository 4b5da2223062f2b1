"""What the method chooser knows about a model before running anything expensive: loss ratios per cycle,
the impact-speed tail under the elastic density, structure (linear damping, additive noise, self-excitation).

The inputs of the error model are the stationary means of

* ``r_imp``: impact energy loss per quasi-period over H, (1 - e1**2 e2**2)(H - G(delta)) / H,
* ``r_damp``: work of the damping force over one cycle over H, |oint h dx| / H,

both computed by quadrature from the model (no averaging or simulation code is involved).

Examples
--------
>>> from models import DuffingImpact, Ma
>>> d = diagnose(DuffingImpact(restitution=Ma(vc=50.0)))
>>> d.linear_damping, d.tail_impact_speed < 1e-10
(True, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hybrid.errors import NormalisationError
from models import Elastic


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
        The lowest impact level (G(delta) for a symmetric gap, 0 for a wall at the equilibrium).
    notes : list of str
    relaxation_time : float
        1 / E_p[(damping work + impact loss) / (T H)]: how long the energy takes to forget its start (sets the
        Monte Carlo burn-in).
    self_excited : bool
        The damping force feeds energy in somewhere (h * y < 0, e.g. van der Pol): outside the domain where the
        averaging error model was calibrated.
    geometry : str
        The barrier geometry (:func:`barrier_geometry`); only those in :data:`CALIBRATED_GEOMETRIES` have fitted
        error models.
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
    geometry: str = "symmetric"


CALIBRATED_GEOMETRIES = ("none", "symmetric")
"""Geometries on which the averaging error model was fitted (the paper's symmetric gaps)."""
GEOMETRIES = ("none", "symmetric", "one-sided", "asymmetric", "equilibrium")
"""Barrier geometries the diagnosis tells apart (see :func:`barrier_geometry`)."""


def barrier_geometry(model) -> str:
    """``none``, ``symmetric`` (G(left) = G(right)), ``one-sided`` (a stop at an offset), ``asymmetric`` (two walls
    at different energies) or ``equilibrium`` (a wall at x = 0, hit by every orbit).

    Examples
    --------
    >>> from models import DuffingImpact, ImpactOscillator
    >>> stop = ImpactOscillator("x", parameters={"D": 0.1}, barriers=(0, None))
    >>> barrier_geometry(DuffingImpact()), barrier_geometry(stop)
    ('symmetric', 'equilibrium')
    """
    from averaging.quadrature import geometry

    geo = geometry(model)
    if not geo.has_barriers:
        return "none"
    if geo.G_delta == 0.0:
        return "equilibrium"
    if geo.walls == 1:
        return "one-sided"
    return "symmetric" if geo.symmetric else "asymmetric"


def _check_averagable(model) -> None:
    """The energy-envelope methods need an autonomous model and one confining single well (any walls)."""
    model.require_autonomous()
    model.check_single_well()




def cycle_quantities(model, H):
    """Damping work per cycle W(H) = |oint h dx|, the period or quasi-period T(H), and the impact loss per cycle.

    A diagnostic, on the orbit nodes of :class:`averaging.quadrature.OrbitNodes` (no turning-point singularity,
    accurate as H -> G(delta)+). The impact loss per quasi-period is (1 - e1**2 e2**2)(H - G(delta)) with
    e2 = e(e1 v) (the exact two-impact loss of docs/paper-readings.md) for a symmetric gap, one impact's loss for a
    single wall, and the two impacts in sequence at their own levels for asymmetric walls.

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
    from averaging.methods import METHODS
    from averaging.quadrature import OrbitNodes, geometry

    H = np.atleast_1d(np.asarray(H, dtype=float))
    h = model._damping_numeric
    orbit = OrbitNodes(model, H)  # the averaging's singularity-free nodes (int w/s dx over the level)
    x, s = orbit.x, orbit.s
    hp = np.broadcast_to(np.asarray(h(x, s), dtype=float), x.shape)
    hm = np.broadcast_to(np.asarray(h(x, -s), dtype=float), x.shape)
    W = np.abs(orbit.integral((hp - hm) * s))  # oint h dx: the y > 0 branch forwards, y < 0 backwards
    T = orbit.integral(2.0)
    # every wall the level hits, each at its own energy (the free orbit's exact loss over one quasi-period)
    loss = np.asarray(METHODS["exact-two-impact"].cycle_loss(model.restitution, H, geometry(model).wall_levels),
                      dtype=float)
    return W, T, loss


def _reference_density(model, h_max, points=600, cycles=None):
    """A cheap p(H) to weight the diagnostics: the paper's averaged density of the *elastic* model.

    For linear damping and additive noise this is the exact elastic density T(H) exp(-beta H). ``cycles``, a dict,
    receives the :func:`cycle_quantities` computed on the returned energies (so that :func:`diagnose` need not
    compute them again).
    """
    H = np.linspace(h_max / points, h_max, points)
    W, T, loss = cycle_quantities(model, H)
    c = model.linear_damping_constant()
    s2 = model.constant_noise_intensity()
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
    if cycles is not None:
        cycles.update(H=H, quantities=(W, T, loss))
    return H, p


def _trapz(y, x):
    return float(np.trapezoid(y, x)) if hasattr(np, "trapezoid") else float(np.trapz(y, x))


def _feeds_energy(model, h_top: float) -> bool:
    """True when h(x, y) * y < 0 somewhere on the orbits up to energy ``h_top`` (negative damping)."""
    h = model._damping_numeric
    lo, hi = model.turning_points(h_top)  # clipped to the walls, whichever side they are on
    left, right = float(lo), float(hi)
    x = np.linspace(left, right, 101)
    y = np.linspace(-math.sqrt(2.0 * h_top), math.sqrt(2.0 * h_top), 101)
    xx, yy = np.meshgrid(x, y)
    power = np.broadcast_to(np.asarray(h(xx, yy), dtype=float), xx.shape) * yy
    return bool(np.any(power < -1e-12 * max(1.0, float(np.max(np.abs(power))))))


def _choose_h_max(model, elastic: bool = True) -> float:
    """An energy above which the stationary mass is negligible (< 1e-5).

    From the density of the elastic model (``elastic=True``) or of the model itself by the paper's averaging.
    """
    c = model.linear_damping_constant()
    s2 = model.constant_noise_intensity()
    if elastic and c is not None and s2 is not None and c > 0 and s2 > 0:
        return 14.0 * s2 / (2.0 * c)  # exp(-beta H) T(H): tail mass ~ e^-14 times a polynomial
    # one averaged density over the widest range tried (the solver fits its grid to where the mass is), then the
    # first of 4, 8, ..., 512 whose top tenth holds < 1e-5 of the mass below it: one solve instead of up to eight
    import warnings

    from averaging import stationary_density
    from hybrid.errors import TruncationWarning

    target = model.with_restitution(Elastic()) if elastic else model
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TruncationWarning)  # mass beyond the widest range: refused below
        sd = stationary_density(target, method="paper", h_max=4.0 * 2.0**7, points=4000)
    H, p = np.asarray(sd.H, dtype=float), np.asarray(sd.p, dtype=float)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(H))])
    h_max = 4.0
    for _ in range(8):
        below = float(np.interp(h_max, H, cum))
        tail = (below - float(np.interp(0.9 * h_max, H, cum))) / below if below > 0 else 1.0
        if tail < 1e-5:
            return h_max
        h_max *= 2.0
    h_max /= 2.0
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
    from averaging.quadrature import geometry

    _check_averagable(model)
    notes: list[str] = []
    kind = barrier_geometry(model)
    G_low = geometry(model).G_delta  # the lowest impact level (inf without walls)
    if kind not in CALIBRATED_GEOMETRIES:
        notes.append(f"{kind} walls: the averaging error model was fitted on symmetric gaps only, so no accuracy is "
                     "predicted for paper or jump here (see benchmarks/geometry_averaging.py for measured L1)")
    c = model.linear_damping_constant()
    s2 = model.constant_noise_intensity()
    law = model.restitution
    vc = float(law.elastic_below()) if model.has_barriers else math.inf
    elastic = bool(law.is_elastic) or not model.has_barriers
    cycles: dict = {}
    try:
        h_el = _choose_h_max(model)
        He, pe = _reference_density(model, h_el, cycles=cycles)
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
        from averaging.quadrature import geometry

        sd_el = stationary_density(model.with_restitution(Elastic()), method="paper", h_max=h_el, points=2000)
        total = above = 0.0
        for wall, Gw in zip([b for b in model.barriers if np.isfinite(b)], geometry(model).wall_levels):
            if Gw >= h_el:
                continue
            v = np.linspace(0.0, math.sqrt(2.0 * (h_el - Gw)), 4001)
            flux = v * sd_el.joint(np.array([wall]), v)[:, 0]
            cum = np.concatenate([[0.0], np.cumsum(0.5 * (flux[1:] + flux[:-1]) * np.diff(v))])
            total += cum[-1]
            above += cum[-1] - np.interp(vc, v, cum)
        tail = float(above / total) if total > 0 else 0.0
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
    W, T, loss = cycles["quantities"] if cycles.get("H") is H else cycle_quantities(model, H)
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
        barrier_energy=float(G_low), notes=notes,
        relaxation_time=float(relax), self_excited=bool(self_excited), geometry=kind,
    )

