r"""The impact-to-impact chain: impacts at the end of each flight, not at Poisson times (method ``chain``).

The ``jump`` method lets impacts arrive as a Poisson clock at rate walls/T(H). Real impacts come once per flight:
after an impact the orbit needs T(H)/walls (the time from one wall to the other, or back to the same wall) before
the next. This module keeps the averaged drift and diffusion of H during the flight and gives the flight its
duration:

* Energy: the conservative no-loss chain of :mod:`averaging.jump` (rates from the exact no-loss density p0 of
  eq. 30, so that without impacts the stationary law is p0 exactly) on a grid of n energies.
* Flight: a clock with K phases advanced at rate K walls/T(H), i.e. a short-time transition kernel over one flight
  whose duration is Erlang(K) with mean T(H)/walls and relative spread 1/sqrt(K) (K -> infinity: the exact flight
  time; K = 1 gives back the Poisson clock of ``jump``). While H < G(delta) the clock turns but its wrap causes no
  impact (the orbit does not reach a wall), so after the energy rises past G(delta) the first impact comes after
  part of a flight.
* Impact: when the clock wraps at H > G(delta), the energy jumps exactly to H' = G + e(v)**2 (H - G),
  v = sqrt(2 (H - G)), its mass split linearly between the two nodes around H' (keeps the mean).

The energies at successive impacts form a Markov chain whose transition kernel is the flight above followed by the
impact map; the time-average density is the renewal-reward average of the flights (occupation of each energy
during a flight, weighted by how often flights start there). Both are read off the stationary vector of the
(n K)-state generator, solved by one sparse LU: its H-marginal is the time average (``p``), and the probability
flux through the wraps above G(delta) is the stationary law of the pre-impact energy (``impact_energy_density``)
with total rate ``impact_rate`` = 1 / (mean flight duration).

With elastic impacts the wraps do not move mass and the stationary vector is p0 uniform over the phases: the
chain reproduces the exact elastic density (``tests/test_chain.py``).

Geometries: as the averaging methods, every wall geometry of the model. A level H hits each wall whose energy G_w
it exceeds once per quasi-period, so the flight is T(H)/hits(H). One impact level (a symmetric gap, a one-sided
stop, a stop at the equilibrium, where every orbit is hit at its highest speed once per half period): the wrap
applies that level's impact map. Two levels (an asymmetric gap): the state also remembers which wall comes next;
between the levels only the lower wall is hit, above both the walls alternate, each with its own impact map.

Examples
--------
>>> from models import DuffingImpact, Ma
>>> sd = chain_density(DuffingImpact(restitution=Ma(0.4)), h_max=4.0)
>>> sd.method, round(sd.mean_energy, 3)     # Monte Carlo: 0.502 +- 0.002; jump 0.516
('chain', 0.501)
"""

from __future__ import annotations

import math

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu

from hybrid.errors import NormalisationError, ParameterError

from .jump import EnergyChain
from .methods import ImpactMethod
from .quadrature import DEFAULT_NODES, geometry
from .stationary import (
    _LOG_DROP,
    StationaryDensity,
    _check_scale,
    _mass_range,
    check_confinement,
    check_energy_range,
    energy_table,
    output_grid,
)

DEFAULT_PHASES = 8
"""Clock phases per flight (relative spread of the flight time 1/sqrt(8) = 0.35; extrapolated with 4)."""
DEFAULT_ENERGIES = 400
"""Energy nodes of the chain (L1 changes by < 1e-4 from 300 to 1200 on the paper's cases)."""


_MAX_STATES = 2_000_000


class _NoLoss(ImpactMethod):
    """The energy part of the chain: no loss drift and no jumps (the impacts are added by the clock)."""

    name = "chain"
    jumps = True
    description = "impact-to-impact chain: flights of duration T(H)/hits(H), exact impact map at each wrap"

    def jump_target(self, law, excess):
        return np.asarray(excess, dtype=float)


