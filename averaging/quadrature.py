"""Orbit integrals int w(x, s)/s dx over an energy level, without the turning-point singularities.

On a level H the speed s = sqrt(2H - 2G(x)) vanishes at the turning points A- < 0 < A+ (G(A) = H), so the
integrands w/s have inverse-square-root singularities there. With x = c + r sin(theta), c = (A+ + A-)/2,
r = (A+ - A-)/2, the factor r cos(theta)/s is analytic on [-pi/2, pi/2], and Gauss-Legendre in theta converges
exponentially. Above the impact level G(delta) the orbit is cut by the barriers: we keep the same substitution with
the *virtual* turning points beyond the barriers (where G, continued past the barrier, equals H) and integrate theta
only up to arcsin((barrier - c)/r). The integrand stays analytic however close H is to G(delta), so the nearly
singular behaviour at +-delta as H -> G(delta)+ costs nothing. When G cannot be continued to the level H beyond a
barrier, the virtual turning point of its linearisation, delta + (H - G(delta))/g(delta), is used instead.
Each side is cut on its own, so asymmetric walls (two impact levels) and a wall at the equilibrium (every level cut,
the virtual turning point on the far side) use the same nodes.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import ParameterError
from models.levels import solve_level

from .symbolic import averaging_equations, fingerprint

DEFAULT_NODES = 64
"""Gauss-Legendre nodes in theta per level (relative error below 1e-12 for the built-in models)."""

_GL_CACHE: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _gauss(n: int):
    if n not in _GL_CACHE:
        _GL_CACHE[n] = np.polynomial.legendre.leggauss(n)
    return _GL_CACHE[n]


def gauss_jacobi(n: int, alpha: float, beta: float):
    """Nodes and weights of the n-point Gauss-Jacobi rule for the weight (1 - t)**alpha (1 + t)**beta on (-1, 1).

    Golub-Welsch: the eigenvalues of the Jacobi matrix of the monic recurrence are the nodes, the squared first
    components of its eigenvectors times the weight's integral the weights. The same rule as
    ``scipy.special.roots_jacobi`` to about 1e-15 in the nodes and in the integrals (very small weights near an end
    agree to a relative 1e-8 at n = 129, beta = 7.5), without importing scipy.special (0.1-0.2 s of start-up).

    Parameters
    ----------
    n : int
        Number of nodes.
    alpha, beta : float
        Exponents of the weight at t = 1 and t = -1 (each > -1).

    Returns
    -------
    nodes, weights : ndarray
        Increasing nodes in (-1, 1) and their weights (they sum to the weight's integral).

    Examples
    --------
    >>> t, w = gauss_jacobi(6, 0.0, 1.5)
    >>> exact = 2**4.5 / 4.5 - 2 * 2**3.5 / 3.5 + 2**2.5 / 2.5  # int (1 + t)**1.5 t**2 over (-1, 1)
    >>> bool(abs(np.sum(w * t**2) - exact) < 1e-13)
    True
    """
    import math

    ab = alpha + beta
    k = np.arange(1, n, dtype=float)
    diag = np.empty(n)
    diag[0] = (beta - alpha) / (ab + 2.0)
    diag[1:] = (beta * beta - alpha * alpha) / ((2.0 * k + ab) * (2.0 * k + ab + 2.0))
    off = np.sqrt(4.0 * k * (k + alpha) * (k + beta) * (k + ab)
                  / ((2.0 * k + ab) ** 2 * (2.0 * k + ab + 1.0) * (2.0 * k + ab - 1.0)))
    nodes, vectors = np.linalg.eigh(np.diag(diag) + np.diag(off, 1) + np.diag(off, -1))
    mass = 2.0 ** (ab + 1.0) * math.exp(math.lgamma(alpha + 1.0) + math.lgamma(beta + 1.0) - math.lgamma(ab + 2.0))
    return nodes, mass * vectors[0] ** 2


class Geometry:
    """The potential G, the force g, the walls and their impact levels of a model at its parameter values (numpy).

    ``wall_levels`` has one energy per finite wall, ``levels`` the distinct ones in increasing order (one for a
    symmetric gap or a single wall, two for asymmetric walls), ``G_delta`` the lowest (0 for a wall at the
    equilibrium, inf without walls).

    Cached per symbolic declaration and parameter values, so that repeated averaging does not touch sympy.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> geo = geometry(DuffingImpact())
    >>> round(geo.G_delta, 12), geo.barriers, geo.walls, geo.levels
    (0.55, (-1.0, 1.0), 2, (0.55,))
    """

    def __init__(self, model):
        ker = averaging_equations(model).potential_kernels
        if ker is None:
            # no closed form: G(x) = x * int_0^1 g(x t) dt by 48-point Gauss-Legendre (vectorised, no cancellation
            # near x = 0, exact for polynomials of degree < 96)
            t, w = _gauss(48)
            t, w = 0.5 * (t + 1.0), 0.5 * w
            g = model.restoring

            def G(x):
                x = np.asarray(x, dtype=float)
                return x * np.sum(g(x[..., None] * t) * w, axis=-1)

            self._G, self._g = G, g
        else:
            Gf, gf, names = ker
            vals = [model.params[k] for k in names]
            self._G = lambda x: np.asarray(Gf(x, *vals), dtype=float) + 0.0 * np.asarray(x, dtype=float)
            self._g = lambda x: np.asarray(gf(x, *vals), dtype=float) + 0.0 * np.asarray(x, dtype=float)
        self.barriers = tuple(float(b) for b in model.barriers)
        left, right = self.barriers
        # one entry per finite wall: the energy above which a level hits it, once per quasi-period
        self.wall_levels = tuple(float(self._G(np.array([b]))[0]) for b in (left, right) if np.isfinite(b))
        self.walls = len(self.wall_levels)
        lv = sorted(self.wall_levels)
        if len(lv) == 2 and abs(lv[0] - lv[1]) <= 1e-12 * max(1.0, abs(lv[1])):
            lv = [lv[1]]  # symmetric: both walls start at one level
            self.wall_levels = (lv[0], lv[0])
        self.levels = tuple(lv)
        """Distinct impact levels, increasing: the energies where a wall starts being hit (kinks of T(H))."""
        self.symmetric = len(self.levels) == 1 and self.walls == 2
        self.G_delta = self.levels[0] if self.levels else float("inf")
        """The lowest impact level: no impacts below it (0 for a wall at the equilibrium)."""
        self.has_barriers = bool(np.isfinite(self.G_delta))

    def hits(self, H) -> np.ndarray:
        """How many walls a level H hits per quasi-period (0, 1 or 2).

        Examples
        --------
        >>> from models import ImpactOscillator
        >>> geometry(ImpactOscillator("x", parameters={"D": 0.1}, barriers=(-0.5, 1.0))).hits([0.1, 0.2, 0.6])
        array([0, 1, 2])
        """
        H = np.asarray(H, dtype=float)
        return sum((H > g).astype(int) for g in self.wall_levels) + np.zeros(H.shape, dtype=int)

    def potential(self, x):
        """G(x)."""
        return self._G(x)

    def restoring(self, x):
        """g(x)."""
        return self._g(x)


_GEOMETRY: dict = {}


def geometry(model) -> Geometry:
    """The cached :class:`Geometry` of ``model`` (keyed by declaration and parameter values)."""
    key = (fingerprint(model), tuple(sorted(model.params.items())), model.barrier_exprs is None)
    geo = _GEOMETRY.get(key)
    if geo is None:
        if len(_GEOMETRY) > 64:
            _GEOMETRY.clear()
        geo = _GEOMETRY[key] = Geometry(model)
    return geo


def turning_points(model, H):
    """Turning points (A-, A+) with G(A) = H on each side of 0, continued beyond the barriers for H > G(delta).

    Parameters
    ----------
    model : ImpactOscillator
    H : array_like
        Energies > 0.

    Returns
    -------
    (ndarray, ndarray)
        A- < 0 < A+. Beyond a barrier where G does not reach H the linearised virtual point is returned.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> [round(float(v[0]), 12) for v in turning_points(DuffingImpact(), 0.55)]
    [-1.0, 1.0]
    """
    H = np.atleast_1d(np.asarray(H, dtype=float))
    geo = geometry(model)
    left, right = geo.barriers
    out = []
    for sign, bound in ((-1.0, left), (+1.0, right)):
        z, missing = solve_level(geo.potential, geo.restoring, H, sign, 0.0)
        if np.isfinite(bound) and missing.any():
            b = abs(bound)
            Gb = float(geo.potential(sign * b))
            gb = float(sign * geo.restoring(sign * b))
            lin = b + (H - Gb) / gb
            z = np.where(missing & (H > Gb), lin, z)
            missing = missing & ~(H > Gb)
        if missing.any():
            raise ParameterError(
                f"energy H={H[missing][0]:.6g} is above the potential everywhere on the "
                f"{'left' if sign < 0 else 'right'}: the orbit is not closed (no turning point)"
            )
        out.append(sign * z)
    return out[0], out[1]


class OrbitNodes:
    """Quadrature nodes on the energy levels ``H``: positions x, speeds s and weights for int w/s dx.

    ``integral(w)`` returns int w(x, s)/s dx over the part of each level inside the barriers.

    Examples
    --------
    >>> import numpy as np
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", parameters={"D": 0.0}, barriers=None)
    >>> nodes = OrbitNodes(lin, np.array([0.5, 2.0]))
    >>> np.round(nodes.integral(2.0) / (2 * np.pi), 12).tolist()    # T = 2 pi for a unit linear spring
    [1.0, 1.0]
    """

    def __init__(self, model, H, nodes: int = DEFAULT_NODES):
        H = np.atleast_1d(np.asarray(H, dtype=float))
        if H.ndim != 1:
            raise ParameterError("energies H must be a 1-D array")
        if not np.all(np.isfinite(H)) or np.any(H <= 0):
            bad = H[~(np.isfinite(H) & (H > 0))][0]
            raise ParameterError(f"orbit integrals need finite energies H > 0, got H={float(bad)!r}")
        self.H = H
        geo = geometry(model)
        lo, hi = turning_points(model, H)
        c = 0.5 * (hi + lo)
        r = 0.5 * (hi - lo)
        left, right = geo.barriers
        # theta in [-pi/2 + gap_lo, pi/2 - gap_hi]; the gaps are nonzero where a barrier cuts the orbit. Angles are
        # measured from the nearer end (phi) so that cos(theta) and |A - x| keep full relative precision there.
        gap_hi = np.where(hi > right, np.arccos(np.clip((right - c) / r, -1, 1)), 0.0)
        gap_lo = np.where(lo < left, np.arccos(np.clip((c - left) / r, -1, 1)), 0.0)
        t, w = _gauss(nodes)
        half = 0.5 * (np.pi - gap_hi - gap_lo)
        phi_hi = gap_hi[:, None] + half[:, None] * (1.0 - t[None, :])  # pi/2 - theta
        phi_lo = gap_lo[:, None] + half[:, None] * (1.0 + t[None, :])  # theta + pi/2
        upper = phi_hi <= phi_lo
        phi = np.where(upper, phi_hi, phi_lo)
        cos_theta = np.sin(phi)
        dist = 2.0 * r[:, None] * np.sin(0.5 * phi) ** 2  # |A - x| to the nearer turning point
        A = np.where(upper, hi[:, None], lo[:, None])
        x = np.where(upper, A - dist, A + dist)
        s2 = 2.0 * (H[:, None] - geo.potential(x))
        # Near a turning point H - G(x) cancels: there use G(A) - G(x) = |A - x| * |mean of g between x and A|
        # (8-point Gauss on a short interval) plus the tiny residual H - G(A) of the root finder.
        near = s2 < 0.5 * H[:, None]
        if near.any():
            rows, cols = np.nonzero(near)
            xs, As = x[rows, cols], A[rows, cols]
            tg, wg = _gauss(8)
            tg, wg = 0.5 * (tg + 1.0), 0.5 * wg
            pts = xs[:, None] + (As - xs)[:, None] * tg[None, :]
            mean_g = np.abs(np.sum(geo.restoring(pts) * wg, axis=1))
            s2[rows, cols] = 2.0 * ((H[rows] - geo.potential(As)) + dist[rows, cols] * mean_g)
        # rounding can still leave s2 <= 0 at a node next to a turning point: use the local linearisation there
        lin = 2.0 * np.abs(geo.restoring(A)) * dist
        s2 = np.where(s2 > 0, s2, np.maximum(lin, 1e-300))
        self.x = x
        self.s = np.sqrt(s2)
        # int w/s dx = int w * (r cos(theta)/s) dtheta
        self.weights = (w[None, :] * half[:, None]) * (r[:, None] * cos_theta) / self.s
        self.impacts = (lo < left) | (hi > right)
        self.model = model

    def integral(self, w) -> np.ndarray:
        """int w(x, s)/s dx for each level; ``w`` is an array broadcastable to the nodes, or a number."""
        return np.sum(np.broadcast_to(w, self.weights.shape) * self.weights, axis=1)


def orbit_integrals(model, H, nodes: int = DEFAULT_NODES) -> dict[str, np.ndarray]:
    """Period, averaged-coefficient integrals, action and <x**2> numerators on the levels ``H``.

    Parameters
    ----------
    model : ImpactOscillator
    H : array_like
        Energies > 0.
    nodes : int
        Gauss-Legendre nodes per level.

    Returns
    -------
    dict
        ``T`` = int 2/s dx (period, eqs. 23/26), ``drift`` = T * m_bar without the impact loss,
        ``diffusion`` = T * sigma2_bar, ``action`` = loop integral of y dx = 2 int s dx, ``x2`` = T <x**2>.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.05}, barriers=None)
    >>> out = orbit_integrals(lin, [1.0])
    >>> round(float(out["action"][0] / (2 * 3.141592653589793)), 12)   # area pi*A**2 = 2 pi H
    1.0
    """
    H = np.atleast_1d(np.asarray(H, dtype=float))
    orb = OrbitNodes(model, H, nodes)
    ker = averaging_equations(model).kernels
    params = dict(model.params)
    return {
        "T": orb.integral(2.0),
        "drift": orb.integral(ker("drift", orb.x, orb.s, params)),
        "diffusion": orb.integral(ker("diffusion", orb.x, orb.s, params)),
        "action": orb.integral(2.0 * orb.s**2),
        "x2": orb.integral(2.0 * orb.x**2),
        "impacts": orb.impacts,
    }


def period(model, H, nodes: int = DEFAULT_NODES) -> np.ndarray:
    """T(H): the free period (eq. 8/23) below G(delta), the quasi-period (eqs. 14/26) above.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", parameters={"D": 0.0}, barriers=None)
    >>> bool(abs(period(lin, 0.3)[0] - 2 * np.pi) < 1e-11)
    True
    """
    return OrbitNodes(model, H, nodes).integral(2.0)


def action(model, H, nodes: int = DEFAULT_NODES) -> np.ndarray:
    """The loop action: the integral of y dx around the level H (= 2 int s dx), cut by the barriers.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", parameters={"D": 0.0}, barriers=None)
    >>> bool(abs(action(lin, 0.5)[0] - np.pi) < 1e-11)
    True
    """
    orb = OrbitNodes(model, H, nodes)
    return orb.integral(2.0 * orb.s**2)
