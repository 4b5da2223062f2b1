"""Accuracy of the fpk spectrum against closed forms, and Example 1's spectrum (docs/results/first-passage-spectra.md).

    python benchmarks/spectrum_accuracy.py [free] [folded] [example1] [stretch] [arcends] [mc [GRID ...]]

Free linear oscillator (c = 0.2, D = 0.05): |H|^2 2D/pi. The same with an elastic stop at x = 0 (the folded
oscillator |s|): the cosine transform of its covariance (tests/test_first_passage_spectra.py). Per grid: the L1
distance of S to the closed form over the closed form's integral on [0, 4], for the finest grid's S and for the
three-grid Richardson extrapolation (``extrapolate=True``: grids G, G/2, G/4, the order observed), the a-posteriori
estimate of the unextrapolated error, the observed order and CPU seconds. ``stretch`` compares the innermost ring
widths 0.4 (the stationary solver's) and 0.02 (the spectrum's default) on the free and folded oscillators, 80 x 96.
``arcends`` compares the phase flux's order at the arcs' ends (``arc_end_order`` 1, first-order upwind, and 2, the
spectrum's default) on the folded oscillator, 40 x 48, 40 x 96 and 80 x 96.
Example 1: x on [0, 6] (150 frequencies, 100 more around the peak), peak, bandwidth, variance check, estimate.
``mc``: Example 1's fpk spectrum against the Monte Carlo reference (benchmarks/spectrum_reference.py), at its
frequencies (every fourth bin on [0, 6] and every bin on [0.95, 1.35]) on grids such as 80x96 (the default):
the L1 distance over [0, 6] over the reference's integral, for the grid's S and its three-grid extrapolation; the
peak frequency as the vertex of the least-squares parabola through the samples above 0.85 of the highest (the
same estimator on both), the half-power bandwidth, the variance, and the L1 the window's own bias would give
(1/2 S'' mu2, mu2 = (4/3) pi^2 / T^2 the Hann kernel's second moment, S'' from the fpk curve).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from test_first_passage_spectra import folded_psd, free_psd  # noqa: E402

from averaging.phase_plane.spectrum import spectrum_fpk  # noqa: E402
from models import DuffingImpact, Elastic, ImpactOscillator, Ma  # noqa: E402


def l1(omega, S, exact):
    return float(np.trapezoid(np.abs(S - exact), omega) / np.trapezoid(exact, omega))


def main(which=("free", "folded", "example1")):
    c, D = 0.2, 0.05
    lin = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    cases = {"free": ({"walls": "model"}, free_psd, dict(points=40, refine=30), ((40, 48), (80, 96))),
             "folded": ({"walls": (0.0, None), "restitution": Elastic()}, folded_psd, dict(points=81, refine=0),
                        ((40, 48), (80, 96), (160, 192)))}
    for name, (kw, exact_fn, freq, grids) in cases.items():
        if name not in which:
            continue
        for grid in grids:
            t0 = time.process_time()
            s = spectrum_fpk(lin, "x", omega_max=4.0, grid=grid, h_max=3.0, extrapolate=True, **freq, **kw)
            exact = exact_fn(c, D, s.omega)
            print(json.dumps({"case": name, "grid": grid, "L1": l1(s.omega, s.unextrapolated, exact),
                              "L1_extrapolated": l1(s.omega, s.S, exact), "estimate": s.details["error_estimate"],
                              "order": s.details["order"], "peak_omega_extrapolated": s.peak_omega,
                              "variance_extrapolated": s.variance, "variance_check": s.variance_check,
                              "cpu_seconds": time.process_time() - t0}), flush=True)
    if "stretch" in which:
        for name in ("free", "folded"):
            kw, exact_fn, freq, _ = cases[name]
            for stretch in (0.4, 0.02):
                t0 = time.process_time()
                s = spectrum_fpk(lin, "x", omega_max=4.0, grid=(80, 96), h_max=3.0, stretch=stretch, **freq, **kw)
                print(json.dumps({"case": name, "grid": (80, 96), "stretch": stretch,
                                  "L1": l1(s.omega, s.S, exact_fn(c, D, s.omega)),
                                  "cpu_seconds": time.process_time() - t0}), flush=True)
    if "arcends" in which:
        kw, exact_fn, freq, _ = cases["folded"]
        for grid in ((40, 48), (40, 96), (80, 96)):
            for order in (1, 2):
                t0 = time.process_time()
                s = spectrum_fpk(lin, "x", omega_max=4.0, grid=grid, h_max=3.0, arc_end_order=order, **freq, **kw)
                print(json.dumps({"case": "folded", "grid": grid, "arc_end_order": order,
                                  "L1": l1(s.omega, s.S, exact_fn(c, D, s.omega)),
                                  "cpu_seconds": time.process_time() - t0}), flush=True)
    model = DuffingImpact(restitution=Ma(vc=0.4))
    for grid in ((40, 48), (80, 96)) if "example1" in which else ():
        t0 = time.process_time()
        s = spectrum_fpk(model, "x", omega_max=6.0, points=150, refine=100, grid=grid, check=True)
        print(json.dumps({"case": "example1", "grid": grid, "peak_omega": s.peak_omega, "peak_S": s.peak_S,
                          "bandwidth": s.bandwidth, "variance": s.variance, "integral": s.integral,
                          "variance_check": s.variance_check, "estimate": s.details["error_estimate"],
                          "order": s.details["order"], "cpu_seconds": time.process_time() - t0}), flush=True)


def against_monte_carlo(grids, arc_end_order=2):
    """fpk of Example 1 against the stored Monte Carlo reference, one JSON line per grid."""
    from averaging.phase_plane.spectrum import _half_power_width, fitted_peak

    ref = np.load(Path(__file__).resolve().parent / "data" / "spectrum_reference.npz")
    omega, S_mc = ref["omega"], ref["S"]
    idx = np.arange(len(omega))
    pick = (omega <= 6.0) & ((idx % 4 == 0) | ((omega >= 0.95) & (omega <= 1.35)))
    w = omega[pick]
    mc = S_mc[pick]
    k = int(np.argmax(mc))
    mc_peak = {"peak_fit": fitted_peak(w, mc), "peak_fit_dt01": fitted_peak(w, ref["S_dt01"][pick]),
               "peak_fit_dt005": fitted_peak(w, ref["S_dt005"][pick]), "bandwidth": _half_power_width(w, mc, k),
               "variance": float(ref["variance"]), "integral_0_6": float(np.trapezoid(mc, w))}
    print(json.dumps({"case": "example1-mc", **mc_peak, "frequencies": int(pick.sum())}), flush=True)

    def l1_mc(S):
        return float(np.trapezoid(np.abs(S - mc), w) / np.trapezoid(mc, w))

    model = DuffingImpact(restitution=Ma(vc=0.4))
    T = 2 * np.pi / (omega[1] - omega[0])
    mu2 = 4 / 3 * np.pi**2 / T**2
    for grid in grids:
        t0 = time.process_time()
        s = spectrum_fpk(model, "x", omega=w, grid=grid, extrapolate=True, arc_end_order=arc_end_order)
        cpu = time.process_time() - t0
        d2 = np.gradient(np.gradient(s.S, w), w)
        kf = int(np.argmax(s.S))
        # what Welch's window makes of the fpk curve (to second order): S + mu2 S'' / 2
        seen = s.unextrapolated + 0.5 * mu2 * np.gradient(np.gradient(s.unextrapolated, w), w)
        print(json.dumps({
            "case": "example1-fpk-vs-mc", "grid": grid, "arc_end_order": arc_end_order,
            "L1": l1_mc(s.unextrapolated), "L1_extrapolated": l1_mc(s.S),
            "estimate": s.details["error_estimate"], "order": s.details["order"],
            "peak_fit": fitted_peak(w, s.unextrapolated), "peak_fit_extrapolated": fitted_peak(w, s.S),
            "peak_error": fitted_peak(w, s.unextrapolated) / mc_peak["peak_fit"] - 1,
            "bandwidth": _half_power_width(w, s.unextrapolated, int(np.argmax(s.unextrapolated))),
            "bandwidth_extrapolated": _half_power_width(w, s.S, kf), "variance_extrapolated": s.variance,
            "integral_0_6_over_variance": float(np.trapezoid(s.S, w)) / s.variance,
            "window_bias_l1": float(np.trapezoid(np.abs(0.5 * d2 * mu2), w) / np.trapezoid(mc, w)),
            "L1_windowed": l1_mc(seen), "peak_fit_windowed": fitted_peak(w, seen),
            "bandwidth_windowed": _half_power_width(w, seen, int(np.argmax(seen))),
            "peak_fit_95": fitted_peak(w, s.unextrapolated, 0.95), "mc_peak_fit_95": fitted_peak(w, mc, 0.95),
            "cpu_seconds": cpu}), flush=True)


if __name__ == "__main__":
    args = sys.argv[1:] or ("free", "folded", "example1", "stretch")
    if args[0] in ("mc", "mc1"):  # mc1: the first-order flux at the arcs' ends
        against_monte_carlo([tuple(int(n) for n in g.split("x")) for g in args[1:]] or [(80, 96)],
                            arc_end_order=1 if args[0] == "mc1" else 2)
    else:
        main(args)
