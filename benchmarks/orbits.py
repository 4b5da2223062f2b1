"""Benchmark: heyoka (Taylor, terminal events) against scipy DOP853 on the free Duffing impact orbit.

Problem: x'' + x + 0.2 x^3 = 0 between barriers at +-1, Ma law V_C = 0.4, x0 = 0, v0 = 2.2, t in [0, T_END].
Reference: an independent heyoka integration in 80-bit long double (tolerance 1.1e-19) with the reset applied
in long double. For each backend and tolerance the script prints impacts per second (compile time excluded and
reported separately), the largest error of the impact times and of the pre-impact energies H- against the
reference, and the speed ratio heyoka / scipy at equal accuracy (the fastest heyoka setting that is at least
as accurate as the scipy setting).

Run:  python benchmarks/orbits.py [--t-end 2000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hybrid.deterministic import simulate_orbit
from hybrid.deterministic._heyoka import _CACHE
from models import DuffingImpact, Ma

A, B, DELTA, VC, V0 = 1.0, 0.2, 1.0, 0.4, 2.2


def reference(t_end: float):
    """Impact times and H- in long double, written directly against heyoka's API (independent of the package)."""
    import heyoka as hy

    ld = np.longdouble
    x, v = hy.make_vars("x", "v")
    events = [hy.t_event(x - ld(DELTA), direction=hy.event_direction.positive, fp_type=ld),
              hy.t_event(x + ld(DELTA), direction=hy.event_direction.negative, fp_type=ld)]
    ta = hy.taylor_adaptive([(x, v), (v, -ld(A) * x - ld(B) * x * x * x)], np.array([0, ld("2.2")], dtype=ld),
                            fp_type=ld, t_events=events)
    vc = ld(VC)
    times, energies = [], []
    while True:
        out = ta.propagate_until(ld(t_end))
        if out[0] == hy.taylor_outcome.time_limit:
            break
        xs, vs = ta.state[0], ta.state[1]
        times.append(ta.time)
        energies.append(vs * vs / 2 + ld(A) * xs * xs / 2 + ld(B) * xs**4 / 4)
        speed = abs(vs)
        e = ld(1) if speed <= vc else (vc / speed) ** (ld(1) / ld(6))
        ta.state[1] = -e * vs
    return np.array(times, dtype=ld), np.array(energies, dtype=ld)


def run(backend, rtol, t_end, repeat):
    import heyoka as hy

    _CACHE.clear()
    hy.llvm_state.clear_memcache()  # cold compile: neither our cache nor heyoka's in-memory one
    model = DuffingImpact(c=0.0, D=0.0, a=A, b=B, delta=DELTA, restitution=Ma(VC))
    first = simulate_orbit(model, (0.0, V0), 1.0, backend=backend, rtol=rtol)  # compile / lambdify once
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = simulate_orbit(model, (0.0, V0), t_end, backend=backend, rtol=rtol)
        best = min(best, time.perf_counter() - t0)
    return res, best, first.compile_time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=2000.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)

    import heyoka as hy

    if hasattr(hy.llvm_state, "set_diskcache_enabled"):
        hy.llvm_state.set_diskcache_enabled(False)  # this process only: measure real compile times
    t0 = time.perf_counter()
    t_ref, H_ref = reference(args.t_end)
    print(f"reference (heyoka, long double): {len(t_ref)} impacts up to t = {args.t_end:g} "
          f"in {time.perf_counter() - t0:.2f} s")
    rows = []
    settings = [("heyoka", None), ("heyoka", 1e-12), ("heyoka", 1e-10), ("heyoka", 1e-8),
                ("scipy", 1e-8), ("scipy", 1e-10), ("scipy", 1e-12)]
    print(f"{'backend':>8} {'rtol':>8} {'impacts':>8} {'steps':>8} {'wall s':>9} {'impacts/s':>11} "
          f"{'max |dt_imp|':>13} {'max |dH-|/H':>12} {'compile s':>10}")
    for backend, rtol in settings:
        res, wall, compile_time = run(backend, rtol, args.t_end, args.repeat)
        n = min(len(t_ref), res.n_impacts)
        err_t = float(np.max(np.abs(res.impacts.t[:n] - t_ref[:n].astype(float)))) if n else np.nan
        H = res.impacts.observables_before["H"][:n]
        err_H = float(np.max(np.abs(H - H_ref[:n].astype(float)) / H_ref[:n].astype(float))) if n else np.nan
        if res.n_impacts != len(t_ref):
            err_t = err_H = np.inf  # a missed or extra impact
        rate = res.n_impacts / wall
        label = "eps" if rtol is None else f"{rtol:.0e}"
        rows.append((backend, rtol, rate, err_t, err_H))
        print(f"{backend:>8} {label:>8} {res.n_impacts:>8d} {res.n_steps:>8d} {wall:>9.4f} {rate:>11.0f} "
              f"{err_t:>13.2e} {err_H:>12.2e} {compile_time:>10.3f}")
    print()
    print("speed ratio at equal accuracy (fastest heyoka setting with both errors <= the scipy setting's):")
    for backend, rtol, rate, err_t, err_H in rows:
        if backend != "scipy":
            continue
        fits = [r for r in rows if r[0] == "heyoka" and r[3] <= err_t and r[4] <= err_H]
        if not fits:
            print(f"  scipy rtol {rtol:.0e}: no heyoka setting is as accurate")
            continue
        best = max(fits, key=lambda r: r[2])
        label = "eps" if best[1] is None else f"{best[1]:.0e}"
        print(f"  scipy DOP853 rtol {rtol:.0e} (time err {err_t:.1e}, energy err {err_H:.1e}, {rate:.0f} impacts/s)"
              f" vs heyoka tol {label} (time err {best[3]:.1e}, energy err {best[4]:.1e}, {best[2]:.0f} impacts/s):"
              f" ratio {best[2] / rate:.1f}x")
    heyoka_eps = rows[0]
    scipy_tight = rows[-1]
    print(f"  heyoka at eps vs scipy at rtol 1e-12: {heyoka_eps[2] / scipy_tight[2]:.1f}x faster with time error "
          f"{heyoka_eps[3]:.1e} vs {scipy_tight[3]:.1e}")


if __name__ == "__main__":
    main()
