"""The energy-angle grid of the phase-plane solver: rings of constant energy cut by the walls into cells.

Coordinates (see the package docstring): u = sign(x) sqrt(2 G(x)), r = sqrt(u**2 + y**2) = sqrt(2 H),
psi = atan2(y, u) in [-pi/2, 3 pi/2). The map (x, y) -> (u, y) -> (H, psi) has du dy = dH dpsi, so cell areas in
(H, psi) are areas in (u, y). A wall x = w is the vertical line u = U in the (u, y) plane; on the ring of energy
H > U**2/2 it removes the angles |psi - psi_w| < arccos(|U| / r) around psi_w = 0 (right wall) or pi (left wall).
"""

from __future__ import annotations

import numpy as np

PSI0 = -0.5 * np.pi
"""Lower end of the angle range; the seam at psi = -pi/2 (x = 0, y < 0) is never inside a forbidden arc."""
PSI1 = 1.5 * np.pi


class RingGrid:
    """Cells of the (H, psi) plane: ``n_energy`` rings between 0 and ``h_max``, ``n_phase`` angles per ring.

    Ring faces include the wall energies so that no ring straddles the grazing orbit. Each ring keeps the
    uniform angle faces that fall inside its allowed arcs (slivers under half a cell are merged), and the arc
    ends where the walls cut it (at the ring's centre energy).

    Parameters
    ----------
    h_max : float
    n_energy, n_phase : int
    walls : dict
        ``{"right": H_R, "left": H_L}`` wall energies (missing key: no wall on that side).
    stretch : float
        theta in (0, 1]: ratio of the ring width at H = 0 to the uniform width h_max / n_energy.
    """

    def __init__(self, h_max: float, n_energy: int, n_phase: int, walls: dict, stretch: float = 1.0):
        self.h_max = float(h_max)
        self.walls = dict(walls)
        # Ring faces H = h_max (theta t + (1 - theta) t**2) on uniform t: rings near H = 0, where the density
        # lives, are 1/theta times finer than near h_max (theta = 1: uniform). Each wall energy replaces the
        # nearest face, so no ring straddles a grazing orbit.
        t = np.linspace(0.0, 1.0, n_energy + 1)
        faces = self.h_max * (stretch * t + (1.0 - stretch) * t * t)
        for h in sorted(float(v) for v in walls.values() if 0.0 < v < self.h_max):
            k = int(np.argmin(np.abs(faces - h)))
            if k in (0, n_energy) or faces[k] in walls.values():
                faces = np.sort(np.append(faces, h))
            else:
                faces[k] = h
        self.H_faces = np.unique(faces)
        self.H_c = 0.5 * (self.H_faces[1:] + self.H_faces[:-1])
        self.dH = np.diff(self.H_faces)
        self.n_rings = len(self.H_c)
        self.dpsi = (PSI1 - PSI0) / n_phase
        uniform = PSI0 + self.dpsi * np.arange(n_phase + 1)
        lo, hi, ring, first = [], [], [], [0]
        self.arcs = []  # per ring: list of (first cell, last cell, cyclic)
        self._wall = {"right": ([], [], []), "left": ([], [], [])}
        for i, Hc in enumerate(self.H_c):
            arcs = self.allowed_arcs(Hc)
            ring_arcs = []
            starts, stops = {}, {}
            for a, b in arcs:
                starts[a] = len(lo)
                inner = uniform[(uniform > a + 0.5 * self.dpsi) & (uniform < b - 0.5 * self.dpsi)]
                edges = np.concatenate([[a], inner, [b]])
                start = len(lo)
                lo.extend(edges[:-1])
                hi.extend(edges[1:])
                ring.extend([i] * (len(edges) - 1))
                ring_arcs.append([start, len(lo) - 1, False])
                stops[b] = len(lo) - 1
            for side, centre in (("right", 0.0), ("left", np.pi)):
                if side in self.walls and Hc > self.walls[side]:
                    w = float(self.wall_angle(side, Hc))
                    # incoming cell starts at centre + w, outgoing ends at centre - w (or at the seam for w = pi/2)
                    c_in = starts.get(centre + w if centre + w < PSI1 else PSI0)
                    out_edge = centre - w if centre - w > PSI0 else PSI1
                    c_out = stops.get(out_edge)
                    if c_in is not None and c_out is not None:
                        for lst, val in zip(self._wall[side], (i, c_in, c_out)):
                            lst.append(val)
            # one arc ending at 3pi/2 and another starting at -pi/2 are joined across the seam
            if len(ring_arcs) >= 1 and arcs[0][0] == PSI0 and arcs[-1][1] == PSI1:
                if len(ring_arcs) == 1:
                    ring_arcs[0][2] = True
                else:
                    ring_arcs[-1][2] = "seam"
            self.arcs.append(ring_arcs)
            first.append(len(lo))
        self.lo = np.array(lo)
        self.hi = np.array(hi)
        self.ring = np.array(ring)
        self.first = np.array(first)
        self.psi = 0.5 * (self.lo + self.hi)
        self.width = self.hi - self.lo
        self.n = len(self.lo)
        # Mass weights: a wall cuts a ring along arccos(|U|/r(H)), which has a square-root onset at the wall
        # energy; the cut at the ring centre would make the ring's area (so p(H)) O(dH**1.5) wrong. The area
        # uses the ring average of the cut angle instead (Gauss-Legendre in s = sqrt(H - H_w), exact onset).
        self.area_width = self.width.copy()
        for side in ("right", "left"):
            rings, cin, cout = (np.array(v, dtype=int) for v in self._wall[side])
            if len(rings) == 0:
                continue
            shift = self._mean_wall_angle(side, rings) - self.wall_angle(side, self.H_c[rings])
            self.area_width[cin] -= shift
            self.area_width[cout] -= shift

    def _mean_wall_angle(self, side, rings, nodes: int = 8):
        """Average over each ring's energies of the wall's half-angle arccos(|U| / r(H))."""
        Hw = self.walls[side]
        t, w = np.polynomial.legendre.leggauss(nodes)
        sa = np.sqrt(np.maximum(self.H_faces[rings] - Hw, 0.0))
        sb = np.sqrt(np.maximum(self.H_faces[rings + 1] - Hw, 0.0))
        s = 0.5 * (sa + sb)[:, None] + 0.5 * (sb - sa)[:, None] * t
        H = Hw + s * s
        integral = np.sum(self.wall_angle(side, H) * 2.0 * s * w, axis=1) * 0.5 * (sb - sa)
        return integral / (self.H_faces[rings + 1] - self.H_faces[rings])

    def wall_angle(self, side: str, H):
        """Half-width arccos(|U|/r) of the forbidden arc of ``side`` at energies H (0 below the wall energy)."""
        Hw = self.walls.get(side)
        H = np.asarray(H, dtype=float)
        if Hw is None:
            return np.zeros_like(H)
        ratio = np.sqrt(np.clip(Hw / np.maximum(H, 1e-300), 0.0, 1.0))
        return np.where(H > Hw, np.arccos(ratio), 0.0)

    def allowed_arcs(self, H: float) -> list[tuple[float, float]]:
        """Allowed angle intervals of the ring at energy H, sorted, inside [-pi/2, 3pi/2]."""
        forbidden = []
        if "right" in self.walls and H > self.walls["right"]:
            a = float(self.wall_angle("right", H))
            forbidden.append((max(-a, PSI0), min(a, PSI1)))
        if "left" in self.walls and H > self.walls["left"]:
            b = float(self.wall_angle("left", H))
            forbidden.append((np.pi - b, np.pi + b))
        arcs, start = [], PSI0
        for a, b in sorted(forbidden):
            if a > start:
                arcs.append((start, a))
            start = max(start, b)
        if start < PSI1:
            arcs.append((start, PSI1))
        return arcs

    # -------------------------------------------------------------- neighbours along a ring
    def angular_faces(self):
        """Faces between consecutive cells of an arc: (lower cell, upper cell, face angle, centre distance)."""
        L, R, F, dist = [], [], [], []
        for arcs in self.arcs:
            for a, b, _cyclic in arcs:
                idx = np.arange(a, b + 1)
                L.append(idx[:-1])
                R.append(idx[1:])
                F.append(self.hi[idx[:-1]])
                dist.append(self.psi[idx[1:]] - self.psi[idx[:-1]])
            for a, b, cyc in arcs:
                if cyc is True:  # full ring: the last cell (below 3pi/2) feeds across the seam into the first
                    L.append([b]), R.append([a]), F.append([PSI1])
                    dist.append([(PSI1 - self.psi[b]) + (self.psi[a] - PSI0)])
                elif cyc == "seam":
                    a0 = arcs[0][0]
                    L.append([b]), R.append([a0]), F.append([PSI1])
                    dist.append([(PSI1 - self.psi[b]) + (self.psi[a0] - PSI0)])
        return (np.concatenate(L).astype(int), np.concatenate(R).astype(int), np.concatenate(F).astype(float),
                np.concatenate(dist).astype(float))

    def radial_faces(self):
        """Overlaps of cells in rings i and i+1: (inner cell, outer cell, face energy, mid angle, length)."""
        inner, outer, Hf, mid, length = [], [], [], [], []
        for i in range(self.n_rings - 1):
            a0, a1 = self.first[i], self.first[i + 1]
            b0, b1 = self.first[i + 1], self.first[i + 2]
            pts = np.unique(np.concatenate([self.lo[a0:a1], self.hi[a0:a1], self.lo[b0:b1], self.hi[b0:b1]]))
            m = 0.5 * (pts[1:] + pts[:-1])
            ca = self._locate(a0, a1, m)
            cb = self._locate(b0, b1, m)
            ok = (ca >= 0) & (cb >= 0)
            inner.append(ca[ok])
            outer.append(cb[ok])
            mid.append(m[ok])
            length.append(np.diff(pts)[ok])
            Hf.append(np.full(ok.sum(), self.H_faces[i + 1]))
        cat = np.concatenate
        return cat(inner).astype(int), cat(outer).astype(int), cat(Hf), cat(mid), cat(length)

    def _locate(self, a0, a1, psi):
        """Cell index in cells a0..a1-1 (sorted, disjoint) containing each angle, or -1."""
        lo, hi = self.lo[a0:a1], self.hi[a0:a1]
        k = np.searchsorted(lo, psi, side="right") - 1
        kk = np.clip(k, 0, len(lo) - 1)
        ok = (k >= 0) & (psi >= lo[kk]) & (psi <= hi[kk])
        return np.where(ok, a0 + kk, -1)

    def locate(self, H, psi):
        """Cell containing each (H, psi) point, or -1 (outside the grid or the walls)."""
        H = np.asarray(H, dtype=float)
        psi = np.asarray(psi, dtype=float)
        i = np.searchsorted(self.H_faces, H, side="right") - 1
        out = np.full(H.shape, -1, dtype=int)
        for r in np.unique(i[(i >= 0) & (i < self.n_rings)]):
            sel = i == r
            out[sel] = self._locate(self.first[r], self.first[r + 1], psi[sel])
        return out

    def neighbours(self):
        """Previous and next cell along each cell's arc (-1 at an open arc end), with the angle offsets."""
        prev = np.full(self.n, -1)
        nxt = np.full(self.n, -1)
        L, R, _, dist = self.angular_faces()
        nxt[L] = R
        prev[R] = L
        d_next = np.zeros(self.n)
        d_prev = np.zeros(self.n)
        d_next[L] = dist
        d_prev[R] = dist
        return prev, nxt, d_prev, d_next

    def wall_cells(self, side: str):
        """Per ring above the wall energy: (ring, incoming cell, outgoing cell) at wall ``side``.

        The flow turns clockwise (psi decreases). At the right wall the incoming cell starts at psi = +alpha
        (y > 0) and the outgoing one ends at -alpha; at the left wall the incoming cell starts at pi + beta
        (y < 0) and the outgoing one ends at pi - beta.
        """
        return tuple(np.array(v, dtype=int) for v in self._wall[side])
