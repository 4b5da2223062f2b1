"""The power spectral density of an observable by Monte Carlo: Welch's segment periodograms, chunk by chunk.

Normalisation: the one-sided density in the angular frequency omega >= 0, with the integral of S over
(0, inf) equal to the variance of the observable,

    S(omega) = (1 / pi) * integral of C(tau) cos(omega tau) over the whole line,   C the autocovariance.

Each chunk of paths is recorded after the burn-in (``sample_paths``, every ``every`` steps) and cut into segments
of ``segment`` samples overlapping by half; each segment is windowed (Hann) and transformed. A chunk returns only
sums (:func:`welch_chunk_sums`: of abs(X)**2, of X, of the values and their squares, and the counts), so chunks
merge by addition, in chunk order: the same seed gives the same numbers on any number of threads or Dask workers.
After the merge every segment is centred on the grand mean (exact, from the sums of X) and the periodograms
abs(X(omega_k))**2 dt_s / (pi n U) (U the window's mean square) are averaged. The chunks are independent (their
seeds come from one SeedSequence), so the spread of their spectra gives a batch-means 95 % interval at every
frequency. The resolution is 2 pi / (segment dt_s) and the band ends at pi / dt_s.

On the GPU (``scheduler="cuda"``, :func:`cuda_recordings`) the CUDA scheduler's kernel, in a recording variant,
stores the samples of a batch of whole chunks; the host computes the same chunk sums (:func:`segment_sums`) on
them. Its streams are Philox per path, not the CPU's xoshiro per chunk: the chunks are independent all the same.
"""

from __future__ import annotations

import math
import time
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


def _window(segment: int) -> np.ndarray:
    """The Hann window without its zero end points (every sample counts)."""
    return np.hanning(segment + 2)[1:-1]


def _observable_function(model, observable: str):
    """The observable as a numeric function of (x, y), the model's parameters substituted (picklable inputs only:
    a Dask worker builds it again from the text)."""
    import sympy as sp

    x, y = sp.symbols("x y")
    names = {"x": x, "y": y, **{k: sp.Symbol(k) for k in model.params}}
    text = observable.strip()
    try:
        expr = model.energy_expr if text == "H" else sp.sympify(text, locals=names)
    except (sp.SympifyError, SyntaxError, TypeError, ValueError):
        raise ParameterError(f"observable {observable!r} is not an expression in x, y, H") from None
    if not isinstance(expr, sp.Expr):
        raise ParameterError(f"observable {observable!r} must be an expression, not a condition")
    unknown = sorted(str(s) for s in expr.free_symbols if str(s) not in names)
    if unknown:
        raise ParameterError(f"observable {observable!r} uses {unknown}: give an expression in x, y and the model's "
                             f"parameters {sorted(model.params)}, or H")
    # by name: the model's own symbols (energy_expr) may carry assumptions that a plain Symbol does not match
    expr = expr.xreplace({s: model.params[str(s)] for s in expr.free_symbols if str(s) in model.params})
    expr = expr.xreplace({s: names[str(s)] for s in expr.free_symbols if str(s) in ("x", "y")})
    return lambdify_numeric((x, y), expr)


def welch_chunk_sums(model, observable: str, scheme: str, dt: float, t_end: float, t_burn: float, paths: int,
                     every: int, segment: int, seed: int, x0) -> dict:
    """The additive sums of one chunk of paths: everything Welch's estimate needs, mergeable by addition.

    ``power`` is the sum over the chunk's half-overlapping segments of abs(X)**2 and ``linear`` the sum of X, X the
    DFT of the windowed raw segment; ``segments``, ``samples``, ``sum``, ``sum_sq`` count the segments and sum the
    recorded values and their squares. Centring on the grand mean m after the merge is exact:
    abs(X - m W)**2 = abs(X)**2 - 2 m Re(X conj(W)) + m**2 abs(W)**2, W the window's DFT.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.05}, barriers=None)
    >>> part = welch_chunk_sums(m, "x", "splitting", 0.01, 120.0, 20.0, 4, 10, 64, 7,
    ...                         (0.0, 0.0))                                   # doctest: +SKIP
    >>> part["power"].shape, part["samples"]                                 # doctest: +SKIP
    ((33,), 4004)
    """
    from ._runner import sample_paths

    value = _observable_function(model, observable)
    _, xs, ys = sample_paths(model, scheme, dt=dt, t_end=t_end, paths=paths, every=every, seed=seed, x0=x0)
    start = int(round(t_burn / (dt * every)))
    obs = np.broadcast_to(np.asarray(value(xs[:, start:], ys[:, start:]), dtype=float), xs[:, start:].shape)
    return segment_sums(obs, segment, observable)


