"""Stationary densities of the averaged energy: p(H) (eq. 30), p(x, y) (eq. 31), moments and impact rate.

The drift methods (``paper``, ``exact-two-impact``) evaluate eq. 30 in log space from Chebyshev tables of the
averaged coefficients. The ``jump`` method solves the stationary jump-diffusion on the output grid with the
conservative chain of :mod:`averaging.jump`, whose no-jump limit is eq. 30 exactly.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from hybrid.errors import ModelError, NormalisationError, ParameterError, VibroError

from .jump import EnergyChain
from .methods import ImpactMethod, get_method
from .quadrature import DEFAULT_NODES, geometry, orbit_integrals
from .symbolic import fingerprint
from .table import EnergyTable

_TABLES: OrderedDict = OrderedDict()
_TABLES_MAX = 16
_SINGLE_WELL: set = set()


def energy_table(model, h_max: float, nodes: int = DEFAULT_NODES) -> EnergyTable:
    """The (cached) Chebyshev table of ``model``'s averaged coefficients on [0, h_max].

    The table does not depend on the restitution law or the method, so it is shared between them.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> energy_table(DuffingImpact(), 4.0) is energy_table(DuffingImpact(), 4.0)
    True
    """
    model.require_autonomous()
    key = (fingerprint(model), tuple(sorted(model.params.items())), float(h_max), int(nodes))
    tab = _TABLES.get(key)
    if tab is None:
        tab = EnergyTable(model, h_max, nodes)
        _TABLES[key] = tab
        while len(_TABLES) > _TABLES_MAX:
            _TABLES.popitem(last=False)
    else:
        _TABLES.move_to_end(key)
    return tab


def check_confinement(model, method: ImpactMethod, h_max: float, nodes: int = DEFAULT_NODES) -> None:
    """Raise :class:`NormalisationError` unless the model can have a stationary energy density.

    Requires a single confining well (``model.check_single_well``) and a log-density that decreases at large
    energies: d log p/dH = (2 m_eff - d sigma2_bar/dH) / sigma2_bar < 0 at h_max, 10 h_max or 100 h_max, where
    m_eff includes the mean impact loss of the method.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> from averaging.methods import METHODS
    >>> m = ImpactOscillator("x", "c*y", parameters={"c": -0.01, "D": 0.01}, barriers=None)
    >>> check_confinement(m, METHODS["paper"], 4.0)
    Traceback (most recent call last):
    ...
    hybrid.errors.NormalisationError: the averaged energy drifts to infinity: ...
    """
    key = (fingerprint(model), tuple(sorted(model.params.items())), model.barrier_exprs is None)
    if key not in _SINGLE_WELL:
        try:
            model.check_single_well()
        except ModelError as exc:
            raise NormalisationError(f"no stationary density: {exc}") from exc
        _SINGLE_WELL.add(key)
    H = np.array([1.0, 1.001, 10.0, 10.01, 100.0, 100.1]) * h_max
    coef = averaged_coefficients(model, H, method if not method.jumps else "exact-two-impact", nodes)
    s2 = coef.diffusion
    if not np.all(s2 > 0):
        raise NormalisationError(
            "the averaged diffusion sigma2_bar(H) is not positive at large H: the model has no noise there "
            "(D = 0?). The stationary density needs noise; set a positive intensity D"
        )
    slope = (2.0 * coef.drift[::2] - np.diff(s2)[::2] / np.diff(H)[::2]) / s2[::2]
    if np.all(slope > 0):
        raise NormalisationError(
            "the averaged energy drifts to infinity: the log-density keeps growing at H = "
            f"{H[0]:g}, {H[2]:g}, {H[4]:g} (net energy input exceeds damping and impact losses), so p(H) cannot be "
            "normalised. Use positive damping, barriers with dissipative impacts, or a smaller noise intensity"
        )


class AveragedCoefficients:
    """Averaged coefficients on given energies (direct quadrature, eqs. 21-26).

    Attributes
    ----------
    H, drift, diffusion, period, loss : ndarray
        m_bar(H) (including the loss drift -loss/T for drift methods), sigma2_bar(H), T(H), and the energy loss
        per quasi-period (0 below G(delta); 0 for the jump method, where impacts are jumps).
    jump_rate, jump_target : ndarray
        For the jump method: the rate of impacts (walls hit / T(H)) and the post-impact energy at the lowest wall
        (at the only wall unless the walls are asymmetric).
    method : str

    Examples
    --------
    >>> from models import DuffingImpact
    >>> c = averaged_coefficients(DuffingImpact(), [0.2, 1.0], "paper")
    >>> list(c.to_pandas().columns)
    ['H', 'drift', 'diffusion', 'period', 'loss', 'jump_rate', 'jump_target']
    """

    def __init__(self, H, drift, diffusion, period, loss, jump_rate, jump_target, method: str):
        self.H, self.drift, self.diffusion, self.period = H, drift, diffusion, period
        self.loss, self.jump_rate, self.jump_target, self.method = loss, jump_rate, jump_target, method

    def to_pandas(self):
        """A DataFrame with one row per energy."""
        import pandas as pd

        return pd.DataFrame({
            "H": self.H, "drift": self.drift, "diffusion": self.diffusion, "period": self.period, "loss": self.loss,
            "jump_rate": self.jump_rate, "jump_target": self.jump_target,
        })

    def __getitem__(self, key):
        return getattr(self, key)

    def __repr__(self) -> str:
        return f"AveragedCoefficients(method={self.method!r}, {len(self.H)} energies)"


def averaged_coefficients(model, H, method="paper", nodes: int = DEFAULT_NODES) -> AveragedCoefficients:
    """m_bar(H), sigma2_bar(H) and T(H) of ``model`` on energies ``H`` > 0 (eqs. 21-26).

    Parameters
    ----------
    model : ImpactOscillator
    H : array_like
        Energies > 0.
    method : str or ImpactMethod
        ``paper``, ``exact-two-impact`` or ``jump`` (see :data:`METHODS`).
    nodes : int
        Gauss-Legendre nodes per level.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.05}, barriers=None)
    >>> c = averaged_coefficients(lin, [1.0])
    >>> round(float(c.drift[0]), 12), round(float(c.diffusion[0]), 12)     # D - c H, 2 D H
    (-0.05, 0.1)
    """
    m = get_method(method)
    H = np.atleast_1d(np.asarray(H, dtype=float))
    o = orbit_integrals(model, H, nodes)
    T = o["T"]
    drift = o["drift"] / T
    diffusion = o["diffusion"] / T
    geo = geometry(model)
    law = model.restitution
    loss = np.zeros_like(H)
    rate = np.zeros_like(H)
    target = H.copy()
    hits = geo.hits(H)
    if m.jumps:
        # the jump at the lowest wall hit (the jump chain itself jumps at every wall hit, each at rate 1/T)
        imp = hits > 0
        rate[imp] = hits[imp] / T[imp]
        Gd = geo.G_delta
        target[imp] = Gd + m.jump_target(law, H[imp] - Gd)
    else:
        loss = m.cycle_loss(law, H, geo.wall_levels)
        drift = drift - loss / T
    return AveragedCoefficients(H, drift, diffusion, T, loss, rate, target, m.name)


class StationaryDensity:
    """The stationary energy density p(H) of a model under one averaging method, and what follows from it.

    Built by :func:`stationary_density`. ``H`` and ``p`` are the grid and the density normalised to 1 on
    [0, h_max]; moments are integrals over [0, h_max] with accurate quadrature.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> sd = stationary_density(DuffingImpact(), "paper", h_max=4.0, points=201)
    >>> round(sd.total_mass, 12)
    1.0
    >>> sd.to_pandas().columns.tolist()
    ['H', 'p']
    """

    def __init__(self, model, method: ImpactMethod, table: EnergyTable, H, log_p, log_density, qH, qw,
                 h_max: float | None = None):
        self.model = model
        self.method = method.name
        self._method = method
        self.table = table
        self.h_max = table.h_max if h_max is None else float(h_max)
        self.h_support = table.h_max  # p is computed on [0, h_support]; 0 above (negligible mass there)
        self.mass_above_h_max = 0.0
        self.H = H
        self.log_p = log_p
        with np.errstate(over="ignore"):
            self.p = np.exp(log_p)
        if len(H) > 1 and H[0] == 0.0 and not np.isfinite(self.p[0]):
            self.p[0] = self._singular_origin_value(float(H[1]), float(self.p[1]), log_density, table)
        elif len(H) > 1 and H[0] == 0.0 and self.p[0] == 0.0:
            # p ~ H**nu with nu fitted numerically: a quadratic minimum (nu = 0) fitted as nu = 3e-7 gives p(0) = 0
            # exactly, where the limit from above is finite (atan(x): 4.26; the CSV lost 3.5 % of its mass)
            with np.errstate(all="ignore"):
                limit = float(np.exp(log_density(np.array([1e-12 * float(H[1])])))[0])
            self.p[0] = limit if np.isfinite(limit) else 0.0
        self._log_density = log_density
        self._qH = qH
        self._qp = np.exp(log_density(qH)) * qw
        Gd = table.G_delta
        self.mean_energy = float(np.sum(self._qp * qH))
        self.mean_x2 = float(np.sum(self._qp * table.mean_x2(qH)))
        self.prob_below_barrier = float(np.sum(self._qp[qH <= Gd])) if np.isfinite(Gd) else 1.0
        self.impact_rate = float(np.sum(self._qp * table.impact_rate(qH)))
        self.total_mass = float(np.sum(self._qp))
        self.tail_density = float(self.p[-1])

    @staticmethod
    def _singular_origin_value(H1: float, p1: float, log_density, table) -> float:
        """A finite p[0] where p(H) ~ H**nu diverges at 0 (nu < 0, a potential flatter than quadratic at its minimum).

        It is the value that gives the first trapezoid cell [0, H1] its exact mass (Gauss-Jacobi for the H**nu
        factor), so that the written density integrates to 1 on its own grid instead of holding inf.
        """
        from .jump import cell_quadrature

        _, Hq, wq = cell_quadrature(np.array([0.0, H1]), table.geometry.levels, table.nu)
        mass = float(np.sum(wq * np.exp(log_density(Hq))))
        return max(2.0 * mass / H1 - p1, 0.0)

    @property
    def barrier_energy(self) -> float:
        """The lowest impact level: G(delta) for a symmetric gap, 0 for a wall at the equilibrium, inf without walls."""
        return self.table.G_delta

    def density(self, H):
        """p(H) at arbitrary energies (0 outside [0, h_max]).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density(DuffingImpact(), "paper", points=101)
        >>> float(sd.density([0.3, 5.0])[1])
        0.0
        """
        H = np.asarray(H, dtype=float)
        inside = (H >= 0) & (H <= self.h_support)
        out = np.zeros_like(H)
        if inside.any():
            out[inside] = np.exp(self._log_density(H[inside]))
        return out

    def _joint_energy(self, H):
        H = np.asarray(H, dtype=float)
        inside = (H >= 0) & (H <= self.h_support)
        out = np.zeros_like(H)
        if inside.any():
            # p/T is finite at H = 0 even where p and T both diverge there (nu < 0): take it just above 0
            Hi = np.maximum(H[inside], 1e-12 * self.h_support)
            out[inside] = np.exp(self._log_density(Hi)) / self.table.period(Hi)
        return out

    def joint(self, x, y):
        """p(x, y) = p(H)/T(H) at H = y**2/2 + G(x) (eq. 31) on the grid x (nx) by y (ny) -> array (ny, nx).

        Zero outside the barriers and above h_max.

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density(DuffingImpact(), "paper", points=101)
        >>> sd.joint(np.linspace(-1, 1, 5), np.linspace(-2, 2, 3)).shape
        (3, 5)
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        left, right = self.model.barriers
        H = 0.5 * y[:, None] ** 2 + self.model.potential(x)[None, :]
        out = self._joint_energy(H)
        out[:, (x < left) | (x > right)] = 0.0
        return out

    def marginal_x(self, x, nodes: int = 96):
        """p(x) = int p(x, y) dy.

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density(DuffingImpact(), "paper", points=101)
        >>> bool(sd.marginal_x(np.array([0.0]))[0] > 0)
        True
        """
        x = np.atleast_1d(np.asarray(x, dtype=float))
        left, right = self.model.barriers
        Gx = self.model.potential(x)
        ok = (x >= left) & (x <= right) & (Gx < self.h_support)
        out = np.zeros_like(x)
        if not ok.any():
            return out
        Gx = Gx[ok]
        ymax = np.sqrt(2.0 * (self.h_support - Gx))
        # p(x, y) has a kink where the level crosses an impact level (one per level; two for asymmetric walls)
        kinks = [np.minimum(np.sqrt(2.0 * np.clip(L - Gx, 0.0, None)), ymax) for L in self.table.geometry.levels]
        ys = np.sort(np.vstack([np.zeros_like(ymax)] + kinks + [ymax]), axis=0)
        t, w = np.polynomial.legendre.leggauss(nodes)
        total = np.zeros_like(Gx)
        for lo, hi in zip(ys[:-1], ys[1:]):
            yy = 0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * t
            vals = self._joint_energy(np.minimum(0.5 * yy**2 + Gx[:, None], self.h_support))
            total += np.sum(vals * w, axis=1) * 0.5 * (hi - lo)
        out[ok] = 2.0 * total
        return out

    def marginal_y(self, y, nodes: int = 96):
        """p(y) = int p(x, y) dx over the barriers.

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sd = stationary_density(DuffingImpact(), "paper", points=101)
        >>> bool(sd.marginal_y(np.array([0.0]))[0] > 0)
        True
        """
        from .quadrature import turning_points

        y = np.atleast_1d(np.asarray(y, dtype=float))
        left, right = self.model.barriers
        out = np.zeros_like(y)
        kin = 0.5 * y * y
        ok = kin < self.h_support
        if not ok.any():
            return out
        kin = kin[ok]
        # x range where H <= h_max, and the points where H crosses G(delta) (kinks of T)
        lo, hi = turning_points(self.model, self.h_support - kin)
        lo, hi = np.maximum(lo, left), np.minimum(hi, right)
        # the x where H crosses an impact level (kinks of T): split there, one pair per level
        cuts = [lo, hi]
        for L in self.table.geometry.levels:
            lev = np.clip(L - kin, 1e-300, None)
            klo, khi = turning_points(self.model, lev)
            has = L - kin > 0
            cuts += [np.where(has, np.clip(klo, lo, hi), lo), np.where(has, np.clip(khi, lo, hi), lo)]
        xs = np.sort(np.vstack(cuts), axis=0)
        pieces = list(zip(xs[:-1], xs[1:]))
        t, w = np.polynomial.legendre.leggauss(nodes)
        total = np.zeros_like(kin)
        for a, b in pieces:
            xx = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * t
            H = np.minimum(kin[:, None] + self.model.potential(xx), self.h_support)
            total += np.sum(self._joint_energy(H) * w, axis=1) * 0.5 * (b - a)
        out[ok] = total
        return out

    def to_pandas(self):
        """DataFrame with columns H, p (metadata in ``.attrs``)."""
        import pandas as pd

        df = pd.DataFrame({"H": self.H, "p": self.p})
        df.attrs.update(self.metadata())
        return df

    def metadata(self) -> dict:
        """Method, model description and summary statistics (JSON-friendly)."""
        return {
            "method": self.method, "model": self.model.describe(), "h_max": self.h_max,
            "mean_energy": self.mean_energy, "mean_x2": self.mean_x2,
            "prob_below_barrier": self.prob_below_barrier, "impact_rate": self.impact_rate,
            "barrier_energy": self.barrier_energy,
        }

    def __repr__(self) -> str:
        return (f"StationaryDensity(model={self.model.name!r}, method={self.method!r}, points={len(self.H)}, "
                f"E[H]={self.mean_energy:.6g}, P(H<G)={self.prob_below_barrier:.6g})")

    def _repr_html_(self) -> str:
        from hybrid.display import summary_html

        return summary_html(f"StationaryDensity of {self.model.name} ({self.method})", {
            "points on [0, h_max]": f"{len(self.H)} on [0, {self.h_max:g}]", "E[H]": self.mean_energy,
            "P(H < G(delta))": self.prob_below_barrier, "E[x^2]": self.mean_x2, "impact rate": self.impact_rate})


