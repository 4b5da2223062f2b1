"""Coloured noise: an oscillator driven by filtered noise, against the closed-form spectrum and the white limit.
=============================================================================================================

``models.excitation`` attaches a filter to any model: an Ornstein-Uhlenbeck filter (bandwidth alpha) or a band-pass
filter (damping ratio zeta, centre omega_f), normalised so that the output tends to the model's white noise of the
same intensity D as the bandwidth grows. The filter's states join the model's and its parameters become automaton
parameters.

1. A linear oscillator x'' + c x' + x = z without barriers: Var x = ``int |H(iw)|^2 S_z(w) dw``, with the filter's
   closed-form spectral density S_z. Monte Carlo for three OU bandwidths and a band-pass filter; the only allowance
   beyond the 95 % interval is the splitting scheme's own bias, known exactly for a linear system.
2. The same oscillator between elastic barriers: as alpha grows, E[H] tends to the white-noise Gibbs value
   (p proportional to T(H) exp(-c H / D)), which the white-noise kernel meets. With impacts the coloured-noise
   deficit shrinks only as 1 / alpha (about 2 % at alpha = 64), so the limit is checked by extrapolation.
3. A Duffing impact oscillator (walls at +-0.6, Newton r = 0.8) under OU noise with alpha = 1: the stationary p(H)
   of the density solver on (x, y, eta) (``averaging.phase_plane.coloured``, as ``vibro pdf --method fpk --filter
   ou``) next to Monte Carlo, and the white-noise density of the same intensity, which holds twice the energy.

Run:  python examples/10_coloured_noise.py [--quick]   (headless; exits 1 if a check fails)
"""

import math
import sys

import matplotlib.pyplot as plt
import numpy as np
from scipy import integrate, linalg

from averaging.phase_plane import stationary_density_xy
from averaging.phase_plane.coloured import stationary_density_coloured
from hybrid.stochastic import simulate_automaton, simulate_ensemble
from models import DuffingImpact, Elastic, ImpactOscillator, Newton
from models.excitation import bandpass_filter, ou_filter

C, D = 0.5, 0.25


def spectrum(w, b, wf):
    """Filter output's spectral density: OU for wf = 0 (b = alpha), band-pass otherwise (b = 2 zeta wf)."""
    return D / math.pi * b**2 * (w**2 if wf else 1.0) / ((wf**2 - w**2) ** 2 + b**2 * w**2 if wf else b**2 + w**2)


def var_x(b, wf):
    return 2 * integrate.quad(lambda w: spectrum(w, b, wf) / ((1 - w**2) ** 2 + (C * w) ** 2), 0, np.inf,
                              limit=400)[0]


def scheme_var_x(dt, b, wf):
    """Var x under the splitting scheme's linear one-step map (half kick, free flight, noise, half kick)."""
    A = np.array([[0, 1, 0, 0], [-1, -C, 0, 1], [0, 0, 0, 1], [0, 0, -wf**2, -b]], dtype=float)
    B = np.array([[0], [0], [0], [b * math.sqrt(2 * D)]])
    K = np.eye(4) + 0.5 * dt * np.diag([0, 1, 0, 1]) @ A
    M, N = K @ (np.eye(4) + dt * np.diag([1, 0, 1, 0]) @ A) @ K, K @ B
    keep = [0, 1, 3] if wf == 0 else [0, 1, 2, 3]  # the OU filter's integral is a random walk: leave it out
    sub = np.ix_(keep, keep)
    return linalg.solve_discrete_lyapunov(M[sub], (N @ N.T)[sub] * dt)[0, 0]


