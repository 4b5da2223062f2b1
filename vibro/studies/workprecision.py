"""Work-precision charts: error against wall time for Monte Carlo schemes, averaging methods and orbit backends.

``vibro bench work-precision --out-dir DIR [--quick]`` calls :func:`work_precision`, which writes

* ``workprecision_mc.csv`` / ``.png``: every Monte Carlo scheme (naive flip, Euler-Maruyama and Milstein with located
  crossings, splitting) over a range of dt and paths, on an *elastic* Duffing model whose stationary statistics
  are known in closed form (:class:`ElasticOracle`): L1 of p(H), |Delta E[x^2]| and the impact-rate error, with
  the statistical noise of each run (two independent halves) as a band;
* ``workprecision_averaging.csv`` / ``.png``: the averaging methods (paper, exact-two-impact, jump), the chain,
  ``fpk`` over its grids and Monte Carlo over run lengths on Example 1 with Ma's law, against ``fpk`` on a finer
  grid (its own estimate stated, and cross-checked by a converged Monte Carlo run);
* ``workprecision_deterministic.csv`` / ``.png``: heyoka and scipy orbits over tolerances: error of the impact
  times (against quadrature of the free quasi-period) and of delta H per impact (eq. 11), cost per impact;
* ``workprecision_forced.csv`` / ``.png`` / ``.txt`` and ``workprecision_coloured...``: the forced fpk (periodic
  density) and the coloured fpk (x, y, eta) over ladders of grids (and time steps), error against CPU time, on a
  closed form (linear oscillators) and against the stored Monte Carlo of examples 08 and 10 (``--parts forced,
  coloured``; the caption in the .txt).

Every CSV has a ``method`` column and one row per (method, setting) with ``wall_time`` (s) and the errors.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import integrate

from hybrid.io import atomic_write, atomic_write_text, write_csv_atomically
from vibro.solve.errormodel import L1_BINS
from vibro.solve.metrics import bin_masses, l1_between_histograms, rebin_counts

MC_LABELS = {"naive": "naive flip", "em": "Euler-Maruyama (located)", "milstein": "Milstein (located)",
             "splitting": "splitting (BAOAB)"}


# ----------------------------------------------------------------------------- independent closed forms

@dataclass
class ElasticOracle:
    """Exact stationary statistics between *elastic* barriers for h = c*y and additive noise sigma**2.

    The stationary density is p(x, y) ~ exp(-beta H) on |x| < delta with beta = 2c / sigma**2, so y ~ N(0, 1/beta)
    independent of x, p(x) ~ exp(-beta G(x)), the impact rate (both walls) is 2 p_x(delta) / sqrt(2 pi beta) (Rice)
    and P(H < h) = int exp(-beta G) erf(sqrt(beta (h - G))) dx / Z. Computed here by scipy quadrature, independently
    of the averaging and simulation code.

    Examples
    --------
    >>> o = ElasticOracle(lambda x: 0.5 * x * x, beta=1.0, delta=np.inf)
    >>> round(o.mean_x2(), 10)           # harmonic oscillator: E[x^2] = 1/beta
    1.0
    >>> round(o.cdf(1.0), 10)            # H ~ Exp(beta) without barriers
    0.6321205588
    """

    G: object
    beta: float
    delta: float

    @classmethod
    def for_model(cls, model) -> ElasticOracle:
        """The oracle for a model with linear damping and additive noise (its restitution law is ignored)."""
        from hybrid.errors import ModelError
        c, s2 = model.linear_damping_constant(), model.constant_noise_intensity()
        if c is None or s2 is None or not (c > 0 and s2 > 0):
            raise ModelError("the elastic closed form needs damping c*y with c > 0 and additive noise")
        return cls(lambda x: float(model.potential(np.array([x]))[0]), 2.0 * c / s2, model.barriers[1])

    def _lim(self):
        return self.delta if np.isfinite(self.delta) else 60.0 / math.sqrt(self.beta)

    def _quad(self, f, hi=None):
        hi = self._lim() if hi is None else hi
        return integrate.quad(f, -hi, hi, epsabs=0.0, epsrel=1e-12, limit=400)[0]

    def z(self) -> float:
        return self._quad(lambda x: math.exp(-self.beta * self.G(x)))

    def mean_x2(self) -> float:
        """E[x^2]."""
        return self._quad(lambda x: x * x * math.exp(-self.beta * self.G(x))) / self.z()

    def impact_rate(self) -> float:
        """Impacts per unit time on both walls (0 without barriers)."""
        if not np.isfinite(self.delta):
            return 0.0
        px = math.exp(-self.beta * self.G(self.delta)) / self.z()
        return 2.0 * px / math.sqrt(2.0 * math.pi * self.beta)

    def cdf(self, h: float) -> float:
        """P(H < h)."""
        if h <= 0:
            return 0.0

        def inner(x):
            gap = h - self.G(x)
            return math.exp(-self.beta * self.G(x)) * math.erf(math.sqrt(self.beta * gap)) if gap > 0 else 0.0

        hi = self._lim()
        # integrate only where G < h (the integrand has a kink at the turning point)
        from scipy.optimize import brentq

        if self.G(hi) > h:
            hi = brentq(lambda x: self.G(x) - h, 0.0, hi, xtol=1e-14)
        return self._quad(inner, hi) / self.z()

    def bin_masses(self, edges) -> np.ndarray:
        """Exact probability of each energy bin, renormalised over the bins."""
        cdf = np.array([self.cdf(float(e)) for e in edges])
        m = np.diff(cdf)
        return m / m.sum()


def free_quasi_period(model, H: float) -> float:
    """Time between two impacts at opposite barriers of the free orbit at energy H > G(delta), symmetric gap:
    half the quasi-period T(H) of :func:`averaging.period` (the one implementation of periods)."""
    from averaging import period

    return 0.5 * float(period(model, float(H))[0])


# ----------------------------------------------------------------------------- Monte Carlo

def _mc_model(quick: bool):
    from models import DuffingImpact, Elastic

    # c = 0.1 relaxes in ~10 time units, so the statistical error falls below the discretisation bias quickly
    return DuffingImpact(restitution=Elastic(), a=1.0, b=0.2, c=0.1, D=0.1, delta=1.0)


def _run_halves(model, scheme, dt, paths, t_end, t_burn, h_max, seed, bins=L1_BINS * 10):
    from hybrid.stochastic import simulate_ensemble

    kw = dict(scheme=scheme, dt=dt, paths=max(paths // 2, 1), t_end=t_end, t_burn=t_burn, h_max=h_max, bins=bins,
              xy_bins=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # coarse steps are the point of the chart
        a = simulate_ensemble(model, seed=seed, **kw)
        b = simulate_ensemble(model, seed=seed + 104729, **kw)
    noise = l1_between_histograms(rebin_counts(a.h_counts, L1_BINS), rebin_counts(b.h_counts, L1_BINS)) / 2.0
    return a.merge(b), noise, a.wall_time + b.wall_time


def mc_work_precision(quick: bool = True, seed: int = 11, progress=print):
    """One row per (scheme, dt, paths): wall time and errors against the elastic closed form.

    Returns
    -------
    pandas.DataFrame
        Columns method, scheme, dt, paths, t_end, path_steps, wall_time, l1, l1_noise, x2_err, x2_ci,
        rate_err, rate_ci.
    """
    import pandas as pd

    model = _mc_model(quick)
    oracle = ElasticOracle.for_model(model)
    h_max = 14.0 / oracle.beta
    edges = np.linspace(0.0, h_max, L1_BINS + 1)
    exact = oracle.bin_masses(edges)
    x2, rate = oracle.mean_x2(), oracle.impact_rate()
    dts = [0.2, 0.1, 0.05, 0.02, 0.01] if quick else [0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.0025]
    paths_list = [64, 512] if quick else [64, 512, 2048]
    t_end, t_burn = 2100.0, 100.0
    rows = []
    for scheme in ("naive", "em", "milstein", "splitting"):
        for dt in dts:
            for paths in paths_list:
                try:
                    stats, noise, wall = _run_halves(model, scheme, dt, paths, t_end, t_burn, h_max, seed)
                except ValueError as exc:  # StepSizeError: the step rule refuses this dt
                    progress(f"  {scheme} dt={dt:g}: refused ({exc})")
                    rows.append(dict(method=MC_LABELS[scheme], scheme=scheme, dt=dt, paths=paths, t_end=t_end,
                                     status="refused", wall_time=np.nan))
                    continue
                mass = rebin_counts(stats.h_counts, L1_BINS)
                l1 = l1_between_histograms(mass, exact)
                rows.append(dict(
                    method=MC_LABELS[scheme], scheme=scheme, dt=dt, paths=paths, t_end=t_end, status="ok",
                    path_steps=stats.path_steps, wall_time=wall, l1=l1, l1_noise=noise,
                    x2_err=abs(stats.mean_x2.value - x2), x2_ci=stats.mean_x2.ci,
                    rate_err=abs(stats.impact_rate.value - rate), rate_ci=stats.impact_rate.ci,
                ))
                progress(f"  {scheme:9s} dt={dt:<6g} paths={paths:<4d} L1={l1:.4f} (noise {noise:.4f}) "
                         f"dx2={rows[-1]['x2_err']:.4f} drate={rows[-1]['rate_err']:.4f} {wall:.2f}s")
    df = pd.DataFrame(rows)
    df.attrs.update(model=repr(model), x2_exact=x2, rate_exact=rate, h_max=h_max)
    return df


def fit_bias_constants(df) -> dict:
    """Fit L1 bias ~ C dt**p (p = declared weak order with barriers) per scheme: the median of
    (L1 - noise) / dt**p over the largest-ensemble rows whose noise is below 40 % of the error."""
    from vibro.solve.planner import scheme_order as _scheme_order

    out = {}
    ok = df[df.status == "ok"]
    for scheme, g in ok[ok.paths == ok.paths.max()].groupby("scheme"):  # the largest ensembles: least noise
        g = g[g.l1 > 2.5 * g.l1_noise]
        if len(g) == 0:
            continue
        p = _scheme_order(scheme)
        out[scheme] = float(np.median((g.l1 - g.l1_noise) / g.dt**p))
    return out


# ----------------------------------------------------------------------------- averaging

def reference_mc(model, h_max, quick: bool, seed: int = 5, progress=print):
    """A converged Monte Carlo reference (splitting, small dt, many paths) and its measured noise."""
    from vibro.solve.planner import pick_scheme

    scheme = pick_scheme(model)
    dt = 0.005 if scheme == "splitting" else 0.002
    paths, t_end = (256, 4100.0) if quick else (512, 8200.0)
    stats, noise, wall = _run_halves(model, scheme, dt, paths, t_end, 100.0, h_max, seed)
    progress(f"  reference MC ({scheme}, dt={dt}, {paths} paths x {t_end:g}): noise {noise:.4f}, {wall:.1f}s")
    return rebin_counts(stats.h_counts, L1_BINS), noise, wall


AVERAGING_REFERENCE_GRID = (320, 384)
"""Grid of the fpk reference of the averaging chart: finer than every fpk point on the chart (its three-grid estimate,
stated on the chart, is the accuracy to which the chart's errors are known)."""


def averaging_work_precision(quick: bool = True, progress=print):
    """Averaging methods and the chain over their grid sizes, the phase-plane FPK solver over its grids, and Monte
    Carlo over run lengths, each against a reference more accurate than all of them.

    The reference is ``fpk`` on :data:`AVERAGING_REFERENCE_GRID` with its three-grid error estimate; a converged
    Monte Carlo run cross-checks it (their L1 distance and the Monte Carlo noise go into the frame's ``attrs``, with
    the reference's estimate). A Monte Carlo reference alone would hide every method better than its noise (about
    0.003): fpk and the chain are.
    """
    import pandas as pd

    from averaging import stationary_density
    from averaging.chain import chain_density
    from averaging.phase_plane import stationary_density_xy
    from models import DuffingImpact
    from vibro.solve.diagnostics import diagnose

    model = DuffingImpact()  # Example 1, Fig. 2 parameters with delta = 1.0
    h_max = diagnose(model).h_max  # stationary mass above it < 1e-5
    edges = np.linspace(0.0, h_max, L1_BINS + 1)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its estimate is measured below, on the chart's bins
        fine = stationary_density_xy(model, grid=AVERAGING_REFERENCE_GRID, h_max=h_max, tol=2.0)
    ref = fine.bin_masses(edges)
    ref_est = fine.estimate_error(edges)
    progress(f"  reference fpk {AVERAGING_REFERENCE_GRID}: estimated L1 {ref_est:.1e} "
             f"({time.perf_counter() - t0:.1f}s)")
    mc_ref, mc_noise, _ = reference_mc(model, h_max, quick, progress=progress)
    mc_ref = mc_ref / mc_ref.sum()
    cross = float(np.abs(mc_ref - ref).sum())
    progress(f"  cross-check: L1(fpk reference, Monte Carlo reference) = {cross:.4f} (Monte Carlo noise "
             f"{mc_noise:.4f})")
    rows = []
    stationary_density(model, method="jump", h_max=h_max, points=50)  # warm caches before timing
    for method in ("paper", "exact-two-impact", "jump", "chain"):
        for points in (50, 100, 200, 400, 800, 1600, 3200):
            t0 = time.perf_counter()
            if method == "chain":  # its cost is set by its own energy nodes (x 8 + 4 clock phases)
                sd = chain_density(model, h_max=h_max, energies=points)
            else:
                sd = stationary_density(model, method=method, h_max=h_max, points=points)
            wall = time.perf_counter() - t0
            l1 = float(np.abs(bin_masses(sd.H, sd.p, edges) - ref).sum())
            rows.append(dict(method=method, setting=f"points={points}", points=points, wall_time=wall, l1=l1,
                             l1_noise=ref_est))
            progress(f"  {method:16s} points={points:<5d} L1={l1:.4f} {wall:.3f}s")
    # the phase-plane FPK solver over its grid (rings x angles), one solve each (no coarse-grid check)
    from averaging.phase_plane import solve_phase_plane

    for grid in ((30, 32), (40, 48), (60, 64), (80, 96), (120, 144), (160, 192)):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a coarse grid warns of its own error; the L1 column measures it
            sd = solve_phase_plane(model, grid=grid, h_max=h_max)
        wall = time.perf_counter() - t0
        l1 = float(np.abs(sd.bin_masses(edges) - ref).sum())
        rows.append(dict(method="fpk", setting=f"grid={grid[0]}x{grid[1]}", points=grid[0] * grid[1], wall_time=wall,
                         l1=l1, l1_noise=ref_est))
        progress(f"  {'fpk':16s} grid={grid[0]}x{grid[1]:<4d} L1={l1:.4f} {wall:.3f}s")
    for paths, t_end in ((8, 600.0), (16, 1100.0), (32, 2100.0), (64, 4100.0)) + (((128, 8100.0),) if not quick
                                                                                 else ()):
        stats, noise, wall = _run_halves(model, "splitting", 0.01, paths, t_end, 100.0, h_max, seed=77)
        l1 = l1_between_histograms(rebin_counts(stats.h_counts, L1_BINS), ref)
        rows.append(dict(method="Monte Carlo (splitting, dt=0.01)", setting=f"paths={paths},t_end={t_end:g}",
                         points=np.nan, wall_time=wall, l1=l1, l1_noise=math.hypot(noise, ref_est)))
        progress(f"  MC paths={paths} t_end={t_end:g} L1={l1:.4f} (noise {noise:.4f}) {wall:.2f}s")
    df = pd.DataFrame(rows)
    df.attrs.update(model=repr(model), reference=f"fpk {AVERAGING_REFERENCE_GRID[0]}x{AVERAGING_REFERENCE_GRID[1]}",
                    reference_estimate=ref_est, mc_cross_check=cross, mc_reference_noise=mc_noise)
    return df


# ----------------------------------------------------------------------------- deterministic

def deterministic_work_precision(quick: bool = True, progress=print):
    """heyoka and scipy orbits across tolerances: impact-time and delta-H errors, cost per impact."""
    import pandas as pd

    from hybrid.deterministic import simulate_orbit
    from models import DuffingImpact, Newton

    e = 0.95
    model = DuffingImpact(restitution=Newton(e), c=0.0, D=0.0)
    Gd = model.barrier_energy
    v0 = 2.2
    t_end = 60.0 if quick else 200.0
    rows = []
    configs = [("heyoka", tol) for tol in (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-15)]
    configs += [("scipy", tol) for tol in (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)]
    for backend, tol in configs:
        simulate_orbit(model, x0=(0.0, v0), t_end=1.0, backend=backend, rtol=tol)  # compile/warm up first
        t0 = time.perf_counter()
        res = simulate_orbit(model, x0=(0.0, v0), t_end=t_end, backend=backend, rtol=tol)
        wall = time.perf_counter() - t0
        df = res.impacts.to_pandas()
        n = len(df)
        # oracle: energies after each impact are G + e^2 (H - G) exactly; times are sums of free half-crossings
        H = 0.5 * v0 * v0
        t = free_quasi_period(model, H) / 2.0  # x = 0 to the first barrier: half of a crossing
        times, dH = [], []
        for _k in range(n):
            times.append(t)
            dH.append((1.0 - e * e) * (H - Gd))
            H = Gd + e * e * (H - Gd)
            t += free_quasi_period(model, H)
        terr = float(np.max(np.abs(df.t.to_numpy() - np.array(times)))) if n else np.nan
        herr = float(np.max(np.abs((df.H_minus - df.H_plus).to_numpy() - np.array(dH)))) if n else np.nan
        rows.append(dict(method=backend, setting=f"rtol={tol:g}", rtol=tol, wall_time=wall, n_impacts=n,
                         cost_per_impact=wall / max(n, 1), t_err=terr, dH_err=herr, status=res.status))
        progress(f"  {backend:6s} rtol={tol:<7g} impacts={n} t_err={terr:.2e} dH_err={herr:.2e} "
                 f"{1e3 * wall / max(n, 1):.3f} ms/impact")
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- forced and coloured fpk

def _benchmark_module(name):
    """A module of the repository's benchmarks/ (its stored Monte Carlo references), or None outside a checkout."""
    import importlib
    import sys

    root = Path(__file__).resolve().parents[2]
    if not (root / "benchmarks" / f"{name}.py").exists():
        return None
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return importlib.import_module(f"benchmarks.{name}")


def forced_work_precision(quick: bool = True, progress=print):
    """The forced fpk (periodic density) over a ladder of cells and time steps: worst-phase L1 of p(H | t) against
    CPU time (its check, the estimate's two extra solves, included).

    Two cases: the linear oscillator without walls (x'' + 0.5 x' + x = 0.4 cos 1.3 t + xi, D = 0.05), against its
    closed form (2 c H / D noncentral chi-square at every section; 8 phases, 40 bins of [0, 3]); and example 08's
    forced Duffing impact oscillator (D = 0.02), against the stored Monte Carlo of ``vibro mc --phases 16``
    (benchmarks/data/fpk_forced_mc.npz, 16 phases, 40 bins of [0, 4]), whose noise is stated in ``attrs``.
    """
    import pandas as pd
    from scipy.stats import ncx2

    from averaging.phase_plane.forced import periodic_density_xy
    from models import ImpactOscillator

    rows = []
    c, A, W, D = 0.5, 0.4, 1.3, 0.05
    lin = ImpactOscillator("x", "c*y", forcing="A*cos(W*t)", barriers=None,
                           parameters={"c": c, "A": A, "W": W, "D": D})
    z = A / (1.0 - W**2 + 1j * c * W)
    edges = np.linspace(0.0, 3.0, L1_BINS + 1)
    for K in ((16, 32) if quick else (16, 32, 64)):
        for grid in ((16, 16), (24, 24), (32, 32)) + (() if quick else ((48, 48),)):
            t0 = time.process_time()
            sol = periodic_density_xy(lin, grid=grid, steps=K, h_max=3.0, phases=8, l1_tol=1.0)
            cpu = time.process_time() - t0
            worst = 0.0
            for t, sec in zip(sol.phase_times(8), sol.sections(8)):
                xp, yp = (z * np.exp(1j * W * t)).real, (1j * W * z * np.exp(1j * W * t)).real
                exact = np.diff(ncx2.cdf(2.0 * edges * c / D, 2, (xp**2 + yp**2) * c / D))
                worst = max(worst, float(np.abs(sec.bin_masses(edges) - exact).sum()))
            rows.append(dict(case="linear", method=f"fpk forced, {K} + {2 * K} steps", setting=str(grid), steps=K,
                             cpu_time=cpu, l1=worst, estimate=sol.error_estimate))
            progress(f"  linear {grid} {K} steps: L1 {worst:.2e} (estimate {sol.error_estimate:.2e}) {cpu:.1f} s")
    bench = _benchmark_module("fpk_forced")
    noise = math.nan
    if bench is not None:
        mc_edges, ref, per_phase = bench.mc_reference("0.02")
        noise = float(per_phase.max())
        ladder = [((30, 60), 16), ((40, 80), 16), ((30, 60), 32), ((40, 80), 32)]
        if not quick:
            ladder += [((60, 120), 32), ((60, 120), 64), ((64, 128), 64)]
        for grid, K in ladder:
            t0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # its GridWarning at the coarse rungs is the point of the ladder
                sol = bench.periodic_density_xy(bench.duffing(0.02), grid=grid, steps=K, h_max=4.0,
                                                phases=bench.PHASES)
            cpu = time.process_time() - t0
            worst = max(float(np.abs(sec.bin_masses(mc_edges) - r).sum())
                        for sec, r in zip(sol.sections(bench.PHASES), ref))
            rows.append(dict(case="example 08", method=f"fpk forced, {K} + {2 * K} steps", setting=str(grid),
                             steps=K, cpu_time=cpu, l1=worst, estimate=sol.error_estimate))
            progress(f"  example 08 {grid} {K} steps: L1 {worst:.4f} (estimate {sol.error_estimate:.4f}) {cpu:.1f} s")
    df = pd.DataFrame(rows)
    df.attrs.update(mc_noise=noise)
    return df


def linear_ou_energy_masses(c: float, D: float, alpha: float, edges) -> np.ndarray:
    """Exact masses of p(H), H = (x^2 + y^2) / 2, on ``edges`` for x'' + c x' + x = eta, eta an OU process
    (d eta = -alpha eta dt + alpha sqrt(2 D) dW): the Gaussian of the Lyapunov covariance, whose (x, y) marginal has
    independent x and y (zero stationary cross-covariance), so p(H) = exp(-a H) I0(b H) / sqrt(vx vy).

    Examples
    --------
    >>> m = linear_ou_energy_masses(0.5, 0.25, 2.0, np.linspace(0.0, 40.0, 401))
    >>> round(float(m.sum()), 6)
    1.0
    """
    from scipy import linalg, special

    S = linalg.solve_continuous_lyapunov(np.array([[0.0, 1.0, 0.0], [-1.0, -c, 1.0], [0.0, 0.0, -alpha]]),
                                         -np.diag([0.0, 0.0, 2 * alpha**2 * D]))
    vx, vy = S[0, 0], S[1, 1]
    a, b = 0.5 * (1 / vx + 1 / vy), 0.5 * (1 / vx - 1 / vy)
    return np.array([integrate.quad(lambda H: np.exp(-H * a) * special.i0(H * b) / np.sqrt(vx * vy), lo, hi)[0]
                     for lo, hi in zip(edges[:-1], edges[1:])])


def coloured_work_precision(quick: bool = True, progress=print):
    """The coloured fpk on (x, y, eta) over a ladder of grids: L1 of p(H) against CPU time (the check's coarse
    solve and the white-noise start included).

    Two cases: the linear oscillator without walls under OU noise (c = 0.5, D = 0.25, alpha = 2), against the
    Lyapunov Gaussian (40 bins of [0, 3]); and example 10's OU-filtered Duffing impact oscillator, against the
    stored Monte Carlo (benchmarks/data/fpk_coloured_mc.npz: two seeds at dt = 0.01, 1.28e9 samples each; 60 bins
    of [0, 3]), with the stored third run (dt = 0.005) as Monte Carlo's own point at its recorded CPU time.
    """
    import json

    import pandas as pd

    from averaging.phase_plane.coloured import stationary_density_coloured
    from models import ImpactOscillator
    from models.excitation import ou_filter

    rows = []
    c, D, alpha = 0.5, 0.25, 2.0
    lin = ou_filter(ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None, name="linear"),
                    alpha=alpha)
    edges = np.linspace(0.0, 3.0, L1_BINS + 1)
    exact = linear_ou_energy_masses(c, D, alpha, edges)
    ladder = ((16, 16, 8), (24, 24, 12), (32, 32, 16)) + (() if quick else ((48, 48, 24), (48, 48, 32)))
    for grid in ladder:
        t0 = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sd = stationary_density_coloured(lin, grid=grid, h_max=3.0)
        cpu = time.process_time() - t0
        l1 = float(np.abs(sd.bin_masses(edges) - exact).sum())
        rows.append(dict(case="linear", method="fpk coloured", setting=str(grid), cpu_time=cpu, l1=l1,
                         estimate=sd.error_estimate))
        progress(f"  linear {grid}: L1 {l1:.2e} (estimate {sd.error_estimate:.2e}) {cpu:.1f} s")
    bench = _benchmark_module("fpk_coloured")
    noise = math.nan
    if bench is not None:
        mc_edges, ref, noise = bench.mc_reference()
        for grid in ladder:
            t0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sd = stationary_density_coloured(bench.model(), grid=grid)
            cpu = time.process_time() - t0
            l1 = float(np.abs(sd.bin_masses(mc_edges) - ref).sum())
            rows.append(dict(case="example 10", method="fpk coloured", setting=str(grid), cpu_time=cpu, l1=l1,
                             estimate=sd.error_estimate))
            progress(f"  example 10 {grid}: L1 {l1:.4f} (estimate {sd.error_estimate:.4f}) {cpu:.1f} s")
        data = np.load(bench.DATA)
        info = json.loads(str(data["dt0.005_seed3_info"]))
        run = bench._masses(data, "dt0.005_seed3")
        rows.append(dict(case="example 10", method="Monte Carlo (stored run)", setting="dt 0.005, 1.28e9 samples",
                         cpu_time=float(info["cpu_s"]), l1=float(np.abs(run - ref).sum()), estimate=math.nan))
    df = pd.DataFrame(rows)
    df.attrs.update(mc_noise=float(noise))
    return df


