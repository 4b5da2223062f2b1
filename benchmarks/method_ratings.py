"""Ratings of the averaging methods (``paper``, ``jump``, ``chain``) against the phase-plane solver ``fpk``.

``vibro solve`` predicts each method's L1 error of p(H) (40 bins of [0, h_max], :mod:`vibro.solve.metrics`) from
the diagnostics of :func:`vibro.solve.diagnose`. This script measures those errors over a random sweep of models
and fits the prediction as an upper quantile, so that the predicted error bounds the measured one in most cases:

* **reference**: ``fpk`` on its default grid with its own estimate (``PhaseDensity.estimate_error``). The
  measured error of a method is ``L1(method, fpk) + estimate(fpk)``, an upper bound of its true error.
* **sweep** (seeded, reproducible): Duffing springs (b = 0, 0.2, 1) with damping linear, van der Pol
  (c1 < 0 < c2), Rayleigh (c y + k3 y**3, c of either sign) or negative linear; noise D over two decades;
  restitution Newton, Ma and a custom law; walls symmetric, asymmetric, one-sided or at the equilibrium, their
  energies from 0.1 to 3 times the noise's energy scale.
* **fit**: per method, one 97th-percentile quantile regression of log(measured error) over all wall families: an
  intercept per family, common slopes in log r_imp and log r_damp (the diagnostics' impact-loss and damping-work
  ratios per cycle), indicators of self-excited and of linear damping, and own slopes for the quasi-linear class
  (linear damping, not self-excited: the paper's Figs. 2, 6, 10, 11), whose errors fall faster with the ratios.
  Pooling the families gives the slopes 240 cases instead of 42-103, which narrows the upper quantile (chain,
  symmetric gaps: median over-prediction 3.5 against 4.8 for the per-family power law). A cross-validated safety
  factor (5 seeded folds) keeps the coverage on unseen cases. The box of the sweep's diagnostics is the rated
  domain: outside it (or for a model class the sweep does not hold, e.g. multiplicative noise) no rating is
  claimed, except on the side where the power law only grows.

Rows are appended to ``benchmarks/data/method_ratings.jsonl`` (a run resumes where it stopped); ``--fit`` writes
the constants into ``vibro/solve/data/error_model.json`` with their provenance.

Run: ``nice -n 10 python benchmarks/method_ratings.py [--cases 300] [--fit]``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

ROWS = ROOT / "benchmarks" / "data" / "method_ratings.jsonl"
CONSTANTS = ROOT / "vibro" / "solve" / "data" / "error_model.json"
METHODS = ("paper", "jump", "chain")
QUANTILE = 0.97
BINS = 40
SEED = 20261125


def _wall(a, b, G):
    """x > 0 with a x**2 / 2 + b x**4 / 4 = G."""
    if b == 0:
        return math.sqrt(2.0 * G / a)
    return math.sqrt((-a + math.sqrt(a * a + 4.0 * b * G)) / b)


def _law(rng):
    from models import CustomRestitution, Ma, Newton

    kind = rng.choice(["newton", "ma", "custom"])
    if kind == "newton":
        e = float(rng.uniform(0.3, 0.95))
        return f"newton:e={e:.3f}", Newton(round(e, 3))
    if kind == "ma":
        vc = float(np.exp(rng.uniform(np.log(0.05), np.log(2.5))))
        return f"ma:vc={vc:.3f}", Ma(round(vc, 3))
    k = float(np.exp(rng.uniform(np.log(0.3), np.log(5.0))))
    expr = f"0.4 + 0.6/(1 + v/{k:.3f})"
    return f"custom:{expr}", CustomRestitution(expr)


def sweep_cases(n: int, seed: int = SEED):
    """``n`` cases (label, model constructor arguments) drawn from the sweep (same seed, same cases)."""
    from models import ImpactOscillator

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        damping = rng.choice(["linear", "linear", "vdp", "rayleigh", "negative"])
        b = float(rng.choice([0.0, 0.2, 1.0]))
        params = {"a": 1.0, "b": b}
        D = float(np.exp(rng.uniform(np.log(0.005), np.log(0.5))))
        if damping == "linear":
            c = float(np.exp(rng.uniform(np.log(0.005), np.log(0.2))))
            scale = float(np.exp(rng.uniform(np.log(0.2), np.log(6.0))))  # D / c: the energy scale
            D = c * scale
            h_expr, params = "c*y", {**params, "c": c}
        elif damping == "vdp":
            c1 = -float(np.exp(rng.uniform(np.log(0.002), np.log(0.02))))
            c2 = float(np.exp(rng.uniform(np.log(0.002), np.log(0.02))))
            h_expr, params = "(c1 + c2*x**2)*y", {**params, "c1": c1, "c2": c2}
            scale = max(D / 0.02, 0.5)
        elif damping == "rayleigh":
            c = float(rng.uniform(-0.01, 0.05))
            k3 = float(np.exp(rng.uniform(np.log(0.002), np.log(0.05))))
            h_expr, params = "c*y + k3*y**3", {**params, "c": c, "k3": k3}
            scale = max(D / max(c, 0.01), 0.3)
        else:  # negative linear damping: the impacts alone dissipate
            c = -float(np.exp(rng.uniform(np.log(0.002), np.log(0.02))))
            h_expr, params = "c*y", {**params, "c": c}
            scale = float(np.exp(rng.uniform(np.log(0.1), np.log(2.0))))
        geo = rng.choice(["symmetric", "symmetric", "asymmetric", "one-sided", "equilibrium"])
        f1 = float(np.exp(rng.uniform(np.log(0.1), np.log(3.0))))
        d1 = _wall(1.0, b, f1 * scale)
        if geo == "symmetric":
            barriers, params = "delta", {**params, "delta": d1}
            positive = ("delta",)
        elif geo == "asymmetric":
            d2 = d1 * float(rng.uniform(1.3, 2.5))
            barriers, params = ("-dl", "dr"), {**params, "dl": d1, "dr": d2}
            positive = ("dl", "dr")
        elif geo == "one-sided":
            barriers, params = (None, "dr"), {**params, "dr": d1}
            positive = ("dr",)
        else:
            barriers, positive = (None, 0), ()
        law_spec, law = _law(rng)
        if damping == "negative" and law_spec.startswith("ma"):
            law_spec, law = "newton:e=0.7", __import__("models").Newton(0.7)  # elastic below V_C: no dissipation
        params["D"] = D
        label = f"{i:03d} {damping} b={b:g} D={D:.3g} {geo} {law_spec}"

        build = partial(ImpactOscillator, "a*x + b*x**3", h_expr, parameters=dict(params), barriers=barriers,
                        positive=positive, restitution=law)

        out.append({"label": label, "damping": str(damping), "geometry": str(geo), "law": law_spec,
                    "params": params, "build": build})
    return out


def measure(case) -> dict:
    """Diagnostics, the fpk reference and its estimate, and each method's L1 and wall time on one case."""
    from averaging import stationary_density
    from averaging.phase_plane import stationary_density_xy
    from vibro.solve import diagnose
    from vibro.solve.metrics import bin_masses

    row = {k: case[k] for k in ("label", "damping", "geometry", "law", "params")}
    model = case["build"]()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = diagnose(model)
            row.update(r_imp=d.r_imp, r_damp=d.r_damp, r_imp_p90=d.r_imp_p90, r_damp_p90=d.r_damp_p90,
                       self_excited=d.self_excited, geometry_diag=d.geometry, h_max=d.h_max,
                       linear_damping=d.linear_damping)
            t0 = time.process_time()
            ref = stationary_density_xy(model, h_max=d.h_max)
            row["t_fpk"] = time.process_time() - t0
    except (ValueError, ArithmeticError) as exc:  # no stationary density (VibroError is a ValueError)
        row["failed"] = f"{type(exc).__name__}: {exc}"[:200]
        return row
    edges = np.linspace(0.0, d.h_max, BINS + 1)
    m_ref = ref.bin_masses(edges)
    row["fpk_est"] = ref.estimate_error(edges)
    for meth in METHODS:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.process_time()
                sd = stationary_density(model, meth, h_max=d.h_max, points=2000)
                row[f"t_{meth}"] = time.process_time() - t0
            row[f"l1_{meth}"] = float(np.abs(bin_masses(sd.H, sd.p, edges) - m_ref).sum())
        except (ValueError, ArithmeticError) as exc:
            row[f"l1_{meth}"] = None
            row[f"err_{meth}"] = f"{type(exc).__name__}: {exc}"[:200]
    return row


