"""Validity and failure maps: where each averaging method, Monte Carlo scheme and orbit backend stops working.

``vibro bench validity --out-dir DIR [--quick]`` calls :func:`validity_maps`, which writes

* ``averaging_<grid>.csv`` / ``.png`` over the grids (c, D), (V_C, delta) and constant e: the L1 distance of each
  averaging method (paper, exact-two-impact, jump), of the impact-to-impact chain and of the phase-plane FPK
  solver (fpk) from Monte Carlo, with the cells where the quasi-conservative
  assumption breaks hatched (damping work per cycle over H at the 90th-percentile energy above
  :data:`vibro.solve.MAX_DAMPING_RATIO`, or impact loss per quasi-period above ``MAX_IMPACT_RATIO``);
  the same rows carry the loss ratios r_imp and r_damp, from which :func:`fit_error_model` fits the error model
  of :mod:`vibro.solve`;
* ``mc_failures.csv`` / ``.png``: Monte Carlo L1 error against the elastic closed form over dt times the
  speed scale over the gap (dt against the barrier-crossing time), with what the step rule said (ok / warned /
  refused), for each scheme, and the stiff-potential refusal;
* ``mc_chattering.csv``: the impact rate of a path pressed into a wall with e < 1 against dt (it does not converge);
* ``orbit_failures.csv``: orbit statuses for Zeno (a force pushing into a wall with e < 1), chattering and grazing.
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

import numpy as np

from hybrid.io import atomic_write, atomic_write_text, write_csv_atomically
from vibro.solve import diagnose, pick_scheme
from vibro.solve.errormodel import L1_BINS, MAX_DAMPING_RATIO, MAX_IMPACT_RATIO
from vibro.solve.metrics import bin_masses, l1_between_histograms, rebin_counts

AVERAGING_METHODS = ("paper", "exact-two-impact", "jump")
"""The averaging methods whose error model :func:`fit_error_model` fits (the constants of :mod:`vibro.solve`)."""
EXTRA_METHODS = ("chain", "fpk")
"""Measured and drawn beside them: the impact-to-impact chain (averaged coefficients, so the quasi-conservative
hatching applies) and the phase-plane FPK solver (no averaging: never hatched)."""


def _grids(quick: bool) -> dict:
    """name -> (x label, x values, y label, y values, model factory(x, y))."""
    from models import DuffingImpact, Ma, Newton, RayleighImpact

    if quick:
        cs, Ds = [0.025, 0.1, 0.4], [0.01, 0.05, 0.2]
        vcs, deltas = [0.1, 0.4, 1.2], [0.6, 1.0, 1.6]
        es, Des = [0.5, 0.8, 0.95], [0.02, 0.1]
        k3s, Drs = [0.003, 0.03, 0.1], [0.02, 0.1]
    else:
        cs, Ds = [0.0125, 0.025, 0.05, 0.1, 0.2, 0.4], [0.01, 0.025, 0.05, 0.1, 0.2]
        vcs, deltas = [0.05, 0.1, 0.2, 0.4, 0.8, 1.6], [0.6, 0.8, 1.0, 1.3, 1.6]
        es, Des = [0.3, 0.5, 0.7, 0.8, 0.9, 0.95], [0.01, 0.05, 0.2]
        k3s, Drs = [0.003, 0.01, 0.03, 0.1], [0.01, 0.03, 0.1]
    return {
        "c_D": ("c", cs, "D", Ds, lambda c, D: DuffingImpact(c=c, D=D)),
        "vc_delta": ("V_C", vcs, "delta", deltas, lambda vc, d: DuffingImpact(restitution=Ma(vc), delta=d)),
        "newton_e": ("e", es, "D", Des, lambda e, D: DuffingImpact(restitution=Newton(e), D=D)),
        # nonlinear (Rayleigh) damping c y + k3 y^3 with elastic walls: isolates the damping term of the error model
        "rayleigh_k3": ("k3", k3s, "D", Drs,
                        lambda k3, D: RayleighImpact(restitution=Ma(1e3), c=0.01, k3=k3, D=D, delta=1.5)),
    }


def _mc_settings(model, diag, quick: bool):
    """Reference Monte Carlo settings: burn-in and length in units of the energy relaxation time."""
    tau = diag.relaxation_time if np.isfinite(diag.relaxation_time) else 40.0
    paths = 128
    t_sample = min((600.0 if quick else 1500.0) * tau, 24000.0 if quick else 60000.0)
    t_burn = min(max(10.0 * tau, 100.0), 5000.0)
    return dict(dt=0.01, paths=paths, t_end=t_sample + t_burn, t_burn=t_burn)


def averaging_map(name: str, quick: bool = True, seed: int = 3, progress=print):
    """One row per (grid cell): L1 of each averaging method from MC, MC noise, loss ratios, wall times."""
    import pandas as pd

    from averaging import stationary_density
    from hybrid.stochastic import simulate_ensemble

    xl, xs, yl, ys, make = _grids(quick)[name]
    rows = []
    for yv in ys:
        for xv in xs:
            model = make(xv, yv)
            diag = diagnose(model)
            h_max = diag.h_max
            edges = np.linspace(0.0, h_max, L1_BINS + 1)
            s = _mc_settings(model, diag, quick)
            scheme = pick_scheme(model)
            kw = dict(scheme=scheme, dt=s["dt"], paths=s["paths"] // 2, t_end=s["t_end"], t_burn=s["t_burn"],
                      h_max=h_max, bins=L1_BINS * 10, xy_bins=None)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                a = simulate_ensemble(model, seed=seed, **kw)
                b = simulate_ensemble(model, seed=seed + 1, **kw)
            ma, mb = rebin_counts(a.h_counts, L1_BINS), rebin_counts(b.h_counts, L1_BINS)
            noise = l1_between_histograms(ma, mb) / 2.0
            ref = (ma + mb) / (ma + mb).sum()
            row = {xl: xv, yl: yv, "mc_noise": noise, "mc_wall": a.wall_time + b.wall_time, "h_max": h_max,
                   "r_imp": diag.r_imp, "r_damp": diag.r_damp, "r_damp_p90": diag.r_damp_p90,
                   "r_imp_p90": diag.r_imp_p90, "tail": diag.tail_impact_speed,
                   "quasi_conservative": bool(diag.r_damp_p90 <= MAX_DAMPING_RATIO
                                              and diag.r_imp_p90 <= MAX_IMPACT_RATIO)}
            for method in AVERAGING_METHODS:
                t0 = time.perf_counter()
                try:
                    sd = stationary_density(model, method=method, h_max=h_max, points=1000)
                    row[f"l1_{method}"] = float(np.abs(bin_masses(sd.H, sd.p, edges) - ref).sum())
                except ValueError as exc:  # a VibroError: reported, not hidden
                    row[f"l1_{method}"] = np.nan
                    row[f"error_{method}"] = str(exc)
                row[f"wall_{method}"] = time.perf_counter() - t0
            for method in EXTRA_METHODS:
                t0 = time.perf_counter()
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")  # a GridWarning is measured by the L1 column itself
                        if method == "fpk":
                            from averaging.phase_plane import solve_phase_plane

                            masses = solve_phase_plane(model, h_max=h_max).bin_masses(edges)
                        else:
                            sd = stationary_density(model, method=method, h_max=h_max, points=1000)
                            masses = bin_masses(sd.H, sd.p, edges)
                    row[f"l1_{method}"] = float(np.abs(masses - ref).sum())
                except ValueError as exc:  # a VibroError: reported, not hidden
                    row[f"l1_{method}"] = np.nan
                    row[f"error_{method}"] = str(exc)
                row[f"wall_{method}"] = time.perf_counter() - t0
            rows.append(row)
            progress(f"  {name}: {xl}={xv:g} {yl}={yv:g} paper={row['l1_paper']:.3f} "
                     f"jump={row['l1_jump']:.3f} chain={row['l1_chain']:.3f} fpk={row['l1_fpk']:.3f} "
                     f"noise={noise:.3f} r_imp={diag.r_imp:.3f} "
                     f"r_damp90={diag.r_damp_p90:.2f} mc {row['mc_wall']:.1f}s")
    df = pd.DataFrame(rows)
    df["grid"] = name
    df.attrs.update(x=xl, y=yl, grid=name)
    return df


def plot_averaging_map(df, path, x: str, y: str, title: str = ""):
    """Heatmaps of L1(method, MC) over the grid; hatched cells: quasi-conservative assumption broken."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    xs = sorted(df[x].unique())
    ys = sorted(df[y].unique())
    methods = [m for m in AVERAGING_METHODS + EXTRA_METHODS if f"l1_{m}" in df]
    fig, axes = plt.subplots(1, len(methods), figsize=(4.2 * len(methods), 3.8), sharey=True)
    norm = LogNorm(vmin=3e-3, vmax=0.5)
    for ax, method in zip(axes, methods):
        Z = np.full((len(ys), len(xs)), np.nan)
        bad = np.zeros_like(Z, dtype=bool)
        for _, r in df.iterrows():
            i, j = ys.index(r[y]), xs.index(r[x])
            Z[i, j] = r[f"l1_{method}"]
            bad[i, j] = not r["quasi_conservative"] and method != "fpk"  # fpk does not average
        im = ax.imshow(Z, origin="lower", cmap="viridis", norm=norm, aspect="auto")
        for i in range(len(ys)):
            for j in range(len(xs)):
                txt = "err" if np.isnan(Z[i, j]) else f"{Z[i, j]:.3f}"
                ax.text(j, i, txt, ha="center", va="center", fontsize=7,
                        color="white" if (np.isnan(Z[i, j]) or Z[i, j] < 0.03) else "black")
                if bad[i, j]:
                    ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///", ec="red", lw=0))
        ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
        ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
        ax.set_xlabel(x)
        ax.set_title(method, fontsize=10)
    axes[0].set_ylabel(y)
    fig.colorbar(im, ax=list(axes), shrink=0.8, label="L1 of p(H) vs MC")
    fig.suptitle(title + "  (red hatch: not quasi-conservative, averaging refused; fpk solves the full (x, y) "
                 "problem)", fontsize=9)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=75, bbox_inches="tight"))
    plt.close(fig)


