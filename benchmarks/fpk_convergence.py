"""Grid convergence of the ``fpk`` phase-plane solver, as fitted orders.

1. Elastic Duffing between walls at +-1 (c = 0.1, D = 0.05): L1 of p(H) (100 bins) against the exact density
   p ~ exp(-cH/D), conditioned on [0, h_max] (exact there: its cross-orbit flux vanishes).
2. An impact case, Fig. 2 with delta = 1.0 (Ma, V_C = 0.4): successive differences L1(p_h, p_h/2); the order is
   log2 of the ratio of successive differences.
3. The equilibrium wall (linear, c = D = 0.05, Newton r = 0.6): successive differences of E[H].

Both grid directions are refined together: (rings, angles) = (40, 48) * 2**k.

4. The a-posteriori estimate (``PhaseDensity.estimate_error``: three grids, Richardson at the observed order capped
   at the lowest fitted ``ESTIMATE_ORDER``) against the true L1 error on the two problems with exact p(H): elastic
   walls (Gibbs) and the linear oscillator with a stop at the equilibrium, r = 1 (the folded Gaussian), on 100 and
   40 bins.

Run: ``python benchmarks/fpk_convergence.py [--estimate-only]``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from averaging.phase_plane import solve_phase_plane  # noqa: E402

GRIDS = [(40, 48), (80, 96), (160, 192), (320, 384)]


def fitted_order(h, err):
    """Least-squares slope of log err against log h."""
    return float(np.polyfit(np.log(h), np.log(err), 1)[0])


def elastic(grids=GRIDS):
    from problems import elastic_duffing

    model, ex = elastic_duffing(delta=1.0, c=0.1, D=0.05)
    h_max = 6.0
    edges = np.linspace(0.0, h_max, 101)
    cdf = np.array([ex.probability_below(h) for h in edges]) / ex.probability_below(h_max)
    errs = []
    for g in grids:
        t0 = time.perf_counter()
        sd = solve_phase_plane(model, grid=g, h_max=h_max)
        errs.append(float(np.abs(sd.bin_masses(edges) - np.diff(cdf)).sum()))
        print(f"  elastic {g}: L1 = {errs[-1]:.2e} ({time.perf_counter() - t0:.2f} s)", flush=True)
    return errs, fitted_order(1.0 / np.array([g[0] for g in grids]), errs)


def successive(quantity, grids=GRIDS, label=""):
    vals = []
    for g in grids:
        t0 = time.perf_counter()
        vals.append(quantity(g))
        print(f"  {label} {g}: done ({time.perf_counter() - t0:.2f} s)", flush=True)
    diffs = [float(np.abs(np.asarray(a) - np.asarray(b)).sum()) for a, b in zip(vals[:-1], vals[1:])]
    return vals, diffs, fitted_order(1.0 / np.array([g[0] for g in grids[:-1]]), diffs)


def estimate_against_exact(grids=GRIDS):
    """Rows (problem, grid, bins, true L1, estimated L1) on the exact problems of tests/test_phase_plane.py."""
    import warnings

    from test_phase_plane import _exact_problems

    from averaging.phase_plane import stationary_density_xy

    rows = []
    for name, model, h_max, kw, cdf in _exact_problems():
        for g in grids:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sd = stationary_density_xy(model, grid=g, h_max=h_max, **kw)
            dt = time.perf_counter() - t0
            for bins in (100, 40):
                edges = np.linspace(0.0, h_max, bins + 1)
                true = float(np.abs(sd.bin_masses(edges) - np.diff(cdf(edges))).sum())
                est = sd.estimate_error(edges)
                rows.append((name, g, bins, true, est))
                print(f"  {name:48s} {str(g):11s} {bins:4d} bins: true {true:.2e} estimate {est:.2e} "
                      f"ratio {est / true:5.2f} ({dt:.2f} s with the estimate)", flush=True)
    bounded = sum(est >= true for *_, true, est in rows)
    print(f"estimate >= true error in {bounded} of {len(rows)} cases")
    import json

    (ROOT / "benchmarks" / "data" / "fpk_estimate.json").write_text(json.dumps(
        [{"problem": n, "grid": list(g), "bins": b, "true": t, "estimate": e} for n, g, b, t, e in rows], indent=1))
    return rows


def main():
    if "--estimate-only" in sys.argv:
        estimate_against_exact()
        return
    estimate_against_exact()
    errs, order = elastic()
    print(f"elastic density: L1 {', '.join(f'{e:.2e}' for e in errs)}; fitted order {order:.2f}")
    from vibro.studies.figures.specs import FIGURES

    case = FIGURES[2].cases[1]
    edges = np.linspace(0.0, case.h_max, 101)
    _, diffs, order = successive(
        lambda g: solve_phase_plane(case.build(), grid=g, h_max=case.h_max).bin_masses(edges), label="fig2 delta=1")
    print(f"Fig. 2 delta = 1.0: successive L1 {', '.join(f'{d:.2e}' for d in diffs)}; fitted order {order:.2f}")
    from models import ImpactOscillator, Newton

    lin = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=None)
    vals, diffs, order = successive(
        lambda g: solve_phase_plane(lin, grid=g, h_max=2.5, walls=(None, 0.0), restitution=Newton(0.6)).mean_energy,
        label="equilibrium wall r=0.6")
    print(f"equilibrium wall r = 0.6: E[H] {', '.join(f'{v:.5f}' for v in vals)}; successive differences "
          f"{', '.join(f'{d:.1e}' for d in diffs)}; fitted order {order:.2f}")


if __name__ == "__main__":
    main()