def run(n: int) -> None:
    done = set()
    if ROWS.exists():
        done = {json.loads(line)["label"] for line in ROWS.read_text().splitlines() if line.strip()}
    ROWS.parent.mkdir(parents=True, exist_ok=True)
    for case in sweep_cases(n):
        if case["label"] in done:
            continue
        t0 = time.perf_counter()
        row = measure(case)
        with ROWS.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        l1 = " ".join(f"{m} {row.get(f'l1_{m}') or float('nan'):.4f}" for m in METHODS)
        print(f"{case['label']:60s} {row.get('failed', l1)[:90]} fpk_est {row.get('fpk_est', float('nan')):.1e} "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)


def quantile_fit(X, y, q=QUANTILE):
    """Linear quantile regression by linear programming: min sum q u+ + (1 - q) u-, X beta + u+ - u- = y."""
    from scipy.optimize import linprog

    n, k = X.shape
    cost = np.concatenate([np.zeros(k), np.full(n, q), np.full(n, 1.0 - q)])
    A = np.hstack([X, np.eye(n), -np.eye(n)])
    res = linprog(cost, A_eq=A, b_eq=y, bounds=[(None, None)] * k + [(0, None)] * (2 * n), method="highs")
    if not res.success:
        raise RuntimeError(res.message)
    return res.x[:k]


