"""The phase-plane solver on several wells: L1 against exact densities, by grid, with the CPU time.

Cases (c = 1, D = 1/2, so the Gibbs density exp(-2 H) is exact):

* ``bistable``: dx = v dt, dv = (-v + x - x**3/4) dt + dW, no walls (the classical benchmark);
* ``bistable-walls``: the same between elastic walls at x = +-2.5 (the Gibbs density is unchanged by them);
* ``single-well``: a = +1, on Cartesian cells and, for comparison, on the energy-angle rings;
* ``newton-walls``: walls at +-2.5 with Newton e = 0.7 (no closed form: successive differences of p(H) on 100 bins).

L1 of the joint density: int int |p_num(x, y) - p(x, y)| dx dy over the solution's box (midpoint rule on
1201 x 1201 points, the exact density normalised on the box). L1 of p(H): sum over 100 equal bins of [min G,
h_max] of |P_num(bin) - P(bin)|. Time: CPU seconds (time.process_time) of one solve, the p(H) integration
included, without the two-grid check.

Run: ``python benchmarks/fpk_multiwell.py`` (about a minute of CPU).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.special import erf

from averaging.phase_plane import solve_phase_plane
from averaging.phase_plane.cartesian import solve_cartesian
from models import Elastic, ImpactOscillator, Newton

H_MAX = 10.0
GRIDS = (40, 60, 80, 120, 160)


def model(a=-1.0, delta=None, law=None):
    params = {"a": a, "b": 0.25, "c": 1.0, "D": 0.5}
    if delta is not None:
        params["delta"] = delta
    return ImpactOscillator("a*x + b*x**3", "c*y", parameters=params, barriers="delta" if delta else None,
                            restitution=law)


def potential(a):
    return lambda x: 0.5 * a * x * x + x**4 / 16.0


def joint_l1(sd, a, n=1201):
    (lo, hi), ym = sd.box()
    xe, ye = np.linspace(lo, hi, n + 1), np.linspace(-ym, ym, n + 1)
    xc, yc = 0.5 * (xe[1:] + xe[:-1]), 0.5 * (ye[1:] + ye[:-1])
    area = (xe[1] - xe[0]) * (ye[1] - ye[0])
    X, Y = np.meshgrid(xc, yc)
    exact = np.exp(-2.0 * (0.5 * Y * Y + potential(a)(X)))
    exact /= exact.sum() * area
    return float(np.abs(sd.joint(xc, yc) - exact).sum() * area)


def energy_bins(a, edges, lo, hi):
    """Exact P(H in bin): x quadrature on 4e5 points, the y integral in closed form (sqrt(pi) erf)."""
    xs = np.linspace(lo, hi, 400001)
    G = potential(a)(xs)
    w = np.exp(-2.0 * G)
    cdf = np.array([np.sum(w * erf(np.sqrt(2.0 * np.maximum(h - G, 0.0)))) for h in edges]) / np.sum(w)
    return np.diff(cdf / cdf[-1])


def row(case, grid, sd, seconds, l1_joint, l1_h):
    print(f"| {case} | {grid} | {sd.grid.n} | {l1_joint} | {l1_h} | {seconds:.2f} |")
    sys.stdout.flush()


def main():
    print("| case | grid | cells | L1 joint | L1 p(H) | CPU s |")
    print("|---|---|---|---|---|---|")
    for case, a, delta in (("bistable", -1.0, None), ("bistable-walls", -1.0, 2.5), ("single-well", 1.0, None)):
        m = model(a, delta, Elastic() if delta else None)
        lo, hi = (-delta, delta) if delta else (-8.0, 8.0)
        for n in GRIDS:
            t = time.process_time()
            sd = solve_cartesian(m, grid=(n, n), h_max=H_MAX, points=3)
            seconds = time.process_time() - t
            edges = np.linspace(sd.h_min, H_MAX, 101)
            l1_h = np.abs(sd.bin_masses(edges) - energy_bins(a, edges, lo, hi)).sum()
            row(case, f"{n} x {n}", sd, seconds, f"{joint_l1(sd, a):.2g}", f"{l1_h:.2g}")
    m = model(1.0)
    for grid in ((160, 192), (320, 384)):
        t = time.process_time()
        sd = solve_phase_plane(m, grid=grid, h_max=8.0, points=3)
        seconds = time.process_time() - t
        edges = np.linspace(0.0, 8.0, 101)
        l1_h = np.abs(sd.bin_masses(edges) - energy_bins(1.0, edges, -8.0, 8.0)).sum()
        row("single-well, rings (h_max 8)", f"{grid[0]} x {grid[1]}", sd, seconds, f"{joint_l1(sd, 1.0):.2g}",
            f"{l1_h:.2g}")
    m = model(-1.0, 2.5, Newton(0.7))
    prev = None
    for n in GRIDS:
        t = time.process_time()
        sd = solve_cartesian(m, grid=(n, n), h_max=H_MAX, points=3)
        seconds = time.process_time() - t
        cur = sd.bin_masses(np.linspace(sd.h_min, H_MAX, 101))
        diff = "" if prev is None else f"{np.abs(cur - prev).sum():.2g} (vs previous grid)"
        row("newton-walls e = 0.7", f"{n} x {n}", sd, seconds, "no closed form", diff)
        prev = cur


if __name__ == "__main__":
    main()