# ----------------------------------------------------------------------------- charts

def _loglog(ax, x, y, label, band=None, marker="o", sort=True):
    order = np.argsort(x) if sort else np.arange(len(x))
    x, y = np.asarray(x)[order], np.asarray(y)[order]
    (line,) = ax.loglog(x, y, marker=marker, ms=4, label=label)
    if band is not None:
        b = np.asarray(band)[order]
        ax.fill_between(x, np.maximum(y - b, y / 3.0), y + b, color=line.get_color(), alpha=0.15, lw=0)


def plot_mc(df, path):
    """Three panels (L1 of p(H), |Delta E x^2|, impact-rate error) against wall time, one curve per scheme/paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = df[df.status == "ok"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    colours = dict(zip(MC_LABELS, ("tab:red", "tab:orange", "tab:blue", "tab:green")))
    most = ok.paths.max()
    for (scheme, paths), g in ok.groupby(["scheme", "paths"]):
        g = g.sort_values("dt", ascending=False)  # left to right: smaller dt, more work
        main_line = paths == most
        kw = dict(color=colours.get(scheme), ls="-" if main_line else ":", marker="o", ms=4 if main_line else 2,
                  lw=1.5 if main_line else 0.8, label=f"{MC_LABELS[scheme]}, {paths} paths")
        for ax, col, band in ((axes[0], "l1", "l1_noise"), (axes[1], "x2_err", "x2_ci"),
                              (axes[2], "rate_err", "rate_ci")):
            y = g[col].clip(lower=1e-5).to_numpy()
            ax.loglog(g.wall_time, y, **kw)
            if main_line:
                b = g[band].to_numpy()
                ax.fill_between(g.wall_time, np.maximum(y - b, y / 3.0), y + b, color=kw["color"], alpha=0.12, lw=0)
    for ax, t in zip(axes, ("L1 of p(H) vs exact", "|E[x²] − exact|", "|impact rate − exact|")):
        ax.set_xlabel("wall time [s] (dt decreasing →)")
        ax.set_title(t, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=6, ncol=1)
    fig.suptitle("Monte Carlo work-precision, elastic Duffing (c=0.1, D=0.1, Δ=1); bands: 95% / noise", fontsize=10)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=66))
    plt.close(fig)


def averaging_caption(df) -> str:
    """What the averaging chart shows, in words: axes, points, reference and its accuracy, and the cross-check.

    Examples
    --------
    >>> import pandas as pd
    >>> df = pd.DataFrame({"method": ["fpk"], "wall_time": [0.1], "l1": [1e-3]})
    >>> df.attrs.update(reference="fpk 320x384", reference_estimate=2e-4, mc_cross_check=4e-3, mc_reference_noise=3e-3)
    >>> "fpk on 320x384" in averaging_caption(df)
    True
    """
    a = df.attrs
    return (f"Each point: one run of a method at one resolution (points or energies of the averaging methods and the "
            f"chain, rings x angles of fpk, paths x time of Monte Carlo), its wall time against the L1 distance of "
            f"its p(H) (40 bins) from the reference, fpk on {a.get('reference', '?').split()[-1]}. The reference's "
            f"own three-grid estimate is {a.get('reference_estimate', float('nan')):.1e} (dotted line): errors "
            f"below it are not resolved. Cross-check: the reference is {a.get('mc_cross_check', float('nan')):.4f} "
            f"from a long Monte Carlo run whose own noise is {a.get('mc_reference_noise', float('nan')):.4f}.")


def plot_averaging(df, path):
    """L1 against the fpk reference vs wall time for the averaging methods, the chain, fpk and Monte Carlo."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 5.2))
    for method, g in df.groupby("method", sort=False):
        _loglog(ax, g.wall_time, g.l1, method, g.l1_noise if method.startswith("Monte") else None, sort=False)
    est = df.attrs.get("reference_estimate")
    if est:
        ax.axhline(est, color="grey", ls=":", lw=1, label="reference's own estimate")
    ax.set_xlabel("wall time of one run [s] (resolution refined →)")
    ax.set_ylabel(f"L1 of p(H), 40 bins, vs {df.attrs.get('reference', 'reference')}")
    ax.set_title("Averaging, chain, fpk and Monte Carlo, Example 1 (Fig. 2, Δ=1, V_C=0.4)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.text(0.01, 0.01, "\n".join(textwrap.wrap(averaging_caption(df), 125)), fontsize=6, va="bottom")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80))
    plt.close(fig)


def plot_deterministic(df, path):
    """Impact-time and delta-H errors against cost per impact for heyoka and scipy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for backend, g in df.groupby("method"):
        g = g.sort_values("rtol", ascending=False)  # loose to tight tolerance
        _loglog(axes[0], 1e3 * g.cost_per_impact, g.t_err.clip(lower=1e-16), backend, sort=False)
        _loglog(axes[1], 1e3 * g.cost_per_impact, g.dH_err.clip(lower=1e-16), backend, sort=False)
        for ax, col in ((axes[0], "t_err"), (axes[1], "dH_err")):
            for _, r in g.iterrows():
                ax.annotate(f"{r.rtol:.0e}", (1e3 * r.cost_per_impact, max(r[col], 1e-16)), fontsize=6,
                            xytext=(3, 2), textcoords="offset points")
    for ax, t in zip(axes, ("max |impact time − quadrature|", "max |δH − (1−e²)(H₋−G(Δ))|")):
        ax.set_xlabel("cost per impact [ms] (labels: rtol)")
        ax.set_title(t, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Orbit backends across tolerances (free Duffing, Newton e=0.95)", fontsize=10)
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80))
    plt.close(fig)


def fpk_caption(df, part: str) -> str:
    """What the forced or coloured chart shows: axes, points, references and their accuracy.

    Examples
    --------
    >>> import pandas as pd
    >>> df = pd.DataFrame({"case": ["linear"], "cpu_time": [1.0], "l1": [1e-3]})
    >>> df.attrs.update(mc_noise=0.002)
    >>> "closed form" in fpk_caption(df, "forced")
    True
    """
    noise = df.attrs.get("mc_noise", float("nan"))
    if part == "forced":
        return ("Each point: one run of the forced fpk (periodic density; Crank-Nicolson at K and 2K steps per "
                "period, combined) on one grid of Cartesian cells (labels), its CPU time (process time, its error "
                "estimate's two extra solves included) against the worst over the phases of the L1 of p(H | t) on 40 "
                "bins; lines join the grids at one K; hollow markers: the run's own estimate. Left: the linear "
                "oscillator without walls against its closed form (exact: every section Gaussian), 8 phases. Right: "
                "example 08 (forced Duffing impact, D = 0.02) against the stored Monte Carlo of vibro mc --phases 16 "
                f"(4 seeds x 384 000 samples per phase), whose noise, {noise:.4f} at the worst phase (dotted), "
                "limits what is resolved; no Monte Carlo run time was stored, so it has no curve.")
    return ("Each point: one run of the coloured fpk on (x, y, eta) at one grid (labels), its CPU time (process time, "
            "the white-noise start and the check's coarse solve included) against the L1 of p(H). Left: the linear "
            "oscillator without walls under OU noise (alpha = 2) against the Lyapunov Gaussian (exact), 40 bins. "
            "Right: example 10 (OU-filtered Duffing impact, alpha = 1) against the stored Monte Carlo (2 seeds at "
            f"dt = 0.01, 1.28e9 samples each; 60 bins), whose noise is {noise:.4f} (dotted); the square is the "
            "stored third Monte Carlo run (dt = 0.005) at its recorded CPU time. Hollow markers: the fpk's own "
            "two-grid estimate.")


def plot_fpk(df, path, part: str):
    """Two panels (closed form, example model) of L1 against CPU time for the forced or the coloured fpk."""
    import textwrap

    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in ("linear", "example 08", "example 10") if c in set(df.case)]
    fig, axes = plt.subplots(1, len(cases), figsize=(5.2 * len(cases), 4.6), squeeze=False)
    for ax, case in zip(axes[0], cases):
        g = df[df.case == case]
        for method, h in g.groupby("method", sort=False):
            h = h.sort_values("cpu_time")
            if method.startswith("Monte"):
                ax.loglog(h.cpu_time, h.l1, "s", color="k", label=method)
                continue
            (line,) = ax.loglog(h.cpu_time, h.l1, "o-", ms=4, label=method)
            ax.loglog(h.cpu_time, h.estimate, "o", mfc="none", color=line.get_color(), ms=6)
            for _, r in h.iterrows():
                ax.annotate(r.setting, (r.cpu_time, r.l1), fontsize=5, xytext=(3, -6), textcoords="offset points")
        noise = df.attrs.get("mc_noise")
        if case != "linear" and noise and np.isfinite(noise):
            ax.axhline(noise, color="grey", ls=":", lw=1, label="Monte Carlo reference's noise")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # minor labels overlap on a short decade
        ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("CPU time of one run [s]")
        ax.set_ylabel("L1 of p(H | t), worst phase" if part == "forced" else "L1 of p(H)")
        ax.set_title(("closed form" if case == "linear" else f"{case}, against stored Monte Carlo"), fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
    fig.suptitle(f"{'Forced (harmonic + white noise)' if part == 'forced' else 'Coloured (OU) noise'} fpk: "
                 "work-precision", fontsize=10)
    fig.text(0.01, 0.01, "\n".join(textwrap.wrap(fpk_caption(df, part), 150)), fontsize=6, va="bottom")
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=80))
    plt.close(fig)


def work_precision(out_dir, quick: bool = False, parts=("mc", "averaging", "deterministic", "forced", "coloured"),
                   progress=print) -> dict:
    """Run the work-precision benchmarks and write CSVs and PNGs into ``out_dir``.

    Parameters
    ----------
    out_dir : path
    quick : bool
        Small sizes (a few minutes on 2 cores).
    parts : sequence of {'mc', 'averaging', 'deterministic', 'forced', 'coloured'}
    progress : callable
        Receives one line per run.

    Returns
    -------
    dict
        part name -> pandas DataFrame.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    runners = {"mc": (mc_work_precision, plot_mc), "averaging": (averaging_work_precision, plot_averaging),
               "deterministic": (deterministic_work_precision, plot_deterministic),
               "forced": (forced_work_precision, lambda df, path: plot_fpk(df, path, "forced")),
               "coloured": (coloured_work_precision, lambda df, path: plot_fpk(df, path, "coloured"))}
    for part in parts:
        if part not in runners:
            from hybrid.errors import ParameterError

            raise ParameterError(f"unknown part {part!r}; choose from {sorted(runners)}")
        run, plot = runners[part]
        progress(f"[work-precision] {part}")
        df = run(quick=quick, progress=progress)
        write_csv_atomically(df, out / f"workprecision_{part}.csv")
        plot(df, out / f"workprecision_{part}.png")
        if part == "averaging":  # the reference and its accuracy travel with the CSV (a DataFrame's attrs do not)
            atomic_write_text(out / "workprecision_averaging.txt", averaging_caption(df) + "\n")
        if part in ("forced", "coloured"):
            atomic_write_text(out / f"workprecision_{part}.txt", fpk_caption(df, part) + "\n")
        results[part] = df
    return results


__all__ = [
    "ElasticOracle", "averaging_work_precision", "coloured_work_precision", "deterministic_work_precision",
    "fit_bias_constants", "forced_work_precision",
    "free_quasi_period", "mc_work_precision", "reference_mc", "work_precision",
]
