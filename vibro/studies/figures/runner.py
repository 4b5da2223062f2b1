"""Compute one figure: analytic densities (``paper``, ``jump``, ``fpk``), Monte Carlo halves, distances, outputs.

The analytic side calls :func:`averaging.stationary_density` (averaging) and
:func:`averaging.phase_plane.solve_phase_plane` (the full (x, y) Fokker-Planck solution, method ``fpk``); the Monte
Carlo side calls
:func:`hybrid.stochastic.simulate_ensemble` twice per case with independent seeds (two half-batches), merges the
halves, and uses their difference to estimate the Monte Carlo noise.
"""

from __future__ import annotations

import inspect
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybrid.errors import ParameterError
from vibro.provenance import versions
from vibro.solve.metrics import bin_average, halves_noise_l1, joint_bin_average, l1_joint, l1_on_bins

from .mcdata import JOINT_GRID, mass_outside, mc_h_density, mc_xy_density, xy_outside, xy_range  # noqa: F401 (xy_range re-exported)
from .specs import FIGURES, PRESETS, Case, FigureSpec, figure_spec
from .store import MCCache, finished, sha256_file, write_json

ANALYTIC_METHODS = ("paper", "jump")
"""Averaging methods drawn in every figure: the paper's drift-only averaging and our jump variant."""
PHASE_METHOD = "fpk"
"""The phase-plane density drawn beside them (one solve on :data:`PHASE_GRID`, no coarse-grid check)."""
PHASE_GRID = (120, 144)
"""Rings and angles of the phase-plane solve: L1 discretisation error of p(H) below 0.0015 on Figs. 2, 12 and 14
(against a 320 x 384 solve), under the Monte Carlo noise of the figures, at half the cost of the default grid."""
ANALYTIC_POINTS = 1500
"""Energy grid points of each analytic density."""


@dataclass
class CaseResult:
    """Everything computed for one case: analytic densities, Monte Carlo halves and merged statistics."""

    case: Case
    model: object
    densities: dict = field(default_factory=dict)
    mc: object = None
    halves: tuple = ()
    mc_seeds: tuple = ()
    mc_wall: float = 0.0
    mc_cached: bool = False
    analytic_wall: float = 0.0
    phase_wall: float = 0.0
    phase_warnings: list = field(default_factory=list)
    metrics: dict = field(default_factory=dict)


@dataclass
class FigureResult:
    """Outcome of :func:`run_figure`: status (``finished`` or ``reused``), paths and the sidecar data."""

    number: int
    status: str
    paths: dict
    sidecar: dict
    wall_time: float


# ------------------------------------------------------------------------------------------ backends
def _call_filtered(fn, *args, **kwargs):
    """Call ``fn`` with only the keyword arguments its signature accepts (the engines may grow or drop options)."""
    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return fn(*args, **kwargs)
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return fn(*args, **kwargs)
    return fn(*args, **{k: v for k, v in kwargs.items() if k in params})


def analytic_density(model, method: str, h_max: float, points: int = ANALYTIC_POINTS):
    """``averaging.stationary_density(model, method, h_max, points)``."""
    from averaging import stationary_density

    return _call_filtered(stationary_density, model, method=method, h_max=h_max, points=points)


def phase_density(model, h_max: float, points: int = ANALYTIC_POINTS):
    """``averaging.phase_plane.solve_phase_plane(model, PHASE_GRID, h_max, points=points)``, warnings recorded.

    Returns the density and the list of warning messages (a reflecting h_max inside the mass, for example).
    """
    import warnings

    from averaging.phase_plane import solve_phase_plane

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sd = solve_phase_plane(model, grid=PHASE_GRID, h_max=h_max, points=points)
    return sd, [str(w.message) for w in caught]


def simulate(model, **settings):
    """``hybrid.stochastic.simulate_ensemble(model, **settings)``."""
    from hybrid.stochastic import simulate_ensemble

    return _call_filtered(simulate_ensemble, model, **settings)