_NO_LOSS = _NoLoss()


class ChainDensity(StationaryDensity):
    """p(H) of the impact-to-impact chain (a :class:`~averaging.StationaryDensity`), with the impact statistics.

    Attributes
    ----------
    phases : int
        Clock phases per flight.
    impact_rate : float
        Impacts per unit time (the wrap flux above the impact level).
    impact_energy_H, impact_energy_density : ndarray
        Energies and the stationary density of the pre-impact energy (the embedded chain's law).

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> sd = chain_density(DuffingImpact(restitution=Ma(0.4)), h_max=4.0)
    >>> bool(abs(np.trapezoid(sd.impact_energy_density, sd.impact_energy_H) - 1) < 1e-9)
    True
    """

    def metadata(self) -> dict:
        out = super().metadata()
        out["phases"] = self.phases
        return out


def chain_generator(chain: EnergyChain, period, wall_levels, law, phases: int):
    """Sparse generator of the (energy node, next wall, clock phase) chain.

    Parameters
    ----------
    chain : EnergyChain
        The no-loss energy chain (no jumps).
    period : ndarray
        T(H) at each node.
    wall_levels : sequence of float
        One impact energy per wall (``Geometry.wall_levels``).
    law : RestitutionLaw
    phases : int

    Returns
    -------
    (scipy.sparse.csr_matrix, ndarray, ndarray, int)
        Q (states ordered (i * walls_tracked + w) * phases + k), the impacting wraps (source state, rate) used for
        the impact flux, and the number of next-wall states per node (1 with one impact level, 2 with two).

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> from averaging.stationary import energy_table
    >>> m = DuffingImpact(restitution=Elastic())
    >>> tab = energy_table(m, 4.0)
    >>> ch = EnergyChain(tab, np.linspace(0, 4, 41), _NO_LOSS, m.restitution)
    >>> Q, *_ = chain_generator(ch, tab.period(ch.grid), tab.geometry.wall_levels, m.restitution, 4)
    >>> bool(abs(Q.sum(axis=1)).max() < 1e-9)
    True
    """
    grid = chain.grid
    n, K = len(grid), int(phases)
    levels = sorted(set(float(v) for v in wall_levels))
    nw = len(levels)  # 1: every wall at one level; 2: asymmetric, the state remembers the next wall
    hits = sum((grid > g).astype(int) for g in wall_levels)
    rate = K * np.where(hits > 0, hits, len(wall_levels)) / np.asarray(period, dtype=float)
    Q0 = chain.generator().tocoo()
    off = Q0.row != Q0.col
    layers = nw * K
    rows = [(Q0.row[off, None] * layers + np.arange(layers)).ravel()]
    cols = [(Q0.col[off, None] * layers + np.arange(layers)).ravel()]
    vals = [np.repeat(Q0.data[off], layers)]
    i = np.arange(n)

    def state(node, w, k):
        return (node * nw + w) * K + k

    if K > 1:  # phase k -> k + 1
        k = np.arange(K - 1)
        for w in range(nw):
            rows.append(state(i[:, None], w, k).ravel())
            cols.append(state(i[:, None], w, k + 1).ravel())
            vals.append(np.repeat(rate, K - 1))
    w_src, w_rate = [], []

    def impact(src, w_from, level, w_to):
        """Wraps of the nodes ``src`` in next-wall state ``w_from``: impact at ``level``, next wall ``w_to``."""
        excess = grid[src] - level
        after = level + (excess - law.impact_loss(excess))
        j = np.clip(np.searchsorted(grid, after, side="right") - 1, 0, n - 2)
        theta = np.clip((after - grid[j]) / (grid[j + 1] - grid[j]), 0.0, 1.0)
        for dst, wt in ((j, 1.0 - theta), (j + 1, theta)):
            r = rate[src] * wt
            keep = r > 0
            rows.append(state(src[keep], w_from, K - 1))
            cols.append(state(dst[keep], w_to, 0))
            vals.append(r[keep])
            w_src.append(state(src[keep], w_from, K - 1))
            w_rate.append(r[keep])

    quiet = i[hits == 0]
    for w in range(nw):  # below every level the clock turns without an impact
        rows.append(state(quiet, w, K - 1))
        cols.append(state(quiet, w, 0))
        vals.append(rate[quiet])
    if nw == 1:
        impact(i[hits > 0], 0, levels[0], 0)
    else:  # w = 0: the lower wall comes next, w = 1: the upper one
        one, two = i[hits == 1], i[hits == 2]
        for w in range(2):
            impact(one, w, levels[0], 1)  # only the lower wall is reached; then the orbit heads to the other side
            impact(two, w, levels[w], 1 - w)
    r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    move = r != c
    N = n * layers
    Q = sparse.coo_matrix((v[move], (r[move], c[move])), shape=(N, N)).tocsr()
    Q = Q - sparse.diags(np.asarray(Q.sum(axis=1)).ravel())
    return Q.tocsr(), np.concatenate(w_src), np.concatenate(w_rate), nw


