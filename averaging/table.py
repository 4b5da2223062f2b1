"""Chebyshev tables of the averaged coefficients on [0, h_max]: the fast path behind p(H).

The orbit integrals are analytic in H below the impact level G(delta) and analytic in u = sqrt(H - G(delta))
above it (the barrier cuts the orbit: T(H) has a square-root kink at G(delta)). So each piece is represented by an
adaptive Chebyshev interpolant in its natural variable; a few dozen levels replace thousands of quadratures, and
integrals of eq. 30 are integrals of polynomials. Near H = 0 the eq. 30 integrand 2 m/s2 behaves like kappa/H: the
table keeps kappa log H analytically and interpolates the regular rest.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C
from scipy.fft import dct
from scipy.special import roots_jacobi

from hybrid.errors import NormalisationError, ParameterError

from .methods import ImpactMethod
from .quadrature import DEFAULT_NODES, _gauss, geometry, orbit_integrals

_SIZES = (17, 33, 65, 129, 257, 513)
_TOL = 1e-13


_JACOBI: dict = {}


def _jacobi(n: int, nu: float):
    key = (n, nu)
    if key not in _JACOBI:
        _JACOBI[key] = roots_jacobi(n, 0.0, nu) if nu != 0.0 else _gauss(n)
    return _JACOBI[key]


def cheb_nodes(n: int) -> np.ndarray:
    """First-kind Chebyshev nodes on (-1, 1) in decreasing order."""
    return np.cos(np.pi * (np.arange(n) + 0.5) / n)


def cheb_coefficients(values: np.ndarray) -> np.ndarray:
    """Chebyshev coefficients of the interpolant through values at :func:`cheb_nodes` (last axis)."""
    n = values.shape[-1]
    c = dct(values, type=2, axis=-1) / n
    c[..., 0] *= 0.5
    return c


def _converged(c: np.ndarray, scale: float) -> bool:
    tail = np.max(np.abs(c[-4:]))
    return bool(tail <= _TOL * max(scale, np.max(np.abs(c))))


def _edges(cuts, U):
    """0, the cuts strictly inside (0, U) without near-duplicates, and U."""
    edges = [0.0]
    for u in sorted(cuts):
        if edges[-1] + 1e-9 * U < u < U * (1 - 1e-9):
            edges.append(float(u))
    return edges + [float(U)]


class Cheb:
    """A Chebyshev series on [a, b].

    Examples
    --------
    >>> f = Cheb.fit(np.exp, 0.0, 1.0)
    >>> round(float(f(0.5)), 14) == round(float(np.exp(0.5)), 14)
    True
    >>> round(float(f.antiderivative()(1.0)), 13) == round(float(np.e - 1), 13)
    True
    """

    def __init__(self, coef, a: float, b: float):
        self.coef = np.asarray(coef, dtype=float)
        self.a, self.b = float(a), float(b)

    @classmethod
    def fit(cls, fun, a, b, scale: float = 0.0):
        """Adaptive interpolant of a vectorised ``fun`` on [a, b] (doubles the degree until the tail is negligible)."""
        for n in _SIZES:
            t = a + (b - a) * 0.5 * (cheb_nodes(n) + 1.0)
            c = cheb_coefficients(np.asarray(fun(t), dtype=float))
            if _converged(c, scale):
                break
        return cls(c, a, b)

    def _t(self, x):
        return (2.0 * np.asarray(x, dtype=float) - (self.a + self.b)) / (self.b - self.a)

    def __call__(self, x):
        return C.chebval(self._t(x), self.coef)

    def __rmul__(self, factor: float) -> Cheb:
        return Cheb(factor * self.coef, self.a, self.b)

    def antiderivative(self) -> Cheb:
        """The integral from a to x, as a series."""
        return Cheb(C.chebint(self.coef, lbnd=-1, scl=0.5 * (self.b - self.a)), self.a, self.b)


def _fit_many(fun, a, b, scales):
    """Fit several quantities returned by ``fun(t) -> dict`` on the same adaptive nodes."""
    for n in _SIZES:
        t = a + (b - a) * 0.5 * (cheb_nodes(n) + 1.0)
        vals = fun(t)
        coefs = {k: cheb_coefficients(np.asarray(v, dtype=float)) for k, v in vals.items()}
        if all(_converged(c, scales.get(k, 0.0)) for k, c in coefs.items()):
            break
    return {k: Cheb(c, a, b) for k, c in coefs.items()}, t, vals


class EnergyTable:
    """Averaged coefficients of ``model`` on [0, h_max] (no impact loss), as Chebyshev interpolants.

    Parameters
    ----------
    model : ImpactOscillator
    h_max : float
    nodes : int
        Orbit quadrature nodes per level.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> tab = EnergyTable(DuffingImpact(), 4.0)
    >>> bool(abs(tab.period(0.0) - 2 * np.pi) < 1e-10)     # small oscillations: 2 pi / sqrt(a)
    True
    """

    def __init__(self, model, h_max: float, nodes: int = DEFAULT_NODES):
        if not (np.isfinite(h_max) and h_max > 0):
            raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
        self.model = model
        self.h_max = float(h_max)
        self.nodes = nodes
        self.G_delta = geometry(model).G_delta
        self.walls = geometry(model).walls
        self.H1 = min(self.G_delta, self.h_max)
        self._fit_low()
        self.has_impacts = self.h_max > self.G_delta
        if self.has_impacts:
            self._fit_high()
        self._loss_cache: dict[tuple, list] = {}

    # ------------------------------------------------------------------ fits
    def _orbits(self, H):
        out = orbit_integrals(self.model, H, self.nodes)
        if np.any(out["diffusion"] <= 0) or not np.all(np.isfinite(out["diffusion"])):
            raise NormalisationError(
                "the averaged diffusion sigma2_bar(H) is not positive: the noise vanishes on whole energy levels "
                "(D = 0?). The stationary density needs noise; set a positive intensity D"
            )
        return out

    def _fit_low(self):
        H1 = self.H1
        tiny = self._orbits(np.array([1e-7, 2e-7]) * H1)["diffusion"]
        self.m_exp = round(2.0 * np.log2(tiny[1] / tiny[0])) / 2.0  # sigma2_bar ~ H**m near 0

        def quantities(H):
            o = self._orbits(H)
            return {
                "logT": np.log(o["T"]),
                "lam": np.log(o["diffusion"]) - self.m_exp * np.log(H),
                "g1": 2.0 * H * o["drift"] / o["diffusion"],
                "x2": o["x2"] / o["T"],
            }

        f, Hn, vals = _fit_many(quantities, 0.0, H1, {"x2": 0.0})
        self.low = f
        kappa = float(f["g1"](0.0))
        nu = kappa - self.m_exp
        if abs(nu) < 1e-7:  # additive noise: 2 m/s2 ~ 1/H exactly, p(0) finite
            kappa, nu = self.m_exp, 0.0
        self.kappa, self.nu = kappa, nu
        if nu <= -1.0:
            raise NormalisationError(
                f"the density behaves like H**{nu:.3g} at H = 0, which is not integrable: the averaged drift "
                "cannot keep the energy away from 0 (noise vanishing at rest). No stationary density exists"
            )
        # Phi_reg(H) = int_0^H (2 m/s2 - kappa/h) dh: fit (g1(h) - kappa)/h on the same nodes
        reg = (vals["g1"] - kappa) / Hn
        self.phi_reg = Cheb(cheb_coefficients(reg), 0.0, H1).antiderivative()

    def _fit_high(self):
        U = np.sqrt(self.h_max - self.G_delta)
        Gd = self.G_delta

        def quantities(u):
            o = self._orbits(Gd + u * u)
            return {
                "logT": np.log(o["T"]),
                "logB": np.log(o["diffusion"]),
                "f2": 4.0 * u * o["drift"] / o["diffusion"],
                "x2": o["x2"] / o["T"],
            }

        f, _, _ = _fit_many(quantities, 0.0, U, {})
        self.high = f
        self.phi2 = f["f2"].antiderivative()
        self.U = U
        self.phi_at_G = self.kappa * np.log(Gd) + float(self.phi_reg(Gd))

    # ------------------------------------------------------------------ loss drift of a method
    def _loss_pieces(self, method: ImpactMethod, law):
        """Cumulative int 2 L / B dH over the impact range, piecewise between kinks of the loss (in u)."""
        key = (method.name, law)  # laws compare by type and parameters (custom callables by identity)
        if key in self._loss_cache:
            return self._loss_cache[key]
        cuts = [v / np.sqrt(2.0) for v in method.speed_breakpoints(law)]
        edges = _edges(cuts, self.U)
        pieces = []
        total = 0.0
        logB = self.high["logB"]
        for a, b in zip(edges[:-1], edges[1:]):
            def integrand(u):
                return 4.0 * u * method.loss(law, u * u, self.walls) * np.exp(-logB(u))

            F = Cheb.fit(integrand, a, b).antiderivative()
            pieces.append((a, b, total, F))
            total += float(F(b))
        self._loss_cache[key] = pieces
        return pieces

    def loss_integral(self, u, method, law):
        """int_{G}^{G + u**2} 2 L(h) / B(h) dh for the drift methods."""
        u = np.asarray(u, dtype=float)
        out = np.zeros_like(u)
        for a, b, base, F in self._loss_pieces(method, law):
            inside = (u >= a) & (u <= b)
            out = np.where(inside, base + F(np.clip(u, a, b)), out)
            out = np.where(u > b, base + float(F(b)), out)
        return out

    # ------------------------------------------------------------------ evaluation
    def _piecewise(self, H, low_fn, high_fn):
        """Evaluate ``low_fn(H)`` below G(delta) and ``high_fn(u)`` above it, each only where needed."""
        H = np.asarray(H, dtype=float)
        if np.any(H < 0) or np.any(H > self.h_max * (1 + 1e-12)):
            raise ParameterError(f"energies must lie in [0, h_max={self.h_max:g}]")
        if not self.has_impacts:
            return low_fn(H)
        low = H <= self.H1
        out = np.empty_like(H)
        if low.any():
            out[low] = low_fn(H[low])
        if not low.all():
            out[~low] = high_fn(np.sqrt(H[~low] - self.G_delta))
        return out

    @staticmethod
    def _sum(*series):
        n = max(len(c.coef) for c in series)
        coef = np.zeros(n)
        for c in series:
            coef[: len(c.coef)] += c.coef
        return Cheb(coef, series[0].a, series[0].b)

    def period(self, H):
        """T(H) from the table (interpolated; exact to about 1e-12).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> bool(EnergyTable(DuffingImpact(), 4.0).period(1.0) < 2 * np.pi)     # hardening and barriers
        True
        """
        return self._piecewise(H, lambda h: np.exp(self.low["logT"](h)), lambda u: np.exp(self.high["logT"](u)))

    def diffusion(self, H):
        """sigma2_bar(H) from the table."""
        def low(h):
            with np.errstate(divide="ignore"):
                return np.exp(self.low["lam"](h) - self.low["logT"](h)) * h**self.m_exp

        return self._piecewise(H, low, lambda u: np.exp(self.high["logB"](u) - self.high["logT"](u)))

    def mean_x2(self, H):
        """<x**2> on the level H."""
        return self._piecewise(H, self.low["x2"], self.high["x2"] if self.has_impacts else None)

    def log_density(self, H, method: ImpactMethod | None = None, law=None):
        """Unnormalised log p(H) of eq. 30 (with the method's loss drift, or none for ``method=None``).

        Examples
        --------
        >>> from models import DuffingImpact, Elastic
        >>> tab = EnergyTable(DuffingImpact(restitution=Elastic()), 4.0)
        >>> lp = tab.log_density(np.array([0.2, 1.0]))   # elastic: log T(H) - c H / D + const
        >>> bool(abs((lp[1] - lp[0]) - (np.log(tab.period(1.0) / tab.period(0.2)) - 0.8 / 2)) < 1e-10)
        True
        """
        if not hasattr(self, "_low_logp"):
            self._low_logp = self._sum(self.phi_reg, -1.0 * self.low["lam"], self.low["logT"])
            if self.has_impacts:
                self._high_logp = self._sum(self.phi2, -1.0 * self.high["logB"], self.high["logT"])

        def low(h):
            with np.errstate(divide="ignore", invalid="ignore"):
                lead = np.where(h > 0, self.nu * np.log(h), 0.0 if self.nu == 0 else (np.inf if self.nu < 0
                                                                                     else -np.inf))
            return lead + self._low_logp(h)

        def high(u):
            out = self.phi_at_G + self._high_logp(u)
            if method is not None and not method.jumps:
                out = out - self.loss_integral(u, method, law)
            return out

        return self._piecewise(H, low, high)

    # ------------------------------------------------------------------ quadrature on [0, h_max]
    def quadrature(self, n: int = 160, cuts=()):
        """Nodes and weights for int_0^h_max F(H) H**nu dH-type integrands of p(H) (weights include H**nu).

        The low piece uses Gauss-Jacobi with the exact H**nu behaviour at 0; the high piece Gauss-Legendre in u,
        split at ``cuts`` (values of u where the integrand has a kink).
        """
        nodes, weights = [], []
        t, w = _jacobi(n, self.nu)
        H1 = self.H1
        nodes.append(0.5 * H1 * (t + 1.0))
        # p = H**nu * exp(R): the Jacobi weight carries H**nu; divide it out again below for uniform treatment
        with np.errstate(divide="ignore", invalid="ignore"):
            weights.append(w * (0.5 * H1) ** (self.nu + 1.0) / nodes[-1] ** self.nu)
        if self.has_impacts:
            edges = _edges(cuts, self.U)
            tl, wl = _gauss(n)
            for a, b in zip(edges[:-1], edges[1:]):
                u = 0.5 * (a + b) + 0.5 * (b - a) * tl
                nodes.append(self.G_delta + u * u)
                weights.append(0.5 * (b - a) * wl * 2.0 * u)
        return np.concatenate(nodes), np.concatenate(weights)
