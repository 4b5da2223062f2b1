"""Harmonic plus random forcing: phase-resolved (Poincaré-section) densities by Monte Carlo and by the fpk solver.
===============================================================================================================

    x'' + c x' + a x + b x^3 = A cos(Omega t) + sqrt(2 D) xi(t),   ``|x| < delta``,   Newton impacts v+ = -r v-

A periodically forced system has periodic statistics: besides the time average, ``simulate_automaton(...,
phases=N, period=T)`` histograms the state at the N phases k T / N of the forcing (dt is lowered so that the
sections fall exactly on steps). Averaging does not apply to a forced model (it refuses it); the phase-plane solver
does (``periodic_density_xy``: the fixed point of the period map of the Fokker-Planck equation on Cartesian cells,
impacts included). This script checks the Monte Carlo and the solver against two independent references:

1. A linear oscillator without barriers (closed form): on every section the density is Gaussian with mean = the
   periodic response A Re(exp(i Omega t) / (w0^2 - Omega^2 + i c Omega)) and variance = the unforced stationary
   variance D / (c w0^2).
2. The Duffing impact oscillator as D -> 0: the section means tend to the deterministic period-1 impacting orbit,
   computed with heyoka (``simulate_orbit``) from its Poincaré section.

Then it reports the densities at D = 0.02, checks that the mean over the sections of E[H | phase] equals the
time average E[H] (a Riemann sum of a periodic mean that the noise makes smooth), and puts the solver's E[H | phase]
and p(H | phase) next to the Monte Carlo's (docs/results/fpk-forced.md compares them at converged Monte Carlo).

Run:  python examples/08_harmonic_random.py [--quick]   (headless; exits 1 if a check fails)
"""

import math
import sys

import matplotlib.pyplot as plt
import numpy as np

from averaging.phase_plane import periodic_density_xy
from hybrid.deterministic import simulate_orbit
from hybrid.stochastic import simulate_automaton
from models import ForcedDuffingImpact, ImpactOscillator, Newton


def linear(c=0.5, w0=1.0, W=1.3, A=0.4, D=0.05):
    # the whole declaration: a linear spring, linear damping, harmonic forcing, white noise, no barriers
    return ImpactOscillator("w0**2*x", "c*y", forcing="A*cos(W*t)",
                            parameters={"c": c, "w0": w0, "W": W, "A": A, "D": D}, barriers=None)


def duffing(D):
    return ForcedDuffingImpact(restitution=Newton(0.8), c=0.1, A=0.5, Omega=1.2, D=D)


def check_linear(quick: bool, N: int = 8) -> bool:
    c, w0, W, A, D = 0.5, 1.0, 1.3, 0.4, 0.05
    m = linear(c, w0, W, A, D)
    z = A / (w0**2 - W**2 + 1j * c * W)
    ens = simulate_automaton(m.to_automaton(), "splitting", dt=0.01, paths=64, t_end=250.0 if quick else 800.0,
                             t_burn=40.0, x0=(0.0, 0.0), seed=11, observables={"x": "x", "x2": "x**2"},
                             histograms={"x": (-3.0, 3.0, 60), "x2": (0.0, 4.0, 40)}, phases=N,
                             period=m.forcing_period, chunk_paths=4)
    var = D / (c * w0**2)
    # the solver: coarse cells suffice for a Gaussian (fourth order in time: Crank-Nicolson at 32 and 64 steps)
    sol = periodic_density_xy(m, grid=(32, 32), steps=32, h_max=3.0, phases=N, check=False)
    print(f"1. linear, no barriers: dt {ens.settings['dt']:.6g} (asked 0.01), {ens.settings['phase_steps']} steps "
          f"per phase, variance D/(c w0^2) = {var:.4g}")
    print("   phase   t      E[x] MC             closed form   fpk       Var[x] MC           fpk")
    misses, worst = 0, 0.0
    for k, (tk, sec) in enumerate(zip(ens.phase_times(), sol.sections(N))):
        mean, second = ens.phase_mean("x", k), ens.phase_mean("x2", k)
        exact = (z * np.exp(1j * W * tk)).real
        v = second.value - mean.value**2
        v_ci = second.ci + 2 * abs(mean.value) * mean.ci  # propagated half-width of E[x^2] - E[x]^2
        miss = (not mean.covers(exact)) + (abs(v - var) > v_ci)
        misses += miss
        fx = float(sec.marginal_x(xs := np.linspace(-3.0, 3.0, 601)) @ xs * (xs[1] - xs[0]))
        fv = sec.mean_x2 - fx**2
        worst = max(worst, abs(fx - exact) / abs(z), abs(fv / var - 1.0))
        print(f"   {k:5d} {tk:6.3f}  {mean:.4f}   {exact:+.4f}       {fx:+.4f}   {v:.4f} ± {v_ci:.4f}   {fv:.4f}"
              + ("  *" if miss else ""))
    print(f"   fpk: largest relative error of the section means and variances {worst:.1e} ({sol.grid.n} cells)")
    # 2N intervals at 95 %: more than 3 misses has a chance below 1 %; the fpk error measured 4.5e-4 (the tests)
    ok = misses <= 3 and worst < 2e-3
    fig, ax = plt.subplots(figsize=(6, 4))
    t = np.linspace(0.0, m.forcing_period, 200)
    ax.plot(t, (z * np.exp(1j * W * t)).real, "k-", label="periodic response (closed form)")
    means = [ens.phase_mean("x", k) for k in range(N)]
    ax.errorbar(ens.phase_times(), [e.value for e in means], [e.ci for e in means], fmt="o",
                label=f"Monte Carlo E[x | phase], {N} sections")
    ax.plot(sol.phase_times(N), [float(sec.marginal_x(xs) @ xs * (xs[1] - xs[0])) for sec in sol.sections(N)], "x",
            ms=9, label="fpk E[x | phase]")
    ax.set(xlabel="t mod T", ylabel="x", title="Linear oscillator, A cos(1.3 t) + white noise")
    ax.legend()
    fig.tight_layout()
    print(f"   {misses} of {2 * N} intervals miss the closed form: {'ok' if ok else 'FAILED'}")
    return ok


