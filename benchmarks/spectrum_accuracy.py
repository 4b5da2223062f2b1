"""Accuracy of the fpk spectrum against closed forms, and Example 1's spectrum (docs/results/first-passage-spectra.md).

    python benchmarks/spectrum_accuracy.py [free] [folded] [example1]

Free linear oscillator (c = 0.2, D = 0.05): |H|^2 2D/pi. The same with an elastic stop at x = 0 (the folded
oscillator |s|): the cosine transform of its covariance (tests/test_first_passage_spectra.py). Prints the L1 distance
of the normalised spectra on [0, 4] per grid, with and without the two-grid extrapolation, and CPU seconds.
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


def l1(s, exact):
    return float(np.trapezoid(np.abs(s.S - exact), s.omega) / np.trapezoid(exact, s.omega))


def main(which=("free", "folded", "example1")):
    c, D = 0.2, 0.05
    lin = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    cases = {"free": ({"walls": "model"}, free_psd), "folded": ({"walls": (0.0, None), "restitution": Elastic()},
                                                                folded_psd)}
    for name, (kw, exact_fn) in cases.items():
        if name not in which:
            continue
        for grid in ((40, 48), (80, 96)):
            for ext in (False, True):
                t0 = time.process_time()
                s = spectrum_fpk(lin, "x", omega_max=4.0, points=60, refine=40 if name == "free" else 0, grid=grid,
                                 h_max=3.0, extrapolate=ext, **kw)
                print(json.dumps({"case": name, "grid": grid, "extrapolated": ext, "L1": l1(s, exact_fn(c, D, s.omega)),
                                  "peak_omega": s.peak_omega, "bandwidth": s.bandwidth, "variance": s.variance,
                                  "variance_check": s.variance_check, "estimate": s.details["error_estimate"],
                                  "cpu_seconds": time.process_time() - t0}), flush=True)
    model = DuffingImpact(restitution=Ma(vc=0.4))
    for grid in ((40, 48), (80, 96)) if "example1" in which else ():
        t0 = time.process_time()
        s = spectrum_fpk(model, "x", omega_max=6.0, points=150, refine=100, grid=grid, check=True)
        print(json.dumps({"case": "example1", "grid": grid, "peak_omega": s.peak_omega, "peak_S": s.peak_S,
                          "bandwidth": s.bandwidth, "variance": s.variance, "integral": s.integral,
                          "variance_check": s.variance_check, "estimate": s.details["error_estimate"],
                          "cpu_seconds": time.process_time() - t0}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ("free", "folded", "example1"))
