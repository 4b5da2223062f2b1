"""A converged Monte Carlo PSD of x for Example 1 (docs/results/first-passage-spectra.md), at two time steps.

    nice -n 10 python benchmarks/spectrum_reference.py [--quick]

Duffing a = 1, b = 0.2, c = 0.025, D = 0.05, walls at +-1, Ma's law V_C = 0.4. Welch (``welch_spectrum``): scheme
``splitting``, paths from rest of length 4400 with the first 400 dropped (the energy relaxes at rate c or faster,
e^{-10} by then), recorded every 0.1 time units, Hann segments of 4096 samples (409.6 time units, resolution
2 pi / 409.6 = 0.0153), centred on the grand mean. Two independent runs, dt = 0.01 and dt = 0.005, each with its own
seed. Per run and pooled: the batch-means 95 % half-width per frequency, and the expected L1 noise of the
normalised spectrum, sqrt(2 / pi) int sigma(omega) d omega / int S d omega over [0, 6] (sigma the standard error;
the mean absolute value of a normal error). The L1 distance between the two steps' spectra is then sqrt(2) times
that noise if the step bias is below it. Writes benchmarks/data/spectrum_reference.npz (omega <= 10) and .json.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from hybrid.stochastic._welch import welch_spectrum
from models import DuffingImpact, Ma

DATA = Path(__file__).resolve().parent / "data"
BAND = 6.0  # the L1 metric's band [0, BAND]
STORE = 10.0  # frequencies stored


def l1_noise(omega, S, ci):
    """Expected L1 of the normalised spectrum's sampling error over [0, BAND]."""
    k = omega <= BAND
    sigma = ci[k] / 1.959963984540054
    return float(np.sqrt(2 / np.pi) * np.trapezoid(sigma, omega[k]) / np.trapezoid(S[k], omega[k]))


def l1(omega, a, b):
    """L1 distance of a to b over [0, BAND] over the integral of b."""
    k = omega <= BAND
    return float(np.trapezoid(np.abs(a[k] - b[k]), omega[k]) / np.trapezoid(b[k], omega[k]))


def main(quick=False):
    model = DuffingImpact(restitution=Ma(vc=0.4))
    paths = 256 if quick else 8192
    runs = []
    for dt, seed in ((0.01, 2601), (0.005, 2602)):
        t0 = time.process_time()
        s = welch_spectrum(model, "x", "splitting", dt=dt, t_end=4400.0, t_burn=400.0, paths=paths,
                           every=int(round(0.1 / dt)), segment=4096, chunk_paths=8, seed=seed, workers=2)
        cpu = time.process_time() - t0
        runs.append((dt, seed, s, cpu))
        print(json.dumps({"dt": dt, "seed": seed, "paths": paths, "segments": s.settings["segments"],
                          "chunks": s.chunks, "variance": s.variance, "mean": s.mean,
                          "integral_over_variance": s.integral / s.variance, "peak_omega_bin": s.peak_omega,
                          "l1_noise": l1_noise(s.omega, s.S, s.ci), "cpu_seconds": cpu}), flush=True)
    (_, _, a, _), (_, _, b, _) = runs
    w = np.array([a.settings["segments"], b.settings["segments"]], dtype=float)
    pooled = (w[0] * a.S + w[1] * b.S) / w.sum()
    pooled_ci = np.sqrt((w[0] * a.ci) ** 2 + (w[1] * b.ci) ** 2) / w.sum()
    between = l1(a.omega, a.S, b.S)
    expected = float(np.hypot(l1_noise(a.omega, a.S, a.ci), l1_noise(b.omega, b.S, b.ci)))
    summary = {
        "model": "DuffingImpact a=1 b=0.2 c=0.025 D=0.05 delta=1 Ma(vc=0.4)", "observable": "x",
        "normalisation": "one-sided: int_0^inf S d omega = Var", "band_for_l1": [0.0, BAND],
        "settings": {k: v for k, v in a.settings.items() if k not in ("dt", "seed", "every")},
        "runs": [{"dt": dt, "seed": seed, "every": s.settings["every"], "paths": s.settings["paths"],
                  "segments": s.settings["segments"], "variance": s.variance, "mean": s.mean,
                  "l1_noise": l1_noise(s.omega, s.S, s.ci), "cpu_seconds": cpu} for dt, seed, s, cpu in runs],
        "l1_between_steps": between, "l1_between_steps_expected_from_noise": expected,
        "pooled_l1_noise": l1_noise(a.omega, pooled, pooled_ci),
        "pooled_variance": float((w[0] * a.variance + w[1] * b.variance) / w.sum()),
        "variance_halfdiff": abs(a.variance - b.variance) / 2,
    }
    print(json.dumps({k: summary[k] for k in ("l1_between_steps", "l1_between_steps_expected_from_noise",
                                                "pooled_l1_noise", "pooled_variance", "variance_halfdiff")}))
    if quick:
        return
    keep = a.omega <= STORE
    DATA.mkdir(exist_ok=True)
    np.savez_compressed(DATA / "spectrum_reference.npz", omega=a.omega[keep], S=pooled[keep], ci=pooled_ci[keep],
                        S_dt01=a.S[keep], ci_dt01=a.ci[keep], S_dt005=b.S[keep], ci_dt005=b.ci[keep],
                        variance=summary["pooled_variance"])
    (DATA / "spectrum_reference.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
