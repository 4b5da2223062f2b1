"""Finite volumes on an (x, y) grid: the phase-plane solver for potentials with several wells.

The energy-angle rings of :mod:`._grid` need one closed orbit per energy. With several wells an energy level
splits into several orbits, and the separatrices through the saddles (where the period diverges) would need a
graph of ring families glued along them. Cartesian cells need no knowledge of the orbits: every potential that
confines the motion (walls or G -> inf) is one rectangle of cells. The price is that the orbits cross the cells,
so the convection's truncation error acts across energies too; the scheme keeps it small by a third-order
upwind-biased face value (kappa = 1/3, linear) in both directions, with a second-order central diffusion. It suits
the moderate noise of the classical bistable benchmarks (D/c of order 0.1-1); at D/c of 1e-2 and below the rings
are the better discretisation (the solver uses them for every single well).

Unknowns are cell averages of p on the cells of H < h_max (the others hold no mass); the box has zero-flux edges,
and a wall is a vertical cell face: the flux y p dy reaching it from the incoming cells (reconstructed at the face
by a quadratic from the three cells upstream) leaves them and enters the cells of the outgoing speeds
-e(v) v, slice by slice, as in :func:`._core._impact_weights`. Every flux leaves one cell and enters another, so
probability is conserved to round-off.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from hybrid.errors import ModelError

KAPPA = 1.0 / 3.0
"""Upwind-biased face value p_up + (1 + k)/4 (p_down - p_up) + (1 - k)/4 (p_up - p_far): third order at k = 1/3."""


def confining_range(potential, h_max: float, left=None, right=None, reach: float = 1e6):
    """(x_lo, x_hi, G_min): the walls, or the outermost x with G(x) = h_max, and the lowest G between them.

    Examples
    --------
    >>> lo, hi, gmin = confining_range(lambda x: -x**2 / 2 + x**4 / 16, 3.0)
    >>> round(hi, 6), round(gmin, 6)
    (3.464102, -1.0)
    """
    def edge(sign, wall):
        if wall is not None:
            return float(wall)
        s = 1.0
        while potential(np.array([sign * s]))[0] <= h_max:
            s *= 2.0
            if s > reach:
                raise ModelError(f"the potential G stays below h_max={h_max:g} out to |x| = {reach:g}: it does not "
                                 "confine the motion on the " + ("right" if sign > 0 else "left") + "; add a wall")
        # the outermost crossing: G(s) > h_max at the bracket's end, scan inwards then bisect
        xs = sign * np.linspace(0.0, s, 4097)
        G = potential(xs)
        above = np.nonzero(G <= h_max)[0]
        k = int(above[-1])
        a, b = xs[k], xs[k + 1]
        for _ in range(60):
            m = 0.5 * (a + b)
            if potential(np.array([m]))[0] <= h_max:
                a = m
            else:
                b = m
        return float(b)

    lo, hi = edge(-1.0, left), edge(1.0, right)
    xs = np.linspace(lo, hi, 20001)
    return lo, hi, float(np.min(potential(xs)))


class CartesianGrid:
    """Uniform cells on [x_lo, x_hi] x [-y_max, y_max] (a face at y = 0), keeping those that reach H < h_max.

    Parameters
    ----------
    x_lo, x_hi : float
        The walls or the turning points at h_max.
    g_min : float
        The lowest potential in between (y_max = sqrt(2 (h_max - g_min))).
    h_max : float
    nx, ny : int
        Cells in x and in y (ny rounded up to even).
    potential : callable
    walls : dict
        ``{"left": x_l, "right": x_r}`` for the sides that have a wall.
    """

    def __init__(self, x_lo, x_hi, g_min, h_max, nx, ny, potential, walls):
        ny += ny % 2
        self.h_max, self.g_min = float(h_max), float(g_min)
        self.walls = dict(walls)
        self.x_faces = np.linspace(x_lo, x_hi, nx + 1)
        y_max = np.sqrt(2.0 * (h_max - g_min))
        self.y_faces = np.linspace(-y_max, y_max, ny + 1)
        self.hx, self.hy = self.x_faces[1] - self.x_faces[0], self.y_faces[1] - self.y_faces[0]
        self.xc = 0.5 * (self.x_faces[1:] + self.x_faces[:-1])
        self.yc = 0.5 * (self.y_faces[1:] + self.y_faces[:-1])
        self.nx, self.ny = nx, ny
        # lowest energy in each cell (G sampled at 5 points per cell, y at the face nearest to 0)
        sub = self.x_faces[:-1, None] + self.hx * np.linspace(0.0, 1.0, 5)[None, :]
        g_low = potential(sub).min(axis=1)
        y_low = np.minimum(np.abs(self.y_faces[:-1]), np.abs(self.y_faces[1:]))
        self.active = (g_low[:, None] + 0.5 * y_low[None, :] ** 2) < h_max  # (nx, ny)
        self.index = np.full((nx, ny), -1)
        self.index[self.active] = np.arange(int(self.active.sum()))
        self.n = int(self.active.sum())
        ii, jj = np.nonzero(self.active)
        self.i, self.j = ii, jj
        self.x, self.y = self.xc[ii], self.yc[jj]

    def cell(self, i, j):
        """Unknown index of cells (i, j), -1 outside the box or inactive."""
        i = np.asarray(i)
        j = np.asarray(j)
        ok = (i >= 0) & (i < self.nx) & (j >= 0) & (j < self.ny)
        out = np.full(np.broadcast(i, j).shape, -1)
        out[ok] = self.index[i[ok], j[ok]] if out.ndim else self.index[int(i), int(j)]
        return out


def _face_value(up, down, far, far2=None, down2=None):
    """Columns and weights of the upwind-biased face value: fifth order (cells far2, far, up, down, down2) where all
    five are there, third order (kappa = 1/3: far, up, down) where three are, central otherwise."""
    has_far = far >= 0
    cu = np.where(has_far, 1.0 - 0.5 * KAPPA, 0.5)
    cd = np.where(has_far, 0.25 * (1.0 + KAPPA), 0.5)
    cf = np.where(has_far, -0.25 * (1.0 - KAPPA), 0.0)
    if far2 is None:
        return (up, down, np.where(has_far, far, up)), (cu, cd, cf)
    five = has_far & (far2 >= 0) & (down2 >= 0)
    z = np.zeros(len(up))
    cols = (up, down, np.where(has_far, far, up), np.where(five, far2, up), np.where(five, down2, up))
    wts = (np.where(five, 47.0 / 60.0, cu), np.where(five, 27.0 / 60.0, cd), np.where(five, -13.0 / 60.0, cf),
           np.where(five, 2.0 / 60.0, z), np.where(five, -3.0 / 60.0, z))
    return cols, wts


def _transverse(grid, Ia, Ja, Ib, Jb, di, dj, weight, h):
    """Columns and weights of weight * d p / d(transverse) at the face between cells (Ia, Ja) and (Ib, Jb): the
    central difference of the face values (p_a + p_b) / 2 of the neighbouring faces (di, dj), 0 where one is missing."""
    a1, b1 = grid.cell(Ia + di, Ja + dj), grid.cell(Ib + di, Jb + dj)
    a0, b0 = grid.cell(Ia - di, Ja - dj), grid.cell(Ib - di, Jb - dj)
    ok = (a1 >= 0) & (b1 >= 0) & (a0 >= 0) & (b0 >= 0)
    w = np.where(ok, weight / (4.0 * h), 0.0)
    return (np.maximum(a1, 0), np.maximum(b1, 0), np.maximum(a0, 0), np.maximum(b0, 0)), (w, w, -w, -w)


class CartesianDiscretisation:
    """The assembled operator (rows = net outflow of each active cell) and the wall maps.

    Parameters
    ----------
    grid : CartesianGrid
    coef : Coefficients
        g, the non-conservative drift and sigma**2 of the model (:class:`._core.Coefficients`).
    law : callable
        e(v), vectorised.
    n_sub : int
        Slices per incoming cell in the impact map.
    """

    def __init__(self, grid: CartesianGrid, coef, law, n_sub: int = 16):
        self.grid = grid
        n = grid.n
        hx, hy = grid.hx, grid.hy
        self.mass_weight = np.full(n, hx * hy)
        s2 = np.asarray(np.broadcast_to(coef.s2(grid.x, grid.y), (n,)), dtype=float)
        self.s2 = s2
        rows, cols, vals = [], [], []

        def add_flux(src, dst, fcols, fvals):
            # flux (sum_k fvals[k] * p[fcols[k]]) from cell src to cell dst
            for c, v in zip(fcols, fvals):
                rows.extend([src, dst])
                cols.extend([c, c])
                vals.extend([v, -v])

        # ---- x faces: convection y p (y constant along a row), upwind-biased in the sign of y
        I, J = np.meshgrid(np.arange(grid.nx - 1), np.arange(grid.ny), indexing="ij")
        I, J = I.ravel(), J.ravel()
        a, b = grid.cell(I, J), grid.cell(I + 1, J)
        ok = (a >= 0) & (b >= 0)
        I, J, a, b = I[ok], J[ok], a[ok], b[ok]
        vel = grid.yc[J]
        pos = vel > 0
        up, down = np.where(pos, a, b), np.where(pos, b, a)
        far = np.where(pos, grid.cell(I - 1, J), grid.cell(I + 2, J))
        far2 = np.where(pos, grid.cell(I - 2, J), grid.cell(I + 3, J))
        down2 = np.where(pos, grid.cell(I + 2, J), grid.cell(I - 1, J))
        fc, fv = _face_value(up, down, far, far2, down2)
        add_flux(a, b, fc, [hy * vel * w for w in fv])
        # the face average of y p is y_j <p> + (hy**2 / 12) d_y p: d_y p from the face values of the rows j +- 1
        add_flux(a, b, *_transverse(grid, I, J, I + 1, J, 0, 1, hy * hy * hy / 12.0 * np.ones(len(a)), hy))

        # ---- y faces: Itô drift m p upwind-biased (its own matrix, so that a time-dependent forcing can replace
        # it: operator_with_drift), -(1/2) d_y(sigma**2 p) central
        I, J = np.meshgrid(np.arange(grid.nx), np.arange(grid.ny - 1), indexing="ij")
        I, J = I.ravel(), J.ravel()
        a, b = grid.cell(I, J), grid.cell(I, J + 1)
        ok = (a >= 0) & (b >= 0)
        I, J, a, b = I[ok], J[ok], a[ok], b[ok]
        xf, yf = grid.xc[I], grid.y_faces[J + 1]
        self._y_faces = (I, J, a, b)
        dx = 1e-4 * max(hx, 1e-12)
        self._drift_dx = dx
        xs = np.concatenate([xf, xf + dx, xf - dx])
        ys = np.concatenate([yf, yf, yf])
        self._drift_xy = (xs, ys)
        m_all = np.asarray(np.broadcast_to(coef.m(xs, ys), xs.shape), dtype=float) - coef.g(xs)
        # -(1/2) d_y(sigma**2 p): fourth-order face derivative where four cells are there, second order otherwise
        lo2, hi2 = grid.cell(I, J - 1), grid.cell(I, J + 2)
        four = (lo2 >= 0) & (hi2 >= 0)
        c = hx / (2.0 * hy)
        inner_w = np.where(four, 15.0 / 12.0, 1.0) * c
        add_flux(a, b, (a, b), (inner_w * s2[a], -inner_w * s2[b]))
        lo2s, hi2s = np.maximum(lo2, 0), np.maximum(hi2, 0)
        add_flux(a[four], b[four], (lo2s[four], hi2s[four]),
                 (-c * s2[lo2s[four]] / 12.0, c * s2[hi2s[four]] / 12.0))

        # ---- walls: the flux y p dy reaching the wall leaves the incoming cell and enters the outgoing cells
        self.walls = {}
        for side, col, sign in (("right", grid.nx - 1, 1.0), ("left", 0, -1.0)):
            if side not in grid.walls:
                continue
            J_in = np.nonzero(sign * grid.yc > 0)[0]
            c_in = grid.cell(np.full(len(J_in), col), J_in)
            keep = c_in >= 0
            J_in, c_in = J_in[keep], c_in[keep]
            step = -1 if side == "right" else 1
            c1 = grid.cell(np.full(len(J_in), col + step), J_in)
            c2 = grid.cell(np.full(len(J_in), col + 2 * step), J_in)
            # the face value: quadratic through three cells upstream (linear with two, constant with one)
            three, two = (c1 >= 0) & (c2 >= 0), (c1 >= 0) & (c2 < 0)
            w0 = np.where(three, 11.0 / 6.0, np.where(two, 1.5, 1.0))
            w1 = np.where(three, -7.0 / 6.0, np.where(two, -0.5, 0.0))
            w2 = np.where(three, 2.0 / 6.0, 0.0)
            speed = np.abs(grid.yc[J_in])
            lo = np.abs(grid.y_faces[J_in + (0 if side == "right" else 1)])  # slice speeds from lo to lo + hy
            frac = np.linspace(0.0, 1.0, n_sub + 1)
            v = lo[:, None] + hy * frac[None, :]
            e = np.ones_like(v)
            e[v > 0] = law(v[v > 0])
            img = e * v  # outgoing speeds of the slice ends
            lo_img, hi_img = np.minimum(img[:, :-1], img[:, 1:]), np.maximum(img[:, :-1], img[:, 1:])
            share = np.diff(v * v, axis=1) / np.diff(v * v, axis=1).sum(axis=1, keepdims=True)  # flux per slice
            # outgoing cells: same column, speeds |y| on the other side of 0
            J_out = np.nonzero(sign * grid.yc < 0)[0]
            out_lo = np.abs(grid.y_faces[J_out + (1 if side == "right" else 0)])
            W = np.zeros((len(J_in), len(J_out)))
            width = hi_img - lo_img
            for k in range(len(J_out)):
                ov = np.clip(np.minimum(hi_img, out_lo[k] + hy) - np.maximum(lo_img, out_lo[k]), 0.0, None)
                point = (width <= 1e-14 * hy) & (lo_img >= out_lo[k]) & (lo_img < out_lo[k] + hy)
                W[:, k] = np.sum(share * np.where(width > 1e-14 * hy, ov / np.where(width > 0, width, 1.0),
                                                  point.astype(float)), axis=1)
            lost = 1.0 - W.sum(axis=1)  # images beyond the box (faster than y_max): into the fastest cell
            W[:, np.argmax(out_lo)] += np.maximum(lost, 0.0)
            c_out = grid.cell(np.full(len(J_out), col), J_out)
            if np.any(c_out < 0) and np.any(W[:, c_out < 0] > 0):
                # an inactive outgoing cell (above h_max): its share goes to the nearest active one below it
                act = np.nonzero(c_out >= 0)[0]
                for k in np.nonzero(c_out < 0)[0]:
                    near = act[np.argmin(np.abs(out_lo[act] - out_lo[k]))]
                    W[:, near] += W[:, k]
                    W[:, k] = 0.0
            flux_coef = hy * speed  # outflow = hy * |y| * p_face
            for src_cols, wts in ((c_in, w0), (c1, w1), (c2, w2)):
                use = (wts != 0) & (src_cols >= 0)
                rows.extend([c_in[use]])
                cols.extend([src_cols[use]])
                vals.extend([flux_coef[use] * wts[use]])
                kk, jj = np.nonzero(W[use].T > 0)
                srcs, ws, fcs = src_cols[use], wts[use], flux_coef[use]
                rows.extend([c_out[kk]])
                cols.extend([srcs[jj]])
                vals.extend([-fcs[jj] * ws[jj] * W[use][jj, kk]])
            self.walls[side] = (J_in, c_in, (c_in, c1, c2), (w0, w1, w2), flux_coef)
        self._fixed = _assemble(rows, cols, vals, n)
        self.A = (self._fixed + self.drift_operator(m_all)).tocsc()

    def drift_points(self):
        """(x, y) where :meth:`drift_operator` needs the Itô drift m(x, y) of y (the coefficient m minus g):
        the y faces, then the same faces shifted by +dx and -dx in x (for m's variation along the face)."""
        return self._drift_xy

    def drift_operator(self, m_all):
        """The y-face convection of the drift ``m_all`` (minus g, at :meth:`drift_points`) as a CSR matrix: the part
        of the operator that a time-dependent force changes (:meth:`operator_with_drift`)."""
        grid = self.grid
        hx = grid.hx
        I, J, a, b = self._y_faces
        m, m_r, m_l = np.split(np.asarray(m_all, dtype=float), 3)
        rows, cols, vals = [], [], []

        def add_flux(src, dst, fcols, fvals):
            for c, v in zip(fcols, fvals):
                rows.extend([src, dst])
                cols.extend([c, c])
                vals.extend([v, -v])

        pos = m > 0
        up, down = np.where(pos, a, b), np.where(pos, b, a)
        far = np.where(pos, grid.cell(I, J - 1), grid.cell(I, J + 2))
        far2 = np.where(pos, grid.cell(I, J - 2), grid.cell(I, J + 3))
        down2 = np.where(pos, grid.cell(I, J + 2), grid.cell(I, J - 1))
        fc, fv = _face_value(up, down, far, far2, down2)
        add_flux(a, b, fc, [hx * m * w for w in fv])
        # <m p> over the face = m <p> + (hx**2 / 12) (m_x d_x p + m_xx p / 2): m's variation along the face
        dx = self._drift_dx
        m_x, m_xx = (m_r - m_l) / (2.0 * dx), (m_r - 2.0 * m + m_l) / (dx * dx)
        add_flux(a, b, *_transverse(grid, I, J, I, J + 1, 1, 0, hx * hx * hx / 12.0 * m_x, hx))
        add_flux(a, b, (a, b), (hx * hx * hx / 24.0 * m_xx * 0.5, hx * hx * hx / 24.0 * m_xx * 0.5))
        return _assemble(rows, cols, vals, grid.n)

    def operator_with_drift(self, m_all):
        """The operator (CSR) with the drift replaced by ``m_all`` at :meth:`drift_points` (a time-dependent force:
        the x faces, the noise and the walls stay)."""
        return (self._fixed + self.drift_operator(m_all)).tocsr()

    def wall_flux(self, p, side):
        """(speeds at the wall, flux per incoming cell) of ``side`` for the density p."""
        J_in, _c_in, srcs, wts, flux_coef = self.walls[side]
        pf = sum(np.where(s >= 0, w * p[np.maximum(s, 0)], 0.0) for s, w in zip(srcs, wts))
        v = np.abs(self.grid.yc[J_in])
        order = np.argsort(v)
        return v[order], (flux_coef * pf)[order]


def _assemble(rows, cols, vals, n):
    """CSR matrix from lists of (row, column, value) arrays (duplicates summed)."""
    flat = [np.atleast_1d(np.asarray(r)) for r in rows]
    return sps.csr_matrix((np.concatenate([np.atleast_1d(np.asarray(v, dtype=float)) for v in vals]),
                           (np.concatenate(flat), np.concatenate([np.atleast_1d(np.asarray(c)) for c in cols]))),
                          shape=(n, n))


def critical_energies(potential, lo: float, hi: float, samples: int = 20001) -> np.ndarray:
    """The values of G at its interior local extrema on [lo, hi] (the well bottoms and the saddles).

    Examples
    --------
    >>> [round(float(v), 9) + 0.0 for v in critical_energies(lambda x: -x**2 / 2 + x**4 / 16, -3.0, 3.0)]
    [-1.0, 0.0, -1.0]
    """
    xs = np.linspace(lo, hi, samples)
    G = potential(xs)
    d = np.diff(G)
    turn = np.nonzero(np.sign(d[1:]) * np.sign(d[:-1]) < 0)[0] + 1
    out = []
    for k in turn:  # refine by a parabola through the three samples
        g0, g1, g2 = G[k - 1], G[k], G[k + 1]
        den = g0 - 2.0 * g1 + g2
        t = 0.5 * (g0 - g2) / den if den != 0 else 0.0
        out.append(float(potential(np.array([xs[k] + t * (xs[1] - xs[0])]))[0]))
    return np.array(out)


def _slopes(grid, p):
    """Central differences of the cell averages along x and y (one-sided next to a missing cell, 0 if alone)."""
    out = []
    for di, dj, h in ((1, 0, grid.hx), (0, 1, grid.hy)):
        nb = grid.cell(grid.i + di, grid.j + dj)
        pb = grid.cell(grid.i - di, grid.j - dj)
        fwd = np.where(nb >= 0, p[np.maximum(nb, 0)] - p, 0.0)
        bwd = np.where(pb >= 0, p - p[np.maximum(pb, 0)], 0.0)
        both = (nb >= 0) & (pb >= 0)
        out.append(np.where(both, 0.5 * (fwd + bwd), fwd + bwd) / h)
    return out


def _level_intervals(xs, Gs, levels, potential):
    """(level index, a, b) of every interval of x in [xs[0], xs[-1]] where G(x) < level; G is sampled at xs and
    the crossings are refined by bisection (all levels at once)."""
    below = Gs[None, :] < levels[:, None]
    f, k = np.nonzero(np.diff(below.astype(np.int8), axis=1))
    lo, hi, h = xs[k], xs[k + 1], levels[f]
    rising = below[f, k]  # True: below -> above, a right end
    for _ in range(52):
        mid = 0.5 * (lo + hi)
        go_right = (potential(mid) < h) == rising  # the crossing lies above mid
        lo, hi = np.where(go_right, mid, lo), np.where(go_right, hi, mid)
    # the ends of the sampled range count as interval ends where G < level there
    f0 = np.nonzero(below[:, 0])[0]
    f1 = np.nonzero(below[:, -1])[0]
    face = np.concatenate([f0, f, f1])
    pos = np.concatenate([np.full(len(f0), xs[0]), 0.5 * (lo + hi), np.full(len(f1), xs[-1])])
    order = np.lexsort((pos, face))
    face, pos = face[order], pos[order]  # per level: start, end, start, end, ...
    return face[0::2], pos[0::2], pos[1::2]


def energy_cdf(grid, potential, p, px, py, faces, per_cell: int = 3, sampling: int = 16):
    """P(H < h) at each energy of ``faces`` for the piecewise-linear density p + px (x - x_c) + py (y - y_c).

    For each h: the intervals of x where G(x) < h (turning points by bisection on a sampling of G), integrated
    in x by Gauss-Legendre after x = a + (b - a) (1 - cos t) / 2 (which makes the square-root ends smooth), and in
    y exactly over |y| < sqrt(2 (h - G(x))) (whole cells by cumulative sums, the two cut cells directly).
    """
    from scipy.special import roots_legendre

    nx, ny = grid.nx, grid.ny
    P, PX, PY = (np.zeros((nx, ny)) for _ in range(3))
    P[grid.i, grid.j], PX[grid.i, grid.j], PY[grid.i, grid.j] = p, px, py
    cum_a = np.concatenate([np.zeros((nx, 1)), np.cumsum(grid.hy * P, axis=1)], axis=1)
    cum_b = np.concatenate([np.zeros((nx, 1)), np.cumsum(grid.hy * PX, axis=1)], axis=1)
    yf = grid.y_faces
    xs = np.linspace(grid.x_faces[0], grid.x_faces[-1], sampling * nx + 1)
    faces = np.asarray(faces, dtype=float)
    lev, A, B = _level_intervals(xs, potential(xs), faces, potential)

    def part(i, j, xi, a, b):  # integral over y in [a, b] inside cell (i, j) of the linear reconstruction
        yc = grid.yc[j]
        return (b - a) * (P[i, j] + PX[i, j] * xi) + PY[i, j] * 0.5 * ((b - yc) ** 2 - (a - yc) ** 2)

    # composite rule: each interval cut at the x faces (the reconstruction jumps there), q nodes per piece in t
    x0, hx = grid.x_faces[0], grid.hx
    k_a = np.clip(np.floor((A - x0) / hx).astype(int), 0, nx - 1)
    k_b = np.clip(np.ceil((B - x0) / hx).astype(int), k_a + 1, nx)
    count = k_b - k_a
    r = np.repeat(np.arange(len(A)), count)
    i = k_a[r] + np.arange(len(r)) - np.repeat(np.cumsum(count) - count, count)
    a, b = A[r], B[r]
    lo, hi = np.maximum(a, grid.x_faces[i]), np.minimum(b, grid.x_faces[i + 1])
    span = np.where(b > a, b - a, 1.0)
    th_lo = np.arccos(np.clip(1.0 - 2.0 * (lo - a) / span, -1.0, 1.0))
    th_hi = np.arccos(np.clip(1.0 - 2.0 * (hi - a) / span, -1.0, 1.0))
    t, w = roots_legendre(per_cell)
    theta = th_lo[:, None] + 0.5 * (th_hi - th_lo)[:, None] * (t[None, :] + 1.0)
    x = a[:, None] + 0.5 * (b - a)[:, None] * (1.0 - np.cos(theta))
    wx = 0.5 * (th_hi - th_lo)[:, None] * w[None, :] * 0.5 * (b - a)[:, None] * np.sin(theta)
    i = np.broadcast_to(i[:, None], x.shape)
    h = faces[lev[r], None]
    xi = x - grid.xc[i]
    s = np.minimum(np.sqrt(2.0 * np.maximum(h - potential(x), 0.0)), yf[-1])
    j0 = np.clip(np.searchsorted(yf, -s, side="right") - 1, 0, ny - 1)
    j1 = np.clip(np.searchsorted(yf, s, side="left") - 1, 0, ny - 1)
    n0 = np.minimum(j0 + 1, ny)
    same = j0 == j1
    inner = (cum_a[i, j1] - cum_a[i, n0]) + (cum_b[i, j1] - cum_b[i, n0]) * xi
    col = np.where(same, part(i, j0, xi, -s, s), part(i, j0, xi, -s, yf[n0]) + part(i, j1, xi, yf[j1], s) + inner)
    return np.bincount(lev[r], np.sum(wx * col, axis=1), len(faces))


def point_values(grid, p):
    """Point values at the cell centres from the cell averages (p - h**2/24 p'' in each direction, fourth order)."""
    out = p.copy()
    for di, dj in ((1, 0), (0, 1)):
        nb = grid.cell(grid.i + di, grid.j + dj)
        pb = grid.cell(grid.i - di, grid.j - dj)
        both = (nb >= 0) & (pb >= 0)
        second = np.where(both, p[np.maximum(nb, 0)] - 2.0 * p + p[np.maximum(pb, 0)], 0.0)
        out -= second / 24.0
    return out