def fit_error_model(frames, quantile: float = 0.9) -> dict:
    """Fit L1(method, MC) ~ floor + slope * r_imp + slope_damp * r_damp on the quasi-conservative cells.

    ``slope`` from the cells with linear damping (where the damping term is absent), then ``slope_damp`` from the
    cells with nonlinear damping after removing floor + slope * r_imp. Each is the ``quantile`` of the ratios, so
    that the prediction bounds most calibration cells from above (a chooser must not be optimistic).
    """
    import pandas as pd

    df = pd.concat(frames, ignore_index=True)
    df = df[df.quasi_conservative]
    nonlinear = df["grid"].eq("rayleigh_k3") if "grid" in df else pd.Series(False, index=df.index)
    floor = float(np.median(df.mc_noise))
    out = {}
    for method in AVERAGING_METHODS:
        col = df[f"l1_{method}"]
        lin = col.notna() & ~nonlinear & (df.r_imp > 1e-4)
        excess = (col[lin] - floor).clip(lower=0.0) / df.r_imp[lin]
        slope = float(np.quantile(excess, quantile)) if len(excess) else math.nan
        nl = col.notna() & nonlinear & (df.r_damp > 1e-4)
        rest = (col[nl] - floor - slope * df.r_imp[nl]).clip(lower=0.0) / df.r_damp[nl]
        out[method] = {"slope": slope, "slope_damp": float(np.quantile(rest, quantile)) if len(rest) else math.nan,
                       "floor": floor, "cells": int(lin.sum()), "cells_nonlinear": int(nl.sum())}
    return out