def _stationary(Q) -> np.ndarray:
    """pi with pi Q = 0, sum 1: one sparse LU of Q^T with the last equation replaced by the normalisation."""
    N = Q.shape[0]
    A = Q.T.tolil()
    A[N - 1, :] = np.ones(N)
    b = np.zeros(N)
    b[N - 1] = 1.0
    lu = splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A")
    pi = lu.solve(b)
    if not np.all(np.isfinite(pi)):
        raise NormalisationError("the impact-to-impact chain has no stationary law (singular generator)")
    pi = np.maximum(pi, 0.0)  # round-off negatives of order 1e-16 in the far tail
    return pi / pi.sum()


def _solve_chain(ch, period, wall_levels, law, phases):
    """(mass per energy node, impact flux per pre-impact node) of the stationary chain with ``phases`` phases."""
    n = len(ch.grid)
    Q, w_src, w_rate, nw = chain_generator(ch, period, wall_levels, law, phases)
    pi = _stationary(Q)
    mass = pi.reshape(n, nw * phases).sum(axis=1)
    flux = np.bincount(w_src // (nw * phases), pi[w_src] * w_rate, minlength=n)
    return mass, flux


EXTRAPOLATE_BLEND = (0.5, 0.95)
"""Relative corrections |a - a_half| / a between which :func:`_extrapolate` passes from the linear Richardson
extrapolation (exact for an error b/K of the values; at a stop at the equilibrium with r = 0.6 the closed form of
E[H] is met to 0.24 % with it, 1.1 % with the logarithmic one, 0.43 % with this blend) to the logarithmic one (for
an error b/K of the decay rate, in the tail; Fig. 2's chain/fpk at H = 3.0, 3.5, 3.8 is 0.90, 1.55, 1.97)."""


def _extrapolate(a, a_half):
    """Richardson in the phases, node by node: 2 a - a_half where the correction is small, exp(2 log a - log
    a_half) where it is large (the tail), blended linearly in between (:data:`EXTRAPOLATE_BLEND`); positive
    wherever a and a_half are (0 where either is 0)."""
    ok = (a > 0) & (a_half > 0)
    safe_a = np.where(ok, a, 1.0)
    x = (a - a_half) / safe_a  # the linear correction relative to a
    lo, hi = EXTRAPOLATE_BLEND
    w = np.clip((np.abs(x) - lo) / (hi - lo), 0.0, 1.0)
    with np.errstate(over="ignore"):
        log_ext = safe_a / np.where(ok, a_half, 1.0) * safe_a
    lin = 2.0 * a - a_half
    return np.where(ok, np.where(w > 0, (1.0 - w) * np.maximum(lin, 0.0) + w * log_ext, lin), 0.0)


def _chain_on(model, h: float, n: int, nodes: int, law, geo, phases: int, extrapolate: bool):
    """The chain on ``n`` energies of [0, h]: (table, grid, EnergyChain, node masses, wrap flux, flux ratio)."""
    tab = energy_table(model, h, nodes)
    grid = np.linspace(0.0, h, n)
    ch = EnergyChain(tab, grid, _NO_LOSS, law)
    if geo.walls > 0:
        period = tab.period(grid)
        mass, flux = _solve_chain(ch, period, geo.wall_levels, law, phases)
        if extrapolate:
            # the error of the flight-time spread is ~ b/K: Richardson with K/2 removes it. On the values where the
            # correction is small; in the tail, where p falls exponentially and the K/2 chain's tail is the heavier,
            # 2 m - m2 turns negative (clipped at 0 it wrote p = 0 above H = 3.5 at Fig. 2's defaults, where fpk has
            # 1.2e-5), so there on the logarithm (the decay rate): see _extrapolate
            m2, f2 = _solve_chain(ch, period, geo.wall_levels, law, phases // 2)
            mass = _extrapolate(mass, m2)
            flux = _extrapolate(flux, f2)
            mass /= mass.sum()
        # wrap flux relative to a uniform clock (1 with elastic impacts), for the impact rate by quadrature
        uniform = mass * tab.impact_rate(grid)
        ok = uniform > 0
        ratio = np.where(ok, flux / np.where(ok, uniform, 1.0), 0.0)
        if ok.any():  # the cell across the lowest impact level takes the value of its upper node
            first = int(np.argmax(ok))
            ratio[:first] = ratio[first]
    else:  # no walls: no impacts, p0
        mass = ch.W / ch.W.sum()
        flux = ratio = np.zeros(n)
    return tab, grid, ch, mass, flux, ratio


def chain_density(model, h_max: float = 4.0, points: int = 2000, phases: int = DEFAULT_PHASES, *,
                  energies: int = DEFAULT_ENERGIES, extrapolate: bool = True, nodes: int = DEFAULT_NODES,
                  check: bool = True) -> ChainDensity:
    """The stationary p(H) of the impact-to-impact chain (see the module docstring).

    ``stationary_density(model, "chain", ...)`` calls this with the defaults.

    Parameters
    ----------
    model : ImpactOscillator
        Any wall geometry the averaging methods take: symmetric, one-sided, asymmetric, or a wall at the
        equilibrium.
    h_max : float
        Upper end of the output range (the chain itself runs on the range carrying the mass).
    points : int
        Output grid size on [0, h_max].
    phases : int
        Clock phases per flight (1 is the Poisson clock of ``jump``).
    energies : int
        Energy nodes of the chain (its cost ~ energies x phases; 400 resolves the paper's cases to 1e-4 in L1).
    extrapolate : bool
        Richardson extrapolation in the phases: 2 p(phases) - p(phases / 2) (``phases`` must be even).
    nodes : int
        Gauss nodes per orbit quadrature.
    check : bool
        Check confinement first.

    Returns
    -------
    ChainDensity

    Raises
    ------
    ParameterError
        points, energies, phases or h_max out of range.
    NormalisationError
        No stationary density.

    Examples
    --------
    >>> from models import ImpactOscillator, Newton
    >>> stop = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=(0, None),
    ...                         restitution=Newton(0.8))
    >>> round(chain_density(stop, h_max=8.0).mean_energy, 3)     # Monte Carlo: 0.266 +- 0.001; jump: 0.304
    0.265
    """
    import warnings

    from hybrid.errors import TruncationWarning

    for name, val, lo, hi in (("points", points, 3, 10_000_000), ("energies", energies, 11, 200_000),
                              ("phases", phases, 1, 4096)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or not lo <= val <= hi:
            raise ParameterError(f"{name}={val!r} must be an integer in [{lo}, {hi}]")
    if isinstance(h_max, bool) or not isinstance(h_max, (int, float, np.integer, np.floating)) or \
            not (math.isfinite(float(h_max)) and h_max > 0):
        raise ParameterError(f"h_max={h_max!r} must be a finite positive energy")
    h_max, points, phases, n = float(h_max), int(points), int(phases), int(energies)
    check_energy_range(model, h_max)
    geo = geometry(model)
    if n * phases * max(len(geo.levels), 1) > _MAX_STATES:
        raise ParameterError(f"energies x phases = {n * phases} states exceeds {_MAX_STATES:.0e} (one sparse LU of "
                             "that size needs many GB); the defaults 400 x 8 resolve the paper's cases to 1e-4 in L1")
    if extrapolate and phases % 2:
        raise ParameterError(f"phases={phases} must be even to extrapolate from phases / 2 (or extrapolate=False)")
    law = model.restitution
    impacts = geo.walls > 0
    with np.errstate(all="ignore"):
        if check:
            check_confinement(model, _NO_LOSS, h_max, nodes)
        _check_scale(model, _NO_LOSS, nodes)
        h, covered = _mass_range(model, _NO_LOSS, law, nodes, h_max)
        tab, grid, ch, mass, flux, ratio = _chain_on(model, h, n, nodes, law, geo, phases, extrapolate)
        for _ in range(4 if covered and impacts else 0):
            # the range came from the no-loss p0; the impacts make p fall sooner: fit the chain's grid to p itself
            dens = mass / np.where(ch.W > 0, ch.W, np.inf)
            with np.errstate(divide="ignore"):
                log_r = np.log(dens) + ch.logp0_nodes
            k = int(np.argmax(log_r))
            past = np.nonzero(log_r[k:] < log_r[k] - _LOG_DROP)[0]
            if not past.size or grid[k + past[0]] >= h / 1.5:
                break
            h = 1.25 * float(grid[k + past[0]])
            tab, grid, ch, mass, flux, ratio = _chain_on(model, h, n, nodes, law, geo, phases, extrapolate)
    r = np.where(ch.W > 0, mass / np.where(ch.W > 0, ch.W, 1.0), 0.0)
    Z = float(np.sum(ch.W * r))
    logZ = ch.shift + np.log(Z)

    def log_density(e):
        with np.errstate(divide="ignore"):
            return np.log(np.interp(e, grid, r)) + tab.log_density(e, None, law) - logZ

    H = output_grid(h, h_max, points)
    with np.errstate(divide="ignore"):
        log_p = np.where(H <= h, log_density(np.minimum(H, h)), -np.inf)
    sd = ChainDensity(model, _NO_LOSS, tab, H, log_p, log_density, ch.Hq, ch.wq, h_max=h_max)
    sd.phases = phases
    if impacts:
        sd.impact_rate = float(np.sum(sd._qp * tab.impact_rate(sd._qH) * np.interp(sd._qH, grid, ratio)))
    sd.impact_energy_H = grid
    width = np.gradient(grid)  # the width of each node's hat function: half at the two ends
    width[[0, -1]] *= 0.5
    sd.impact_energy_density = flux / max(flux.sum(), 1e-300) / width
    if not (np.isfinite(sd.mean_energy) and abs(sd.total_mass - 1.0) < 1e-6):
        raise NormalisationError(f"the chain's p(H) could not be normalised (total mass {sd.total_mass!r}); "
                                 "increase energies or check the model's parameters")
    if not covered:
        top = float(np.sum(mass[grid > 0.95 * h]))
        if top > 1e-3:
            warnings.warn(TruncationWarning(
                f"h_max={h_max:g} does not cover the mass: {top:.3g} of it lies in the top 5 % of the range, where "
                "the chain reflects; raise h_max"), stacklevel=2)
    return sd


__all__ = ["DEFAULT_ENERGIES", "DEFAULT_PHASES", "ChainDensity", "chain_density", "chain_generator"]