_LOG_DROP = 40.0
"""Beyond the energy where p(H) has fallen by e**-40 from its peak the mass is negligible (below about 1e-16)."""

TAIL_WARN = 1e-3
"""Mass above h_max beyond which :func:`stationary_density` warns (:class:`~hybrid.errors.TruncationWarning`)."""

_MAX_POINTS = 10_000_000


ENERGY_RANGE = 1e15
"""How far ``h_max`` may lie from the model's energy scale (G(delta), or G(1) without walls), up or down (every
method answers at 1e15 times the scale both ways, as at a moderate h_max): beyond, double precision cannot hold the
density's grid and quadrature (h_max = 1e300 overflowed the coefficients, 1e-300
underflowed them, and each was refused with a message about the model instead of h_max)."""


def check_energy_range(model, h_max: float, walls="model") -> None:
    """Refuse an ``h_max`` more than :data:`ENERGY_RANGE` above or below the model's energy scale.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> check_energy_range(DuffingImpact(), 4.0)
    >>> check_energy_range(DuffingImpact(), 1e-300)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hybrid.errors.ParameterError: h_max=1e-300 lies ... below the model's energy scale G = 0.55; ...
    """
    try:
        G = geometry(model).G_delta if walls == "model" else np.inf  # walls given apart: the well's scale G(1)
        scale = float(G) if np.isfinite(G) and G > 0 else float(model.potential(1.0))
    except (VibroError, ArithmeticError):
        return  # no scale to compare with (not a single well): the solvers' own checks apply
    if not (np.isfinite(scale) and scale > 0):
        return
    ratio = h_max / scale
    if not 1.0 / ENERGY_RANGE <= ratio <= ENERGY_RANGE:
        side = "above" if ratio > 1 else "below"
        raise ParameterError(f"h_max={h_max:g} lies {max(ratio, 1 / ratio):.3g} times {side} the model's energy "
                             f"scale G = {scale:.3g}; double precision cannot resolve p(H) over that range: give "
                             f"an h_max within {ENERGY_RANGE:.0e} of it (the density's mass sits a few times D/c "
                             "above 0)")


