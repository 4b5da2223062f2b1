"""Speed of the averaging (and, with --l1, its accuracy against Monte Carlo).

    python benchmarks/averaging_speed.py            # timings of p(H) on 2000 points, ratio against scipy quad
    python benchmarks/averaging_speed.py --l1       # L1 distance of p(H) from long Monte Carlo (a few minutes)

Timings: the first call (symbolic derivation, lambdify, Chebyshev table), a repeated call with the table cached,
and a call on fresh parameters (kernels cached, table rebuilt), against a baseline that evaluates eq. 30 on the
same grid with a plain ``scipy.integrate.quad`` loop (T, the action and the cumulative integral by quad).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings

import numpy as np
from scipy import integrate

from averaging import stationary_density
from averaging.stationary import _TABLES
from models import DuffingImpact, Ma


def _best(fn, repeat=7):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def quad_baseline(model, H):
    """Eq. 30 for Example 1 (paper method) by a plain scipy.integrate.quad loop (the baseline)."""
    a, b, c, D, delta = (model.params[k] for k in ("a", "b", "c", "D", "delta"))
    Gd = model.barrier_energy
    law = model.restitution

    def G(x):
        return 0.5 * a * x * x + 0.25 * b * x**4

    def coeffs(h):
        lim = min(float(model.amplitude(h)), delta)
        s = lambda x: np.sqrt(max(2 * h - 2 * G(x), 0.0))  # noqa: E731
        T = 2 * 2 * integrate.quad(lambda x: 1 / s(x) if s(x) > 0 else 0.0, 0, lim, limit=200)[0]
        Ia = 2 * integrate.quad(s, 0, lim, limit=200)[0]
        loss = 0.0
        if h > Gd:
            e = law.coefficient(np.sqrt(2 * (h - Gd)))
            loss = (1 - e**4) * (h - Gd)
        return (D - 2 * c * Ia / T - loss / T), 4 * D * Ia / T

    def f(h):
        m, s2 = coeffs(h)
        return 2 * m / s2 - 1 / h

    logp = np.empty(len(H) - 1)
    acc, prev = 0.0, 1e-12
    for i, h in enumerate(H[1:]):
        acc += integrate.quad(f, prev, h, limit=50)[0]
        prev = h
        logp[i] = acc + np.log(h) - np.log(coeffs(h)[1])
    return logp


def speed(points=2000):
    model = DuffingImpact()
    rows = []
    for method in ("paper", "exact-two-impact", "jump"):
        _TABLES.clear()
        t0 = time.perf_counter()
        stationary_density(model, method, h_max=4.0, points=points)
        first = time.perf_counter() - t0
        cached = _best(lambda m=method: stationary_density(model, m, h_max=4.0, points=points))

        def fresh(m=method):
            _TABLES.clear()
            stationary_density(model.with_params(D=0.05 + 1e-3 * np.random.rand()), m, h_max=4.0, points=points)

        rebuilt = _best(fresh, repeat=3)
        rows.append((method, first, cached, rebuilt))
    H = np.linspace(0, 4.0, points)
    n_base = 200  # the quad loop is slow: time 200 points and scale linearly
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        quad_baseline(model, H[: n_base + 1] * 1.0)
    base = (time.perf_counter() - t0) * (points - 1) / n_base
    print(f"p(H) on {points} points, Duffing Fig. 2 (delta=1, Ma vc=0.4), 2 cores")
    print(f"baseline (eq. 30 for the paper method by a scipy.integrate.quad loop, {n_base} points timed, scaled to "
          f"{points}): {base * 1e3:.0f} ms")
    print(f"{'method':18s} {'first call':>11s} {'cached':>9s} {'new params':>11s} {'quad/cached':>12s} "
          f"{'quad/new':>9s}")
    for method, first, cached, rebuilt in rows:
        print(f"{method:18s} {first * 1e3:9.1f}ms {cached * 1e3:7.1f}ms {rebuilt * 1e3:9.1f}ms "
              f"{base / cached:11.0f}x {base / rebuilt:8.0f}x")
    return rows, base


def l1_table(paths=512, t_end=4200.0, t_burn=200.0, dt=1e-3, bins=100, seed=7):
    """L1 distance between averaged p(H) and Monte Carlo, both normalised on [0, 4], on MC bins."""
    from hybrid.stochastic import simulate_ensemble

    cases = [("Fig. 2", dict(delta=0.8), 0.4), ("Fig. 2", dict(delta=1.0), 0.4), ("Fig. 2", dict(delta=1.2), 0.4),
             ("Fig. 6", dict(delta=0.6, D=0.01), 0.05)]
    print(f"MC: milstein dt={dt}, {paths} paths, t_end={t_end}, burn {t_burn}, {bins} bins on [0, 4], seed {seed}")
    print(f"{'case':8s} {'delta':>5s} {'D':>5s} {'vc':>5s} {'paper':>8s} {'exact2':>8s} {'jump':>8s} "
          f"{'MC-noise':>8s} {'paper/jump':>10s}")
    out = []
    for name, params, vc in cases:
        model = DuffingImpact(restitution=Ma(vc=vc)).with_params(**params)
        h_max = 4.0
        stats = simulate_ensemble(model, "milstein", dt=dt, paths=paths, t_end=t_end, t_burn=t_burn, seed=seed,
                                  h_max=h_max, bins=bins, xy_bins=None)
        edges = stats.h_edges
        mc = stats.h_counts / stats.h_counts.sum()
        # MC noise floor: L1 between two independent halves' estimate ~ sqrt(2/pi) * sum sd; use half-split
        dists, moments = {}, {}
        for method in ("paper", "exact-two-impact", "jump"):
            sd = stationary_density(model, method, h_max=h_max, points=2001)
            moments[method] = (sd.mean_energy, sd.impact_rate, sd.prob_below_barrier)
            t, w = np.polynomial.legendre.leggauss(8)
            mid = 0.5 * (edges[:-1] + edges[1:])[:, None]
            half = 0.5 * np.diff(edges)[:, None]
            mass = np.sum(sd.density(mid + half * t) * w, axis=1) * half[:, 0]
            dists[method] = float(np.abs(mass / mass.sum() - mc).sum())
        noise = stats_noise(model, dt, paths, t_end, t_burn, h_max, bins, seed)
        print(f"{name:8s} {params['delta']:5.2f} {model.params['D']:5.2f} {vc:5.2f} {dists['paper']:8.4f} "
              f"{dists['exact-two-impact']:8.4f} {dists['jump']:8.4f} {noise:8.4f} "
              f"{dists['paper'] / dists['jump']:10.2f}")
        out.append((name, params, vc, dists, noise))
        print(f"{'':8s} E[H]: MC {stats.mean_energy.value:.4f}+-{stats.mean_energy.ci:.4f} "
              + " ".join(f"{k} {v[0]:.4f}" for k, v in moments.items()))
        print(f"{'':8s} impact rate: MC {stats.impact_rate.value:.4f}+-{stats.impact_rate.ci:.4f} "
              + " ".join(f"{k} {v[1]:.4f}" for k, v in moments.items()))
        print(f"{'':8s} P(H<G): MC {stats.prob_below_barrier.value:.4f}+-{stats.prob_below_barrier.ci:.4f} "
              + " ".join(f"{k} {v[2]:.4f}" for k, v in moments.items()))
    return out


def stats_noise(model, dt, paths, t_end, t_burn, h_max, bins, seed):
    """L1 between two independent MC runs of half the paths each, divided by sqrt(2): the MC noise of the full run
    (approximately, scaled by 1/sqrt(2) again for twice the paths)."""
    from hybrid.stochastic import simulate_ensemble

    runs = [simulate_ensemble(model, "milstein", dt=dt, paths=paths // 2, t_end=t_end, t_burn=t_burn,
                              seed=seed + 1000 + k, h_max=h_max, bins=bins, xy_bins=None) for k in range(2)]
    a, b = (r.h_counts / r.h_counts.sum() for r in runs)
    return float(np.abs(a - b).sum()) / 2.0


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--l1", action="store_true", help="also measure the L1 table against Monte Carlo")
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--paths", type=int, default=512)
    parser.add_argument("--t-end", type=float, default=4200.0)
    args = parser.parse_args(argv)
    speed(args.points)
    if args.l1:
        l1_table(paths=args.paths, t_end=args.t_end)
    return 0


if __name__ == "__main__":
    sys.exit(main())