# ----------------------------------------------------------------------------- Monte Carlo failures

def mc_failure_map(quick: bool = True, seed: int = 9, progress=print):
    """L1 of p(H) against the elastic closed form over dt * speed / gap for each scheme, with the step-rule verdict.

    The model is elastic Duffing (c = 0.1, D = 0.1) at several gaps: dt is measured against the barrier-crossing
    time gap / speed. Also records the stiff-potential refusal (a = 1e4).
    """
    import pandas as pd

    from hybrid.errors import StepSizeError
    from hybrid.stochastic import StepSizeWarning, check_step, simulate_ensemble, speed_scale
    from models import DuffingImpact, Elastic

    from .workprecision import ElasticOracle

    rows = []
    deltas = [0.25, 1.0] if quick else [0.15, 0.25, 0.5, 1.0]
    dts = [0.005, 0.02, 0.05, 0.1, 0.2] if quick else [0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.4]
    for delta in deltas:
        model = DuffingImpact(restitution=Elastic(), c=0.1, D=0.1, delta=delta)
        oracle = ElasticOracle.for_model(model)
        h_max = 14.0 / oracle.beta
        exact = oracle.bin_masses(np.linspace(0.0, h_max, L1_BINS + 1))
        v = 4.0 * speed_scale(model, h_max)
        for scheme in ("naive", "em", "milstein", "splitting"):
            for dt in dts:
                verdict, l1, wall = "ok", np.nan, np.nan
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    try:
                        check_step(model, dt, h_max)
                        stats = simulate_ensemble(model, scheme, dt=dt, paths=64, t_end=1100.0, t_burn=100.0,
                                                  h_max=h_max, bins=L1_BINS * 10, xy_bins=None, seed=seed,
                                                  check_dt=False)
                        l1 = l1_between_histograms(rebin_counts(stats.h_counts, L1_BINS), exact)
                        wall = stats.wall_time
                    except StepSizeError:
                        verdict = "refused"
                    if verdict == "ok" and any(issubclass(w.category, StepSizeWarning) for w in caught):
                        verdict = "warned"
                rows.append(dict(method=scheme, delta=delta, dt=dt, crossing_ratio=v * dt / (2 * delta),
                                 verdict=verdict, l1=l1, wall_time=wall))
                progress(f"  mc-failure {scheme:9s} delta={delta:g} dt={dt:g} v*dt/gap={v * dt / (2 * delta):.3f} "
                         f"{verdict:7s} L1={l1:.3f}")
    stiff = DuffingImpact(a=1e4)
    try:
        check_step(stiff, 0.01, 4.0)
        stiff_verdict = "ok"
    except StepSizeError as exc:
        stiff_verdict = f"refused: {exc}"
    df = pd.DataFrame(rows)
    df.attrs["stiff"] = stiff_verdict
    return df