def deterministic_sections(m, N: int):
    """x and H at the phases k T / N on the attracting orbit (heyoka, after 150 periods of transient)."""
    T = m.forcing_period
    state = simulate_orbit(m.with_params(D=0.0), (0.0, 0.0), t_end=150 * T).state
    xs, hs, n_imp = [], [], 0
    t0 = 150 * T
    for k in range(N):
        r = simulate_orbit(m.with_params(D=0.0), state, t0=t0, t_end=t0 + k * T / N) if k else None
        s = state if r is None else r.state
        xs.append(s[0])
        hs.append(float(m.energy(s[0], s[1])))
    one = simulate_orbit(m.with_params(D=0.0), state, t0=t0, t_end=t0 + T)
    n_imp = one.n_impacts
    assert np.allclose(one.state, state, atol=1e-8), "the attractor is not period-1"
    return np.array(xs), np.array(hs), n_imp


def check_duffing(quick: bool, N: int = 16) -> bool:
    x_det, h_det, n_imp = deterministic_sections(duffing(0.0), N)
    print(f"2. Duffing impact oscillator, A = 0.5, Omega = 1.2, r = 0.8: a period-1 orbit with {n_imp} impacts per "
          "period (heyoka)")
    ok = True
    for D in (1e-4, 0.02):
        m = duffing(D)
        T = m.forcing_period  # a whole number of periods after burn-in: rates per period are not cut
        ens = simulate_automaton(m.to_automaton(), "splitting", dt=0.005, paths=64,
                                 t_end=(30 + (48 if quick else 190)) * T, t_burn=30 * T, x0=(0.0, 0.0), seed=5,
                                 observables={"H": m.energy_expr, "x": "x"},
                                 histograms={"H": (0.0, 4.0, 200), "x": (-1.0, 1.0, 80)}, phases=N,
                                 period=m.forcing_period, chunk_paths=4)
        H = ens.mean("H")
        h_phase = np.array([ens.phase_mean("H", k).value for k in range(N)])
        means = [ens.phase_mean("x", k) for k in range(N)]
        dev = np.array([abs(e.value - xd) for e, xd in zip(means, x_det)])
        rate = sum(ens.rate(tr) for tr in ens.transitions) * m.forcing_period
        print(f"   D = {D:g}: E[H] = {H}, mean of E[H | phase] over the {N} sections = {h_phase.mean():.4f}, "
              f"impacts per period {rate:.3f}")
        if D <= 1e-4:
            # D -> 0: within O(D / c) of the deterministic orbit (the spread is sqrt(D / c) ~ 0.03)
            worst = float(dev.max())
            worst_h = float(np.max(np.abs(h_phase - h_det)))
            print(f"   max |E[x | phase] - x_orbit(phase)| = {worst:.2e}, max |E[H | phase] - H_orbit(phase)| = "
                  f"{worst_h:.2e}; impacts per period {rate:.3f} vs {n_imp}")
            ok &= worst < 0.02 and worst_h < 0.02 and abs(rate - n_imp) < 0.01
        else:
            # with noise E[H | t] is smooth in t, and the sections tile the period: their mean is a Riemann sum of
            # it, equal to the time average E[H] (sampled every step) within the statistical error
            ok &= abs(h_phase.mean() - H.value) < 3 * H.ci
            e, dens = ens.density("H")
            mode = 0.5 * (e[np.argmax(dens)] + e[np.argmax(dens) + 1])
            spread = [math.sqrt(max(ens.phase_mean("H", k).value, 0.0)) for k in (0, N // 4, N // 2)]
            print(f"   time-averaged p(H): mode at H = {mode:.3f}; section means of x at phases 0, 1/4, 1/2: "
                  + ", ".join(f"{means[k].value:+.3f} (orbit {x_det[k]:+.3f})" for k in (0, N // 4, N // 2))
                  + f"; sqrt E[H | phase] {', '.join(f'{s:.3f}' for s in spread)}")
            ok &= against_fpk(m, ens, N)
    print(f"   Duffing checks: {'ok' if ok else 'FAILED'}")
    return ok


def against_fpk(m, ens, N: int) -> bool:
    """The periodic density by the phase-plane solver next to the Monte Carlo sections: E[H | phase] inside the
    Monte Carlo intervals, and p(H | phase) on 40 bins."""
    # coarse cells, for speed; 32 + 64 steps keep the estimate (cells + time steps, 0.014) within l1_tol
    sol = periodic_density_xy(m, grid=(40, 80), steps=32, h_max=4.0, phases=N, l1_tol=0.02)
    h_fpk = sol.mean_energy_at(sol.phase_times(N))
    mc = [ens.phase_mean("H", k) for k in range(N)]
    misses = sum(not e.covers(v) for e, v in zip(mc, h_fpk))
    l1 = []
    for k, sec in enumerate(sol.sections(N)):
        e, dens = ens.phase_density("H", k)
        coarse = (dens * np.diff(e)).reshape(40, -1).sum(axis=1)  # 200 bins of [0, 4] -> 40
        l1.append(float(np.abs(sec.bin_masses(e[::5]) - coarse).sum()))
    print(f"   fpk ({sol.grid.n} cells, {sol.iterations} period maps; estimated L1 error {sol.error_estimate:.1e}): "
          f"time-averaged E[H] = {sol.mean_energy:.4f}, impacts per period {sol.impact_rate * sol.period:.3f}; "
          f"E[H | phase] outside the Monte Carlo intervals at {misses} of {N} phases; L1 of p(H | phase) against "
          f"this Monte Carlo {np.mean(l1):.3f} (its own sampling noise: the converged comparison is in "
          "docs/results/fpk-forced.md)")
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    t = sol.phase_times(N)
    right.errorbar(t, [e.value for e in mc], [e.ci for e in mc], fmt="o", label="Monte Carlo")
    fine = np.linspace(0.0, sol.period, 200)
    right.plot(fine, sol.mean_energy_at(fine), "k-", label="fpk")
    right.set(xlabel="t mod T", ylabel="E[H | t]", title="Forced Duffing impact oscillator, D = 0.02")
    right.legend()
    for k in (0, N // 4):
        e, dens = ens.phase_density("H", k)
        left.stairs(dens, e, label=f"Monte Carlo, t = {t[k]:.2f}")
        sec = sol.section(t[k])
        left.plot(sec.H, sec.p, label=f"fpk, t = {t[k]:.2f}")
    left.set(xlabel="H", ylabel="p(H | t)", xlim=(0.0, 2.5))
    left.legend()
    fig.tight_layout()
    return misses <= 3  # N intervals at 95 %: more than 3 misses has a chance below 1 % (the fpk error is smaller)


def main(quick: bool) -> int:
    ok = check_linear(quick)
    ok &= check_duffing(quick)
    print("OK" if ok else "FAILED")
    plt.show()  # nothing to show when headless (Agg); the documentation's gallery shows the figure
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main("--quick" in sys.argv))
