"""Chebyshev tables of the averaged coefficients on [0, h_max]: the fast path behind p(H).

The orbit integrals are analytic in H below the first impact level and analytic in u = sqrt(H - L) just above each
impact level L (a wall starts cutting the orbit there: T(H) has a square-root kink at L). The energy range is cut
at every impact level (one level for a symmetric gap or a one-sided stop, two for asymmetric walls), and each piece
is an adaptive Chebyshev interpolant in its natural variable; a few dozen levels replace thousands of quadratures,
and integrals of eq. 30 are integrals of polynomials. Near H = 0 the eq. 30 integrand 2 m/s2 behaves like kappa/H:
the table keeps kappa log H analytically and interpolates the regular rest. A wall at the equilibrium (level 0) is
hit by every orbit: the first piece is then in u = sqrt(H) from 0, with the same kappa log H treatment.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev as C

from hybrid.errors import NormalisationError, ParameterError

from .methods import ImpactMethod
from .quadrature import DEFAULT_NODES, _gauss, gauss_jacobi, geometry, orbit_integrals

_SIZES = (17, 33, 65, 129, 257, 513)
_TOL = 1e-13


_JACOBI: dict = {}


def _jacobi(n: int, nu: float):
    key = (n, nu)
    if key not in _JACOBI:
        _JACOBI[key] = gauss_jacobi(n, 0.0, nu) if nu != 0.0 else _gauss(n)
    return _JACOBI[key]


def cheb_nodes(n: int) -> np.ndarray:
    """First-kind Chebyshev nodes on (-1, 1) in decreasing order."""
    return np.cos(np.pi * (np.arange(n) + 0.5) / n)


def dct2(values: np.ndarray) -> np.ndarray:
    """Unnormalised DCT-II along the last axis, y_k = 2 sum_j x_j cos(pi k (2j + 1) / (2n)), by one complex FFT.

    The even-odd reordering of Makhoul (1980); numpy's FFT, because scipy.fft imports scipy.special, a tenth of a
    second of every command's start-up.

    Examples
    --------
    >>> x = np.array([1.0, 2.0, 0.5])
    >>> k, j = np.arange(3)[:, None], np.arange(3)[None, :]
    >>> bool(np.allclose(dct2(x), 2 * (np.cos(np.pi * k * (2 * j + 1) / 6) * x).sum(axis=1)))
    True
    """
    x = np.asarray(values, dtype=float)
    n = x.shape[-1]
    v = np.concatenate([x[..., ::2], x[..., 1::2][..., ::-1]], axis=-1)
    twiddle = np.exp(-0.5j * np.pi * np.arange(n) / n)
    return 2.0 * (twiddle * np.fft.fft(v, axis=-1)).real


def cheb_coefficients(values: np.ndarray) -> np.ndarray:
    """Chebyshev coefficients of the interpolant through values at :func:`cheb_nodes` (last axis)."""
    n = values.shape[-1]
    c = dct2(values) / n
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


class _UPiece:
    """Fits on [L, L + U**2] in u = sqrt(H - L) above the impact level L (the orbit is cut by the walls below)."""

    zero = False

    def __init__(self, level, U, fits):
        self.level, self.U, self.f = float(level), float(U), fits
        self.phi2 = fits["f2"].antiderivative()
        self.logp = EnergyTable._sum(self.phi2, -1.0 * fits["logB"], fits["logT"])
        self.phi_base = 0.0  # Phi at the level, set by the table

    def u(self, H):
        return np.sqrt(np.maximum(H - self.level, 0.0))

    def period(self, u):
        return np.exp(self.f["logT"](u))

    def diffusion(self, u):
        return np.exp(self.f["logB"](u) - self.f["logT"](u))

    def log_B(self, u):
        return self.f["logB"](u)

    def log_p0(self, u):
        return self.phi_base + self.logp(u)

    def phi_end(self):
        return self.phi_base + float(self.phi2(self.U))


class _ZeroPiece(_UPiece):
    """A wall at the equilibrium: fits in u = sqrt(H) from 0, with sigma2_bar ~ H**m and 2 m/s2 ~ kappa/H there."""

    zero = True

    def __init__(self, U, fits, m_exp, kappa, phi_reg):
        self.level, self.U, self.f = 0.0, float(U), fits
        self.m_exp, self.kappa, self.phi_reg = m_exp, kappa, phi_reg
        self.nu = kappa - m_exp
        self.logp = EnergyTable._sum(phi_reg, -1.0 * fits["lam"], fits["logT"])
        self.phi_base = 0.0

    def diffusion(self, u):
        with np.errstate(divide="ignore"):
            return np.exp(self.f["lam"](u) - self.f["logT"](u)) * (u * u) ** self.m_exp

    def log_B(self, u):
        with np.errstate(divide="ignore"):
            return self.f["lam"](u) + self.m_exp * np.log(u * u)

    def log_p0(self, u):
        with np.errstate(divide="ignore", invalid="ignore"):
            lead = np.where(u > 0, self.nu * np.log(u * u), 0.0 if self.nu == 0 else (
                np.inf if self.nu < 0 else -np.inf))
        return lead + self.logp(u)

    def phi_end(self):
        return self.kappa * np.log(self.U**2) + float(self.phi_reg(self.U))


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
        geo = geometry(model)
        self.geometry = geo
        self.G_delta = geo.G_delta
        self.walls = geo.walls
        self.wall_levels = geo.wall_levels
        self.levels = [L for L in geo.levels if L < self.h_max]
        self.has_impacts = self.h_max > self.G_delta
        self.H1 = min(self.G_delta, self.h_max)
        self.pieces: list[_UPiece] = []
        if self.levels and self.levels[0] == 0.0:
            self._fit_zero(min(self.levels[1], self.h_max) if len(self.levels) > 1 else self.h_max)
            rest = self.levels[1:]
        else:
            self._fit_low()
            rest = self.levels
        for k, L in enumerate(rest):
            top = rest[k + 1] if k + 1 < len(rest) else self.h_max
            self._fit_high(L, top)
        phi = self.phi_at_G
        for piece in self.pieces:
            if not piece.zero:
                piece.phi_base = phi
            phi = piece.phi_end()
        self.starts = np.array([p.level for p in self.pieces])
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

        f, Hn, vals = _fit_many(self._fitted_quantities, 0.0, H1, {"x2": 0.0})
        self.low = f
        kappa, nu = self._kappa(float(f["g1"](0.0)))
        # Phi_reg(H) = int_0^H (2 m/s2 - kappa/h) dh: fit (g1(h) - kappa)/h on the same nodes
        reg = (vals["g1"] - kappa) / Hn
        self.phi_reg = Cheb(cheb_coefficients(reg), 0.0, H1).antiderivative()
        self.phi_at_G = self.kappa * np.log(H1) + float(self.phi_reg(H1))

    def _fitted_quantities(self, H):
        """The smooth quantities fitted near H = 0 (the diffusion with its power law H**m_exp divided out)."""
        o = self._orbits(H)
        return {
            "logT": np.log(o["T"]),
            "lam": np.log(o["diffusion"]) - self.m_exp * np.log(H),
            "g1": 2.0 * H * o["drift"] / o["diffusion"],
            "x2": o["x2"] / o["T"],
        }

    def _kappa(self, kappa):
        nu = kappa - self.m_exp
        if abs(nu) < 1e-7:  # additive noise: 2 m/s2 ~ 1/H exactly, p(0) finite
            kappa, nu = self.m_exp, 0.0
        self.kappa, self.nu = kappa, nu
        if nu <= -1.0:
            raise NormalisationError(
                f"the density behaves like H**{nu:.3g} at H = 0, which is not integrable: the averaged drift "
                "cannot keep the energy away from 0 (noise vanishing at rest). No stationary density exists"
            )
        return kappa, nu

    def _fit_zero(self, top):
        """The first piece for a wall at the equilibrium: every level is cut, fitted in u = sqrt(H) from 0."""
        U = np.sqrt(top)
        tiny = self._orbits(np.array([1e-7, 2e-7]) * top)["diffusion"]
        self.m_exp = round(2.0 * np.log2(tiny[1] / tiny[0])) / 2.0

        f, un, vals = _fit_many(lambda u: self._fitted_quantities(u * u), 0.0, U, {"x2": 0.0})
        kappa, nu = self._kappa(float(f["g1"](0.0)))
        # Phi_reg = int_0^H (2 m/s2 - kappa/h) dh = int_0^u 2 (g1 - kappa)/u' du'
        phi_reg = Cheb(cheb_coefficients(2.0 * (vals["g1"] - kappa) / un), 0.0, U).antiderivative()
        self.H1 = 0.0
        self.phi_at_G = -np.inf  # no impact-free range
        self.pieces.append(_ZeroPiece(U, f, self.m_exp, kappa, phi_reg))

    def _fit_high(self, level, top):
        U = np.sqrt(top - level)

        def quantities(u):
            o = self._orbits(level + u * u)
            return {
                "logT": np.log(o["T"]),
                "logB": np.log(o["diffusion"]),
                "f2": 4.0 * u * o["drift"] / o["diffusion"],
                "x2": o["x2"] / o["T"],
            }

        f, _, _ = _fit_many(quantities, 0.0, U, {})
        self.pieces.append(_UPiece(level, U, f))

    # ------------------------------------------------------------------ loss drift of a method
    def loss_breakpoints(self, method: ImpactMethod, law) -> list[float]:
        """Energies inside (0, h_max) where the method's loss per quasi-period has a kink."""
        return [h for h in method.loss_breakpoints(law, self.wall_levels) if 0.0 < h < self.h_max]

    def _loss_pieces(self, method: ImpactMethod, law):
        """Cumulative int 2 L / B dH over the impact range, piecewise between levels and kinks of the loss (in u)."""
        key = (method.name, law)  # laws compare by type and parameters (custom callables by identity)
        if key in self._loss_cache:
            return self._loss_cache[key]
        kinks = self.loss_breakpoints(method, law)
        out = []
        total = 0.0
        levels = self.wall_levels
        for piece in self.pieces:
            cuts = [np.sqrt(h - piece.level) for h in kinks if piece.level < h < piece.level + piece.U**2]
            edges = _edges(cuts, piece.U)
            pieces = []
            for a, b in zip(edges[:-1], edges[1:]):
                def integrand(u, piece=piece):
                    with np.errstate(divide="ignore", invalid="ignore"):
                        val = 4.0 * u * method.cycle_loss(law, piece.level + u * u, levels) * np.exp(-piece.log_B(u))
                    return np.where(u > 0, val, 0.0)

                if piece.zero and a == 0.0:
                    probe = integrand(np.array([1e-6, 1e-3]) * b)
                    if probe[0] > 10.0 * probe[1] + 1e-300:
                        raise NormalisationError(
                            "the impact loss at a wall at the equilibrium outweighs the noise near H = 0 (noise "
                            "vanishing at rest): the drift methods have no density there; use --method jump or fpk")
                F = Cheb.fit(integrand, a, b).antiderivative()
                pieces.append((a, b, total, F))
                total += float(F(b))
            out.append(pieces)
        self._loss_cache[key] = out
        return out

    def loss_integral(self, k, u, method, law):
        """int 2 L(h) / B(h) dh from the first impact level to the level u of piece k, for the drift methods."""
        u = np.asarray(u, dtype=float)
        out = np.zeros_like(u)
        pieces = self._loss_pieces(method, law)[k]
        for a, b, base, F in pieces:
            inside = (u >= a) & (u <= b)
            out = np.where(inside, base + F(np.clip(u, a, b)), out)
            out = np.where(u > b, base + float(F(b)), out)
        return out

    # ------------------------------------------------------------------ evaluation
    def _piecewise(self, H, low_fn, piece_fn):
        """``low_fn(H)`` below the first impact level, ``piece_fn(piece, k, u)`` on each piece above it."""
        H = np.asarray(H, dtype=float)
        if np.any(H < 0) or np.any(H > self.h_max * (1 + 1e-12)):
            raise ParameterError(f"energies must lie in [0, h_max={self.h_max:g}]")
        if not self.pieces:
            return low_fn(H)
        out = np.empty_like(H)
        idx = np.searchsorted(self.starts, H, side="left") - 1  # a level itself belongs to the piece below
        if self.pieces[0].zero:
            idx = np.maximum(idx, 0)
        low = idx < 0
        if low.any():
            out[low] = low_fn(H[low])
        for k, piece in enumerate(self.pieces):
            sel = idx == k
            if sel.any():
                out[sel] = piece_fn(piece, k, piece.u(H[sel]))
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
        return self._piecewise(H, lambda h: np.exp(self.low["logT"](h)), lambda p, k, u: p.period(u))

    def diffusion(self, H):
        """sigma2_bar(H) from the table."""
        def low(h):
            with np.errstate(divide="ignore"):
                return np.exp(self.low["lam"](h) - self.low["logT"](h)) * h**self.m_exp

        return self._piecewise(H, low, lambda p, k, u: p.diffusion(u))

    def mean_x2(self, H):
        """<x**2> on the level H."""
        return self._piecewise(H, lambda h: self.low["x2"](h), lambda p, k, u: p.f["x2"](u))

    def impact_rate(self, H):
        """Impacts per unit time on the level H: the walls it hits over T(H).

        Examples
        --------
        >>> from models import ImpactOscillator
        >>> m = ImpactOscillator("x", parameters={"D": 0.1}, barriers=(0, None))
        >>> round(float(EnergyTable(m, 2.0).impact_rate(1.0)), 12) == round(1 / np.pi, 12)   # once per half period
        True
        """
        H = np.asarray(H, dtype=float)
        n = self.geometry.hits(H)
        out = np.zeros_like(H)
        if np.any(n > 0):
            out[n > 0] = n[n > 0] / self.period(H[n > 0])
        return out

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
        if not hasattr(self, "_low_logp") and hasattr(self, "low"):
            self._low_logp = self._sum(self.phi_reg, -1.0 * self.low["lam"], self.low["logT"])

        def low(h):
            with np.errstate(divide="ignore", invalid="ignore"):
                lead = np.where(h > 0, self.nu * np.log(h), 0.0 if self.nu == 0 else (np.inf if self.nu < 0
                                                                                     else -np.inf))
            return lead + self._low_logp(h)

        def high(piece, k, u):
            out = piece.log_p0(u)
            if method is not None and not method.jumps:
                out = out - self.loss_integral(k, u, method, law)
            return out

        return self._piecewise(H, low, high)

    # ------------------------------------------------------------------ quadrature on [0, h_max]
    def quadrature(self, n: int = 160, cuts=()):
        """Nodes and weights for integrals of p(H) over [0, h_max] (the weights carry the H**nu behaviour at 0).

        The impact-free piece uses Gauss-Jacobi with the exact H**nu behaviour at 0; each piece above an impact
        level Gauss-Legendre in its u, split at ``cuts`` (energies where the integrand has a kink). A wall at the
        equilibrium puts the H**nu behaviour into the first u piece (Gauss-Jacobi in u).
        """
        nodes, weights = [], []
        if hasattr(self, "low"):
            t, w = _jacobi(n, self.nu)
            H1 = self.H1
            nodes.append(0.5 * H1 * (t + 1.0))
            # p = H**nu * exp(R): the Jacobi weight carries H**nu; divide it out again below for uniform treatment
            with np.errstate(divide="ignore", invalid="ignore"):
                weights.append(w * (0.5 * H1) ** (self.nu + 1.0) / nodes[-1] ** self.nu)
        tl, wl = _gauss(n)
        for piece in self.pieces:
            inner = [np.sqrt(h - piece.level) for h in cuts if piece.level < h < piece.level + piece.U**2]
            edges = _edges(inner, piece.U)
            for a, b in zip(edges[:-1], edges[1:]):
                if piece.zero and a == 0.0:
                    # p dH = u**(2 nu) exp(R) 2 u du: Jacobi weight u**(2 nu + 1)
                    beta = 2.0 * piece.nu + 1.0
                    t, w = _jacobi(n, beta)
                    u = 0.5 * b * (t + 1.0)
                    nodes.append(u * u)
                    weights.append(2.0 * w * (0.5 * b) ** (beta + 1.0) / u ** (2.0 * piece.nu))
                    continue
                u = 0.5 * (a + b) + 0.5 * (b - a) * tl
                nodes.append(piece.level + u * u)
                weights.append(0.5 * (b - a) * wl * 2.0 * u)
        return np.concatenate(nodes), np.concatenate(weights)