def plot_mc_failures(df, path):
    """L1 against dt*speed/gap; markers show what the step rule said."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    markers = {"ok": "o", "warned": "^", "refused": "x"}
    colours = {"naive": "tab:red", "em": "tab:orange", "milstein": "tab:blue", "splitting": "tab:green"}
    styles = ["-", "--", ":", "-."]
    deltas = sorted(df.delta.unique())
    for (scheme, delta), g in df.groupby(["method", "delta"]):
        g = g.sort_values("crossing_ratio")
        run = g[g.verdict != "refused"]
        col = colours.get(scheme, "k")
        ax.loglog(run.crossing_ratio, run.l1, lw=0.9, alpha=0.7, color=col, ls=styles[deltas.index(delta) % 4],
                  label=f"{scheme}, Δ={delta:g}")
        for verdict, m in markers.items():
            sel = g[g.verdict == verdict]
            if len(sel):
                yv = sel.l1.fillna(1.0) if verdict == "refused" else sel.l1
                ax.scatter(sel.crossing_ratio, yv, marker=m, color=col, s=22)
    ax.axvline(0.1, color="orange", ls="--", lw=1, label="warn (v dt / gap = 0.1)")
    ax.axvline(0.5, color="red", ls="--", lw=1, label="refuse (0.5), x at L1=1")
    ax.set_xlabel("dt × (4 × speed scale) / gap   (dt over the barrier-crossing time)")
    ax.set_ylabel("L1 of p(H) vs exact (elastic)")
    ax.set_title("Monte Carlo: where dt fails (o ok, ^ warned, x refused)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80))
    plt.close(fig)


def mc_chattering(progress=print):
    """Inelastic collapse under noise: a force presses the mass into a wall with Newton e = 0.3.

    The impact rate should converge as dt -> 0 if it were meaningful; it keeps growing instead (measured 26 -> 50 per
    unit time from dt = 0.02 to 0.0025: the chattering path hits the wall on 43 % -> 11 % of the steps). Returns one
    row per dt with impacts per step and per time.
    """
    import pandas as pd

    from hybrid.stochastic import simulate_ensemble
    from models import ImpactOscillator, Newton

    push = ImpactOscillator("x - 2", "c*y", parameters={"c": 0.1, "D": 0.01, "delta": 1.0},
                            restitution=Newton(0.3), name="push")
    rows = []
    for dt in (0.02, 0.01, 0.005, 0.0025):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            st = simulate_ensemble(push, "milstein", dt=dt, paths=8, t_end=120.0, t_burn=20.0, h_max=4.0,
                                   xy_bins=None, seed=5)
        rows.append(dict(method="milstein", dt=dt, impact_rate=st.impact_rate.value,
                         impacts_per_step=st.impacts / st.path_steps, warnings=len(caught)))
        progress(f"  chattering dt={dt:g}: impact rate {st.impact_rate.value:.1f}/s, "
                 f"{st.impacts / st.path_steps:.3f} impacts per step, {len(caught)} warnings")
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- orbit failures

def orbit_failures(progress=print):
    """Statuses reported by ``simulate_orbit`` in the classic failure modes (Zeno, chattering, grazing)."""
    import pandas as pd

    from hybrid.deterministic import simulate_orbit
    from models import DuffingImpact, ImpactOscillator, Newton

    rows = []
    # a constant force pushing into the right wall: inelastic collapse, impacts accumulate (Zeno)
    push = ImpactOscillator("x - 2", 0, parameters={"D": 0.0, "delta": 1.0}, restitution=Newton(0.5), name="push")
    for backend in ("heyoka", "scipy"):
        for case, kw in (("zeno", {}), ("chattering (zeno detection off)", {"zeno_window": 0, "min_dwell": 1e-6})):
            t0 = time.perf_counter()
            res = simulate_orbit(push, x0=(0.9, 0.5), t_end=50.0, backend=backend, **kw)
            rows.append(dict(case=case, method=backend, status=res.status, n_impacts=res.n_impacts,
                             zeno_time=getattr(res, "zeno_time", None), message=res.message,
                             wall_time=time.perf_counter() - t0))
    # grazing: energy a hair above G(delta): the impact speed is sqrt(2 * 1e-10)
    m = DuffingImpact(c=0.0, D=0.0, restitution=Newton(0.9))
    v0 = math.sqrt(2.0 * (m.barrier_energy + 1e-10))
    for backend in ("heyoka", "scipy"):
        t0 = time.perf_counter()
        res = simulate_orbit(m, x0=(0.0, v0), t_end=10.0, backend=backend)
        rows.append(dict(case="grazing (H - G = 1e-10)", method=backend, status=res.status,
                         n_impacts=res.n_impacts, zeno_time=None, message=res.message,
                         wall_time=time.perf_counter() - t0))
    df = pd.DataFrame(rows)
    for _, r in df.iterrows():
        progress(f"  orbit {r.case:32s} {r.method:6s} status={r.status} impacts={r.n_impacts}")
    return df


def validity_maps(out_dir, quick: bool = False, parts=("averaging", "mc", "orbits"), progress=print) -> dict:
    """Write every validity/failure map (CSV + PNG) into ``out_dir``; returns the DataFrames by name.

    Parameters
    ----------
    out_dir : path
    quick : bool
        Coarse grids and short runs.
    parts : sequence of {'averaging', 'mc', 'orbits'}
    progress : callable
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    if "averaging" in parts:
        titles = {"c_D": "Duffing, Ma V_C=0.4, Δ=1", "vc_delta": "Duffing, c=0.025, D=0.05",
                  "newton_e": "Duffing, Newton e, c=0.025, Δ=1",
                  "rayleigh_k3": "Rayleigh c=0.01 + k3 y³, elastic walls Δ=1.5"}
        for name in _grids(quick):
            progress(f"[validity] averaging {name}")
            df = averaging_map(name, quick=quick, progress=progress)
            write_csv_atomically(df, out / f"averaging_{name}.csv")
            plot_averaging_map(df, out / f"averaging_{name}.png", df.attrs["x"], df.attrs["y"], titles[name])
            results[f"averaging_{name}"] = df
        fit = fit_error_model([results[k] for k in results if k.startswith("averaging_")])
        progress(f"[validity] fitted error model: {fit}")
        import json

        atomic_write_text(out / "error_model.json", json.dumps(fit, indent=2))
        results["error_model"] = fit
    if "mc" in parts:
        progress("[validity] Monte Carlo failures")
        df = mc_failure_map(quick=quick, progress=progress)
        write_csv_atomically(df, out / "mc_failures.csv")
        plot_mc_failures(df, out / "mc_failures.png")
        progress(f"  stiff potential a=1e4, dt=0.01: {df.attrs['stiff']}")
        results["mc_failures"] = df
        ch = mc_chattering(progress=progress)
        write_csv_atomically(ch, out / "mc_chattering.csv")
        results["mc_chattering"] = ch
    if "orbits" in parts:
        progress("[validity] orbit failures")
        df = orbit_failures(progress=progress)
        write_csv_atomically(df, out / "orbit_failures.csv")
        results["orbit_failures"] = df
    return results


