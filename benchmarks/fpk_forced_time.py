"""The time error of the forced ``fpk`` solver, and the estimate of it from a third run at half the steps.

The result of ``periodic_density_xy`` (``scheme="richardson"``) is R_K = (4 p_2K - p_K) / 3, with p_K the periodic
Crank-Nicolson density at K steps per period. Its time error is measured here against R_128 (Crank-Nicolson at 128
and 256 steps) on the same cells, so that the cells' error cancels: the L1 of p(H | t) on 100 bins of the energy
range, worst of 8 phases. The estimate is |R_K - R_K/2| / 3 (order 2 assumed: conservative for a combination
whose order rises from 2 to 4 as dt falls), on the same cells and on the cells twice coarser (where the solver
computes it: the check's grid). The whole estimate (cells + time steps) of ``periodic_density_xy`` is also
compared with the true error of the linear case, from its closed form.

Models: example 08's forced Duffing impact oscillator (D = 0.02, Newton r = 0.8, walls at +-1; cells (60, 120) and
(30, 60)) and the linear oscillator without walls (c = 0.5, W = 1.3, A = 0.4, D = 0.05; (32, 32) and (16, 16)).
Run: ``python benchmarks/fpk_forced_time.py [--quick]`` (CPU is ``time.process_time``).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from averaging.phase_plane import forced as F  # noqa: E402
from hybrid.automaton import lambdify_numeric  # noqa: E402
from models import ForcedDuffingImpact, ImpactOscillator, Newton, X, Y  # noqa: E402
from models.oscillator import T  # noqa: E402

sys.path.insert(0, str(ROOT / "tests"))
from problems import forced_linear_energy_masses  # noqa: E402

PHASES = 8


def cn_runs(model, h, grid, steps_list):
    """{K: snapshots (K, cells)} of the periodic Crank-Nicolson density at each K, and the plane."""
    free = F.unforced(model)
    left, right = F._walls(model, "model")
    plane = F._CartesianPlane(model, free, model.restitution, h, *grid, left, right)
    drift = lambdify_numeric((X, Y, T), model.substitute(model.ito_drift))
    period = model.forcing_period
    top = max(steps_list)
    xs, ys = plane.drift_xy
    drifts = [np.broadcast_to(np.asarray(drift(xs, ys, t), dtype=float), xs.shape) for t in
              period / top * np.arange(top)]
    operators = [plane.operator(m) for m in drifts]
    p0 = F.null_vector(plane.disc.A, plane.mass_weight)
    out, cpu = {}, {}
    for K in sorted(steps_list):
        s = top // K
        t0 = time.process_time()
        out[K] = F._fixed_point(plane, operators[::s], drifts[::s], period / K, "cn", p0, 1e-10, 300)[0]
        cpu[K] = time.process_time() - t0
    return plane, operators, out, cpu


def masses(model, plane, operators, snapshots, h, edges):
    """(PHASES, bins) bin masses of p(H | k T / PHASES)."""
    K = len(snapshots)
    sol = F.PeriodicDensity(model, plane, model.forcing_period * np.arange(K) / K, model.forcing_period, snapshots,
                            operators[::len(operators) // K], 50, h)
    return np.array([s.bin_masses(edges) for s in sol.sections(PHASES)])


def study(label, model, h, fine, coarse, ks, ref_k):
    edges = np.linspace(F.confining_range(F.unforced(model).potential, h, *F._walls(model, "model"))[2], h, 101)
    steps = sorted({*ks, *(2 * k for k in ks), *(k // 2 for k in ks), ref_k, 2 * ref_k})
    print(f"{label}: h = {h:.4g}; L1 of p(H | t) on 100 bins, worst of {PHASES} phases", flush=True)
    rich = {}
    for g in (fine, coarse):
        plane, ops, cn, cpu = cn_runs(model, h, g, [k for k in steps if k >= PHASES // 2])
        rich[g] = {K: (4.0 * cn[2 * K][::2] - cn[K]) / 3.0 for K in cn if 2 * K in cn}
        rich[g] = {K: masses(model, plane, ops, R, h, edges) for K, R in rich[g].items() if K >= PHASES}
        rich[g]["cpu"] = cpu
    ref = rich[fine][ref_k]
    print("   K + 2K    true (fine)  est. fine  ratio   est. coarse  ratio   CPU s of the K/2 run (fine, coarse)")
    for K in ks:
        true = np.abs(rich[fine][K] - ref).sum(axis=1).max()
        est = {g: np.abs(rich[g][K] - rich[g][K // 2]).sum(axis=1).max() / 3.0 for g in (fine, coarse)}
        print(f"   {K:3d} + {2 * K:3d}  {true:.2e}     {est[fine]:.2e}   {est[fine] / true:5.2f}   "
              f"{est[coarse]:.2e}     {est[coarse] / true:5.2f}   {rich[fine]['cpu'][K // 2]:.1f}, "
              f"{rich[coarse]['cpu'][K // 2]:.1f}", flush=True)


def total_linear(lin, runs):
    """The whole estimate (cells + time steps) of ``periodic_density_xy`` against the closed form: 2 c H / D is
    noncentral chi-square at every section (L1 of p(H | t) on 100 bins of its range, worst of 8 phases)."""
    c, A, W, D = (lin.params[k] for k in ("c", "A", "W", "D"))
    z = A / (1.0 - W**2 + 1j * c * W)
    print("linear oscillator, the whole estimate against the closed form (L1 of p(H | t), 100 bins, worst of 8 "
          "phases)")
    print("   grid       K + 2K    cells     time      estimate  true      estimate / true  CPU s")
    for grid, K in runs:
        t0 = time.process_time()
        sol = F.periodic_density_xy(lin, grid=grid, steps=K, h_max=3.0, phases=8, l1_tol=1.0)
        cpu = time.process_time() - t0
        edges = np.linspace(0.0, sol.grid.h_max, 101)
        true = 0.0
        for t, s in zip(sol.phase_times(8), sol.sections(8)):
            exact = forced_linear_energy_masses(z, W, c, D, t, edges)
            true = max(true, float(np.abs(s.bin_masses(edges) - exact).sum()))
        print(f"   {str(grid):10s} {K:3d} + {2 * K:3d}  {sol.grid_estimate:.2e}  {sol.time_estimate:.2e}  "
              f"{sol.error_estimate:.2e}  {true:.2e}  {sol.error_estimate / true:6.2f}           {cpu:.1f}", flush=True)


def main(quick: bool) -> None:
    lin = ImpactOscillator("x", "c*y", forcing="A*cos(W*t)", barriers=None,
                           parameters={"c": 0.5, "A": 0.4, "W": 1.3, "D": 0.05})
    total_linear(lin, [((24, 24), 16), ((32, 32), 16), ((32, 32), 32), ((48, 48), 16), ((48, 48), 32),
                       ((64, 64), 64)][:3 if quick else None])
    if quick:
        return
    study("linear oscillator, no walls", lin, 3.0, (32, 32), (16, 16), (16, 32, 64), 128)
    duff = ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=0.02)
    h = F.periodic_density_xy(duff, grid=(30, 60), steps=8, scheme="cn", check=False).grid.h_max
    study("example 08, D = 0.02", duff, h, (60, 120), (30, 60), (16, 32, 64), 128)


if __name__ == "__main__":
    main("--quick" in sys.argv)
