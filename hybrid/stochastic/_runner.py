"""The oscillator front end of the one Monte Carlo engine: ``simulate_ensemble``, ``solve_ensemble``,
``drive_paths`` and ``sample_paths``.

An :class:`~models.ImpactOscillator` run is validated here (settings, step rule, noise, initial state), turned into
the job of its automaton (:mod:`._front`), and run by the executor every ensemble shares
(:func:`~hybrid.stochastic._auto_exec.run_chunks`: chunks on ``numba.get_num_threads()`` threads or on Dask, the
one checkpoint format, resume). Each chunk's automaton statistics become a row of :class:`EnsembleStatistics`; the
numbers are bitwise the same for any number of threads, any Dask cluster, any completion order, and across a
checkpoint and resume.
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

import numba as nb
import numpy as np

from hybrid.automaton import lambdify_numeric, real_symbol
from hybrid.errors import (
    CheckpointError,
    HistogramRangeWarning,
    ModelError,
    ParameterError,
    RestitutionError,
    StepSizeError,
    VibroError,
    VibroWarning,
)
from hybrid.sizes import check_limit, check_size

from . import _auto_exec, _front, _kernel_modules, _rng
from ._auto_exec import check_chunk_count, default_chunk_paths
from ._problem import (
    CHATTER_IMPACTS_PER_STEP,
    MAX_MEMORY,
    MAX_PATH_STEPS,
    ChatteringWarning,
    EnsembleProblem,
    Execution,
    MonteCarloAlgorithm,
    StepSizeWarning,
    positive_int,
)
from ._schemes import get_scheme
from ._statistics import COUNTS, SUMS, EnsembleStatistics

CHECKPOINT_FILE = _auto_exec.ENSEMBLE_CHECKPOINT_FILE

MIN_CHUNKS_FOR_CI = 8
"""Fewer chunks than this make the batch-means intervals unreliable (a warning says so)."""
OUTSIDE_WARN = 1e-3
"""Share of the samples outside a histogram's range above which :class:`HistogramRangeWarning` is raised."""


EM_TEMPERATURE_BIAS = 0.02
"""Largest relative temperature bias omega0**2 * dt / c of explicit Euler-Maruyama accepted without a warning
(2 %: as large as the impact effects the paper measures)."""


# ---------------------------------------------------------------------------------------------------- step rule
def speed_scale(model, h_max: float) -> float:
    """A typical speed: sqrt(sigma**2 / (2 k)) for constant linear damping k y and additive noise, else sqrt(2 h_max).

    For Example 1 this is sqrt(D / c), the standard deviation of the stationary velocity.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> round(speed_scale(DuffingImpact(), 4.0), 6)
    1.414214
    """
    kv, sv = model.linear_damping_constant(), model.constant_noise_intensity()
    if kv is not None and sv is not None and kv > 0 and sv > 0:
        return math.sqrt(sv / (2 * kv))
    return math.sqrt(2.0 * h_max)


def _linear_damping(model) -> float:
    """c_eff = -d m / d y at the equilibrium (x, y) = (0, 0): the damping rate of small oscillations."""
    X, Y = real_symbol("x"), real_symbol("y")
    rate = -model.substitute(model.ito_drift.diff(Y)).subs({X: 0.0, Y: 0.0})
    try:
        return float(rate)
    except TypeError:  # a damping law that is not differentiable at rest
        return float("nan")


def _visited_span(model, h_max: float) -> tuple[float, float]:
    """The positions a path visits up to energy h_max: the gap, cut where a side is open by the turning point."""
    left, right = model.barriers
    if np.isfinite(left) and np.isfinite(right):
        return left, right
    amp = float(np.max(np.abs(model.turning_points(h_max))))
    return (left if np.isfinite(left) else -amp), (right if np.isfinite(right) else amp)


