"""The power spectral density of an observable by Monte Carlo: Welch's segment periodograms, chunk by chunk.

Normalisation: the one-sided density in the angular frequency omega >= 0, with the integral of S over
(0, inf) equal to the variance of the observable,

    S(omega) = (1 / pi) * integral of C(tau) cos(omega tau) over the whole line,   C the autocovariance.

Each chunk of paths is recorded after the burn-in (``sample_paths``, every ``every`` steps), cut into segments of
``segment`` samples overlapping by half, each segment detrended by its mean, windowed (Hann) and transformed; the
periodograms |X(omega_k)|^2 dt_s / (pi n U) (U the window's mean square) are averaged. The chunks are independent
(their seeds come from one SeedSequence), so their spectra merge by averaging and their spread gives a batch-means
95 % interval at every frequency. The resolution is 2 pi / (segment dt_s) and the band ends at pi / dt_s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hybrid.automaton import lambdify_numeric
from hybrid.errors import ParameterError


@dataclass
class WelchSpectrum:
    """One-sided PSD S(omega) of an observable by Monte Carlo, with a 95 % batch-means interval.

    Attributes
    ----------
    omega, S, ci : ndarray
        Angular frequencies (from 0 to the band edge), the spectrum, and the half-width of its interval.
    variance, mean : float
        The observable's variance and mean over the recorded samples.
    chunks : int
        Independent chunks merged (the batches of the interval).
    settings : dict
    """

    omega: np.ndarray
    S: np.ndarray
    ci: np.ndarray
    variance: float
    mean: float
    chunks: int
    settings: dict = field(default_factory=dict)

    @property
    def integral(self) -> float:
        """The integral of S over the band (trapezoid): equal to ``variance`` up to the tail beyond the band edge."""
        return float(np.trapezoid(self.S, self.omega))

    @property
    def peak_omega(self) -> float:
        """The frequency of the largest S (the band's first bin excluded: it carries the segment's detrending)."""
        k = 1 + int(np.argmax(self.S[1:]))
        return float(self.omega[k])

    def to_pandas(self):
        """Columns omega, S, S_lo, S_hi."""
        import pandas as pd

        return pd.DataFrame({"omega": self.omega, "S": self.S, "S_lo": self.S - self.ci, "S_hi": self.S + self.ci})

    def __repr__(self) -> str:
        return (f"WelchSpectrum({len(self.omega)} frequencies up to {self.omega[-1]:.4g}, variance "
                f"{self.variance:.4g}, peak at {self.peak_omega:.4g}, {self.chunks} chunks)")


def _periodograms(values: np.ndarray, segment: int, dt_s: float) -> tuple[np.ndarray, int]:
    """Sum of the one-sided Hann periodograms of every half-overlapping segment of every row; and their number."""
    window = np.hanning(segment + 2)[1:-1]  # no zero end points: every sample counts
    norm = dt_s / (math.pi * segment * float(np.mean(window**2)))
    starts = range(0, values.shape[1] - segment + 1, segment // 2)
    total, count = np.zeros(segment // 2 + 1), 0
    for s in starts:
        block = values[:, s:s + segment]
        block = (block - block.mean(axis=1, keepdims=True)) * window
        spec = np.abs(np.fft.rfft(block, axis=1)) ** 2 * norm
        total += spec.sum(axis=0)
        count += block.shape[0]
    return total, count


def welch_spectrum(model, observable: str = "x", scheme: str = "splitting", *, dt: float, t_end: float,
                   t_burn: float, paths: int, every: int = 10, segment: int = 1024, chunk_paths: int = 8,
                   seed: int = 1, x0=(0.0, 0.0)) -> WelchSpectrum:
    """The one-sided PSD of ``observable`` (an expression in x and y, or ``H``) by Monte Carlo (Welch).

    Parameters
    ----------
    model : ImpactOscillator
        An autonomous oscillator model (its paths are recorded by ``sample_paths``).
    observable : str
        ``x``, ``y``, ``H`` or an expression in x, y and the model's parameters.
    scheme, dt, x0 :
        As in :func:`sample_paths`.
    t_end, t_burn : float
        Length of every path and the burn-in dropped from it.
    paths, chunk_paths : int
        Paths in all, and per chunk (the batches of the interval: give at least 8 chunks).
    every, segment : int
        Record every ``every`` steps; segments of ``segment`` recorded samples (an even number).
    seed : int
        Root seed: chunk k draws from ``SeedSequence(seed).spawn(chunks)[k]``.

    Returns
    -------
    WelchSpectrum

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.05}, barriers=None)
    >>> s = welch_spectrum(m, "x", dt=0.01, t_end=600.0, t_burn=50.0, paths=64,
    ...                    every=10, segment=512)                            # doctest: +SKIP
    >>> round(s.peak_omega, 1)                                               # doctest: +SKIP
    1.0
    """
    import sympy as sp

    from ._runner import sample_paths

    for name, value in (("paths", paths), ("every", every), ("segment", segment), ("chunk_paths", chunk_paths)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ParameterError(f"{name}={value!r} must be a positive integer")
    if segment < 8 or segment % 2:
        raise ParameterError(f"segment={segment} must be an even number of at least 8 samples")
    if not (math.isfinite(t_burn) and 0 <= t_burn < t_end):
        raise ParameterError(f"t_burn={t_burn!r} must lie in [0, t_end={t_end!r})")
    dt_s = dt * every
    recorded = int(round((t_end - t_burn) / dt_s))
    if recorded < segment:
        raise ParameterError(f"t_end - t_burn = {t_end - t_burn:g} holds {recorded} recorded samples, fewer than one "
                             f"segment of {segment}: lengthen the paths or shorten the segment")
    chunks = -(-paths // chunk_paths)
    if chunks < 2:
        raise ParameterError(f"paths={paths} in chunks of {chunk_paths} gives one chunk: the interval needs several")
    x, y = sp.symbols("x y")
    names = {"x": x, "y": y, **{k: sp.Symbol(k) for k in model.params}}
    text = observable.strip()
    expr = model.energy_expr if text == "H" else sp.sympify(text, locals=names)
    unknown = sorted(str(s) for s in expr.free_symbols if str(s) not in names)
    if unknown:
        raise ParameterError(f"observable {observable!r} uses {unknown}: give an expression in x, y and the model's "
                             f"parameters {sorted(model.params)}, or H")
    expr = expr.xreplace({sp.Symbol(k): v for k, v in model.params.items()})
    expr = expr.xreplace({s: names[str(s)] for s in expr.free_symbols if str(s) in ("x", "y")})
    value = lambdify_numeric((x, y), expr)
    seeds = np.random.SeedSequence(seed).spawn(chunks)
    chunk_spectra, sums, squares, samples = [], 0.0, 0.0, 0
    for k in range(chunks):
        n = min(chunk_paths, paths - k * chunk_paths)
        root = int(seeds[k].generate_state(1, dtype=np.uint64)[0] % (2**62))
        _, xs, ys = sample_paths(model, scheme, dt=dt, t_end=t_end, paths=n, every=every, seed=root, x0=x0)
        start = int(round(t_burn / dt_s))
        obs = np.broadcast_to(np.asarray(value(xs[:, start:], ys[:, start:]), dtype=float), xs[:, start:].shape)
        if not np.all(np.isfinite(obs)):
            raise ParameterError(f"observable {observable!r} is not finite on the recorded paths")
        total, count = _periodograms(obs, segment, dt_s)
        chunk_spectra.append(total / count)
        sums += float(obs.sum())
        squares += float((obs**2).sum())
        samples += obs.size
    spectra = np.array(chunk_spectra)
    mean = sums / samples
    omega = 2 * math.pi * np.fft.rfftfreq(segment, d=dt_s)
    half = 1.959963984540054 * spectra.std(axis=0, ddof=1) / math.sqrt(chunks)
    return WelchSpectrum(omega=omega, S=spectra.mean(axis=0), ci=half, variance=squares / samples - mean * mean,
                         mean=mean, chunks=chunks,
                         settings={"scheme": scheme, "dt": dt, "t_end": t_end, "t_burn": t_burn, "paths": paths,
                                   "every": every, "segment": segment, "chunk_paths": chunk_paths, "seed": seed,
                                   "resolution": 2 * math.pi / (segment * dt_s), "band_edge": math.pi / dt_s})