SHIFT = 1e-4
"""Added to r_imp and r_damp before their logarithm (a ratio of 0 stays finite)."""


FAMILIES = {"symmetric": ("none", "symmetric"), "asymmetric": ("asymmetric",), "one-sided": ("one-sided",),
            "equilibrium": ("equilibrium",)}
FOLDS = 5


def _family(geometry: str) -> str:
    return next(fam for fam, geos in FAMILIES.items() if geometry in geos)


def fit() -> dict:
    """Fit the ratings from the rows and write them into the error model (with their provenance).

    One quantile regression per method over all wall families together (240 cases rather than 12-100 per
    family): an intercept per family, common slopes in log r_imp and log r_damp, indicators of self-excited and of
    linear damping, and separate slopes for the quasi-linear class (linear damping, not self-excited), whose
    errors fall faster with the loss ratios (:func:`vibro.solve.errormodel.rating_features`). The slopes shared
    across families leave fewer constants per case, so the upper quantile sits closer to the measured errors.
    """
    import subprocess

    from vibro.solve.errormodel import RATING_FEATURES, rating_features

    rows = [json.loads(line) for line in ROWS.read_text().splitlines() if line.strip()]
    ok = [r for r in rows if "failed" not in r]
    model = json.loads(CONSTANTS.read_text())
    ratings = {}
    report = []
    fams = list(FAMILIES)
    for meth in METHODS:
        ratings[meth] = {}
        sel = [r for r in ok if r.get(f"l1_{meth}") is not None]
        fam = np.array([_family(r["geometry_diag"]) for r in sel])
        X = np.array([[float(f == F) for F in fams]
                      + list(rating_features(r["r_imp"], r["r_damp"], r["self_excited"], r["linear_damping"]))
                      for r, f in zip(sel, fam)])
        y = np.log([r[f"l1_{meth}"] + r["fpk_est"] for r in sel])
        beta = quantile_fit(X, y)
        # the quantile fit bounds 97 % of the cases it was fitted on, fewer of those it has not seen: a safety
        # factor from cross-validation (the 97th percentile of measured / predicted out of fold, seeded folds)
        # restores the coverage on unseen cases
        fold = np.random.default_rng(SEED).permutation(np.arange(len(sel)) % FOLDS)
        ratio = np.empty(len(sel))
        for k in range(FOLDS):
            b_k = quantile_fit(X[fold != k], y[fold != k])
            ratio[fold == k] = np.exp(y[fold == k] - X[fold == k] @ b_k)
        safety = float(max(1.0, np.quantile(ratio, QUANTILE)))
        beta[:len(fams)] += math.log(safety)
        pred = np.exp(X @ beta)
        meas = np.exp(y)
        for j, F in enumerate(fams):
            m = fam == F
            if m.sum() < 8:
                continue
            ri = np.array([r["r_imp"] for r, mm in zip(sel, m) if mm])
            rd = np.array([r["r_damp"] for r, mm in zip(sel, m) if mm])
            box = {"r_imp": [float(ri.min()), float(ri.max())], "r_damp": [float(rd.min()), float(rd.max())]}
            cover, held_out = float(np.mean(pred[m] >= meas[m])), float(np.mean(ratio[m] <= safety))
            ratings[meth][F] = {"log_scale": float(beta[j]), "features": list(RATING_FEATURES),
                                "coef": [float(v) for v in beta[len(fams):]], "shift": SHIFT, "safety": safety,
                                "cases": int(m.sum()), "coverage": cover, "held_out_coverage": held_out,
                                "rated_box": box, "median_l1": float(np.median(meas[m])),
                                "max_l1": float(np.max(meas[m])),
                                "median_over_prediction": float(np.median(pred[m] / meas[m]))}
            report.append(f"{meth:6s} {F:12s} n={int(m.sum()):3d} scale {np.exp(beta[j]):.3g} (safety {safety:.2f}): "
                          f"coverage {cover:.2f} (held out {held_out:.2f}), median prediction/measured "
                          f"{np.median(pred[m] / meas[m]):.1f}, measured median {np.median(meas[m]):.4f} max "
                          f"{np.max(meas[m]):.4f}")
        report.append(f"{meth:6s} coefficients " + ", ".join(f"{n} {v:+.3f}" for n, v in
                                                            zip(RATING_FEATURES, beta[len(fams):])))
    est = np.array([r["fpk_est"] for r in ok])
    t = np.array([r["t_fpk"] for r in ok])
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True).stdout.strip()
    except OSError:
        commit = "unknown"
    model["ratings"] = ratings
    model["ratings_source"] = (
        f"benchmarks/method_ratings.py --fit (commit {commit}): {len(ok)} sweep cases ({len(rows) - len(ok)} of "
        f"{len(rows)} drawn had no stationary density); measured error = L1(method, fpk on its default grid) + "
        f"fpk's own estimate at the time of the sweep (two grids, order 1.3), on {BINS} bins of [0, h_max]; "
        f"one {QUANTILE:.0%} quantile regression of log L1 per method over all wall families: log L1 = log_scale "
        "(one per family) + coef . features, the features log(r_imp + shift), log(r_damp + shift), self-excited "
        "(0/1), linear damping (0/1) and, for the quasi-linear class (linear damping, not self-excited), log(r_imp "
        "+ shift) and log(r_damp + shift) again (its own slopes); coverage = share of the family's cases the rating "
        f"bounds, held_out_coverage the share bounded by the out-of-fold prediction ({FOLDS}-fold, seeded) times "
        "the safety factor, which is the 97th percentile of measured over out-of-fold predicted (at least 1) and "
        "is included in log_scale")
    model["fpk"] = {
        "floor": float(np.quantile(est, QUANTILE)), "median": float(np.median(est)), "cost_s": float(np.median(t)),
        "source": f"benchmarks/method_ratings.py: {QUANTILE:.0%} quantile of fpk's own two-grid estimate (40 bins) "
                  f"over the {len(ok)} sweep cases at the default grid; median {np.median(est):.2g}, max "
                  f"{est.max():.2g}; cost = median CPU time with the estimate. solve reports the estimate of the "
                  "run itself, not this prediction",
    }
    CONSTANTS.write_text(json.dumps(model, indent=2) + "\n")
    print("\n".join(report))
    print(f"fpk estimate: median {np.median(est):.2g}, {QUANTILE:.0%} {np.quantile(est, QUANTILE):.2g}, max "
          f"{est.max():.2g}; wrote {CONSTANTS}")
    return ratings


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=300)
    ap.add_argument("--fit", action="store_true", help="only fit the constants from the rows already measured")
    args = ap.parse_args(argv)
    if not args.fit:
        run(args.cases)
    fit()


if __name__ == "__main__":
    main()