def check_step(model, dt: float, h_max: float = 4.0, scheme=None) -> dict:
    """Apply the step-size rule; raise :class:`StepSizeError` or warn :class:`StepSizeWarning`.

    Rule (v = 4 * :func:`speed_scale`, gap = right - left barrier, omega**2 = max g'(x) on the gap, or on
    |x| <= A(h_max) without barriers):

    * refuse when v * dt > gap / 2 (a fast path crosses half the gap in one step: the in-step location is then
      exact but the force and noise are frozen over a large part of an orbit) or omega * dt > 1;
    * warn when v * dt > gap / 10 or omega * dt > 0.2 (expect a visible bias; compare with dt / 2);
    * for explicit Euler-Maruyama (``scheme='em'``), warn when its energy pumping, a relative temperature bias of
      about omega0**2 * dt / c (omega0**2 = g'(0), c = the damping rate at rest), exceeds
      :data:`EM_TEMPERATURE_BIAS`.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> check_step(DuffingImpact(), 1e-3)["ok"]
    True
    """
    v = 4.0 * speed_scale(model, h_max)
    lo, hi = _visited_span(model, h_max)
    xs = np.linspace(lo, hi, 401)
    gx = model.restoring(xs)
    omega = math.sqrt(max(float(np.max(np.diff(gx) / np.diff(xs))), 0.0))
    left, right = model.barriers
    gap = right - left
    info = {"speed": v, "gap": gap, "omega": omega, "v_dt_over_gap": v * dt / gap if np.isfinite(gap) else 0.0,
            "omega_dt": omega * dt, "ok": True}
    if v * dt > gap / 2:
        raise StepSizeError(
            f"dt={dt:g} is too large: a typical fast path (speed {v:.3g} = 4 x speed scale) crosses "
            f"{v * dt / gap:.2f} of the gap {gap:.3g} in one step (limit 0.5); use dt <= {gap / (10 * v):.3g}"
        )
    if omega * dt > 1.0:
        raise StepSizeError(
            f"dt={dt:g} is too large for the stiffest oscillation (omega={omega:.3g}, omega*dt={omega * dt:.2f} > 1); "
            f"use dt <= {0.2 / omega:.3g}"
        )
    scheme_name = getattr(scheme, "name", scheme)
    if scheme_name == "em":
        c_eff = _linear_damping(model)
        h = 1e-6 * (hi - lo)
        omega0_sq = float(np.diff(model.restoring(np.array([-h, h])))[0] / (2 * h))
        omega0_sq = omega0_sq if omega0_sq > 0 else omega * omega
        bias = omega0_sq * dt / c_eff if c_eff > 0 else float("inf")
        info["em_temperature_bias"] = bias
        if bias > EM_TEMPERATURE_BIAS:
            info["ok"] = False
            limit = f"dt <= {EM_TEMPERATURE_BIAS * c_eff / omega0_sq:.3g}" if c_eff > 0 else "a smaller dt"
            warnings.warn(
                f"explicit Euler-Maruyama pumps energy: relative temperature bias ~ omega0^2 dt / c = {bias:.3g} "
                f"at dt={dt:g}; use scheme 'splitting' or 'milstein', or {limit}", StepSizeWarning, stacklevel=3,
            )
    if v * dt > gap / 10 or omega * dt > 0.2:
        info["ok"] = False
        warnings.warn(
            f"dt={dt:g} is coarse (speed*dt/gap={v * dt / gap:.3f} > 0.1 or omega*dt={omega * dt:.3f} > 0.2): "
            "expect a visible discretisation bias", StepSizeWarning, stacklevel=3,
        )
    return info


# ---------------------------------------------------------------------------------------------------- set-up
def _as_x0(x0) -> tuple[float, float]:
    """``x0`` as a pair of floats, or a one-line :class:`ParameterError` (a scalar, a string, complex values)."""
    try:
        if isinstance(x0, (str, bytes)) or any(isinstance(v, (complex, np.complexfloating)) for v in x0):
            raise TypeError
        return tuple(float(v) for v in x0)
    except (TypeError, ValueError):
        raise ParameterError(f"x0={x0!r} must be two finite numbers (position, velocity), e.g. x0=(0.0, 0.0)") from None


def _check_x0(model, x0) -> None:
    if len(x0) != 2 or not all(math.isfinite(v) for v in x0):
        raise ParameterError(f"x0={x0!r} must be two finite numbers (position, velocity)")
    left, right = model.barriers
    if not (left <= x0[0] <= right):
        raise ParameterError(f"initial position x0={x0[0]:g} is outside the barriers [{left:g}, {right:g}]")
    # on a wall the velocity must be zero or point into the gap (the impact has already happened)
    if (x0[0] == right and x0[1] > 0) or (x0[0] == left and x0[1] < 0):
        raise ParameterError(
            f"x0={tuple(x0)!r} starts on a barrier moving outwards; give a velocity of 0 or one pointing into the gap"
        )


def _check_noise(model, h_max: float = 4.0) -> None:
    """Refuse a noise intensity that makes sigma**2 complex or negative (the kernel takes its square root)."""
    import sympy as sp

    X, Y = real_symbol("x"), real_symbol("y")
    s2 = sp.sympify(model.substitute(model.diffusion_squared))
    if s2.has(sp.I) or any(isinstance(a, sp.Number) and not a.is_real for a in sp.preorder_traversal(s2)):
        raise ParameterError(
            f"the noise gives sigma^2 = {s2}, which is complex; noise intensities must be real and >= 0"
        )
    # on the states a path visits: the gap (or the turning points at h_max) times |y| <= 2 sqrt(2 h_max)
    lo, hi = _visited_span(model, h_max)
    vmax = 2.0 * math.sqrt(2.0 * h_max)
    xs = np.linspace(lo, hi, 41)
    ys = np.linspace(-vmax, vmax, 41)
    xx, yy = np.meshgrid(xs, ys)
    with np.errstate(all="ignore"):
        try:
            val = np.broadcast_to(np.asarray(lambdify_numeric((X, Y), s2)(xx, yy), dtype=float), xx.shape)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"the noise gives sigma^2 = {s2}, which is not a real number ({exc})") from None
    bad = ~(val >= 0.0)
    if bad.any():
        i = np.flatnonzero(bad.ravel())[0]
        raise ParameterError(
            f"the noise gives sigma^2 = {val.ravel()[i]:g} at x={xx.ravel()[i]:g}, y={yy.ravel()[i]:g} "
            f"(sigma^2 = {s2}); it must be >= 0: use noise intensities >= 0"
        )


def _bin_scale(lo: float, hi: float, n: int) -> float:
    """n / (hi - lo), lowered by ulps until (hi - lo) * scale <= n: a sample exactly at hi (a wall) is binned.

    The kernel computes (v - lo) * scale, monotone in v, so every v <= hi maps into [0, n] and, the last bin being
    closed, into a bin.
    """
    scale = n / (hi - lo)
    while (hi - lo) * scale > n:
        scale = float(np.nextafter(scale, 0.0))
    return float(scale)


