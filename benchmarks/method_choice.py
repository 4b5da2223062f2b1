"""Acceptance of ``vibro solve --tol``: the method it chooses, its estimated and its true L1 error, and its time.

Cases: the 21 energy curves of the paper's Figs. 2, 6 and 10-14 (``vibro.studies.figures.specs``) and the example
geometries of ``benchmarks/example_models.py`` (asymmetric gap, one-sided stop, stop at the equilibrium), at
``--tol 0.02`` and ``--tol 0.005``.

* **run**: ``python -m vibro solve ... --out FILE.csv`` as a subprocess (start-up included), wall time measured
  around it; the chosen method and the estimate after the run are read from its output.
* **true L1**: on the 40 bins of [0, h_max] that ``solve`` uses (h_max from ``diagnose``), against a converged
  reference: ``fpk`` on the grid (240, 288) ((320, 384) for the stop at the equilibrium), whose own three-grid
  estimate is printed beside it (cached in ``benchmarks/data/method_choice_refs.npz``).

Writes the tables to ``docs/results/method-choice.md``.
Run: ``nice -n 10 python benchmarks/method_choice.py [--references] [--only KEY,...]`` (``--references``: only
the cached references; ``--only``: rerun those cases, keep the others' rows from benchmarks/data/method_choice.json).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

REFS = ROOT / "benchmarks" / "data" / "method_choice_refs.npz"
PAGE = ROOT / "docs" / "results" / "method-choice.md"
REF_GRID = (240, 288)
REF_GRIDS = {"EquilibriumStop": (320, 384)}  # converges at order 0.5-0.75 (the inelastic stop at the equilibrium)
TOLS = (0.02, 0.005)
EXAMPLES = (("asymmetric gap (ex. 09)", "AsymmetricGap"), ("one-sided stop", "OneSidedStop"),
            ("stop at the equilibrium, r = 0.6 (ex. 06)", "EquilibriumStop"))


def cases():
    """(key, label, CLI model arguments, model) for every acceptance case."""
    from benchmarks import example_models
    from vibro.studies.figures.specs import ENERGY_FIGURES, FIGURES

    out = []
    for n in ENERGY_FIGURES:
        for i, c in enumerate(FIGURES[n].cases):
            args = ["--model", c.model]
            for k, v in c.params:
                args += ["--param", f"{k}={v}"]
            args += ["--restitution", f"ma:vc={c.vc}"]
            out.append((f"f{n}_{i}", f"Fig. {n} {c.label}", args, c.build()))
    for label, cls in EXAMPLES:
        out.append((cls, label, ["--model", f"benchmarks/example_models.py:{cls}"],
                    getattr(example_models, cls)()))
    return out


def reference(key, model, h_max, edges):
    """Bin masses of the converged reference on ``edges`` and its own estimate (cached)."""
    from averaging.phase_plane import stationary_density_xy

    store = dict(np.load(REFS)) if REFS.exists() else {}
    tag = f"{key}_{h_max:.9g}"
    if tag + "_m" not in store:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sd = stationary_density_xy(model, grid=REF_GRIDS.get(key, REF_GRID), h_max=h_max, tol=2.0)
        store[tag + "_m"] = sd.bin_masses(edges)
        store[tag + "_est"] = np.array([sd.estimate_error(edges)])
        REFS.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(REFS, **store)
    return store[tag + "_m"], float(store[tag + "_est"][0])


def run_solve(args, tol, out):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "vibro", "solve", *args, "--tol", str(tol), "--no-progress",
                          "--out", str(out)], cwd=ROOT, capture_output=True, text=True, env=env, timeout=900)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if res.returncode != 0:
        raise RuntimeError(res.stderr)
    method = re.search(r"^method: (\S+)", res.stdout, re.M).group(1)
    est = float(re.search(r"^estimated L1 error after the run: (\S+)", res.stdout, re.M).group(1))
    grid = re.search(r"^settings: grid=(\(\d+, \d+\))", res.stdout, re.M)
    esc = re.search(r"^escalated: (.*)$", res.stdout, re.M)
    return method + (f" {grid.group(1)}" if grid else ""), est, wall, cpu, esc.group(1) if esc else "", res.stderr


def main():
    import pandas as pd

    from vibro.solve import diagnose
    from vibro.solve.metrics import bin_masses

    only = set(sys.argv[sys.argv.index("--only") + 1].split(",")) if "--only" in sys.argv else None
    saved = ROOT / "benchmarks" / "data" / "method_choice.json"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for key, label, args, model in cases():
            if only is not None and key not in only:
                rows += [r for r in json.loads(saved.read_text()) if r["key"] == key]
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                h_max = diagnose(model).h_max
            edges = np.linspace(0.0, h_max, 41)
            ref, ref_est = reference(key, model, h_max, edges)
            for tol in TOLS:
                out = Path(tmp) / f"{key}_{tol}.csv"
                method, est, wall, cpu, esc, err = run_solve(args, tol, out)
                df = pd.read_csv(out)
                true = float(np.abs(bin_masses(df.H.values, df.p.values, edges) - ref).sum())
                rows.append({"key": key, "case": label, "tol": tol, "method": method, "estimate": est, "true": true,
                             "ref_est": ref_est, "wall_s": wall, "cpu_s": cpu, "escalated": esc,
                             "warned": "warning" in err.lower(), "load": os.getloadavg()[0]})
                print(f"{label:42s} tol {tol:<6g} {method:18s} est {est:.2e} true {true:.2e} (ref {ref_est:.0e}) "
                      f"{wall:5.2f} s (cpu {cpu:5.2f} s) {esc}", flush=True)
    write_page(rows)
    saved.write_text(json.dumps(rows, indent=1) + "\n")


def _load_range(rows) -> str:
    loads = [r["load"] for r in rows if "load" in r]
    return f"{min(loads):.0f}-{max(loads):.0f}" if loads else "not recorded"


def choices_line(sel) -> str:
    """How often each method was chosen, e.g. 'fpk 17, chain 3, jump 2'."""
    from collections import Counter

    counts = Counter(r["method"].split()[0] for r in sel)
    return ", ".join(f"{m} {n}" for m, n in counts.most_common())


def write_page(rows):
    lines = ["# Method choice of `vibro solve`: chosen method, estimated and true error, time", "",
             "Generated by `benchmarks/method_choice.py` (issue 23). For each case `python -m vibro solve ... --tol "
             "TOL --out FILE.csv` ran as a subprocess (Python start-up and imports included) on the shared "
             f"2-core machine, beside other workers: the 1-minute load average was {_load_range(rows)} during the "
             "run, so the wall time is inflated several-fold; the CPU time (user + system of the subprocess) is "
             "closer to what one idle core would take (a loaded machine inflates it too, less). The estimate is "
             "the one `solve` reports after its run (fpk: its three-grid Richardson "
             "estimate; paper, jump, chain: their rating against fpk over the sweep of "
             "`benchmarks/method_ratings.py`). The true L1 is on the 40 bins of [0, h_max] that `solve` uses, "
             f"against `fpk` on the grid {REF_GRID} ((320, 384) for the stop at the equilibrium); that reference's "
             "own three-grid estimate is the column `ref`: the true L1 is known to within it.", ""]
    for tol in TOLS:
        sel = [r for r in rows if r["tol"] == tol]
        within = sum(r["true"] <= tol for r in sel)
        bounded = sum(r["true"] <= r["estimate"] + r["ref_est"] for r in sel)
        strict = sum(r["true"] <= r["estimate"] for r in sel)
        walls = np.array([r["wall_s"] for r in sel])
        cpus = np.array([r["cpu_s"] for r in sel])
        lines += [f"## `--tol {tol:g}`", "",
                  f"Within tolerance: {within} of {len(sel)}. Estimate (plus the reference's own) bounds the true "
                  f"L1: {bounded} of {len(sel)} (the estimate alone: {strict}). CPU time: median "
                  f"{np.median(cpus):.2f} s, slowest {cpus.max():.2f} s; wall time (loaded machine): median "
                  f"{np.median(walls):.2f} s, slowest {walls.max():.2f} s. Chosen: {choices_line(sel)}.", "",
                  "| case | method | estimated L1 | true L1 | ref | CPU (s) | wall (s) | escalation |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in sel:
            lines.append(f"| {r['case']} | {r['method']} | {r['estimate']:.2g} | {r['true']:.2g} | "
                         f"{r['ref_est']:.0e} | {r['cpu_s']:.2f} | {r['wall_s']:.2f} | {r['escalated'] or '-'} |")
        lines.append("")
    lines += startup_section() + ratings_section() + fpk_estimate_section()
    PAGE.parent.mkdir(parents=True, exist_ok=True)
    PAGE.write_text("\n".join(lines) + "\n")
    print(f"wrote {PAGE}")


def startup_section():
    """CPU time of solve against the commit before the start-up work (benchmarks/solve_startup.py writes it)."""
    path = ROOT / "benchmarks" / "data" / "solve_startup.json"
    if not path.exists():
        return []
    d = json.loads(path.read_text())
    out = ["## Start-up against a baseline", "",
           f"`benchmarks/solve_startup.py --baseline` (a source tree of commit {d['baseline']}): `vibro solve --tol "
           f"{d['tol']:g}` on a case of each figure, the current tree and the baseline alternating, "
           f"{d['repeats']} runs each, median CPU time (user + system). {d['summary']}.", "",
           "| case | current CPU (s) | baseline CPU (s) | ratio |", "|---|---|---|---|"]
    out += [f"| {label} | {cur:.2f} | {base:.2f} | {cur / base:.2f} |" for label, cur, base in d["rows"]]
    return out + [""]


def ratings_section():
    """The fitted ratings of vibro/solve/data/error_model.json as a table (what solve predicts from)."""
    from vibro.solve.errormodel import error_model

    m = error_model()
    out = ["## The ratings behind the choice", "", m.get("ratings_source", ""), "",
           "Predicted L1 = exp(log_scale + coef . features) (:func:`vibro.solve.errormodel.rating_features`; "
           "r_imp, r_damp: the diagnostics' impact loss and damping work per cycle over H); `scale` = "
           "exp(log_scale) of the wall family; `coverage` is the share of the family's sweep cases it bounds, "
           "`held out` the same for the out-of-fold prediction times the safety factor; `over` the median of "
           "predicted over measured; outside the box of the sweep's (r_imp, r_damp) no rating is claimed.", "",
           "| method | walls | cases | scale | coverage | held out | over | median L1 | max L1 |",
           "|---|---|---|---|---|---|---|---|---|"]
    import math

    coefs = []
    for meth, fams in m.get("ratings", {}).items():
        for fam, r in fams.items():
            out.append(f"| {meth} | {fam} | {r['cases']} | {math.exp(r['log_scale']):.3g} | {r['coverage']:.2f} | "
                       f"{r['held_out_coverage']:.2f} | {r['median_over_prediction']:.1f} | {r['median_l1']:.4f} | "
                       f"{r['max_l1']:.4f} |")
        if fams and "coef" in next(iter(fams.values())):
            r = next(iter(fams.values()))
            coefs.append(f"- {meth}: " + ", ".join(f"{n} {c:+.3f}" for n, c in zip(r["features"], r["coef"])))
    out += ["", "Coefficients (shared by the wall families of a method):", "", *coefs]
    f = m["fpk"]
    out += ["", f"fpk: predicted estimate at the default grid {f['floor']:.2g} ({f['source']}).", ""]
    return out


def fpk_estimate_section():
    """fpk's three-grid estimate against the true error on the problems with exact p(H) (benchmarks/fpk_convergence.py
    --estimate-only writes the rows)."""
    path = ROOT / "benchmarks" / "data" / "fpk_estimate.json"
    if not path.exists():
        return []
    rows = json.loads(path.read_text())
    out = ["## fpk's own estimate against exact answers", "",
           "`benchmarks/fpk_convergence.py --estimate-only`: the three-grid estimate (Richardson against the grid "
           "twice coarser at the order observed against the grid four times coarser, at most 1.3) and the true L1 "
           "error of p(H) on two problems with exact "
           "answers: elastic walls (the Gibbs density) and the linear oscillator with a stop at the equilibrium, "
           "r = 1 (the folded Gaussian). "
           f"The estimate bounds the true error in {sum(r['estimate'] >= r['true'] for r in rows)} of {len(rows)}.",
           "", "| problem | grid | bins | true L1 | estimate | estimate / true |", "|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['problem']} | {tuple(r['grid'])} | {r['bins']} | {r['true']:.2e} | {r['estimate']:.2e} | "
                   f"{r['estimate'] / r['true']:.1f} |")
    return out + [""]


def references_only():
    """Compute (and cache) the references alone."""
    from vibro.solve import diagnose

    for key, label, _args, model in cases():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            h_max = diagnose(model).h_max
        t0 = time.perf_counter()
        _, est = reference(key, model, h_max, np.linspace(0.0, h_max, 41))
        print(f"{label:42s} reference estimate {est:.1e} ({time.perf_counter() - t0:.1f} s)", flush=True)


if __name__ == "__main__":
    if "--references" in sys.argv:
        references_only()
    else:
        main()
