"""The energy from rest: Monte Carlo at fixed times against the averaged transient density.
==========================================================================================

    x'' + c x' + x + b x^3 = sqrt(2 D) xi(t),   ``|x| < 1``,   Ma's restitution (Example 1 of the paper)

``simulate_snapshots`` records the ensemble at the times t_j = j T / N from one start (here rest, x = y = 0):
E[H](t_j) with a 95 % confidence interval, and the histogram of H at each t_j. ``averaging.transient_density``
solves the averaged forward equation (eqs. 27-29) for p(H, t | H0 = 0). Two checks, then the comparison:

1. A linear oscillator without barriers, whose E[H](t) from rest is exact (a matrix exponential of the moment
   equations): the Monte Carlo must agree within 3 CIs at every time.
2. The Duffing impact model: the averaged E[H](t) (``jump``, impacts as jumps of the energy) beside the Monte
   Carlo. Averaging assumes many oscillations per change of energy; the printed table shows by how much it differs,
   in units of the Monte Carlo CI, without asking it to agree.

Run:  python examples/13_transient_from_rest.py [--quick] [--outdir DIR]   (headless; exits 1 if check 1 fails)
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.linalg import expm

from averaging.transient import transient_density
from hybrid.stochastic import simulate_snapshots
from models import DuffingImpact, ImpactOscillator, Ma


def exact_linear(c: float, D: float, t: float) -> float:
    """E[H](t) from rest of x'' + c x' + x = sqrt(2 D) xi: the moments (Exx, Exy, Eyy) solve a linear ODE."""
    gen = np.zeros((4, 4))
    gen[:3, :3] = [[0, 2, 0], [-1, -c, 1], [0, -2, -2 * c]]
    gen[2, 3] = 2 * D
    exx, _, eyy = (expm(gen * t) @ [0.0, 0.0, 0.0, 1.0])[:3]
    return 0.5 * (exx + eyy)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").partition("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer paths (a smoke run)")
    parser.add_argument("--outdir", default=None, help="folder for the figure (default: a new temporary folder)")
    args = parser.parse_args(argv)
    paths = 1000 if args.quick else 4000
    ok = True

    c, D = 0.1, 0.05
    linear = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    snap = simulate_snapshots(linear, "splitting", dt=0.01, paths=paths, t_end=30.0, snapshots=6, x0=(0.0, 0.0),
                              seed=11, histograms={"H": (0.0, 3.0, 60)}, chunk_paths=paths // 16)
    print(f"1. linear oscillator from rest, {paths} paths: E[H](t) against the exact moments")
    for j, t in enumerate(snap.times):
        est, exact = snap.mean("H", j), exact_linear(c, D, t)
        good = abs(est.value - exact) <= 3 * est.ci
        ok &= good
        print(f"   t = {t:5.1f}   MC {est}   exact {exact:.5f}   {'ok' if good else 'FAIL'}")

    model = DuffingImpact(restitution=Ma(0.4))
    snap = simulate_snapshots(model, "splitting", dt=0.01, paths=paths, t_end=80.0, snapshots=8, x0=(0.0, 0.0),
                              seed=12, histograms={"H": (0.0, 4.0, 80)}, chunk_paths=paths // 16)
    averaged = transient_density(model, 0.0, snap.times, method="jump", points=800)
    mc, ci = snap.means("H")
    print(f"2. Example 1 (Ma V_C = 0.4) from rest, {paths} paths: E[H](t), Monte Carlo and averaged (jump)")
    print("       t     MC E[H]      CI      jump   (jump - MC) / CI")
    for t, m, h, a in zip(snap.times, mc, ci, averaged.mean_energy):
        print(f"   {t:5.1f}   {m:9.5f}   {h:7.5f}   {a:7.5f}   {(a - m) / h:+6.1f}")

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        plt = None
    if plt is not None:
        outdir = Path(args.outdir) if args.outdir else Path(tempfile.mkdtemp(prefix="vibro-example-13-"))
        outdir.mkdir(parents=True, exist_ok=True)
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.errorbar(snap.times, mc, yerr=ci, fmt="o", ms=4, capsize=3, label="Monte Carlo (95 % CI)")
        dense = np.linspace(0.0, snap.times[-1], 200)
        ax.plot(dense, transient_density(model, 0.0, dense, method="jump", points=800).mean_energy, "k-",
                label="averaged transient (jump)")
        ax.set(xlabel="t", ylabel="E[H](t)", title="Example 1 from rest (x = y = 0)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(outdir / "13_transient_from_rest.png", dpi=110)
        print(f"wrote {outdir / '13_transient_from_rest.png'}")
    print("OK" if ok else "FAILED: see above")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
