"""The Monte Carlo PSD (Welch, chunk by chunk) against the free linear oscillator's exact spectrum."""

from __future__ import annotations

import numpy as np
import pytest

from hybrid.errors import ParameterError
from hybrid.stochastic._welch import welch_spectrum
from models import ImpactOscillator


def test_welch_meets_the_linear_oscillator_spectrum():
    c, D = 0.2, 0.05
    m = ImpactOscillator("x", "c*y", parameters={"c": c, "D": D}, barriers=None)
    s = welch_spectrum(m, "x", dt=0.01, t_end=1100.0, t_burn=100.0, paths=64, every=20, segment=512, chunk_paths=8,
                       seed=2)
    exact = 2 * D / np.pi / ((1 - s.omega**2) ** 2 + (c * s.omega) ** 2)  # one-sided: integral = D / c
    assert s.integral == pytest.approx(s.variance, rel=0.01)  # the normalisation, within the sampled band
    assert s.variance == pytest.approx(D / c, rel=0.05)
    # away from the resonance (where the window's resolution, 0.06 here, smears the peak of width c) the estimate
    # meets the exact spectrum within its interval; the detrended first bin is left out
    away = (s.omega > 0.1) & (s.omega < 4.0) & (np.abs(s.omega - 1.0) > 0.4)
    assert np.all(np.abs(s.S - exact)[away] <= 3 * s.ci[away])
    assert abs(s.peak_omega - 1.0) <= s.settings["resolution"]
    assert list(s.to_pandas().columns) == ["omega", "S", "S_lo", "S_hi"]


def test_welch_requests_are_checked():
    m = ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.05}, barriers=None)
    with pytest.raises(ParameterError, match="segment"):
        welch_spectrum(m, dt=0.01, t_end=10.0, t_burn=1.0, paths=16, segment=7)
    with pytest.raises(ParameterError, match="fewer than one segment"):
        welch_spectrum(m, dt=0.01, t_end=10.0, t_burn=1.0, paths=16, segment=1024)
    with pytest.raises(ParameterError, match="uses"):
        welch_spectrum(m, "z + x", dt=0.01, t_end=100.0, t_burn=1.0, paths=16, segment=64)