def segment_sums(obs: np.ndarray, segment: int, observable: str = "the observable") -> dict:
    """The sums of :func:`welch_chunk_sums` of recorded values ``obs`` (paths, samples): the one computation of the
    CPU and the GPU routes.

    Examples
    --------
    >>> part = segment_sums(np.ones((2, 16)), 8)
    >>> part["segments"], part["samples"], part["power"].shape
    (6, 32, (5,))
    """
    if not np.all(np.isfinite(obs)):
        raise ParameterError(f"observable {observable!r} is not finite on the recorded paths")
    window = _window(segment)
    power = np.zeros(segment // 2 + 1)
    linear = np.zeros(segment // 2 + 1, dtype=complex)
    segments = 0
    for s in range(0, obs.shape[1] - segment + 1, segment // 2):  # a fixed order: the same sums on any executor
        spec = np.fft.rfft(obs[:, s:s + segment] * window, axis=1)
        power += (spec.real**2 + spec.imag**2).sum(axis=0)
        linear += spec.sum(axis=0)
        segments += obs.shape[0]
    return {"power": power, "linear": linear, "segments": segments, "samples": int(obs.size),
            "sum": float(obs.sum()), "sum_sq": float((obs * obs).sum())}


def _cuda_chunks(model, observable: str, scheme: str, dt: float, t_end: float, t_burn: float, paths: int,
                 every: int, segment: int, chunk_paths: int, seed: int, x0, **device) -> tuple[list[dict], dict]:
    """The chunks' sums of :func:`welch_chunk_sums` on the GPU (:func:`cuda_recordings`), and the device's
    settings: each batch of recorded paths is cut, chunk by chunk (paths k * chunk_paths ...), into the same
    segments as on the CPU."""
    value = _observable_function(model, observable)
    parts, info = [], {}
    for _, states in cuda_recordings(model, scheme, dt, t_end, t_burn, paths, every, chunk_paths, seed, x0,
                                     info=info, **device):
        xs, ys = states[:, :, 0], states[:, :, 1]
        obs = np.broadcast_to(np.asarray(value(xs, ys), dtype=float), xs.shape)
        for c in range(0, states.shape[0], chunk_paths):
            parts.append(segment_sums(obs[c:c + chunk_paths], segment, observable))
    return parts, info


def cuda_recordings(model, scheme: str, dt: float, t_end: float, t_burn: float, paths: int, every: int,
                    chunk_paths: int, seed: int, x0, *, precision: str = "f64", threads_per_block: int = 128,
                    launch_steps=None, batch_paths=None, info: dict | None = None):
    """The recorded states of an oscillator ensemble on the GPU, batch by batch: yields ``(lo, states)``, the
    states (x, y) (batch, samples, 2) of paths lo, lo + 1, ... at steps n_burn + j * every (j = 0, 1, ...), the
    columns that :func:`welch_chunk_sums` keeps of ``sample_paths``.

    The oscillator's automaton runs on the CUDA scheduler's kernel in its recording variant
    (:class:`~hybrid.stochastic._auto_cuda.CudaRecorder`); each batch of whole chunks is recorded on the device and
    copied to the host. Path i draws the Philox normals of path i (key from ``seed``) in any batch, so neither the
    batches nor the launch configuration change a number. ``info`` receives the device's settings.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("x", "c*y", parameters={"c": 1.0, "D": 0.5}, barriers=None)
    >>> lo, states = next(cuda_recordings(m, "splitting", 0.05, 20.0, 2.0, 8, 2, 4, 3,
    ...                                   (0.0, 0.0)))                        # doctest: +SKIP
    >>> states.shape                                                          # doctest: +SKIP
    (8, 181, 2)
    """
    from hybrid.sizes import MAX_MEMORY, check_size

    from . import _auto_cuda, _front, _runner

    sch = _runner.get_scheme(scheme)
    x0 = _runner._as_x0(x0)
    n_total = int(round(t_end / dt))
    start = int(round(t_burn / (dt * every)))
    settings = _runner._settings(model, sch, dt, paths, n_total * dt, start * every * dt, seed, 4.0, 8, None, None,
                                 every, chunk_paths, 8, None, x0)
    settings["n_burn"] = start * every  # exactly: the samples are the CPU's columns start, start + 1, ...
    settings["n_samp"] = n_total // every - start
    _runner._check_noise(model)
    _front.check_model(model, sch)
    _runner.check_step(model, dt, scheme=sch)
    sc = _runner._scales(settings)
    chunks, _ = _front._job(model, settings, sc["h_scale"], sc["v_scale"], (sc["x_scale"], sc["y_scale"]), sch.name)
    auto_scheme = _front.AUTOMATON_SCHEME_OF[sch.name]
    automaton, observables, _, st = _front._generated(model, auto_scheme)
    samples = 1 + settings["n_samp"]
    row = samples * (len(st.states) * np.dtype(np.float32 if precision == "f32" else float).itemsize + 24)

    def check(limit):
        # twice the recording: the host holds a batch's copy while the next one is recorded and converted
        check_size(f"the GPU recording of a chunk of {chunk_paths} paths", memory=2.0 * chunk_paths * row,
                   max_memory=limit, detail=f"{samples} samples x {row // samples} bytes per path, twice (a batch "
                   "in hand and the next)", fix="shorten t_end, raise every, or lower chunk_paths")

    check(MAX_MEMORY)  # the host's limit, before any device is asked for
    device = _auto_cuda.CudaRecorder(chunks.job, automaton, auto_scheme, observables, "stratonovich",
                                     summed=_front._SUMMED, phases=0, n_trans=len(st.transitions), seed=seed,
                                     precision=precision, threads_per_block=threads_per_block)
    limit = 4e9 if _auto_cuda.simulator_enabled() else 0.8 * device.cuda.current_context().get_memory_info()[0]
    limit = min(limit, MAX_MEMORY)
    check(limit)
    if batch_paths is None:
        batch_paths = chunk_paths * max(1, int(limit // 4 // (chunk_paths * row)))
    elif isinstance(batch_paths, bool) or not isinstance(batch_paths, (int, np.integer)) or batch_paths < 1 \
            or batch_paths % chunk_paths:
        raise ParameterError(f"batch_paths={batch_paths!r} must be a positive multiple of chunk_paths={chunk_paths}")
    info = {} if info is None else info
    info.update({"scheduler": "cuda", "precision": precision, "rng": _auto_cuda.RNG, "threads_per_block": device.tpb,
                 "batch_paths": int(batch_paths), "cuda_kernel": device.name})
    bad, t0, fbad = np.zeros(3), time.perf_counter(), device.module.FW_FBAD
    for lo in range(0, paths, batch_paths):
        hi = min(paths, lo + batch_paths)
        first, rec, rows = device.record(lo, hi, launch_steps)
        iw = rows["IWS"]
        failed = np.flatnonzero(iw[:, 5])
        if failed.size and not bad[0]:
            bad[1] = rows["FWS"][failed[0], fbad]
        bad[0] += iw[:, 5].sum()
        bad[2] += rows["CNT"][:, 1].sum() + iw[:, 1].sum()
        _runner._refuse_failed_checks(model, bad, "of the recorded paths")  # before the numbers are used
        bad[2] = 0  # warned once per batch at most
        yield lo, np.concatenate([first[:, None, :], rec], axis=1).astype(float)
    info["device_seconds"] = time.perf_counter() - t0


def _merge(parts: list[dict]) -> dict:
    """Sum the chunks' sums in chunk order (floating-point addition is not associative: a fixed order gives the
    same numbers on any number of threads or workers)."""
    total = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in parts[0].items()}
    for part in parts[1:]:
        for k, v in part.items():
            total[k] = total[k] + v
    return total


def _centred_spectrum(part: dict, mean: float, segment: int, dt_s: float) -> np.ndarray:
    """The averaged one-sided periodogram of the segments in ``part``, each centred on ``mean``."""
    window = _window(segment)
    W = np.fft.rfft(window)
    n = part["segments"]
    power = (part["power"] - 2 * mean * (part["linear"] * np.conj(W)).real + n * mean * mean * np.abs(W) ** 2)
    return power / n * dt_s / (math.pi * segment * float(np.mean(window**2)))


def _run_chunks(tasks, scheduler, workers) -> list[dict]:
    """``welch_chunk_sums(*task)`` for every task, on local threads (the kernel releases the GIL) or Dask, by the
    engine's one executor (:func:`~hybrid.stochastic._auto_exec.map_tasks`); the results in task order."""
    from . import _auto_exec

    if workers is None:
        import numba

        workers = numba.get_num_threads()
    results: list = [None] * len(tasks)
    rest = tasks
    if scheduler in (None, "threads", "local") and workers > 1:
        results[0] = welch_chunk_sums(*tasks[0])  # alone: the kernel is compiled or loaded once, not by every thread
        rest = tasks[1:]
    offset = len(tasks) - len(rest)
    _auto_exec.map_tasks(welch_chunk_sums, rest, lambda i, out: results.__setitem__(offset + i, out), workers=workers,
                         scheduler=scheduler, label="vibro-welch")
    return results


def welch_spectrum(model, observable: str = "x", scheme: str = "splitting", *, dt: float, t_end: float,
                   t_burn: float, paths: int, every: int = 10, segment: int = 1024, chunk_paths: int = 8,
                   seed: int = 1, x0=(0.0, 0.0), scheduler=None, workers: int | None = None,
                   precision: str = "f64", threads_per_block: int = 128, launch_steps: int | None = None,
                   batch_paths: int | None = None) -> WelchSpectrum:
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
    scheduler : None, "threads", "dask", "dask=ADDRESS", "cuda" or a ``distributed.Client``
        Where the chunks run; ``workers`` local threads (default ``numba.get_num_threads()``). The chunks' sums
        are merged in chunk order, so the numbers are the same on any of the CPU schedulers. ``cuda``: the
        oscillator's automaton on the GPU (the CUDA scheduler's kernel, recording every sample's state; the host
        cuts the same segments). Its Philox streams differ from the CPU's xoshiro streams: the same seed gives
        other paths, and spectra that agree within their intervals, not bitwise.
    precision, threads_per_block, launch_steps, batch_paths :
        ``cuda`` only: the kernel's float type, its block size and steps per launch (no number depends on these
        two), and the paths recorded per batch (a multiple of ``chunk_paths``; default: as many as a quarter of
        the device's free memory, at most 4 GB, holds, so that two batches fit; no number depends on it either).

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
    for name, value in (("paths", paths), ("every", every), ("segment", segment), ("chunk_paths", chunk_paths)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ParameterError(f"{name}={value!r} must be a positive integer")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or workers < 1):
        raise ParameterError(f"workers={workers!r} must be a positive integer")
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
    gpu = isinstance(scheduler, str) and scheduler == "cuda"
    if isinstance(scheduler, str) and not (gpu or scheduler in ("threads", "local")
                                           or scheduler.partition("=")[0] == "dask"):
        raise ParameterError(f"scheduler={scheduler!r}; the Monte Carlo spectrum runs on threads, dask, dask=ADDRESS, "
                             "cuda or a distributed.Client")
    if not gpu and (precision != "f64" or batch_paths is not None or launch_steps is not None
                    or threads_per_block != 128):
        raise ParameterError("precision, threads_per_block, launch_steps and batch_paths are settings of "
                             "scheduler='cuda'")
    _observable_function(model, observable)  # refuse a bad observable before any path is run
    device = {}
    if gpu:
        parts, device = _cuda_chunks(model, observable, scheme, dt, t_end, t_burn, paths, every, segment,
                                     chunk_paths, seed, x0, precision=precision,
                                     threads_per_block=threads_per_block, launch_steps=launch_steps,
                                     batch_paths=batch_paths)
    else:
        seeds = np.random.SeedSequence(seed).spawn(chunks)
        tasks = [(model, observable, scheme, dt, t_end, t_burn, min(chunk_paths, paths - k * chunk_paths), every,
                  segment, int(seeds[k].generate_state(1, dtype=np.uint64)[0] % (2**62)), x0)
                 for k in range(chunks)]
        parts = _run_chunks(tasks, scheduler, workers)
    total = _merge(parts)
    mean = total["sum"] / total["samples"]
    # centred on the grand mean (exact after the merge), not on each segment's own mean, which would take the
    # segment's lowest frequencies out with it
    spectra = np.array([_centred_spectrum(part, mean, segment, dt_s) for part in parts])
    S = _centred_spectrum(total, mean, segment, dt_s)
    omega = 2 * math.pi * np.fft.rfftfreq(segment, d=dt_s)
    weights = np.array([part["segments"] for part in parts], dtype=float)
    # batch means over the chunks, weighted by their segments (the last chunk may be short)
    spread = np.sqrt(np.sum(weights[:, None] * (spectra - S) ** 2, axis=0) / (weights.sum() * (chunks - 1)))
    half = 1.959963984540054 * spread
    return WelchSpectrum(omega=omega, S=S, ci=half,
                         variance=total["sum_sq"] / total["samples"] - mean * mean, mean=mean, chunks=chunks,
                         settings={"scheme": scheme, "dt": dt, "t_end": t_end, "t_burn": t_burn, "paths": paths,
                                   "every": every, "segment": segment, "chunk_paths": chunk_paths, "seed": seed,
                                   "segments": int(total["segments"]),
                                   "resolution": 2 * math.pi / (segment * dt_s), "band_edge": math.pi / dt_s,
                                   **device})