def output_grid(h_mass: float, h_max: float, points: int) -> np.ndarray:
    """The ``points`` energies from 0 to ``h_max`` that p(H) is written on, placed where its mass is.

    Uniform when the mass reaches h_max; when it ends at ``h_mass`` < h_max (p has fallen by e**-40 there), all
    but a few of them lie on [0, h_mass], and the rest step geometrically up to h_max over energies where p is 0.
    A uniform grid over [0, 1e6] would put a density living on [0, 3] into its first cell.

    Examples
    --------
    >>> H = output_grid(20.0, 1e6, 2000)
    >>> len(H), float(H[-1]), int(np.sum(H <= 20.0))
    (2000, 1000000.0, 1938)
    """
    if h_mass >= h_max:
        return np.linspace(0.0, h_max, points)
    tail = max(1, min(points // 32, 64))  # enough steps that a log-scale plot of the empty range still reads
    return np.concatenate([np.linspace(0.0, h_mass, points - tail), np.geomspace(h_mass, h_max, tail + 1)[1:]])


def _check_scale(model, m, nodes) -> None:
    """Refuse parameters whose density varies on an energy scale double precision cannot handle (D = 1e-300).

    The scale is 1 / |d log p / dH| = sigma2_bar / |2 m_bar - d sigma2_bar / dH| (eq. 30) at a few energies around
    the model's own energy G(delta) (or G(1) without barriers). It must lie within 1e-100 to 1e100 of it.
    """
    G = geometry(model).G_delta
    ref = float(G) if np.isfinite(G) and G > 0 else float(model.potential(1.0))  # wall at the equilibrium: G = 0
    H = ref * np.array([0.25, 0.2501, 0.5, 0.5001, 0.9, 0.9001])
    coef = averaged_coefficients(model, H, m if not m.jumps else "exact-two-impact", nodes)
    s2 = coef.diffusion
    with np.errstate(all="ignore"):
        slope = (2.0 * coef.drift[::2] - np.diff(s2)[::2] / np.diff(H)[::2]) / s2[::2]
        size = float(np.max(np.abs(slope))) * ref
    if not (np.all(np.isfinite(slope)) and 1e-100 <= size <= 1e100):
        scale = ref / size if size > 0 else float("inf")
        raise NormalisationError(
            f"p(H) varies on an energy scale of about {scale:.3g} against the model's energy {ref:.3g} (parameters "
            f"{dict(model.params)}): double precision cannot represent that density; rescale the parameters "
            "(noise intensity, damping) to moderate sizes"
        )


def _drop_energy(tab, drift, law, h: float) -> float | None:
    """The first energy above the peak of p(H) in [0, h] where p has fallen by e**-_LOG_DROP, or None."""
    Hs = np.unique(np.concatenate([np.linspace(0.0, h, 4001), np.geomspace(h * 1e-12, h, 2001)]))
    with np.errstate(all="ignore"):
        lp = tab.log_density(Hs, drift, law)
    lp = np.where(np.isfinite(lp), lp, -np.inf)
    k = int(np.argmax(lp))
    if not np.isfinite(lp[k]):
        return None
    past = np.nonzero(lp[k:] < lp[k] - _LOG_DROP)[0]
    return float(Hs[k + past[0]]) if past.size else None


def _mass_range(model, m, law, nodes, h_max: float) -> tuple[float, bool]:
    """(h, covered): an energy range [0, h], h <= h_max, fitted to where p(H) carries its mass.

    ``covered`` is True when p has fallen by e**-40 inside [0, h]; the range then shrinks from h_max towards the
    mass (a table and a grid spread over [0, 1e8] would not resolve a density living on [0, 20]). The jump method
    is searched with its no-loss density p0, whose tail is the heavier one.
    """
    drift = None if m.jumps else m
    h = float(h_max)
    for _ in range(12):
        hd = _drop_energy(energy_table(model, h, nodes), drift, law, h)
        if hd is None:
            if h >= h_max:
                return h, False
            h = min(h_max, 4.0 * h)  # shrank too far: p has not fallen yet
            continue
        if hd >= h / 4.0:
            return h, True
        h = 2.0 * hd
    return h, True


def _solve(model, m, law, nodes, h: float, points: int):
    """The density on [0, h]: (table, internal grid, log p there, log-density function, quadrature nodes, weights)."""
    tab = energy_table(model, h, nodes)
    H = np.linspace(0.0, float(h), int(points))
    if not m.jumps:
        qH, qw = tab.quadrature(cuts=tab.loss_breakpoints(m, law) if tab.has_impacts else [])
        lq = tab.log_density(qH, m, law)
        S = float(np.max(lq))
        logZ = S + np.log(np.sum(qw * np.exp(lq - S)))

        def log_density(e):
            return tab.log_density(e, m, law) - logZ

        return tab, H, log_density(H), log_density, qH, qw
    chain = EnergyChain(tab, H, m, law)
    r = chain.stationary_ratio()
    Z = float(np.sum(chain.W * r))
    logZ = chain.shift + np.log(Z)

    def log_density(e):
        return np.log(np.interp(e, H, r)) + tab.log_density(e, None, law) - logZ

    return tab, H, np.log(r) + chain.logp0_nodes - logZ, log_density, chain.Hq, chain.wq


def _tail_mass(model, m, law, nodes, h_max: float, points: int) -> tuple[float, bool]:
    """(mass of p(H) above ``h_max``, exact): from a solution on a range grown from h_max until it covers the mass.

    When p has not fallen by e**-40 before the range reaches 4**30 h_max or the coefficients overflow, the mass
    is measured on the largest range reached and is a lower bound (``exact`` False).
    """
    drift = None if m.jumps else m
    h, good, exact = float(h_max), float(h_max), False
    for _ in range(30):
        h *= 4.0
        try:
            found = _drop_energy(energy_table(model, h, nodes), drift, law, h)
        except NormalisationError:  # the coefficients overflow this far out
            break
        good = h
        if found is not None:
            exact = True
            break
    if exact:
        good, _ = _mass_range(model, m, law, nodes, good)
    _, _, _, log_density, qH, qw = _solve(model, m, law, nodes, good, points)
    p = np.exp(log_density(qH)) * qw
    return float(np.sum(p[qH > h_max]) / np.sum(p)), exact


def stationary_density(model, method="paper", h_max: float = 4.0, points: int = 2000,
                       nodes: int = DEFAULT_NODES, check: bool = True) -> StationaryDensity:
    """The stationary energy density p(H) on ``points`` energies in [0, h_max], normalised to 1 there.

    The density is computed on the part of [0, h_max] where it carries its mass: above the energy where p has
    fallen by e**-40 from its peak, ``p`` is 0, so the answer does not depend on h_max once h_max covers the mass
    (a huge h_max no longer spreads the grid and the quadrature over empty energies), and the output grid
    (:func:`output_grid`) puts all but a few of its points below that energy, so that ``H``, ``p`` integrate to 1
    by the trapezoid rule and give the same moments. Where p diverges at H = 0 (p ~ H**nu, nu < 0), ``p[0]`` is
    the finite value that gives the first cell its exact mass.

    Parameters
    ----------
    model : ImpactOscillator
        Any model with a single confining well, between any walls: symmetric, asymmetric (G(left) != G(right)),
        one-sided, or a wall at the equilibrium.
    method : str or ImpactMethod
        ``paper`` (eq. 13 loss as drift), ``exact-two-impact``, ``jump`` (impacts as jumps at Poisson times), or
        ``chain`` (the jumps at the end of each flight, :func:`averaging.chain.chain_density`).
    h_max : float
        Upper end of the energy range. Mass above it is discarded (the density is the one conditional on
        H <= h_max): when that is more than :data:`TAIL_WARN` of the total, a
        :class:`~hybrid.errors.TruncationWarning` says how much (``result.mass_above_h_max``).
    points : int
        Output grid size (the jump method solves on this many energies over the range carrying the mass).
    nodes : int
        Gauss-Legendre nodes per orbit quadrature (>= 16).
    check : bool
        Check confinement first (raises :class:`NormalisationError` when p cannot be normalised).

    Raises
    ------
    ParameterError
        ``points``, ``h_max`` or ``nodes`` of the wrong type or out of range.
    NormalisationError
        No stationary density, or one that double precision cannot represent (its energy scale under- or
        overflows, e.g. D = 1e-300).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> sd = stationary_density(DuffingImpact(), "jump", h_max=4.0, points=400)
    >>> 0.0 < sd.prob_below_barrier < 1.0
    True
    """
    model.require_autonomous()
    import warnings

    from hybrid.errors import TruncationWarning

    m = get_method(method)
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or not 3 <= points <= _MAX_POINTS:
        raise ParameterError(f"points={points!r} must be an integer in [3, {_MAX_POINTS:.0e}] (the output grid size)")
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or not 16 <= nodes <= 4096:
        raise ParameterError(f"nodes={nodes!r} must be an integer in [16, 4096] (Gauss nodes per orbit; default "
                             f"{DEFAULT_NODES}); fewer cannot resolve the orbit integrals near the turning points")
    if isinstance(h_max, bool) or not isinstance(h_max, (int, float, np.integer, np.floating)) or \
            not (math.isfinite(float(h_max)) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    h_max = float(h_max)
    check_energy_range(model, h_max)
    points = int(points)
    if m.flights:
        from .chain import chain_density

        return chain_density(model, h_max=h_max, points=points, phases=m.phases, nodes=nodes, check=check)
    law = model.restitution
    try:
        with np.errstate(all="ignore"):
            if check:
                check_confinement(model, m, h_max, nodes)
            _check_scale(model, m, nodes)
            h, covered = _mass_range(model, m, law, nodes, h_max)
            tab, Hin, log_in, log_density, qH, qw = _solve(model, m, law, nodes, h, points)
            for _ in range(4 if covered and m.jumps else 0):
                # the range came from the no-loss p0; the jumps make p fall sooner: fit the grid to p itself
                k = int(np.argmax(log_in))
                past = np.nonzero(log_in[k:] < log_in[k] - _LOG_DROP)[0]
                if not past.size or Hin[k + past[0]] >= h / 1.5:
                    break
                h = 1.25 * float(Hin[k + past[0]])
                # the chain's accuracy is set by its spacing: at least 8001 nodes over the mass
                tab, Hin, log_in, log_density, qH, qw = _solve(model, m, law, nodes, h, max(points, 8001))
            tail, exact = (0.0, True) if covered else _tail_mass(model, m, law, nodes, h_max, points)
    except (ValueError, ZeroDivisionError, FloatingPointError, OverflowError) as exc:
        if isinstance(exc, VibroError):
            raise
        raise NormalisationError(
            f"p(H) cannot be computed in double precision for these parameters {dict(model.params)} "
            f"({type(exc).__name__}); its energy scale under- or overflows: use parameters of moderate size"
        ) from exc
    H = output_grid(h, h_max, points)
    inside = H <= h
    log_p = np.full(points, -np.inf)
    log_p[inside] = log_density(H[inside]) if h < h_max else log_in
    sd = StationaryDensity(model, m, tab, H, log_p, log_density, qH, qw, h_max=h_max)
    sd.mass_above_h_max = tail
    stats = (sd.mean_energy, sd.mean_x2, sd.prob_below_barrier, sd.impact_rate, sd.total_mass)
    if not (np.all(np.isfinite(log_p[1:][inside[1:]])) and np.all(np.isfinite(stats))
            and abs(sd.total_mass - 1) < 1e-6):
        raise NormalisationError(
            f"p(H) could not be normalised accurately (total mass {sd.total_mass!r}); increase points or check "
            "the model's parameters"
        )
    if tail > TAIL_WARN:
        warnings.warn(TruncationWarning(
            f"h_max={h_max:g} cuts off {'' if exact else 'at least '}{tail:.3g} of the stationary probability mass "
            "(the density returned is the one conditional on H <= h_max); raise h_max to cover the mass"), stacklevel=2)
    return sd