def _check_work(paths, dt, t_end, bins, xy_bins, v_bins, max_path_steps, max_memory) -> None:
    """Refuse, with the estimate, a run beyond ``max_path_steps`` path-steps or ``max_memory`` bytes of histograms."""
    max_path_steps = check_limit("max_path_steps", max_path_steps)
    max_memory = check_limit("max_memory", max_memory)
    steps = float(t_end) / float(dt)  # in floats: t_end / dt may exceed every integer type (or be inf)
    cells = float(bins) + float(v_bins) + (float(xy_bins[0]) * float(xy_bins[1]) if xy_bins is not None else 0.0)
    # int64 histograms: one set per running thread, the running totals, one buffered result and a merge copy
    copies = nb.get_num_threads() + 3
    check_size("the run", work=paths * steps, work_unit="path-steps", max_work=max_path_steps,
               work_fix=f"{paths} paths x {steps:.3g} steps of dt={dt:g} up to t_end={t_end:g}; lower paths or "
                        "t_end, raise dt, or raise the limit (max_path_steps=, --max-path-steps)",
               memory=8.0 * cells * copies, max_memory=max_memory,
               memory_fix=f"{cells:.3g} histogram bins x 8 bytes x {copies} copies; lower bins, xy_bins or v_bins, "
                          "or raise the limit (max_memory=, --max-memory-gb)")


