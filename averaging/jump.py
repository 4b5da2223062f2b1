"""A conservative Markov-chain (finite-volume) generator of the averaged energy process on an H grid.

Node i carries the probability mass pi_i of the hat function around H_i. The diffusion part is built from the exact
no-jump density p0 of eq. 30: with the masses W_i = int hat_i p0 dH and the conductances
kappa_{i+1/2} = sigma2_bar(H_{i+1/2}) p0(H_{i+1/2}) / (2 (H_{i+1} - H_i)), the rates are
q(i -> i+1) = kappa_{i+1/2} / W_i and q(i+1 -> i) = kappa_{i+1/2} / W_{i+1} (Scharfetter-Gummel-like). They satisfy
detailed balance for pi = W, so without jumps the chain's stationary law reproduces eq. 30 exactly, and the flux
-(sigma2_bar/2) p0 d(p/p0)/dH of the FPK equation is discretised conservatively. Impacts are jumps from node i: for
each wall of energy G_w below H_i, at rate 1/T(H_i), to the post-impact energy H' = G_w + e**2 (H_i - G_w), its
mass split linearly between the two nodes around H' (this keeps the mean jump size). The top node also stands for
the tail above h_max that the grid cuts off (its jump rates are scaled by 1 + tail mass / W_top, see
:meth:`EnergyChain._tail_factor`); a plain reflecting top would make the far tail of p(H) flatten towards h_max.

Because the only upward moves are to the next node, the stationary equation Q^T pi = 0 is equivalent to the balance
of probability flow across each cut between nodes i and i+1; it is solved exactly by one downward sweep in O(N)
(sums of positive terms only, no cancellation). :meth:`EnergyChain.generator` gives the sparse Q for the transient
problems and for checking the residual of Q^T pi.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from .methods import ImpactMethod
from .quadrature import gauss_jacobi

_CELL_NODES = 5


def cell_quadrature(grid, levels, nu: float, k: int = _CELL_NODES):
    """Gauss nodes inside every cell [H_j, H_j+1] of ``grid``, for integrands of p(H).

    ``levels`` are the impact levels (a number or a sequence): cells are split there, and the parts above a level L
    are integrated in u = sqrt(H - L) (p has a square-root kink at each level). The first cell uses Gauss-Jacobi for
    the H**nu behaviour at 0 (in u when a wall sits at the equilibrium, level 0); weights are divided by H**nu so
    that p itself is the integrand.

    Returns
    -------
    cell : int array, H : node energies, w : weights (same length)

    Examples
    --------
    >>> cell, H, w = cell_quadrature(np.linspace(0.0, 2.0, 5), 1.2, 0.0)
    >>> round(float(w.sum()), 12)
    2.0
    >>> _, H, w = cell_quadrature(np.linspace(0.0, 2.0, 5), (0.0, 0.7), 0.5)   # p ~ H**0.5, a wall at 0
    >>> round(float(np.sum(w * H**0.5)), 8) == round(2.0**1.5 / 1.5, 8)
    True
    """
    grid = np.asarray(grid, dtype=float)
    levels = np.atleast_1d(np.asarray(levels, dtype=float))
    levels = np.sort(levels[np.isfinite(levels)])
    inner = levels[(levels > grid[0]) & (levels < grid[-1])]
    edges = np.unique(np.concatenate([grid, inner]))
    a, b = edges[:-1], edges[1:]
    cell = np.clip(np.searchsorted(grid, a, side="right") - 1, 0, len(grid) - 2)
    base_i = np.searchsorted(levels, a, side="right") - 1  # the impact level at or below the sub-cell
    tl, wl = np.polynomial.legendre.leggauss(k)
    cells, Hs, ws = [], [], []
    zero = len(levels) > 0 and levels[0] == 0.0
    first = np.zeros(len(a), dtype=bool)
    if nu != 0.0 and a[0] == 0.0:
        first[0] = True
        if zero:  # p dH = u**(2 nu) exp(R) 2 u du
            beta = 2.0 * nu + 1.0
            t, w = gauss_jacobi(k, 0.0, beta)
            ub = np.sqrt(b[0])
            u = 0.5 * ub * (t + 1.0)
            Hs.append(u * u)
            ws.append(2.0 * w * (0.5 * ub) ** (beta + 1.0) / u ** (2.0 * nu))
        else:
            t, w = gauss_jacobi(k, 0.0, nu)
            h = 0.5 * b[0] * (t + 1.0)
            Hs.append(h)
            ws.append(w * (0.5 * b[0]) ** (nu + 1.0) / h**nu)
        cells.append(np.full(k, cell[0]))
    plain = (base_i < 0) & ~first
    if plain.any():
        lo, hi = a[plain], b[plain]
        h = 0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * tl
        cells.append(np.repeat(cell[plain], k))
        Hs.append(h.ravel())
        ws.append((0.5 * (hi - lo)[:, None] * wl).ravel())
    in_u = (base_i >= 0) & ~first
    if in_u.any():
        L = levels[base_i[in_u]]
        ua, ub = np.sqrt(np.maximum(a[in_u] - L, 0.0)), np.sqrt(b[in_u] - L)
        u = 0.5 * (ua + ub)[:, None] + 0.5 * (ub - ua)[:, None] * tl
        cells.append(np.repeat(cell[in_u], k))
        Hs.append((L[:, None] + u * u).ravel())
        ws.append((0.5 * (ub - ua)[:, None] * wl * 2.0 * u).ravel())
    return np.concatenate(cells), np.concatenate(Hs), np.concatenate(ws)


class EnergyChain:
    """The generator of the averaged energy process on ``grid`` (see the module docstring).

    Parameters
    ----------
    table : EnergyTable
    grid : array
        Increasing energies from 0 to at most table.h_max.
    method : ImpactMethod
        Drift methods put their loss into p0; jump methods add jumps to the no-loss p0.
    law : RestitutionLaw

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> from averaging.table import EnergyTable
    >>> from averaging.methods import METHODS
    >>> m = DuffingImpact(restitution=Elastic())
    >>> ch = EnergyChain(EnergyTable(m, 4.0), np.linspace(0, 4, 201), METHODS["jump"], m.restitution)
    >>> pi = ch.stationary_masses()
    >>> bool(np.abs(ch.generator().T @ pi).max() < 1e-12)
    True
    """

    def __init__(self, table, grid, method: ImpactMethod, law):
        grid = np.asarray(grid, dtype=float)
        self.table, self.grid, self.method, self.law = table, grid, method, law
        n = len(grid)
        drift_method = None if method.jumps else method
        self.logp0_nodes = table.log_density(grid, drift_method, law)
        cell, Hq, wq = cell_quadrature(grid, table.geometry.levels, table.nu)
        logq = table.log_density(Hq, drift_method, law)
        self.shift = S = float(np.max(logq))
        pq = wq * np.exp(logq - S)
        frac = (Hq - grid[cell]) / (grid[cell + 1] - grid[cell])
        W = np.bincount(cell, pq * (1.0 - frac), minlength=n) + np.bincount(cell + 1, pq * frac, minlength=n)
        self.cell, self.Hq, self.wq, self.logq, self.frac = cell, Hq, wq, logq, frac
        self.W = W  # scaled by exp(-S)
        mid = 0.5 * (grid[:-1] + grid[1:])
        with np.errstate(divide="ignore"):
            self.kappa = (0.5 * table.diffusion(mid) * np.exp(table.log_density(mid, drift_method, law) - S)
                          / np.diff(grid))
        # jumps
        self.jump_from = np.zeros(0, dtype=int)
        self.jump_to = np.zeros(0, dtype=int)
        self.jump_rate = np.zeros(0)
        if method.jumps and table.has_impacts:
            # one jump per wall and quasi-period: rate 1/T(H) above the wall's level, to H minus that wall's loss
            frms, tos, rts = [], [], []
            geo = table.geometry
            for Gw in sorted(set(geo.wall_levels)):
                count = geo.wall_levels.count(Gw)
                src = np.nonzero(grid > Gw)[0]
                excess = grid[src] - Gw
                after = method.jump_target(law, excess)
                moving = after < excess
                src, excess, after = src[moving], excess[moving], after[moving]
                rate = count / table.period(grid[src])
                Hn = Gw + after
                j = np.clip(np.searchsorted(grid, Hn, side="right") - 1, 0, n - 2)
                theta = (Hn - grid[j]) / (grid[j + 1] - grid[j])
                frms += [src, src]
                tos += [j, j + 1]
                rts += [rate * (1.0 - theta), rate * theta]
            frm, to, rt = np.concatenate(frms), np.concatenate(tos), np.concatenate(rts)
            rt = np.where(frm == n - 1, rt * self._tail_factor(drift_method), rt)
            keep = (to != frm) & (rt > 0)
            self.jump_from, self.jump_to, self.jump_rate = frm[keep], to[keep], rt[keep]

    def _tail_factor(self, drift_method) -> float:
        """1 + (mass above h_max) / W_top: the top node also stands for the tail it cuts off, so it jumps faster.

        A reflecting top would force d(p/p0)/dH = 0 at h_max and fatten the tail near it. Above h_max the jumps
        leave locally at rate q = (walls hit)/T, so r = p/p0 decays like exp(-lam H) with
        (sigma2_bar/2)(lam**2 - lam (ln kappa)') = q, kappa = sigma2_bar p0 / 2 (landings from above are neglected).
        """
        table, grid = self.table, self.grid
        h1, h0 = float(grid[-1]), float(grid[-2])
        s1, s0 = table.diffusion(np.array([h1, h0]))
        l1, l0 = table.log_density(np.array([h1, h0]), drift_method, self.law)
        dlogp0 = (l1 - l0) / (h1 - h0)
        a = (np.log(s1) - np.log(s0)) / (h1 - h0) + dlogp0
        b = 2.0 * float(table.impact_rate(np.array([h1]))[0]) / s1
        lam_p = 0.5 * (a + np.sqrt(a * a + 4.0 * b)) - dlogp0
        if not (np.isfinite(lam_p) and lam_p > 0 and self.W[-1] > 0):
            return 1.0
        return 1.0 + np.exp(l1 - self.shift) / lam_p / self.W[-1]

    # ------------------------------------------------------------------ generator
    def generator(self) -> sparse.csr_matrix:
        """Sparse Q with Q[i, j] the rate i -> j and rows summing to zero."""
        n = len(self.grid)
        W = self.W
        with np.errstate(divide="ignore", invalid="ignore"):
            up = np.where(W[:-1] > 0, self.kappa / W[:-1], 0.0)
            down = np.where(W[1:] > 0, self.kappa / W[1:], 0.0)
        i = np.arange(n - 1)
        rows = np.concatenate([i, i + 1, self.jump_from])
        cols = np.concatenate([i + 1, i, self.jump_to])
        vals = np.concatenate([up, down, self.jump_rate])
        Q = sparse.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
        Q = Q - sparse.diags(np.asarray(Q.sum(axis=1)).ravel())
        return Q.tocsr()

    # ------------------------------------------------------------------ stationary law
    def stationary_ratio(self) -> np.ndarray:
        """r_i = pi_i / W_i: the stationary density relative to p0 at the nodes (r = 1 without jumps)."""
        n = len(self.grid)
        r = np.ones(n)
        if len(self.jump_from) == 0:
            return r
        W, kappa = self.W.tolist(), self.kappa.tolist()
        out_rate = np.bincount(self.jump_from, self.jump_rate, minlength=n).tolist()
        targets: list[list] = [[] for _ in range(n)]
        for i, j, q in zip(self.jump_from.tolist(), self.jump_to.tolist(), self.jump_rate.tolist()):
            targets[i].append((j, q))
        land = [0.0] * n
        J = 0.0
        r_list = r.tolist()
        for i in range(n - 2, -1, -1):
            k = i + 1
            mass = W[k] * r_list[k]
            if targets[k]:
                for j, q in targets[k]:
                    land[j] += mass * q
                J += mass * out_rate[k]
            J -= land[k]
            if J < 0.0:
                J = 0.0
            r_list[i] = r_list[k] + (J / kappa[i] if kappa[i] > 0 else 0.0)
        return np.asarray(r_list)

    def stationary_masses(self) -> np.ndarray:
        """Stationary probabilities pi of the nodes (sum 1)."""
        pi = self.W * self.stationary_ratio()
        return pi / pi.sum()