def main(quick: bool) -> int:
    t_end = 1500.0 if quick else 6000.0
    ok = True
    lin = ImpactOscillator("x", "c*y", parameters={"c": C, "D": D}, barriers=None, name="linear")
    print(f"1. x'' + {C} x' + x = z, no barriers; white noise of intensity D = {D} gives Var x = {D / C:.4f}")
    cases = [("OU alpha = 0.5", ou_filter(lin, alpha=0.5), 0.5, 0.0, 0.01),
             ("OU alpha = 2", ou_filter(lin, alpha=2.0), 2.0, 0.0, 0.01),
             ("OU alpha = 8", ou_filter(lin, alpha=8.0), 8.0, 0.0, 0.005),
             ("band-pass zeta = 0.25, omega_f = 1.5", bandpass_filter(lin, zeta=0.25, omega_f=1.5), 0.75, 1.5, 0.01)]
    for label, model, b, wf, dt in cases:
        ens = simulate_automaton(model, "splitting", dt=dt, paths=64, t_end=t_end, t_burn=30.0, x0=(0, 0, 0, 0),
                                 seed=10, chunk_paths=4, observables={"z2": "z**2", "x2": "x**2", "y2": "y**2"},
                                 histograms={"z2": (0, 1e3, 1), "x2": (0, 1e3, 1), "y2": (0, 1e3, 1)})
        est, exact, bias = ens.mean("x2"), var_x(b, wf), abs(scheme_var_x(dt, b, wf) - var_x(b, wf))
        good = abs(est.value - exact) <= 3 * est.ci + bias
        ok &= good
        print(f"   {label:<38} Var x: Monte Carlo {est}, spectrum {exact:.4f} (scheme bias {bias:.1e}) "
              f"{'ok' if good else 'FAILED'}")

    delta = 0.6
    theta = D / C
    walls = ImpactOscillator("x", "c*y", parameters={"c": C, "D": D, "delta": delta}, restitution=Elastic())

    def period(H):
        return 2 * math.pi if H <= delta**2 / 2 else 4 * math.asin(delta / math.sqrt(2 * H))

    def moment(k):
        return integrate.quad(lambda H: H**k * period(H) * math.exp(-H / theta), 0, 60 * theta,
                              points=[delta**2 / 2], limit=400)[0]

    gibbs = moment(1) / moment(0)
    white = simulate_ensemble(walls, "splitting", dt=0.01, paths=64, t_end=t_end, t_burn=20.0, seed=3,
                              h_max=4.0).mean_energy
    print(f"2. the same oscillator between elastic barriers at +-{delta}: white-noise Gibbs E[H] = {gibbs:.4f}, "
          f"white-noise kernel {white}")
    ok &= abs(white.value - gibbs) <= 3 * white.ci
    filtered = ou_filter(walls, alpha=1.0)
    alphas, means, sigmas = (2.0, 16.0, 32.0, 64.0), [], []
    for alpha in alphas:
        est = simulate_automaton(filtered, "splitting", dt=0.005, paths=64, t_end=t_end, t_burn=20.0,
                                 x0=(0, 0, 0, 0), seed=5, chunk_paths=4, params={"alpha": alpha},
                                 histograms={"H": (0.0, 4.0, 40)}).mean("H")
        means.append(est.value)
        sigmas.append(est.ci / 1.96)
        print(f"   OU alpha = {alpha:>4g}: E[H] = {est}  ({est.value / gibbs - 1:+.1%} from white noise; "
              f"alpha x deficit {alpha * (gibbs - est.value):.3f})")
    # the deficit is first order in 1 / alpha: fit E = E_inf + a / alpha on the three largest bandwidths
    X = np.column_stack([np.ones(3), 1.0 / np.array(alphas[1:])])
    w = 1.0 / np.array(sigmas[1:]) ** 2
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    e_inf, slope = cov @ X.T @ (w * np.array(means[1:]))
    good = abs(e_inf - gibbs) <= 3 * math.sqrt(cov[0, 0]) and slope < 0
    ok &= good
    print(f"   alpha -> inf (fit E_inf + a / alpha): E_inf = {e_inf:.4f} ± {1.96 * math.sqrt(cov[0, 0]):.4f}, "
          f"a = {slope:.3f}; Gibbs {gibbs:.4f} {'ok' if good else 'FAILED'}")
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.errorbar(alphas, means, 1.96 * np.array(sigmas), fmt="o", label="Monte Carlo, OU-filtered noise")
    fit_alphas = np.geomspace(alphas[1], 1e3, 50)
    ax.plot(fit_alphas, e_inf + slope / fit_alphas, "C0--", label="fit E_inf + a / alpha")
    ax.axhline(gibbs, color="k", lw=1, label="white-noise Gibbs E[H] (alpha -> inf)")
    ax.set(xscale="log", xlabel="filter bandwidth alpha", ylabel="E[H] (95 % interval)",
           title=f"Linear oscillator between elastic walls at +-{delta}, OU-filtered noise")
    ax.legend()
    fig.tight_layout()
    ok &= duffing_against_monte_carlo(t_end, quick)
    print("OK" if ok else "FAILED")
    plt.show()  # nothing to show when headless (Agg); the documentation's gallery shows the figure
    return 0 if ok else 1


def duffing_against_monte_carlo(t_end: float, quick: bool) -> bool:
    """Section 3: the coloured-noise density solver against Monte Carlo on an OU-filtered Duffing impact model."""
    duffing = DuffingImpact(restitution=Newton(0.8), c=0.2, D=0.1, delta=0.6)
    model = ou_filter(duffing, alpha=1.0)
    sd = stationary_density_coloured(model, grid=(32, 32, 16) if quick else None, tol=0.05 if quick else 0.005)
    edges = np.linspace(0.0, 1.5, 31)
    ens = simulate_automaton(model, "splitting", dt=0.01, paths=64, t_end=2 * t_end, t_burn=50.0, x0=(0, 0, 0, 0),
                             seed=12, chunk_paths=4, histograms={"H": (0.0, 1.5, 30)})
    mc_e, mc_p = ens.density("H")
    l1 = float(np.abs(sd.bin_masses(edges) - mc_p * np.diff(mc_e)).sum())
    est = ens.mean("H")
    coarse = sd._coarse_solve.mean_energy  # the solve on the grid twice coarser: the solver's own E[H] error scale
    good = abs(sd.mean_energy - est.value) <= 3 * est.ci / 1.96 + abs(sd.mean_energy - coarse)
    white = stationary_density_xy(duffing)
    print(f"3. OU-filtered Duffing impact oscillator (alpha = 1, D = 0.1, walls at +-0.6, r = 0.8): density solver "
          f"E[H] = {sd.mean_energy:.5f} (grid {sd.metadata()['grid']}, estimated L1 of p(H) {sd.error_estimate:.2g}, "
          f"{sd.timing['solve']:.1f} s), Monte Carlo {est}, L1 of p(H) between them {l1:.3f}; white noise of the "
          f"same D: {white.mean_energy:.5f} "
          f"{'ok' if good else 'FAILED'}")
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.stairs(mc_p, mc_e, label="Monte Carlo (OU-filtered noise)", color="0.6", fill=True)
    H = np.linspace(0.0, 1.5, 301)
    ax.plot(H, sd.density(H), "C0", label="density solver on (x, y, eta)")
    ax.plot(H, white.density(H), "C1--", label="white noise of the same intensity")
    ax.axvline(duffing.barrier_energy, color="k", lw=0.8, ls=":", label="wall energy G(0.6)")
    ax.set(xlabel="H", ylabel="p(H)", title="Duffing impact oscillator under OU noise (alpha = 1)")
    ax.legend()
    fig.tight_layout()
    return good


if __name__ == "__main__":
    sys.exit(main("--quick" in sys.argv))