def _settings(model, scheme, dt, paths, t_end, t_burn, seed, h_max, bins, xy_bins, xy_range, stride, chunk_paths,
              v_bins, v_max, x0, max_path_steps=MAX_PATH_STEPS, max_memory=MAX_MEMORY) -> dict:
    real = (int, float, np.integer, np.floating)
    for name, val in (("dt", dt), ("t_end", t_end), ("h_max", h_max)):
        if not (isinstance(val, real) and math.isfinite(val) and val > 0):
            raise ParameterError(f"{name}={val!r} must be a finite positive number")
    if not (isinstance(t_burn, real) and math.isfinite(t_burn) and t_burn >= 0):
        raise ParameterError(f"t_burn={t_burn!r} must be a finite number >= 0")
    if t_burn >= t_end:
        raise ParameterError(f"t_burn={t_burn:g} must be smaller than t_end={t_end:g} (nothing would be sampled)")
    paths = positive_int("paths", paths)
    bins = positive_int("bins", bins)
    stride = positive_int("stride", stride)
    v_bins = positive_int("v_bins", v_bins)
    chunk_paths = (default_chunk_paths(paths, float(t_end) / float(dt)) if chunk_paths is None
                   else positive_int("chunk_paths", chunk_paths))
    chunk_paths = min(chunk_paths, paths)  # one chunk holds every path: same numbers, no arrays for absent paths
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"seed={seed!r} must be a non-negative integer (randomness only from explicit seeds)")
    if xy_bins is not None:
        xy_bins = [positive_int("xy_bins", b) for b in xy_bins]
        if len(xy_bins) != 2:
            raise ParameterError(f"xy_bins={xy_bins!r} must be two positive integers (nx, ny)")
    _check_work(paths, dt, t_end, bins, xy_bins, v_bins, max_path_steps, max_memory)
    n_total = int(round(t_end / dt))
    n_burn = int(round(t_burn / dt))
    n_samp = (n_total - n_burn) // stride
    if n_samp < 1:
        raise ParameterError(f"t_end - t_burn = {t_end - t_burn:g} holds no sample at dt={dt:g}, stride={stride}")
    _check_x0(model, x0)
    left, right = model.barriers
    if xy_bins is not None:
        if xy_range is None:
            amp = float(np.max(np.abs(model.turning_points(h_max))))
            xr = (left if np.isfinite(left) else -amp, right if np.isfinite(right) else amp)
            ymax = math.sqrt(2.0 * h_max)
            xy_range = [list(xr), [-ymax, ymax]]
        else:
            (a, b), (c, d) = xy_range
            if not (b > a and d > c):
                raise ParameterError(f"xy_range={xy_range!r} must be ((x_lo, x_hi), (y_lo, y_hi)) with lo < hi")
            xy_range = [[float(a), float(b)], [float(c), float(d)]]
    else:
        xy_range = None
    if v_max is None:
        v_max = 2.0 * math.sqrt(2.0 * h_max)
    elif not (isinstance(v_max, real) and math.isfinite(v_max) and v_max > 0):
        # the kernel bins speeds by v * v_bins / v_max: a negative v_max would index from the end
        raise ParameterError(f"v_max={v_max!r} must be a finite positive speed")
    try:
        g_bar = float(min(model.potential(np.array([left, right])))) if model.has_barriers else float("inf")
    except Exception:  # infinite side: the finite barrier's energy
        g_bar = float(np.nanmin([float(model.potential(b)) if np.isfinite(b) else np.inf for b in (left, right)]))
    return {
        "scheme": scheme.name, "dt": float(dt), "paths": paths, "t_end": n_total * dt, "t_burn": n_burn * dt,
        "seed": int(seed), "h_max": float(h_max), "bins": bins, "xy_bins": xy_bins, "xy_range": xy_range,
        "stride": stride, "chunk_paths": chunk_paths, "n_chunks": -(-paths // chunk_paths), "v_bins": v_bins,
        "v_max": float(v_max), "x0": [float(x0[0]), float(x0[1])], "n_burn": n_burn, "n_samp": n_samp,
        "steps_per_path": n_burn + n_samp * stride, "t_sample": n_samp * stride * dt, "g_barrier": g_bar,
        "model": model.describe(), "fingerprint": model.fingerprint(),
    }


def _scales(s: dict) -> dict:
    """The bin scales of the run ``s``: H on [0, h_max], (x, y) on ``xy_range``, impact speeds on [0, v_max]."""
    xy = s["xy_bins"]
    (xlo, xhi), (ylo, yhi) = s["xy_range"] if xy is not None else ((0.0, 1.0), (0.0, 1.0))
    nx, ny = xy if xy is not None else (1, 1)
    return dict(h_scale=_bin_scale(0.0, s["h_max"], s["bins"]), x_scale=_bin_scale(xlo, xhi, nx),
                y_scale=_bin_scale(ylo, yhi, ny), v_scale=_bin_scale(0.0, s["v_max"], s["v_bins"]))


# ---------------------------------------------------------------------------------------------------- checkpoints
_RESUME_KEYS = ("scheme", "dt", "paths", "t_end", "t_burn", "seed", "h_max", "bins", "xy_bins", "xy_range", "stride",
                "chunk_paths", "v_bins", "v_max", "x0", "model", "fingerprint")


def _run_id(settings: dict) -> str:
    """The identity of the run ``settings`` in checkpoints: the keyed settings, the kernel, the law's numbers and the
    model's parameters (a resume with any of them changed is refused, naming it)."""
    return _auto_exec.identity({**{k: settings.get(k) for k in _RESUME_KEYS}, **settings.get("identity", {})})


def _write_checkpoint(directory: Path, stats: EnsembleStatistics) -> None:
    """The checkpoint of the statistics so far, in the one format (:func:`~hybrid.stochastic._auto_exec.write`)."""
    done = np.zeros(int(stats.settings["n_chunks"]), bool)
    done[stats.chunk_ids] = True
    _auto_exec.write(directory, _run_id(stats.settings), done, stats.to_arrays(), CHECKPOINT_FILE)


def _load_checkpoint(directory: Path, settings: dict) -> EnsembleStatistics | None:
    arrays = _auto_exec.read(directory, _run_id(settings), CHECKPOINT_FILE)
    if arrays is None:
        return None
    try:
        return EnsembleStatistics.from_arrays({k: v for k, v in arrays.items() if k not in ("done", "format")})
    except Exception as exc:
        raise CheckpointError(f"checkpoint {directory / CHECKPOINT_FILE} is not a valid checkpoint "
                              f"({type(exc).__name__}); delete it or use another --checkpoint directory") from None


def _outside_warnings(stats: EnsembleStatistics) -> None:
    """Warn (:class:`HistogramRangeWarning`) for each histogram with more than :data:`OUTSIDE_WARN` outside."""
    out = stats.outside()
    for name, d in out.items():
        if d["fraction"] > OUTSIDE_WARN:
            hints = {"H": ["H < 0 needs a potential below 0 (the histogram starts at 0)" if d.get("below") else "",
                           "raise h_max" if d.get("above") else ""],
                     "xy": ["widen xy_range (or raise h_max)"],
                     "speed": ["crossing speeds < 0 come from the Euler-Maruyama in-step velocity turning before the "
                               "wall: reduce dt or use splitting or milstein" if d.get("below") else "",
                               "raise v_max" if d.get("above") else ""]}[name]
            detail = ", ".join(f"{d[k]} {k}" for k in ("below", "above") if k in d)
            warnings.warn(
                f"{d['fraction']:.3g} of the {d['total']} {name} samples fall outside the {name} histogram "
                f"({detail or str(d['outside']) + ' outside'}); they are counted, not binned, and its density "
                f"integrates to {1 - d['fraction']:.4g}: {'; '.join(filter(None, hints))}", HistogramRangeWarning,
                stacklevel=3,
            )


def _refuse_bad_e(model, n_bad: int, v: float, e: float, where: str) -> None:
    """Refuse a run in which the law gave e outside (0, 1] at an impact (the kernel checks every impact)."""
    if n_bad:
        raise RestitutionError(
            f"restitution law {model.restitution!r} gave e({float(v):.6g}) = {float(e)!r}, outside (0, 1], at "
            f"{n_bad} impact(s) {where} (a law is only validated on a grid of speeds beforehand); make it return "
            "0 < e <= 1 at every impact speed"
        )


def _bad_restitution(model, cnt, sm, ids) -> None:
    """:func:`_refuse_bad_e` for finished chunks (their count and sum rows)."""
    n_bad = cnt[:, COUNTS.index("bad_e")]
    if n_bad.any():
        row = int(np.flatnonzero(n_bad)[0])
        _refuse_bad_e(model, int(n_bad.sum()), sm[row, SUMS.index("bad_e_speed")],
                      sm[row, SUMS.index("bad_e_value")], f"of chunk {int(ids[row])}")


def _in_kernel(model, fn, *args, **kwargs):
    """``fn(*args, **kwargs)``; an exception raised inside the compiled kernel (a callable law, a math domain
    error) becomes one line (:func:`_run_error`), the framework's own errors pass as they are."""
    try:
        return fn(*args, **kwargs)
    except VibroError:
        raise
    except Exception as exc:
        raise _run_error(model, exc) from exc


def _run_error(model, exc: Exception) -> VibroError:
    """A one-line error for an exception raised inside the compiled kernel (for example by a callable law)."""
    text = str(exc).splitlines()[0] if str(exc) else ""
    if getattr(model.restitution, "callable", None) is not None:
        return RestitutionError(
            f"the restitution callable {model.restitution!r} raised {type(exc).__name__}({text!r}) during the run; "
            "make it return 0 < e <= 1 for every impact speed v without raising"
        )
    return ModelError(f"the compiled kernel raised {type(exc).__name__}({text!r}) during the run; check the model "
                      "expressions at the states the paths reach")


# ---------------------------------------------------------------------------------------------------- runner
def simulate_ensemble(model, scheme="milstein", dt=1e-3, paths=256, t_end=2200.0, t_burn=200.0, seed=1, h_max=4.0,
                      bins=400, xy_bins=(80, 80), xy_range=None, stride=1, progress=False, checkpoint=None,
                      resume=False, scheduler=None, *, chunk_paths=None, checkpoint_every=4, v_bins=200, v_max=None,
                      x0=(0.0, 0.0), check_dt=True, max_path_steps=MAX_PATH_STEPS, max_memory=MAX_MEMORY,
                      precision="f64", threads_per_block=128, launch_steps=None,
                      kernel="auto") -> EnsembleStatistics:
    """Simulate an ensemble of paths of ``model`` and return streaming statistics (no paths are stored).

    Parameters
    ----------
    model : ImpactOscillator
    scheme : str or Scheme
        One of :data:`SCHEMES`: ``milstein`` (default), ``splitting`` (weak order 2), ``em``, ``naive``.
    dt, t_end, t_burn : float
        Step, end time and burn-in (statistics start after ``t_burn``); every path starts at ``x0``.
    paths : int
        Number of paths; cut into chunks of ``chunk_paths`` (default :func:`default_chunk_paths`).
    seed : int
        Root of ``numpy.random.SeedSequence``; the same seed gives the same numbers on any threads or cluster.
    h_max, bins : float, int
        Histogram of H on [0, h_max].
    xy_bins, xy_range : (nx, ny) or None, ((x_lo, x_hi), (y_lo, y_hi)) or None
        Joint histogram of (x, y); the default range is the barriers (or the turning points at h_max) times
        |y| <= sqrt(2 h_max). ``xy_bins=None`` skips it.
    stride : int
        Statistics every ``stride`` steps.
    progress : bool
        tqdm progress bar.
    checkpoint : path or None
        Directory of a checkpoint written every ``checkpoint_every`` chunks and at the end (atomic).
    resume : bool
        Continue from the checkpoint: finished chunks are not recomputed, none is counted twice.
    scheduler : None, "threads", "dask", "dask=ADDRESS", "cuda" or a ``distributed.Client``
        Where chunks run: numba threads in this process (default), Dask (a LocalCluster for "dask"), or an NVIDIA
        GPU with numba-cuda (one thread per path: the automaton's CUDA target, :mod:`hybrid.stochastic._auto_cuda`,
        runs ``model.to_automaton()``'s generated step code with counter-based normals; ``pip install -e ".[cuda]"``).
    precision : {"f64", "f32"}
        Floating point of the ``cuda`` kernel (the CPU kernels are double only).
    threads_per_block, launch_steps : int
        ``cuda`` only: block size and steps per kernel launch; neither changes any number.
    kernel : {"auto", "automaton"}
        The CPU kernel, for every scheme and law: the one generated from ``model.to_automaton()``, whose schemes
        :data:`~hybrid.stochastic.AUTOMATON_SCHEME_OF` takes for the oscillator's (``milstein``: ``symplectic``,
        ``splitting``: ``baoab``, ``em``, ``naive``); a restitution law given as a numba-compilable Python callable
        is called by its reset. ``settings['kernel']`` says which ran (``cuda`` on the GPU).
    check_dt : bool
        Apply :func:`check_step` (refuse or warn on coarse steps).
    max_path_steps, max_memory : float
        Refuse, before starting, a run of more path-steps (default 1e13) or whose histograms need more bytes
        (default 4e9); the message gives the estimate.

    Returns
    -------
    EnsembleStatistics
        Samples outside a histogram's range are counted (:meth:`EnsembleStatistics.outside`); more than 0.1 %
        outside gives a :class:`~hybrid.errors.HistogramRangeWarning`.

    Raises
    ------
    ParameterError
        Bad or unbounded settings; :class:`~hybrid.errors.CheckpointError` for an unusable checkpoint.
    RestitutionError
        The law gave e outside (0, 1] at an impact, or a callable law raised.

    See Also
    --------
    solve_ensemble : the same run from an :class:`EnsembleProblem`, a :class:`MonteCarloAlgorithm` and an
        :class:`Execution` (this function builds the three from its keywords).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> s = simulate_ensemble(DuffingImpact(), "splitting", dt=0.01, paths=4, t_end=20.0, t_burn=5.0,
    ...                       xy_bins=None)  # doctest: +SKIP
    >>> s.violations  # doctest: +SKIP
    0
    """
    problem = EnsembleProblem(model, x0=x0, t_end=t_end, t_burn=t_burn, h_max=h_max, bins=bins, xy_bins=xy_bins,
                              xy_range=xy_range, v_bins=v_bins, v_max=v_max, stride=stride)
    algorithm = MonteCarloAlgorithm(scheme=scheme, dt=dt, check_dt=check_dt, precision=precision, kernel=kernel)
    execution = Execution(paths=paths, seed=seed, chunk_paths=chunk_paths, scheduler=scheduler, progress=progress,
                          checkpoint=checkpoint, resume=resume, checkpoint_every=checkpoint_every,
                          max_path_steps=max_path_steps, max_memory=max_memory,
                          threads_per_block=threads_per_block, launch_steps=launch_steps)
    return solve_ensemble(problem, algorithm, execution)


def solve_ensemble(problem: EnsembleProblem, algorithm: MonteCarloAlgorithm | None = None,
                   execution: Execution | None = None) -> EnsembleStatistics:
    """Run the ensemble ``problem`` with ``algorithm`` (default Milstein, dt = 1e-3) under ``execution``.

    The three groups are described in :mod:`hybrid.stochastic._problem`; :func:`simulate_ensemble` documents every
    setting, its checks and its errors.

    Parameters
    ----------
    problem : EnsembleProblem
    algorithm : MonteCarloAlgorithm, optional
    execution : Execution, optional

    Returns
    -------
    EnsembleStatistics

    Examples
    --------
    >>> from models import DuffingImpact
    >>> problem = EnsembleProblem(DuffingImpact(), t_end=20.0, t_burn=5.0, xy_bins=None)
    >>> stats = solve_ensemble(problem, MonteCarloAlgorithm("splitting", dt=0.01),
    ...                        Execution(paths=4))  # doctest: +SKIP
    >>> stats.violations  # doctest: +SKIP
    0
    """
    algorithm = MonteCarloAlgorithm() if algorithm is None else algorithm
    execution = Execution() if execution is None else execution
    for obj, kind in ((problem, EnsembleProblem), (algorithm, MonteCarloAlgorithm), (execution, Execution)):
        if not isinstance(obj, kind):
            raise ParameterError(f"expected a {kind.__name__}, got {type(obj).__name__}; build one with "
                                 f"hybrid.stochastic.{kind.__name__}(...)")
    model = problem.model
    sch, settings = _prepare(problem, algorithm, execution)
    ex = execution
    if ex.scheduler == "cuda":  # the automaton's CUDA target runs the same job; the result checks are shared
        keyed = {k: settings.get(k) for k in _RESUME_KEYS}
        stats = _front.run_on_cuda(model, sch.name, settings, _scales(settings), keyed=keyed,
                                   precision=algorithm.precision,
                                   threads_per_block=ex.threads_per_block, launch_steps=ex.launch_steps,
                                   checkpoint=ex.checkpoint, resume=ex.resume,
                                   checkpoint_every=int(ex.checkpoint_every))
    else:
        stats = _run_on_cpu(model, sch, settings, ex)
    return _check_result(model, stats, settings, algorithm.dt)


def _prepare(problem: EnsembleProblem, algorithm: MonteCarloAlgorithm, ex: Execution):
    """Validate all three groups before anything is compiled; the scheme and the run's settings record."""
    pb, model = problem, problem.model
    _kernel_modules.refuse_forced(model)
    sch = get_scheme(algorithm.scheme)
    x0 = _as_x0(pb.x0)
    settings = _settings(model, sch, algorithm.dt, ex.paths, pb.t_end, pb.t_burn, ex.seed, pb.h_max, pb.bins,
                         pb.xy_bins, pb.xy_range, pb.stride, ex.chunk_paths, pb.v_bins, pb.v_max, x0,
                         ex.max_path_steps, ex.max_memory)
    _check_noise(model, settings["h_max"])
    if algorithm.check_dt:
        settings["step_rule"] = check_step(model, algorithm.dt, pb.h_max, sch)
    scheduler = ex.scheduler
    local = scheduler in (None, "threads", "local")
    gpu = isinstance(scheduler, str) and scheduler == "cuda"
    if not (local or gpu or (isinstance(scheduler, str) and scheduler.partition("=")[0] == "dask")
            or hasattr(scheduler, "submit")):  # before compiling: a typo must not cost a kernel build
        raise ParameterError(f"unknown scheduler {scheduler!r}; use threads, dask, dask=ADDRESS, cuda or a Client")
    if not gpu:
        check_chunk_count(settings["paths"], settings["chunk_paths"])
    if algorithm.precision != "f64" and not gpu:
        raise ParameterError(f"precision={algorithm.precision!r} needs scheduler='cuda' (the CPU kernels are "
                             "double only)")
    if ex.resume and ex.checkpoint is None:
        raise ParameterError("resume=True needs a checkpoint directory")
    positive_int("checkpoint_every", ex.checkpoint_every)
    settings["kernel"] = _choose_kernel(model, sch, algorithm.kernel, gpu)
    return sch, settings


def _choose_kernel(model, sch, kernel, gpu: bool) -> str:
    """The kernel that runs the scheme: 'automaton' on the CPU (every scheme, every law), 'cuda' on the GPU."""
    if kernel not in _front.KERNELS:
        hint = (" (the oscillator's own CPU kernel is gone: every CPU ensemble runs on the kernel generated from "
                "model.to_automaton())" if kernel == "oscillator" else "")
        raise ParameterError(f"kernel={kernel!r}; use one of {list(_front.KERNELS)}{hint}")
    if gpu and kernel == "automaton":
        raise ParameterError("kernel='automaton' is a CPU kernel; scheduler='cuda' runs its own GPU kernel: "
                             "drop one of them")
    _front.check_model(model, sch)  # before anything is compiled
    return "cuda" if gpu else "automaton"


def _run_on_cpu(model, sch, settings: dict, ex: Execution) -> EnsembleStatistics:
    """The oscillator's automaton job on local threads or Dask through the shared executor, with checkpoints: the
    statistics before the result checks."""
    checkpoint, resume = ex.checkpoint, ex.resume
    ckdir = Path(checkpoint) if checkpoint is not None else None
    if ckdir is not None:
        _auto_exec.check_directory(ckdir, resume, CHECKPOINT_FILE)
    law_fn = getattr(model.restitution, "callable", None)
    if ckdir is not None and law_fn is not None and _kernel_modules.callable_digest(law_fn) is None:
        raise CheckpointError(
            f"the restitution callable {model.restitution!r} reads objects that cannot be fingerprinted, so a "
            "checkpoint could be resumed with another law; run without a checkpoint or declare the law as an "
            "expression of v"
        )
    scales = _scales(settings)
    t0 = time.perf_counter()
    chunks, identity = _front.plan(model, settings, scales["h_scale"], scales["v_scale"],
                                   (scales["x_scale"], scales["y_scale"]), sch.name)
    settings["identity"] = {**identity,
                            "params": {k: float.hex(float(model.params[k])) for k in tuple(model.params)}}
    states = _rng.chunk_states(settings["seed"], settings["n_chunks"])

    stats = None
    if ckdir is not None and resume:  # before compiling: a checkpoint of another run must not cost a kernel build
        stats = _load_checkpoint(ckdir, settings)
    kern = _front.compile_job(chunks, identity, t0)
    if stats is None:
        stats = EnsembleStatistics.empty(settings)
    stats.settings.update({k: v for k, v in settings.items() if k not in stats.settings})
    stats.compile_time = kern.compile_time
    done = set(stats.chunk_ids.tolist())
    pending = [k for k in range(settings["n_chunks"]) if k not in done]

    bar = None
    if ex.progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=settings["n_chunks"], initial=stats.done_chunks, unit="chunk", desc=f"mc {sch.name}")
    t_start = time.perf_counter()
    wall0 = stats.wall_time
    buffer: list = []

    def flush():
        # results are added in batches that grow with the run (add_chunks copies the per-chunk table)
        if buffer:
            stats.add_chunks(*(np.concatenate(parts) for parts in zip(*buffer)))
            buffer.clear()
        stats.wall_time = wall0 + time.perf_counter() - t_start

    # integer histograms add exactly in any grouping: bound the buffered ones by memory as well as by count
    hist_bytes = 8 * (settings["bins"] + settings["v_bins"] + (math.prod(settings["xy_bins"]) if settings["xy_bins"]
                                                               else 0))
    max_buffer = max(1, min(max(32, stats.done_chunks // 4), (64 << 20) // hist_bytes))

    def accept(k, out):
        result = chunks.rows([k], [out])  # the automaton's statistics as a row of EnsembleStatistics
        _bad_restitution(model, result[5], result[6], result[0])  # before the chunk can reach a checkpoint
        buffer.append(result)
        if len(buffer) >= min(max(32, stats.done_chunks // 4), max_buffer):
            flush()

    def save():
        flush()
        _write_checkpoint(ckdir, stats)

    try:
        _in_kernel(model, _auto_exec.run_chunks, chunks.job, pending, states, accept, threads=nb.get_num_threads(),
                   scheduler=ex.scheduler, module=kern.module, save=save if ckdir is not None else None,
                   checkpoint_every=int(ex.checkpoint_every), progress=bar)
    finally:
        if bar is not None:
            bar.close()
    flush()
    return stats


def _check_result(model, stats: EnsembleStatistics, settings: dict, dt: float) -> EnsembleStatistics:
    """Refuse diverged paths and bad restitution values; report samples outside the histograms; flag chattering
    (any scheduler)."""
    _bad_restitution(model, stats.chunk_counts, stats.chunk_sums, stats.chunk_ids)
    bad = stats.total("nonfinite")
    if bad:
        raise ModelError(f"{bad} samples had a non-finite energy: the paths diverged; reduce dt or check the model")
    _outside_warnings(stats)
    chunks = len(stats.chunk_ids)
    if chunks < MIN_CHUNKS_FOR_CI:
        # batch means with few batches: the t quantile is huge and the variance estimate itself noisy
        warnings.warn(
            f"only {chunks} chunks: the batch-means confidence intervals are unreliable below {MIN_CHUNKS_FOR_CI} "
            f"(use more paths or a smaller chunk_paths, e.g. chunk_paths={max(1, stats.paths // 16)})",
            VibroWarning, stacklevel=3,
        )
    sampled_steps = stats.paths * settings["n_samp"] * settings["stride"]
    per_step = stats.impacts / sampled_steps if sampled_steps else 0.0
    # inelastic collapse needs e < 1; elastic walls at a coarse dt are resolved exactly by the in-step location
    if per_step > CHATTER_IMPACTS_PER_STEP and not model.restitution.is_elastic:
        stats.settings["chattering"] = {"impacts_per_step": per_step, "limit": CHATTER_IMPACTS_PER_STEP}
        warnings.warn(
            f"chattering: {per_step:.3g} impacts per path-step (limit {CHATTER_IMPACTS_PER_STEP}); paths bounce "
            f"against a wall on the step scale, so impact rates and wall statistics are not resolved by dt={dt:g}; "
            "reduce dt until the impact rate stops changing, or treat the sticking phase in the model",
            ChatteringWarning, stacklevel=3,
        )
    return stats


def drive_paths(model, scheme, dt: float, normals, x0=(0.0, 0.0)) -> np.ndarray:
    """Final states (paths, 2) of paths driven by given standard normals ``normals`` (paths, steps), one per step.

    For convergence tests: summing fine normals in blocks of m and dividing by sqrt(m) gives the same Brownian path
    on a coarser grid. Every step goes through the automaton kernel's event loop (its ``drive``). No statistics, no
    step-size rule.

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> m = DuffingImpact(restitution=Elastic(), delta=float("inf"), D=0.0)
    >>> drive_paths(m, "splitting", 0.01, np.zeros((1, 100)), x0=(0.5, 0.0)).shape  # doctest: +SKIP
    (1, 2)
    """
    sch = get_scheme(scheme)
    x0 = _as_x0(x0)
    _check_noise(model)
    _front.check_model(model, sch)
    z = np.ascontiguousarray(normals, dtype=float)
    if z.ndim != 2:
        raise ParameterError(f"normals must be a 2-D array (paths, steps), got shape {z.shape}")
    if not (math.isfinite(dt) and dt > 0):
        raise ParameterError(f"dt={dt!r} must be a finite positive number")
    module, prm = _front.kernel_module(model, sch.name)
    n = z.shape[0]
    # the increments as the ensembles form them: sqrt(dt) * z
    dws = np.ascontiguousarray((math.sqrt(float(dt)) * z)[:, :, None])
    out = np.empty((n, 2))
    bad = np.zeros(3)
    _in_kernel(model, module.drive, np.array(x0, dtype=float), 0, dws, float(dt), 0.0, prm, out, np.empty((n, 0, 3)),
               np.zeros(n, dtype=np.int64), bad)
    _refuse_failed_checks(model, bad, "of the driven paths")
    return out


def sample_paths(model, scheme="milstein", dt=1e-3, t_end=10.0, paths=4, every=10, seed=1, x0=(0.0, 0.0),
                 check_dt=True, *, chunk_paths=None):
    """Store a few paths: times (n,), x and y (paths, n) every ``every`` steps, for plots and checks.

    The paths are those of :func:`simulate_ensemble` with the same model, scheme, ``dt``, ``paths``, ``t_end``,
    ``seed`` and ``chunk_paths`` (the same kernel steps them with the same draws), stored instead of summarised.
    At most 10**7 stored values.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> t, x, y = sample_paths(DuffingImpact(), "splitting", dt=0.01, t_end=1.0, paths=2,
    ...                        every=10)  # doctest: +SKIP
    >>> x.shape  # doctest: +SKIP
    (2, 11)
    """
    sch = get_scheme(scheme)
    paths = positive_int("paths", paths)
    every = positive_int("every", every)
    if not (math.isfinite(dt) and dt > 0 and math.isfinite(t_end) and t_end > 0):
        raise ParameterError(f"dt={dt!r} and t_end={t_end!r} must be finite and positive")
    nstep = int(round(t_end / dt))
    if nstep < every:
        raise ParameterError(f"t_end={t_end:g} holds fewer than every={every} steps of dt={dt:g}")
    if paths * (nstep // every + 1) * 2 > 10**7:
        raise ParameterError("too many stored values (> 1e7); raise every or lower paths / t_end")
    x0 = _as_x0(x0)
    _check_x0(model, x0)
    _check_noise(model)
    _front.check_model(model, sch)
    chunk = (default_chunk_paths(paths, float(t_end) / float(dt)) if chunk_paths is None
             else positive_int("chunk_paths", chunk_paths))
    chunk = min(chunk, paths)  # as simulate_ensemble chooses it: the same chunks, the same streams
    states = _rng.chunk_states(seed, check_chunk_count(paths, chunk))
    if check_dt:
        check_step(model, dt, scheme=sch)
    module, prm = _front.kernel_module(model, sch.name)
    zx, zk, zf = _rng.ziggurat_tables()
    nrec = nstep // every + 1
    out = np.empty((paths, nrec, 2))
    bad = np.zeros(3)
    for k, state in enumerate(states):
        lo = k * chunk
        part = np.zeros(3)
        _in_kernel(model, module.record_chunk, state.copy(), min(chunk, paths - lo), (nrec - 1) * every, every,
                   float(dt), 0.0, np.array(x0, dtype=float), 0, prm, zx, zk, zf, out[lo: lo + chunk], part)
        if part[0] and not bad[0]:
            bad[1] = part[1]
        bad[0] += part[0]
        bad[2] += part[2]
    _refuse_failed_checks(model, bad, "of the sampled paths")
    t = np.arange(nrec) * every * dt
    return t, out[:, :, 0], out[:, :, 1]


def _refuse_failed_checks(model, bad, where: str) -> None:
    """:func:`_refuse_bad_e` for the kernel's ``bad`` (failed checks, first speed, steps over the event cap)."""
    if bad[0]:
        v = float(bad[1])
        try:
            e = float(np.asarray(model.restitution.coefficient(np.array([v])), dtype=float)[0])
        except Exception:  # a law that fails at that speed: it is refused all the same
            e = float("nan")
        _refuse_bad_e(model, int(bad[0]), v, e, where)
    if bad[2]:
        warnings.warn(f"{int(bad[2])} steps {where} hit the cap of events in one step (chattering); reduce dt",
                      ChatteringWarning, stacklevel=3)
