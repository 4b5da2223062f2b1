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


def _free_oscillator():
    return ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.05}, barriers=None)


SMALL = dict(dt=0.01, t_end=120.0, t_burn=20.0, paths=12, every=10, segment=64, chunk_paths=4, seed=5)


def test_welch_merges_chunk_sums_the_same_way_on_any_number_of_threads():
    m = _free_oscillator()
    one = welch_spectrum(m, "x", workers=1, **SMALL)
    two = welch_spectrum(m, "x", workers=2, **SMALL)
    three = welch_spectrum(m, "x", workers=3, **SMALL)
    for other in (two, three):
        assert np.array_equal(one.S, other.S) and np.array_equal(one.ci, other.ci)
        assert one.variance == other.variance and one.mean == other.mean


def test_welch_centres_every_segment_on_the_grand_mean_exactly():
    """The merged sums give what a direct computation on the same recorded paths gives: every half-overlapping
    Hann segment centred on the mean of all samples, one-sided periodograms averaged."""
    from hybrid.stochastic._runner import sample_paths

    m = _free_oscillator()
    s = welch_spectrum(m, "x + 0.3", workers=1, **SMALL)  # an offset: the centring matters
    seeds = np.random.SeedSequence(SMALL["seed"]).spawn(3)
    rows = []
    for k in range(3):
        root = int(seeds[k].generate_state(1, dtype=np.uint64)[0] % (2**62))
        _, xs, _ = sample_paths(m, "splitting", dt=0.01, t_end=120.0, paths=4, every=10, seed=root)
        rows.append(xs[:, 200:] + 0.3)  # t_burn 20 at 0.1 per sample
    obs = np.concatenate(rows)
    mean = obs.mean()
    window = np.hanning(66)[1:-1]
    segs = [obs[:, a:a + 64] for a in range(0, obs.shape[1] - 63, 32)]
    power = np.mean([np.abs(np.fft.rfft((g - mean) * window, axis=1)) ** 2 for g in segs], axis=(0, 1))
    direct = power * 0.1 / (np.pi * 64 * np.mean(window**2))
    assert s.mean == pytest.approx(mean, rel=1e-12)
    assert s.variance == pytest.approx(obs.var(), rel=1e-9)
    np.testing.assert_allclose(s.S, direct, rtol=1e-9, atol=1e-12 * direct.max())


@pytest.mark.slow
def test_welch_on_dask_gives_the_thread_numbers():
    pytest.importorskip("distributed")
    m = _free_oscillator()
    local = welch_spectrum(m, "x", workers=2, **SMALL)
    remote = welch_spectrum(m, "x", scheduler="dask", **SMALL)
    assert np.array_equal(local.S, remote.S) and np.array_equal(local.ci, remote.ci)
    assert local.variance == remote.variance


def test_cli_spectrum_by_monte_carlo_writes_the_interval(tmp_path):
    from vibro.cli import main

    out = tmp_path / "S.csv"
    assert main(["spectrum", "--method", "mc", "--paths", "16", "--t-end", "120", "--t-burn", "20", "--every", "10",
                 "--segment", "64", "--out", str(out)]) == 0
    rows = out.read_text().splitlines()
    assert rows[0] == "omega,S,S_lo,S_hi" and len(rows) == 1 + 33
    assert main(["spectrum", "--method", "mc", "--paths", "16", "--t-end", "10", "--t-burn", "5",
                 "--out", str(tmp_path / "T.csv")]) == 2  # shorter than one segment
    assert not (tmp_path / "T.csv").exists()
    assert main(["spectrum", "--method", "mc", "--scheduler", "cuda", "--out", str(tmp_path / "T.csv")]) == 2