__all__ = ["AVERAGING_METHODS", "EXTRA_METHODS", "averaging_map", "fit_error_model", "mc_chattering", "mc_failure_map",
           "orbit_failures", "plot_averaging_map", "plot_mc_failures", "validity_maps"]


# ----------------------------------------------------------------------------- verification of the chooser

def verification_cases(quick: bool = False) -> list:
    """(label, model) pairs NOT in the calibration grids of :func:`averaging_map` (other potentials, damping laws,
    restitution laws and parameter values)."""
    from models import CustomRestitution, DuffingImpact, DuffingVanDerPolImpact, Ma, RayleighImpact

    cases = [
        ("duffing a=1 b=0.2 c=0.025 D=0.005 Ma(2.0)", DuffingImpact(restitution=Ma(2.0), D=0.005)),
        ("duffing a=2 b=0.5 c=0.03 D=0.02 delta=0.8 Ma(0.3)",
         DuffingImpact(restitution=Ma(0.3), a=2.0, b=0.5, c=0.03, D=0.02, delta=0.8)),
        ("duffing c=0.3 D=0.15 delta=0.7 Ma(0.2) (heavily damped)",
         DuffingImpact(restitution=Ma(0.2), c=0.3, D=0.15, delta=0.7)),
        ("duffing-vdp delta=3 D=0.01 Ma(0.4)", DuffingVanDerPolImpact(delta=3.0)),
        ("rayleigh c=0.02 k3=0.01 D=0.05 Ma(0.4)", RayleighImpact()),
    ]
    if not quick:
        cases += [
            ("linear a=1 b=0 c=0.05 D=0.03 delta=1.2 custom e=1/(1+v/3)",
             DuffingImpact(restitution=CustomRestitution("1/(1 + v/3)"), b=0.0, c=0.05, D=0.03, delta=1.2)),
            ("duffing-vdp delta=1 D=0.01 Ma(0.4)", DuffingVanDerPolImpact(delta=1.0)),
            ("duffing c=0.015 D=0.03 delta=1.1 Ma(0.6)",
             DuffingImpact(restitution=Ma(0.6), c=0.015, D=0.03, delta=1.1)),
        ]
    return cases


