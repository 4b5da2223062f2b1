"""Accuracy and cost of p(H) by ``paper``, ``jump``, ``chain`` and ``fpk`` against Monte Carlo on 21 paper cases.

L1 = sum |m_method - m_MC| over 100 bins of [0, h_max], with m the bin probabilities (the methods' bin masses,
unnormalised; Monte Carlo counts over its total count). ``noise`` is the expected L1 of the Monte Carlo
histogram itself (half the L1 between its two independent halves, :func:`vibro.solve.metrics.halves_noise_l1`).
Monte Carlo references come from ``benchmarks/mc_references.py`` (cached in ``benchmarks/data``).

Run: ``python benchmarks/density_accuracy.py [--grid NE NP] [--cases f2_1,f12_0]``.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from averaging import stationary_density  # noqa: E402
from averaging.chain import chain_density  # noqa: E402
from averaging.phase_plane import solve_phase_plane, stationary_density_xy  # noqa: E402
from benchmarks.mc_references import DATA, cases  # noqa: E402
from vibro.solve.metrics import bin_average  # noqa: E402

BINS = 100


def mc_masses(store, key):
    a = store[key + "_a"].reshape(BINS, -1).sum(axis=1).astype(float)
    b = store[key + "_b"].reshape(BINS, -1).sum(axis=1).astype(float)
    merged = (a + b) / (a.sum() + b.sum())
    noise = 0.5 * float(np.abs(a / a.sum() - b / b.sum()).sum())
    return merged, noise


def _cold():
    """Empty the cache of averaged-coefficient tables, so that each timed method builds its own (the symbolic
    derivation, once per model declaration, stays cached)."""
    import averaging.stationary as st

    st._TABLES.clear()


def averaging_masses(model, method, h_max, edges):
    _cold()
    t0 = time.perf_counter()
    sd = stationary_density(model, method, h_max=h_max, points=2000)
    dt = time.perf_counter() - t0
    return bin_average(sd.H, sd.p, edges) * np.diff(edges), dt, sd.mean_energy


def chain_masses(model, h_max, edges, **kw):
    _cold()
    t0 = time.perf_counter()
    sd = chain_density(model, h_max=h_max, **kw)
    dt = time.perf_counter() - t0
    return bin_average(sd.H, sd.p, edges) * np.diff(edges), dt, sd.mean_energy


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", type=int, nargs=2, default=None)
    ap.add_argument("--cases", default=None)
    ap.add_argument("--no-check", action="store_true", help="time fpk without the coarse-grid error estimate")
    args = ap.parse_args(argv)
    store = dict(np.load(DATA))
    only = set(args.cases.split(",")) if args.cases else None
    kw = {} if args.grid is None else {"grid": tuple(args.grid)}
    print(f"{'case':7s} {'label':10s} {'paper':>7s} {'jump':>7s} {'chain':>7s} {'fpk':>7s} {'noise':>7s} | "
          f"{'t_paper':>7s} {'t_jump':>7s} {'t_chain':>7s} {'t_fpk':>7s} {'t_solve':>6s} | {'E[H] fpk':>9s} "
          f"{'E[H] MC':>15s} {'est':>7s}")
    rows = []
    for key, _n, case, _dt, _burn in cases(equilibrium=False):
        if only and key not in only:
            continue
        if key + "_a" not in store:
            continue
        model = case.build()
        edges = np.linspace(0.0, case.h_max, BINS + 1)
        mc, noise = mc_masses(store, key)
        res = {}
        for meth in ("paper", "jump"):
            m, t, _ = averaging_masses(model, meth, case.h_max, edges)
            res[meth] = (float(np.abs(m - mc).sum()), t)
        m, t, _ = chain_masses(model, case.h_max, edges)
        res["chain"] = (float(np.abs(m - mc).sum()), t)
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            if args.no_check:
                sd = solve_phase_plane(model, h_max=case.h_max, **kw)
            else:
                sd = stationary_density_xy(model, h_max=case.h_max, **kw)
        tf = time.perf_counter() - t0
        t0 = time.perf_counter()
        solve_phase_plane(model, h_max=case.h_max, **kw)  # one solve, without the coarse-grid error estimate
        ts = time.perf_counter() - t0
        l1f = float(np.abs(sd.bin_masses(edges) - mc).sum())
        centres = 0.5 * (edges[1:] + edges[:-1])
        e_mc = float(np.sum(mc * centres))
        info = store[key + "_info"]
        ci = 0.5 * np.hypot(info[6], info[8]) / np.sqrt(float(store.get(key + "_pairs", [1])[0]))
        est = sd.error_estimate if sd.error_estimate is not None else float("nan")
        print(f"{key:7s} {case.label:10s} {res['paper'][0]:7.4f} {res['jump'][0]:7.4f} {res['chain'][0]:7.4f} "
              f"{l1f:7.4f} {noise:7.4f} | {res['paper'][1]:7.3f} {res['jump'][1]:7.3f} {res['chain'][1]:7.3f} "
              f"{tf:7.3f} {ts:6.3f} | {sd.mean_energy:9.5f} "
              f"{e_mc:8.5f}±{ci:.5f} {est:7.4f}" + (" WARN" if w else ""), flush=True)
        rows.append((res["paper"][0], res["jump"][0], res["chain"][0], l1f, noise, tf, ts, res["paper"][1],
                     res["jump"][1], res["chain"][1]))
    if rows:
        r = np.array(rows)
        med = np.median(r, axis=0)
        print(f"median  {'':10s} {med[0]:7.4f} {med[1]:7.4f} {med[2]:7.4f} {med[3]:7.4f} {med[4]:7.4f} | "
              f"{med[7]:7.3f} {med[8]:7.3f} {med[9]:7.3f} {med[5]:7.3f} {med[6]:6.3f}")
        print(f"worst   {'':10s} {r[:, 0].max():7.4f} {r[:, 1].max():7.4f} {r[:, 2].max():7.4f} {r[:, 3].max():7.4f} "
              f"{r[:, 4].max():7.4f} | {r[:, 7].max():7.3f} {r[:, 8].max():7.3f} {r[:, 9].max():7.3f} "
              f"{r[:, 5].max():7.3f} {r[:, 6].max():6.3f}")


def equilibrium_cases(grid=None):
    """E[H] of fpk for the linear oscillator with one wall at x = 0 against Monte Carlo at dt and dt/2."""
    from benchmarks.mc_references import EQ_RESTITUTION, eq_model
    from models import ImpactOscillator

    store = dict(np.load(DATA))
    print("\nlinear oscillator, c = 0.05, D = 0.05, one wall at the equilibrium (Newton r); E[H]:")
    print(f"{'r':>4s} {'fpk':>8s} {'t_fpk':>6s} {'MC dt=0.01':>17s} {'MC dt=0.005':>17s} {'fpk-MC(dt/2)':>12s} | "
          f"{'chain':>8s} {'t_chain':>7s} {'chain-MC':>9s} | {'Poisson':>8s} {'Poisson-MC':>10s}")
    for r in EQ_RESTITUTION:
        lin = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=None)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sd = stationary_density_xy(lin, h_max=2.5, walls=(None, 0.0), restitution=eq_model(r).restitution,
                                       **({} if grid is None else {"grid": grid}))
        tf = time.perf_counter() - t0
        out = []
        for suffix in ("", "_half"):
            E = store[f"eq{r}{suffix}_E"]
            out.append((E.mean(), 2.13 * E.std(ddof=1) / np.sqrt(len(E))))  # t(0.975, 15)
        (e1, c1), (e2, c2) = out
        t0 = time.perf_counter()
        # the chain's top is reflecting: h_max = 8 leaves < 1e-4 of E[H] to the cut (the Poisson clock's tail is heavy)
        _cold()
        stop = ImpactOscillator("x", "c*y", parameters={"c": 0.05, "D": 0.05}, barriers=(0, None),
                                restitution=eq_model(r).restitution)
        ch = chain_density(stop, h_max=8.0)
        tc = time.perf_counter() - t0
        # one phase, no extrapolation: the Poisson clock of the jump method
        po = chain_density(stop, h_max=8.0, phases=1, extrapolate=False)
        print(f"{r:4.1f} {sd.mean_energy:8.5f} {tf:6.2f} {e1:9.5f}±{c1:.5f} {e2:9.5f}±{c2:.5f} "
              f"{100 * (sd.mean_energy / e2 - 1):+10.2f} % | {ch.mean_energy:8.5f} {tc:7.3f} "
              f"{100 * (ch.mean_energy / e2 - 1):+7.2f} % | {po.mean_energy:8.5f} "
              f"{100 * (po.mean_energy / e2 - 1):+8.2f} %  (fpk est. L1 {sd.error_estimate:.4f})")


def dt_bias():
    """L1 between the Monte Carlo references at dt and dt/2, with their noise, and fpk against each."""
    from benchmarks.mc_references import HALF_DT_CASES

    store = dict(np.load(DATA))
    print("\nMonte Carlo dt bias (100 bins): L1(MC dt, MC dt/2), noise of each; fpk against each")
    for key, _n, case, dt, _burn in cases(equilibrium=False):
        if key not in HALF_DT_CASES or key + "_half_a" not in store:
            continue
        a, na = mc_masses(store, key)
        b, nb = mc_masses(store, key + "_half")
        edges = np.linspace(0.0, case.h_max, BINS + 1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sd = solve_phase_plane(case.build(), h_max=case.h_max)
        m = sd.bin_masses(edges)
        print(f"{key:7s} dt={dt:g}: L1(dt, dt/2)={np.abs(a - b).sum():.4f} noise {na:.4f}/{nb:.4f}; "
              f"fpk-MC(dt)={np.abs(m - a).sum():.4f} fpk-MC(dt/2)={np.abs(m - b).sum():.4f}")


if __name__ == "__main__":
    main()
    if "--cases" not in sys.argv:
        equilibrium_cases()
        dt_bias()
