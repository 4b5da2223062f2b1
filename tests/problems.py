"""Problems with known answers, shared by the test modules (independent oracles, not the code's own output).

Every oracle here is computed from a closed form or with mpmath / plain scipy quadrature, independently of the
framework's averaging and simulation code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mpmath as mp
import numpy as np
import sympy as sp
from scipy import integrate

from hybrid import HybridAutomaton, Mode, Transition
from models import DuffingImpact, Elastic, ImpactOscillator, Ma, Newton

# ----------------------------------------------------------------------------- free orbits

def energy_loss_per_impact(e: float, H_minus: float, G_delta: float) -> float:
    """Eq. 11: delta H = (1 - e**2)(H_minus - G(delta))."""
    return (1.0 - e * e) * (H_minus - G_delta)


def exact_two_impact_loss(law, H_minus: float, G_delta: float) -> float:
    """Loss over two successive free impacts: (1 - e1**2 e2**2)(H - G), e2 = e(e1 v) (docs/paper-readings.md)."""
    v = math.sqrt(2.0 * (H_minus - G_delta))
    e1 = float(law.coefficient(v))
    e2 = float(law.coefficient(e1 * v))
    return (1.0 - e1 * e1 * e2 * e2) * (H_minus - G_delta)


def paper_two_impact_loss(law, H_minus: float, G_delta: float) -> float:
    """Eq. 13 as printed: (1 - e**4)(H - G), the same e at both barriers."""
    v = math.sqrt(2.0 * (H_minus - G_delta))
    e = float(law.coefficient(v))
    return (1.0 - e**4) * (H_minus - G_delta)


def duffing_potential(x, a=1.0, b=0.2):
    """G(x) = a x**2/2 + b x**4/4."""
    return 0.5 * a * x * x + 0.25 * b * x**4


def period_mpmath(G, H: float, lo: float, hi: float, dps: int = 30) -> float:
    """2 * int_lo^hi dx / sqrt(2H - 2G(x)) with mpmath tanh-sinh (handles the endpoint singularities)."""
    with mp.workdps(dps):
        def f(x):
            gap = 2 * mp.mpf(H) - 2 * G(x)
            return 1 / mp.sqrt(gap) if gap > 0 else mp.mpf(0)  # a root found 1 ulp outside the well

        return float(2 * mp.quad(f, [lo, hi]))


def action_mpmath(G, H: float, lo: float, hi: float, dps: int = 30) -> float:
    """int_lo^hi sqrt(2H - 2G(x)) dx with mpmath."""
    with mp.workdps(dps):
        f = lambda x: mp.sqrt(max(2 * mp.mpf(H) - 2 * G(x), 0))  # noqa: E731
        return float(mp.quad(f, [lo, hi]))


def duffing_period(H: float, a=1.0, b=0.2, delta=math.inf) -> float:
    """Free period (eq. 8) or quasi-period (eq. 14) of the Duffing oscillator, by mpmath."""
    A = math.sqrt((math.sqrt(a * a + 4 * b * H) - a) / b) if b > 0 else math.sqrt(2 * H / a)
    if A < delta:  # free orbit: the turning point must be exact, so integrate in theta (x = A sin theta)
        return duffing_free_period_mp(H, a, b)
    lim = delta
    G = lambda x: a * x * x / 2 + b * x**4 / 4  # noqa: E731
    return period_mpmath(G, H, -lim, lim)


# ----------------------------------------------------------------------------- elastic stationary densities

@dataclass(frozen=True)
class ElasticStationary:
    """Exact stationary statistics of x'' + c x' + g(x) = sqrt(2D) xi between elastic barriers at +-delta.

    p(x, y) is proportional to exp(-c H / D) on |x| < delta, so p(x) ~ exp(-c G(x)/D) and y ~ N(0, D/c).
    """

    G: callable  # numpy-callable potential
    c: float
    D: float
    delta: float

    @property
    def beta(self) -> float:
        return self.c / self.D

    def _z(self) -> float:
        return integrate.quad(lambda x: math.exp(-self.beta * self.G(x)), -self.delta, self.delta,
                              epsabs=0, epsrel=1e-13)[0]

    def mean_x2(self) -> float:
        """E[x**2]."""
        num = integrate.quad(lambda x: x * x * math.exp(-self.beta * self.G(x)), -self.delta, self.delta,
                             epsabs=0, epsrel=1e-13)[0]
        return num / self._z()

    def mean_y2(self) -> float:
        """E[y**2] = D / c."""
        return self.D / self.c

    def marginal_x(self, x):
        """p(x) on |x| < delta."""
        x = np.asarray(x, dtype=float)
        return np.where(np.abs(x) <= self.delta, np.exp(-self.beta * self.G(x)) / self._z(), 0.0)

    def impact_rate_per_wall(self) -> float:
        """p_x(delta) * E[y; y > 0] = p_x(delta) * sqrt(D / (2 pi c)) (Rice's formula)."""
        return float(self.marginal_x(self.delta)) * math.sqrt(self.D / (2 * math.pi * self.c))

    def energy_density(self, H, G_delta: float | None = None):
        """p(H) proportional to T(H) exp(-c H / D), normalised on [0, inf); T by mpmath per point."""
        H = np.atleast_1d(np.asarray(H, dtype=float))
        Gd = self.G(self.delta) if G_delta is None else G_delta
        out = np.empty_like(H)
        for i, h in enumerate(H):
            if h <= 0:
                out[i] = 0.0
                continue
            lim = self.delta if h >= Gd else _level(self.G, h, self.delta)
            out[i] = period_mpmath(self.G, h, -lim, lim, dps=20) * math.exp(-self.beta * h)
        # normalisation: int T(H) e^{-beta H} dH = 2 * int int e^{-beta H} dy dx = 2*Z*sqrt(2 pi / beta)/... :
        # int dx dy e^{-beta(y^2/2+G)} = Z * sqrt(2 pi / beta); and dx dy = T(H)/... so int T e^{-bH} dH = that.
        norm = self._z() * math.sqrt(2 * math.pi / self.beta)
        return out / norm

    def probability_below(self, level: float) -> float:
        """P(H < level), by quadrature of the exact joint density."""
        def inner(x):
            gap = level - self.G(x)
            if gap <= 0:
                return 0.0
            ymax = math.sqrt(2 * gap)
            return math.exp(-self.beta * self.G(x)) * math.erf(ymax * math.sqrt(self.beta / 2))
        num = integrate.quad(inner, -self.delta, self.delta, epsabs=0, epsrel=1e-12, limit=200)[0]
        return num / self._z()


def _level(G, H, hi):
    """Positive root of G(x) = H below hi (G increasing on [0, hi])."""
    from scipy.optimize import brentq

    return brentq(lambda x: G(x) - H, 0.0, hi * (1 + 1e-12) + 1e-300, xtol=1e-15, rtol=4 * np.finfo(float).eps)


def elastic_duffing(delta=1.0, a=1.0, b=0.2, c=0.025, D=0.05) -> tuple[ImpactOscillator, ElasticStationary]:
    """Example 1 with elastic barriers, and its exact stationary statistics."""
    model = DuffingImpact(restitution=Elastic(), a=a, b=b, c=c, D=D, delta=delta)
    return model, ElasticStationary(lambda x: duffing_potential(x, a, b), c, D, delta)


def linear_oscillator_energy_density(H, c: float, D: float):
    """Linear oscillator without barriers, h = c y, f = 1: p(H) = (c/D) exp(-c H / D)."""
    H = np.asarray(H, dtype=float)
    return (c / D) * np.exp(-c * H / D)


def forced_linear_energy_masses(response: complex, omega: float, c: float, D: float, t: float, edges) -> np.ndarray:
    """Exact masses of p(H | t) on ``edges`` for x'' + c x' + x = Re(F e^{i omega t}) + sqrt(2 D) xi, without walls:
    the section at t is Gaussian with mean the periodic response (``response`` = F / (1 - omega^2 + i c omega)) and
    covariance D/c I, so 2 H c / D is noncentral chi-square with 2 degrees of freedom."""
    from scipy.stats import ncx2

    xp, yp = (response * np.exp(1j * omega * t)).real, (1j * omega * response * np.exp(1j * omega * t)).real
    return np.diff(ncx2.cdf(2.0 * np.asarray(edges) * c / D, 2, (xp**2 + yp**2) * c / D))


def ou_stationary_variance(c: float, D: float) -> float:
    """dv = -c v dt + sqrt(2D) dB: stationary variance D / c."""
    return D / c


# ----------------------------------------------------------------------------- bouncing ball (Zeno)

def bouncing_ball(r: float = 0.8, gravity: float = 9.81) -> HybridAutomaton:
    """A ball over a floor at x = 0: x' = v, v' = -g, reset v -> -r v at x = 0 going down."""
    x, v = sp.symbols("x v")
    g, rr = sp.symbols("g r")
    return HybridAutomaton(
        states=(x, v), parameters={"g": gravity, "r": r},
        modes=[Mode("air", (v, -g))],
        transitions=[Transition("floor", "air", "air", guard=x, direction=-1, reset=(x, -rr * v))],
    )


def bouncing_ball_zeno_time(v0: float, r: float, gravity: float = 9.81) -> float:
    """Launched upwards from the floor at speed v0: impacts at 2 v0 r^k / g; they accumulate at 2 v0 / (g (1 - r))."""
    return 2.0 * v0 / (gravity * (1.0 - r))


def bouncing_ball_impact_times(v0: float, r: float, n: int, gravity: float = 9.81) -> np.ndarray:
    """The first n impact times of the ball launched upwards from x = 0 at speed v0 (a geometric series)."""
    k = np.arange(1, n + 1)
    return 2.0 * v0 / gravity * (1.0 - r**k) / (1.0 - r)


__all__ = [
    "ElasticStationary", "Ma", "Newton", "action_mpmath", "bouncing_ball", "bouncing_ball_impact_times",
    "bouncing_ball_zeno_time", "duffing_period", "duffing_potential", "elastic_duffing", "energy_loss_per_impact",
    "exact_two_impact_loss", "linear_oscillator_energy_density", "ou_stationary_variance",
    "paper_two_impact_loss", "period_mpmath",
]


# ----------------------------------------------------------------------------- added for issue 2 (orbits)

def duffing_free_period_mp(H: float, a: float = 1.0, b: float = 0.2, dps: int = 40) -> float:
    """Free period (eq. 8, no barriers) of the Duffing oscillator to full double precision.

    The turning point A is computed in mpmath precision; with x = A sin(theta),
    2H - 2G(x) = cos(theta)**2 * (a A**2 + b A**4 (1 + sin(theta)**2) / 2), so the integrand has no singularity.
    ``duffing_period`` takes A in double precision, which costs ~1e-8 relative through the 1/sqrt singularity.
    """
    with mp.workdps(dps):
        H, a, b = mp.mpf(H), mp.mpf(a), mp.mpf(b)
        A = mp.sqrt((mp.sqrt(a * a + 4 * b * H) - a) / b) if b > 0 else mp.sqrt(2 * H / a)
        f = lambda th: 1 / mp.sqrt(a + b * A * A * (1 + mp.sin(th) ** 2) / 2)  # noqa: E731
        return float(4 * mp.quad(f, [0, mp.pi / 2]))


# ----------------------------------------------------------------------------- added for issue 26 (rare events)

def euler_ou_exceedance(b: float, *, theta: float = 1.0, s: float = math.sqrt(2.0), dt: float = 0.01,
                        steps: int = 100, x0: float = 0.0, per_sigma: int = 20, low: float = -6.0) -> float:
    """P(max_{1 <= k <= steps} x_k >= b) for the Euler chain x_{k+1} = (1 - theta dt) x_k + s sqrt(dt) Z_k.

    This is the exact exceedance of the simulated process (Euler-Maruyama of dx = -theta x dt + s dW, the level
    read at step ends), not of the diffusion. The density of the paths still below b, u_k, is carried on the nodes
    of [low, b] (spacing sigma / per_sigma, sigma = s sqrt(dt), composite Simpson); each step adds
    int u_k(x) P(x_{k+1} >= b | x) dx, so the probability is summed, never taken as 1 - survival (no cancellation
    at 1e-9). At per_sigma = 20 and 40 the answers at P = 1e-3, 1e-6 and 1e-9 agree to 3e-8 relative; the mass
    below ``low`` (the stationary N(0, s^2 / 2 theta) puts 1e-9 there at the defaults) hardly reaches b in time.
    """
    from scipy.stats import norm

    a, sigma = 1.0 - theta * dt, s * math.sqrt(dt)
    h = sigma / per_sigma
    m = int(math.ceil((b - low) / h))
    m += m % 2
    x = b - h * np.arange(m + 1)[::-1]  # nodes; the last is b
    w = np.full(m + 1, 2 * h / 3)
    w[1::2], w[0], w[-1] = 4 * h / 3, h / 3, h / 3
    kernel = norm.pdf((x[:, None] - a * x[None, :]) / sigma) / sigma  # kernel[y, x]: density of x_{k+1} = y
    escape = norm.sf((b - a * x) / sigma)
    u = norm.pdf((x - a * x0) / sigma) / sigma
    p = float(norm.sf((b - a * x0) / sigma))
    for _ in range(steps - 1):
        p += float(np.dot(w * u, escape))
        u = kernel @ (w * u)
    return p