def solve_verification(out_dir=None, tol: float = 0.02, quick: bool = False, cases=None, progress=print):
    """For each verification case: the chosen method, its actual L1 against converged MC, and the time saved.

    Returns
    -------
    pandas.DataFrame
        case, method, expected_l1, actual_l1, wall_time, mc_wall_time (always-MC at the same tol),
        mc_actual_l1, time_saved, ref_noise, reason.
    """
    import pandas as pd

    from vibro.solve.solver import solve

    from .workprecision import _run_halves

    rows = []
    for label, model in (cases if cases is not None else verification_cases(quick)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = solve(model, tol)
            edges = sol.edges
            h_max = float(edges[-1])
            scheme = pick_scheme(model)
            tau = sol.choice.diagnostics.relaxation_time
            tau = tau if np.isfinite(tau) else 100.0
            t_burn = min(max(200.0, 10.0 * tau), 20000.0)
            span = min(max(200.0 * tau, 4000.0), 16000.0) if quick else min(max(500.0 * tau, 8000.0), 40000.0)
            t_end = t_burn + span
            stats, ref_noise, ref_wall = _run_halves(model, scheme, 0.005, 256, t_end, t_burn, h_max, seed=4242)
            ref = rebin_counts(stats.h_counts, L1_BINS)
            ref = ref / ref.sum()
            actual = float(np.abs(sol.masses - ref).sum())
            if sol.method == "monte-carlo":
                mc = sol
            else:
                mc = solve(model, tol, method="monte-carlo")
            mc_actual = float(np.abs(mc.masses - ref).sum())
        rows.append(dict(case=label, method=sol.method, expected_l1=sol.choice.expected_error,
                         estimated_l1=sol.estimated_error, actual_l1=actual,
                         wall_time=sol.wall_time, mc_wall_time=mc.wall_time, mc_actual_l1=mc_actual,
                         time_saved=mc.wall_time - sol.wall_time, ref_noise=ref_noise, ref_wall=ref_wall,
                         reason=sol.choice.reason))
        progress(f"  {label}: {sol.method} expected {sol.choice.expected_error:.3f} actual {actual:.3f} "
                 f"(ref noise {ref_noise:.3f}) {sol.wall_time:.2f}s vs MC {mc.wall_time:.2f}s (MC L1 {mc_actual:.3f})")
    df = pd.DataFrame(rows)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_csv_atomically(df, out / "solve_verification.csv")
    return df


__all__ += ["solve_verification", "verification_cases"]
