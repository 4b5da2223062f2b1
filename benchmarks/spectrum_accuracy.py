"""Accuracy of the fpk spectrum against closed forms, and Example 1's spectrum (docs/results/first-passage-spectra.md).

    python benchmarks/spectrum_accuracy.py [free] [folded] [example1] [stretch]

Free linear oscillator (c = 0.2, D = 0.05): |H|^2 2D/pi. The same with an elastic stop at x = 0 (the folded
oscillator |s|): the cosine transform of its covariance (tests/test_first_passage_spectra.py). Per grid: the L1
distance of S to the closed form over the closed form's integral on [0, 4], for the finest grid's S and for the
three-grid Richardson extrapolation (``extrapolate=True``: grids G, G/2, G/4, the order observed), the a-posteriori
estimate of the unextrapolated error, the observed order and CPU seconds. ``stretch`` compares the innermost ring
widths 0.4 (the stationary solver's) and 0.02 (the spectrum's default) on the free and folded oscillators, 80 x 96.
Example 1: x on [0, 6] (150 frequencies, 100 more around the peak), peak, bandwidth, variance check, estimate.
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
    model = DuffingImpact(restitution=Ma(vc=0.4))
    for grid in ((40, 48), (80, 96)) if "example1" in which else ():
        t0 = time.process_time()
        s = spectrum_fpk(model, "x", omega_max=6.0, points=150, refine=100, grid=grid, check=True)
        print(json.dumps({"case": "example1", "grid": grid, "peak_omega": s.peak_omega, "peak_S": s.peak_S,
                          "bandwidth": s.bandwidth, "variance": s.variance, "integral": s.integral,
                          "variance_check": s.variance_check, "estimate": s.details["error_estimate"],
                          "order": s.details["order"], "cpu_seconds": time.process_time() - t0}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ("free", "folded", "example1", "stretch"))