def _value(est):
    """A float from an Estimate (``.value``) or a plain number; NaN when missing."""
    if est is None:
        return float("nan")
    v = getattr(est, "value", est)
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _ci(est):
    return float(getattr(est, "ci", float("nan"))) if est is not None else float("nan")


def mc_settings(spec: FigureSpec, case: Case, preset: str) -> dict:
    """Keyword arguments of ``simulate_ensemble`` for one case (for one half; paths are halved)."""
    size = spec.size(preset)
    half = max(1, size.paths // 2)
    return {
        "scheme": spec.scheme, "dt": spec.dt, "paths": half, "t_end": size.t_end, "t_burn": size.t_burn,
        "h_max": case.h_max, "bins": spec.bins, "xy_bins": (spec.xy_bins, spec.xy_bins), "xy_range": xy_range(case),
    }


def case_seeds(case: Case, settings: dict) -> tuple[int, int]:
    """Two independent seeds (one per half-batch), derived from the case and its settings only.

    The same case simulated by two figures gets the same seeds, so that the cached run is shared.

    Examples
    --------
    >>> from vibro.studies.figures import FIGURES
    >>> a = case_seeds(FIGURES[2].cases[0], {"dt": 0.01}); a == case_seeds(FIGURES[2].cases[0], {"dt": 0.01})
    True
    """
    text = json.dumps({"case": case.describe(), "settings": settings}, sort_keys=True, default=str)
    root = int.from_bytes(__import__("hashlib").sha256(text.encode()).digest()[:4], "little")
    a, b = np.random.SeedSequence(root).generate_state(2)
    return int(a), int(b)


# ------------------------------------------------------------------------------------------ compute
def compute_case(spec: FigureSpec, case: Case, preset: str, with_mc: bool, cache: MCCache | None,
                 progress: bool) -> CaseResult:
    """Analytic densities of both methods and (optionally) the two Monte Carlo halves of one case."""
    model = case.build()
    res = CaseResult(case=case, model=model)
    t0 = time.perf_counter()
    for method in ANALYTIC_METHODS:
        res.densities[method] = analytic_density(model, method, case.h_max)
    res.analytic_wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    res.densities[PHASE_METHOD], res.phase_warnings = phase_density(model, case.h_max)
    res.phase_wall = time.perf_counter() - t0
    if not with_mc:
        return res
    settings = mc_settings(spec, case, preset)
    seeds = case_seeds(case, settings)
    res.mc_seeds = seeds
    payload = {"case": case.describe(), "settings": settings, "seeds": seeds}
    cached = cache.get(payload) if cache is not None else None
    t0 = time.perf_counter()
    if cached is not None:
        res.halves = cached
        res.mc_cached = True
    else:
        res.halves = tuple(simulate(model, seed=s, progress=progress, **settings) for s in seeds)
        if cache is not None:
            cache.put(payload, res.halves)
    res.mc_wall = time.perf_counter() - t0
    a, b = res.halves
    res.mc = _merged(a, b)
    return res


def _merged(a, b):
    import copy

    m = copy.deepcopy(a)
    out = m.merge(b)
    return out if out is not None else m


def case_metrics(spec: FigureSpec, res: CaseResult) -> dict:
    """Distances, peaks, moments and the Monte Carlo noise of one case (the sidecar's per-case entry)."""
    model = res.model
    G = model.barrier_energy
    out: dict = {"G_delta": G, "analytic_wall_s": res.analytic_wall, "fpk_wall_s": res.phase_wall,
                 "fpk_warnings": list(res.phase_warnings)}
    for method, sd in res.densities.items():
        H, p = np.asarray(sd.H), np.asarray(sd.p)
        k = int(np.argmax(p))
        out[method] = {
            "peak_p": float(p[k]), "peak_H": float(H[k]), "mean_energy": _value(getattr(sd, "mean_energy", None)),
            "prob_below_barrier": _value(getattr(sd, "prob_below_barrier", None)),
            "tail_p_over_peak": float(p[-1] / p[k]) if p[k] > 0 else float("nan"),
        }
    if res.mc is None:
        return out
    mc = res.mc
    edges = np.asarray(mc.h_edges, dtype=float)
    p_mc = mc_h_density(mc)
    pa, pb = (mc_h_density(h) for h in res.halves)
    widths = np.diff(edges)
    span = edges[-1] - edges[0]
    k = int(np.argmax(p_mc))
    out["mc"] = {
        "peak_p": float(p_mc[k]), "peak_H": float(0.5 * (edges[k] + edges[k + 1])),
        "mean_energy": _value(mc.mean_energy), "mean_energy_ci": _ci(mc.mean_energy),
        "prob_below_barrier": _value(getattr(mc, "prob_below_barrier", None)),
        "impact_rate": _value(getattr(mc, "impact_rate", None)),
        "mass_above_h_max": mass_outside(mc),
        "mass_outside_xy_window": xy_outside(mc),
        "mass_in_last_5pct_of_range": float(np.sum((p_mc * widths)[edges[1:] > edges[0] + 0.95 * span])),
        "noise_l1_halves": halves_noise_l1(pa, pb, widths),
        "seeds": list(res.mc_seeds), "wall_s": res.mc_wall, "cached": res.mc_cached,
        "compile_s": float(sum(getattr(h, "compile_time", 0.0) or 0.0 for h in res.halves)),
        "path_steps": int(sum(int(getattr(h, "path_steps", 0) or 0) for h in res.halves)),
    }
    l1 = {}
    binavg = {}
    for method, sd in res.densities.items():
        binavg[method] = bin_average(sd.H, sd.p, edges)
        l1[f"{method}_vs_mc"] = l1_on_bins(binavg[method], p_mc, edges)
    if "paper" in binavg and "jump" in binavg:
        l1["paper_vs_jump"] = l1_on_bins(binavg["paper"], binavg["jump"], edges)
    l1["mc_noise"] = out["mc"]["noise_l1_halves"]
    out["l1_energy"] = l1
    if spec.kind == "joint":
        xe, ye = (np.asarray(e, dtype=float) for e in mc.xy_edges)
        pxy = mc_xy_density(mc)
        pxa, pxb = (mc_xy_density(h) for h in res.halves)
        area = np.outer(np.diff(ye), np.diff(xe))
        lj = {f"{m}_vs_mc": l1_joint(joint_bin_average(sd.joint, xe, ye), pxy, xe, ye)
              for m, sd in res.densities.items()}
        lj["mc_noise"] = float(0.5 * np.sum(np.abs(pxa - pxb) * area))
        out["l1_joint"] = lj
    return out


# ------------------------------------------------------------------------------------------ claims
def _monotone(values, decreasing=True) -> bool:
    d = np.diff(np.asarray(values, dtype=float))
    return bool(np.all(d < 0) if decreasing else np.all(d > 0))


def check_claims(spec: FigureSpec, results: list[CaseResult], metrics: list[dict]) -> list[dict]:
    """The paper's qualitative statements for this figure, evaluated on our numbers (never tuned to agree)."""
    n = spec.number
    checks = []

    def peaks(source):
        return [m[source]["peak_p"] for m in metrics if source in m]

    def add(statement, holds, detail):
        checks.append({"statement": statement, "holds": holds, "detail": detail})

    sources = [s for s in ("paper", "jump", PHASE_METHOD, "mc") if all(s in m for m in metrics)]
    if n in (2, 14):
        for s in sources:
            add(f"peak of p(H) falls as Δ grows ({s})", _monotone(peaks(s)), {"peaks": peaks(s)})
    if n in (6, 12):
        for s in sources:
            add(f"peak of p(H) falls as V_C grows ({s}; the paper's wording for Fig. 6)", _monotone(peaks(s)),
                {"peaks": peaks(s)})
        if all("mc" in m for m in metrics):
            means = [m["mc"]["mean_energy"] for m in metrics]
            add("mean energy grows with V_C (less dissipation; Monte Carlo)", _monotone(means, False), {"means": means})
            if n == 6:
                add("the paper's inference for Fig. 6: more energy is dissipated as V_C grows, i.e. the mean energy "
                    "falls (Monte Carlo)", _monotone(means, True), {"means": means})
    if n in (10, 13):
        for s in sources:
            add(f"peak of p(H) falls as D grows ({s})", _monotone(peaks(s)), {"peaks": peaks(s)})
    if n == 11:
        for s in sources:
            add(f"peak of p(H) rises as c grows ({s})", _monotone(peaks(s), False), {"peaks": peaks(s)})
    if n in (15, 16):
        # Judged on the analytic joint density along y = 0 (paper method): the ring is where p(x, 0) peaks.
        res, d = results[0], results[0].case.delta
        sd = res.densities["paper"]
        xs = np.linspace(-d, d, 401)
        row = np.asarray(sd.joint(xs, np.array([0.0]))).ravel()
        p00, p_edge, p_max = float(row[200]), float(max(row[0], row[-1])), _joint_max(res)
        x_ring = float(abs(xs[int(np.argmax(row))]))
        detail = {"p00": p00, "p_at_barrier": p_edge, "p_max": p_max, "x_of_max_on_y0": x_ring, "delta": d}
        if n == 15:
            add("complete ring: p(0, 0) below half the ring's maximum and the ring's maximum on y = 0 inside the "
                "barriers (paper method)", p00 < 0.5 * p_max and x_ring < d - 0.05, detail)
            # The paper's text says the system has no impact at Δ = 3.0; measure it.
            above = {s: 1.0 - metrics[0][s]["prob_below_barrier"] for s in sources}
            add("no impacts at Δ = 3.0 (paper's text): P(H > G(Δ)) below 1 % (every method)",
                all(v < 0.01 for v in above.values()),
                {"prob_above_barrier": above, "p_at_barrier_over_max": p_edge / p_max,
                 "mc_impact_rate": metrics[0].get("mc", {}).get("impact_rate")})
        else:
            add("truncated ring: the density on y = 0 is largest at the barriers x = ±Δ and p(0, 0) lies below "
                "it (paper method)", x_ring > d - 0.05 and p00 < p_edge, detail)
    if spec.kind == "joint" and n not in (15, 16):
        m = metrics[0]
        if "l1_joint" in m:
            add("analytic joint density agrees with Monte Carlo (L1 on the Monte Carlo cells; no threshold)", None,
                m["l1_joint"])
    return checks


def _joint_max(res: CaseResult) -> float:
    (x0, x1), (y0, y1) = xy_range(res.case)
    xs, ys = np.linspace(x0, x1, JOINT_GRID), np.linspace(y0, y1, JOINT_GRID)
    return float(np.max(res.densities["paper"].joint(xs, ys)))


# ------------------------------------------------------------------------------------------ outputs
def curve_rows(spec: FigureSpec, results: list[CaseResult]):
    """The long-format table of every plotted curve and point (the figure's CSV)."""
    import pandas as pd

    frames = []
    for res in results:
        label = res.case.label
        for method, sd in res.densities.items():
            frames.append(pd.DataFrame({"curve": f"{label} | {method}", "case": label, "method": method,
                                        "quantity": "p(H)", "x": np.asarray(sd.H), "y": np.asarray(sd.p)}))
        if res.mc is not None:
            edges = np.asarray(res.mc.h_edges, dtype=float)
            pa, pb = (mc_h_density(h) for h in res.halves)
            frames.append(pd.DataFrame({
                "curve": f"{label} | mc", "case": label, "method": "mc", "quantity": "p(H)",
                "x": 0.5 * (edges[1:] + edges[:-1]), "y": mc_h_density(res.mc), "x_lo": edges[:-1],
                "x_hi": edges[1:], "ci": 1.96 * 0.5 * np.abs(pa - pb),
            }))
        if spec.kind == "joint":
            (x0, x1), (y0, y1) = xy_range(res.case)
            xs, ys = np.linspace(x0, x1, JOINT_GRID), np.linspace(y0, y1, JOINT_GRID)
            XX, YY = np.meshgrid(xs, ys)
            for method, sd in res.densities.items():
                frames.append(pd.DataFrame({"curve": f"{label} | {method} joint", "case": label, "method": method,
                                            "quantity": "p(x,y)", "x": XX.ravel(), "y": YY.ravel(),
                                            "z": np.asarray(sd.joint(xs, ys)).ravel()}))
            if res.mc is not None:
                xe, ye = (np.asarray(e, dtype=float) for e in res.mc.xy_edges)
                xc, yc = 0.5 * (xe[1:] + xe[:-1]), 0.5 * (ye[1:] + ye[:-1])
                XX, YY = np.meshgrid(xc, yc)
                lo_x, lo_y = np.meshgrid(xe[:-1], ye[:-1])
                hi_x, hi_y = np.meshgrid(xe[1:], ye[1:])
                frames.append(pd.DataFrame({"curve": f"{label} | mc joint", "case": label, "method": "mc",
                                            "quantity": "p(x,y)", "x": XX.ravel(), "y": YY.ravel(),
                                            "z": mc_xy_density(res.mc).ravel(), "x_lo": lo_x.ravel(),
                                            "x_hi": hi_x.ravel(), "y_lo": lo_y.ravel(), "y_hi": hi_y.ravel()}))
    table = pd.concat(frames, ignore_index=True)
    cols = ["curve", "case", "method", "quantity", "x", "y", "z", "x_lo", "x_hi", "y_lo", "y_hi", "ci"]
    for c in cols:
        if c not in table:
            table[c] = np.nan
    return table[cols]


def output_names(number: int) -> dict:
    """File names of figure ``number``: PNG, CSV and the JSON sidecar.

    Examples
    --------
    >>> output_names(2)["sidecar"]
    'fig02.json'
    """
    stem = f"fig{number:02d}"
    return {"png": f"{stem}.png", "csv": f"{stem}.csv", "sidecar": f"{stem}.json"}


def run_figure(number, out_dir, preset: str = "default", with_mc: bool = True, force: bool = False,
               progress: bool = False, dpi: int = 110, cache: bool = True, log=None) -> FigureResult:
    """Compute, draw and write figure ``number`` into ``out_dir``; reuse it when already finished.

    Parameters
    ----------
    number : int or str
        Paper figure number, 2-16.
    out_dir : path
        Output directory (created).
    preset : {'quick', 'default', 'full'}
        Monte Carlo size.
    with_mc : bool
        Run Monte Carlo (False: analytic curves only, labelled so).
    force : bool
        Recompute even when a finished figure with the same spec hash exists.
    progress : bool
        Show tqdm progress bars (meant for a terminal).
    dpi : int
        PNG resolution.
    cache : bool
        Share Monte Carlo runs between figures through ``out_dir/.mc-cache``.
    log : callable, optional
        Called with one line per stage (each case, the drawing); for logs, where bars would be redrawn as lines.

    Returns
    -------
    FigureResult

    Examples
    --------
    >>> run_figure(1, "/tmp/never")
    Traceback (most recent call last):
    ...
    hybrid.errors.ParameterError: figure 1 is not reproduced: choose a number from 2 to 16, or 'all'
    """
    from tqdm.auto import tqdm

    spec = figure_spec(number)
    if preset not in PRESETS:
        raise ParameterError(f"unknown size preset {preset!r}; choose one of {PRESETS}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = output_names(spec.number)
    paths = {k: out_dir / v for k, v in names.items()}
    spec_hash = spec.spec_hash(preset, {"mc": bool(with_mc), "dpi": int(dpi)})
    if not force and finished(paths["sidecar"], spec_hash):
        data = json.loads(paths["sidecar"].read_text(encoding="utf-8"))
        return FigureResult(spec.number, "reused", paths, data, 0.0)
    t_start = time.perf_counter()
    mc_cache = MCCache(out_dir / ".mc-cache") if cache else None
    results = []
    bar = tqdm(spec.cases, desc=f"figure {spec.number}", unit="case", disable=not progress, leave=False)
    for k, case in enumerate(bar, 1):
        bar.set_postfix_str(case.label)
        if log is not None:
            log(f"figure {spec.number}: case {k}/{len(spec.cases)} {case.label}: averaging"
                + (" and Monte Carlo" if with_mc else ""))
        results.append(compute_case(spec, case, preset, with_mc, mc_cache, progress))
    metrics = [case_metrics(spec, r) for r in results]
    claims = check_claims(spec, results, metrics)
    table = curve_rows(spec, results)

    from vibro.references import PAPER, READINGS

    from .render import render_figure
    from .store import atomic_write

    if log is not None:
        log(f"figure {spec.number}: drawing {paths['png']}")
    notes = disagreements(spec, metrics, claims)
    caption = render_caption(spec, metrics, with_mc, preset, notes)
    atomic_write(paths["png"], lambda tmp: render_figure(spec, results, metrics, caption, tmp, dpi=dpi))
    atomic_write(paths["csv"], lambda tmp: table.to_csv(tmp, index=False, float_format="%.10g"))
    wall = time.perf_counter() - t_start
    sidecar = {
        "figure": spec.number, "status": "finished", "kind": spec.kind, "title": spec.title,
        "paper": PAPER, "paper_readings": READINGS,
        "caption": caption, "claim": spec.claim, "choices": list(spec.choices), "in_paper_mc": spec.in_paper_mc,
        "preset": preset, "monte_carlo": bool(with_mc), "spec_hash": spec_hash,
        "methods": {"analytic": list(ANALYTIC_METHODS), "analytic_points": ANALYTIC_POINTS,
                    "phase_plane": {"method": PHASE_METHOD, "grid": list(PHASE_GRID),
                                    "call": "averaging.phase_plane.solve_phase_plane (one solve)"},
                    "monte_carlo": {"engine": "hybrid.stochastic.simulate_ensemble", "halves": 2,
                                    "per_half": {k: v for k, v in mc_settings(spec, spec.cases[0], preset).items()
                                                 if k not in ("h_max", "xy_range")}}
                    if with_mc else None},
        "l1_definition": "L1 = sum over Monte Carlo bins of |bin-averaged analytic p - p_mc| * bin width; "
                         "mc_noise = L1(half A, half B) / 2 (expected L1 of the merged histogram's noise)",
        "spec": spec.to_dict(),
        "cases": {r.case.label: m for r, m in zip(results, metrics)},
        "claims": claims,
        "disagreements": notes,
        "versions": versions(), "wall_time_s": wall,
        "command": " ".join(["vibro", "figure", str(spec.number), f"--{preset}" if preset != "default" else ""]
                            ).strip() + ("" if with_mc else " --no-mc"),
        "outputs": {names["png"]: sha256_file(paths["png"]), names["csv"]: sha256_file(paths["csv"])},
    }
    write_json(paths["sidecar"], sidecar)  # last: marks the figure finished
    return FigureResult(spec.number, "finished", paths, sidecar, wall)


NOISE_FACTOR = 3.0
"""An analytic curve 'disagrees' with Monte Carlo when its L1 exceeds this many times the Monte Carlo noise L1."""


def disagreements(spec: FigureSpec, metrics: list[dict], claims: list[dict]) -> list[str]:
    """Where our numbers contradict the paper's statement for this figure, one sentence each.

    A claim that fails on our data is listed, and so is every case where the paper method's L1 distance from
    Monte Carlo exceeds ``NOISE_FACTOR`` times the Monte Carlo noise (the paper shows its curves on top of the
    simulation as agreeing).

    Examples
    --------
    >>> m = [{"l1_energy": {"paper_vs_mc": 0.06, "jump_vs_mc": 0.02, "fpk_vs_mc": 0.004, "mc_noise": 0.005}}]
    >>> disagreements(FIGURES[2], m, [])[0].startswith("Δ = 0.8: the paper method is off Monte Carlo by L1 = 0.060")
    True
    """
    out = [f"Claim not reproduced: {c['statement']}." for c in claims if c["holds"] is False]
    key = "l1_joint" if spec.kind == "joint" else "l1_energy"
    for case, m in zip(spec.cases, metrics):
        l1 = m.get(key)
        if not l1:
            continue
        paper, jump, noise = l1["paper_vs_mc"], l1["jump_vs_mc"], l1["mc_noise"]
        if paper > NOISE_FACTOR * noise:
            fpk = f", fpk {l1['fpk_vs_mc']:.3f}" if "fpk_vs_mc" in l1 else ""
            out.append(f"{case.label}: the paper method is off Monte Carlo by L1 = {paper:.3f}, "
                       f"{paper / noise:.0f}x the Monte Carlo noise ({noise:.3f}); jump method {jump:.3f}{fpk}.")
    return out


def render_caption(spec: FigureSpec, metrics: list[dict], with_mc: bool, preset: str,
                   notes: list[str] | None = None) -> str:
    """The caption under the figure: what is drawn, our choices, the L1 distances and the disagreements."""
    from vibro.references import PAPER_TITLE, READINGS

    parts = [f"Fig. {spec.number} of \"{PAPER_TITLE}\", reproduced (preset '{preset}'; our readings of the paper: "
             f"{READINGS}). The paper: " + spec.claim]
    parts += list(spec.choices)
    if spec.kind == "energy":
        parts.append("Lines: averaging, solid = paper method (eq. 30), dashed = jump method; dash-dot = phase-plane "
                     "Fokker-Planck solution (fpk); symbols: Monte Carlo; dotted verticals: H = G(Δ).")
    else:
        parts.append("Panels: eq. 31 with the paper and jump methods, the phase-plane Fokker-Planck solution (fpk, "
                     "no averaging), and Monte Carlo, on one colour scale.")
    if with_mc:
        rows = []
        for case, m in zip(spec.cases, metrics):
            key = "l1_joint" if spec.kind == "joint" else "l1_energy"
            l1 = m.get(key, {})
            rows.append(f"{case.label}: paper {l1.get('paper_vs_mc', float('nan')):.3f}, jump "
                        f"{l1.get('jump_vs_mc', float('nan')):.3f}, fpk {l1.get('fpk_vs_mc', float('nan')):.3f}, "
                        f"MC noise {l1.get('mc_noise', float('nan')):.3f}")
        parts.append(("L1 vs Monte Carlo (joint cells) — " if spec.kind == "joint" else "L1 vs Monte Carlo — ")
                     + "; ".join(rows) + ".")
    else:
        parts.append("Monte Carlo not run (analytic only).")
    if notes:
        parts.append("Where our numbers disagree with the paper: " + " ".join(notes))
    return " ".join(parts)


def run_figures(numbers, out_dir, progress: bool = False, **kwargs) -> list[FigureResult]:
    """Run several figures in order (``all`` = 2-16), reusing finished ones; see :func:`run_figure`."""
    from tqdm.auto import tqdm

    if numbers == "all":
        numbers = sorted(FIGURES)
    results = []
    for n in tqdm(list(numbers), desc="figures", unit="fig", disable=not progress):
        results.append(run_figure(n, out_dir, progress=progress, **kwargs))
    return results


