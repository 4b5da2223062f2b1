"""First passage, survival and spectra: ``vibro.first_passage`` and ``vibro.spectrum`` over their methods.

* ``first_passage(model, domain, x0, method=...)``: ``fpk`` (the phase-plane generator, any domain), ``paper`` and
  ``jump`` (the averaged energy, domains H < H_c), ``mc`` (an event-exact Monte Carlo ensemble of the model's
  automaton with the domain's exit as a transition), ``splitting`` (fixed-level splitting for small probabilities of
  leaving before t_max).
* ``spectrum(model, observable, method=...)``: ``fpk`` (the resolvent of the phase-plane generator) and ``mc``
  (Welch's segment periodograms of a Monte Carlo ensemble, with a batch-means interval).

Examples
--------
>>> from models import DuffingImpact, Ma
>>> r = first_passage(DuffingImpact(restitution=Ma(0.4)), "H < 0.5", method="jump")
>>> round(r.mean_time, 1)
10.7
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from averaging.phase_plane.passage import (
    BackwardProblem,
    Domain,
    FirstPassage,
    PassageWarning,
    first_passage_fpk,
)
from averaging.phase_plane.spectrum import Spectrum, spectrum_fpk
from hybrid.errors import ParameterError

PASSAGE_METHODS = ("fpk", "mc", "splitting", "paper", "jump")
SPECTRUM_METHODS = ("fpk", "mc")


def _start(x0):
    if isinstance(x0, str):
        if x0 != "stationary":
            raise ParameterError(f"x0={x0!r}: give a state (x, y) or 'stationary'")
        return x0
    try:
        state = tuple(float(v) for v in x0)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"x0={x0!r} must be a state (x, y) or 'stationary'") from exc
    if len(state) != 2 or not all(np.isfinite(state)):
        raise ParameterError(f"x0={x0!r} must be a finite state (x, y)")
    return state


def first_passage(model, domain, x0=(0.0, 0.0), method: str = "fpk", **options) -> FirstPassage:
    """Time to first leave ``domain`` from ``x0``: mean, survival R(t) = P(T > t), density and decay rate.

    Parameters
    ----------
    model : ImpactOscillator
    domain : str
        The safe domain, one inequality in x, y, H and the model's parameters: ``"H < 2.0"``, ``"abs(x) <= 0.8"``.
    x0 : (x, y) or 'stationary'
        Start state (default rest), or the stationary density restricted to the domain (fpk only).
    method : {'fpk', 'paper', 'jump', 'mc', 'splitting', 'auto'}
        ``fpk`` (default; ``auto`` is fpk): the phase-plane generator, accurate with hard impacts;
        ``paper``/``jump``: the averaged energy (H < H_c only; 15-18 % short at H_c = 2 on Example 1);
        ``mc``: event-exact Monte Carlo (options ``paths``, ``dt``, ``t_max``, ``seed``, ``scheme``, ``points``,
        ``chunk_paths``, ``continuity_correction``);
        ``splitting``: P(T <= t_max) by fixed-level splitting (options ``t_max``, ``dt``, ``levels``,
        ``clones``, ``replicas``, ``seed``, ``scheme``, ``continuity_correction``), for probabilities too small
        for ``mc``.
    **options
        Passed to the method: fpk takes ``grid``, ``h_max``, ``t_max``, ``steps``, ``check``, ``survival``;
        paper/jump take ``points``, ``t_max``, ``steps``.

    Returns
    -------
    FirstPassage
        ``to_pandas()`` gives t, R, density (and R_lo, R_hi for mc, R_poisson for x-level domains).

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> r = first_passage(DuffingImpact(restitution=Ma(0.4)), "H < 0.5", grid=(60, 64), check=False, steps=50)
    >>> round(r.mean_time, 1), list(r.to_pandas().columns)
    (10.7, ['t', 'R', 'density'])
    """
    if method == "auto":
        method = "fpk"
    if method not in PASSAGE_METHODS:
        raise ParameterError(f"method={method!r}; use one of {', '.join(PASSAGE_METHODS)} (or auto)")
    start = _start(x0)
    if method == "fpk":
        return first_passage_fpk(model, domain, start, **options)
    dom = domain if isinstance(domain, Domain) else Domain(domain, model)
    if not isinstance(start, str) and not dom.contains(*start):
        raise ParameterError(f"the start (x, y) = ({start[0]:g}, {start[1]:g}) lies outside the domain {dom.text!r}")
    if method == "mc":
        return first_passage_mc(model, dom, start, **options)
    if method == "splitting":
        return first_passage_splitting(model, dom, start, **options)
    return first_passage_averaged(model, dom, start, method, **options)


def first_passage_averaged(model, domain: Domain, start, method: str = "paper", *, points: int = 2000,
                           t_max: float | None = None, steps: int = 800) -> FirstPassage:
    """First passage of the averaged energy to H_c (``paper`` or ``jump``): the chain of
    :func:`averaging.mean_first_passage_time`, with R(t) by BDF2 and the decay rate.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.1}, barriers=None)
    >>> r = first_passage_averaged(lin, Domain("H < 1", lin), (0.0, 0.0), points=400)
    >>> bool(r.R[0] == 1.0 and r.R[-1] < 0.02)
    True
    """
    from averaging.transient import passage_generator

    if domain.energy_level is None:
        raise ParameterError(f"method {method!r} averages the energy: it takes domains H < H_c only, not "
                             f"{domain.text!r}; use method='fpk'")
    if isinstance(start, str):
        raise ParameterError(f"method {method!r} starts from a state; the stationary start is for method fpk")
    if int(steps) != steps or steps < 10:
        raise ParameterError(f"steps={steps!r} must be an integer >= 10")
    t0 = time.perf_counter()
    H_c = domain.energy_level
    H0 = float(model.energy(np.array([start[0]]), np.array([start[1]]))[0])
    grid, Q = passage_generator(model, H_c, method, points)
    n = len(grid) - 1
    back = BackwardProblem((-Q[:n, :n]).tocsc(), np.ones(n))
    j = min(int(np.searchsorted(grid, H0, side="right")) - 1, n - 1)
    th = (H0 - grid[j]) / (grid[j + 1] - grid[j])
    w = np.zeros(n)
    w[j] += 1.0 - th
    if j + 1 < n:
        w[j + 1] += th
    mean = float(w @ back.mean_time())
    t_end = 5.0 * mean if t_max is None else float(t_max)
    if not (np.isfinite(t_end) and t_end > 0):
        raise ParameterError(f"t_max={t_max!r} must be a finite positive time")
    t = np.linspace(0.0, t_end, int(steps) + 1)
    R, f = back.survival(t, w)
    details = {"points": int(points), "seconds": time.perf_counter() - t0}
    return FirstPassage(method, domain.text, start, mean, t, R, f, back.decay_rate(), None, details)


def _needs_state_and_horizon(method: str, start, t_max, why: str) -> None:
    """The Monte Carlo methods start from a state and stop at t_max: refuse the rest in one line."""
    if isinstance(start, str):
        raise ParameterError(f"method {method!r} starts from a state; x0='stationary' is for method='fpk'")
    if t_max is None:
        raise ParameterError(f"method {method!r} needs t_max ({why})")


# -zeta(1/2) / sqrt(2 pi): a diffusion watched at steps of dt overshoots a level by this many local standard
# deviations sqrt(sigma^2 dt) on average (Siegmund's correction of discrete monitoring)
CONTINUITY_BETA = 0.5826


def _exit_relation(model, domain: Domain, dt: float | None = None):
    """The domain as the relation phi < 0 in the automaton's states (H replaced by the model's energy).

    With ``dt``, the level is moved in by the continuity correction: phi + beta sqrt(dt) sigma_phi < 0, with
    sigma_phi^2 = sum_j (grad phi . G_j)^2 the local variance rate of phi (G the mode's noise matrix). A level read at
    step ends is otherwise crossed late by O(sqrt(dt)): +5.2 % on the mean time of Example 1 at H_c = 0.25 and
    dt = 0.01 (docs/results/first-passage-spectra.md). Returns (automaton, relation, whether it was corrected).
    """
    import sympy as sp

    from models import X, Y

    base = model.to_automaton()
    phi = domain.phi
    energy = base.observables.get("H")
    if energy is not None:
        phi = phi.subs(sp.Symbol("H"), energy)
    phi = phi.subs({X: base.states[0], Y: base.states[1]})
    corrected = False
    noises = {m.noise for m in base.modes}
    if dt is not None and len(noises) == 1 and None not in noises:
        noise = next(iter(noises))
        rows = [tuple(g) if isinstance(g, tuple) else (g,) for g in noise]
        width = max(len(r) for r in rows)
        grad = [sp.diff(phi, s) for s in base.states]
        rate = sum(sp.expand(sum(grad[i] * (rows[i][j] if j < len(rows[i]) else 0) for i in range(len(rows)))) ** 2
                   for j in range(width))
        if rate != 0:
            phi = phi + CONTINUITY_BETA * sp.sqrt(sp.Float(dt) * rate)
            corrected = True
    return base, sp.StrictLessThan(phi, 0), corrected


def _slack_at(automaton, phi, start) -> float:
    """phi at the start state (t = 0, the automaton's default parameters); NaN where it cannot be evaluated."""
    values = {**automaton.resolve_parameters({}), "t": 0.0,
              **{str(s): float(v) for s, v in zip(automaton.states, np.atleast_1d(np.asarray(start, dtype=float)))}}
    try:
        return float(phi.xreplace({s: values[s.name] for s in phi.free_symbols}))
    except (KeyError, TypeError, ValueError):
        return float("nan")


def _watched_relation(model, domain: Domain, start, dt: float, continuity_correction: bool):
    """The exit relation a Monte Carlo path at step dt watches: moved in by the continuity correction where asked,
    unless the start lies within the correction's band (then the plain level, with a PassageWarning)."""
    base, relation, corrected = _exit_relation(model, domain, float(dt) if continuity_correction else None)
    if corrected and not _slack_at(base, relation.lhs, start) < 0:
        # the start lies within the correction's band of the level, or outside the domain (which the plain relation
        # refuses later, in the user's words): the correction, asymptotic for levels far from the start, is off
        base, relation, corrected = _exit_relation(model, domain)
        if domain.contains(*start):
            warnings.warn(f"the start lies within 0.5826 sqrt(dt) sigma of the level of {domain.text!r}: the Monte "
                          "Carlo watches the plain level (late by O(sqrt(dt))); lower dt or start further inside",
                          PassageWarning, stacklevel=4)
    return base, relation, corrected


def first_passage_mc(model, domain: Domain, start, *, paths: int = 2000, dt: float = 0.002,
                     t_max: float | None = None, seed: int = 1, scheme: str = "baoab", points: int = 400,
                     chunk_paths: int | None = None, continuity_correction: bool = True) -> FirstPassage:
    """First passage by event-exact Monte Carlo (:func:`hybrid.stochastic.simulate_first_passage`).

    The exit is a transition into an absorbing mode, located inside the step for every scheme; R(t) counts every
    path at ``points`` times (95 % Wilson band in R_lo, R_hi); ``error_estimate`` is the 95 % half-width of the
    mean. Paths still inside at ``t_max`` are censored: the mean is then that of min(T, t_max), a lower bound, and
    a warning says how many. With ``continuity_correction`` (the default) the level is moved in by
    0.5826 sqrt(dt) times the local noise of the domain's slack, which removes the O(sqrt(dt)) lateness of a level
    watched at discrete steps; ``details["continuity_correction"]`` says whether it applied.

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> m = DuffingImpact(restitution=Ma(0.4))
    >>> r = first_passage_mc(m, Domain("H < 0.25", m), (0.0, 0.0), paths=64, t_max=60.0)   # doctest: +SKIP
    """
    from hybrid.stochastic import simulate_first_passage

    _needs_state_and_horizon("mc", start, t_max, "the end of every path; paths still inside are censored")
    base, relation, corrected = _watched_relation(model, domain, start, dt, continuity_correction)
    t0 = time.perf_counter()
    chunk = chunk_paths or max(1, min(64, paths // 16))
    run = simulate_first_passage(base, relation, scheme, dt=dt, paths=paths, t_max=float(t_max), x0=tuple(start),
                                 seed=seed, snapshots=int(points), chunk_paths=chunk)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est = run.mean_time()
    for w in caught:  # censoring: said once, as this module's warning
        warnings.warn(str(w.message), PassageWarning, stacklevel=2)
    table = run.to_pandas()
    t, R = table["t"].to_numpy(), table["R"].to_numpy()
    dens = np.concatenate([[0.0], (R[:-1] - R[1:]) / np.diff(t)])
    details = {"paths": int(paths), "dt": float(dt), "scheme": scheme, "seed": int(seed), "chunk_paths": chunk,
               "censored": run.censored, "seconds": time.perf_counter() - t0,
               "continuity_correction": corrected,
               "ci": [est.value - est.ci, est.value + est.ci]}
    res = FirstPassage("mc", domain.text, start, est.value, t, R, dens, float("nan"), est.ci, details)
    res.R_lo, res.R_hi = table["R_lo"].to_numpy(), table["R_hi"].to_numpy()
    return res


def first_passage_splitting(model, domain: Domain, start, *, t_max: float | None = None, dt: float = 0.002,
                            levels: int = 10, clones: int = 1000, replicas: int = 8, seed: int = 1,
                            scheme: str = "baoab", continuity_correction: bool = True) -> FirstPassage:
    """P(T <= t_max), the probability of leaving the domain before ``t_max``, by fixed-level splitting
    (:func:`hybrid.stochastic.splitting_probability`, for small probabilities).

    The importance function is the domain's slack phi (the domain is phi < 0); ``levels`` equally spaced levels
    lead from phi(x0) to 0. With ``continuity_correction`` (the default, as in ``mc``) the slack is moved in by
    0.5826 sqrt(dt) times its local noise, so that the probability is that of the continuous path, not of one
    watched at steps of dt (which crosses late: at small P the difference is several per cent, since P falls
    steeply with the level). The result's R is [1, 1 - P] at t = [0, t_max] with the 95 % interval of the replicas
    in R_lo, R_hi; it has no mean time (NaN). ``details`` holds the probability, its CI, the stage shares and the
    cost against brute force.
    """
    from hybrid.stochastic import splitting_probability

    _needs_state_and_horizon("splitting", start, t_max, "the probability is that of leaving before t_max")
    base, relation, corrected = _watched_relation(model, domain, start, dt, continuity_correction)
    t0 = time.perf_counter()
    est = splitting_probability(base, relation.lhs, 0.0, levels=levels, t_max=float(t_max), x0=tuple(start), dt=dt,
                                clones=clones, replicas=replicas, scheme=scheme, seed=seed)
    P, half = est.probability, est.ci
    details = {"probability": P, "ci": [P - half, P + half], "levels": est.levels.tolist(),
               "stage_shares": est.stage_shares.mean(axis=0).tolist(), "path_steps": est.path_steps,
               "brute_force_steps": est.brute_force_steps, "speedup": est.speedup, "cpu_seconds": est.cpu_time,
               "replica_relative_variance": est.replica_relative_variance
               if np.isfinite(est.replica_relative_variance) else None, "clones": int(clones),
               "replicas": int(replicas), "dt": float(dt), "scheme": scheme, "seed": int(seed),
               "continuity_correction": corrected, "seconds": time.perf_counter() - t0}
    t = np.array([0.0, float(t_max)])
    res = FirstPassage("splitting", domain.text, start, float("nan"), t, np.array([1.0, 1.0 - P]),
                       np.array([0.0, 0.0]), float("nan"), half, details)
    res.R_lo = np.array([1.0, max(0.0, 1.0 - P - half)])
    res.R_hi = np.array([1.0, min(1.0, 1.0 - P + half)])
    return res


def spectrum(model, observable: str = "x", method: str = "fpk", **options) -> Spectrum:
    """One-sided power spectral density of ``observable``, normalised so that int_0^inf S d omega = Var.

    Parameters
    ----------
    model : ImpactOscillator
    observable : str
        Expression in x, y, H and the model's parameters.
    method : {'fpk', 'mc', 'auto'}
        ``fpk`` (``auto``): one complex sparse solve of the phase-plane generator's resolvent per frequency;
        ``mc``: Welch's periodograms of a Monte Carlo ensemble (:func:`spectrum_mc`).
    **options
        fpk: ``omega``, ``omega_max``, ``points``, ``refine``, ``grid``, ``h_max`` (see
        :func:`averaging.phase_plane.spectrum.spectrum_fpk`); mc: see :func:`spectrum_mc`.

    Returns
    -------
    Spectrum
        ``peak_omega``, ``bandwidth`` (half-power width), ``variance``, ``variance_check``; ``to_pandas()``.

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> lin = ImpactOscillator("x", "c*y", parameters={"c": 0.2, "D": 0.05}, barriers=None)
    >>> s = spectrum(lin, "x", omega_max=3.0, points=25, refine=10, grid=(20, 32), h_max=3.0)
    >>> round(s.peak_omega, 2)
    0.99
    """
    if method == "auto":
        method = "fpk"
    if method not in SPECTRUM_METHODS:
        raise ParameterError(f"method={method!r}; use one of {', '.join(SPECTRUM_METHODS)} (or auto)")
    if method == "mc":
        return spectrum_mc(model, observable, **options)
    return spectrum_fpk(model, observable, **options)


def spectrum_mc(model, observable: str = "x", *, dt: float = 0.01, t_end: float = 2100.0, t_burn: float = 100.0,
                paths: int = 64, every: int = 20, segment: int = 512, chunk_paths: int = 8, seed: int = 1,
                scheme: str = "splitting", scheduler=None, workers: int | None = None) -> Spectrum:
    """The one-sided PSD by Monte Carlo (Welch, :func:`hybrid.stochastic._welch.welch_spectrum`), as a
    :class:`Spectrum` with the 95 % batch-means half-width per frequency in ``details['ci']``.

    The variance is the samples' own, so ``variance_check`` tests the normalisation; the frequency resolution
    2 pi / (segment every dt) and the band edge pi / (every dt) are in ``details``. The CPU schedulers (None or
    "threads" with ``workers`` threads, "dask", "dask=ADDRESS" or a ``distributed.Client``) never change a number;
    "cuda" draws its own counter-based streams, so it agrees with them within the intervals, not bitwise.
    """
    from hybrid.stochastic._welch import welch_spectrum

    w = welch_spectrum(model, observable, scheme, dt=dt, t_end=t_end, t_burn=t_burn, paths=paths, every=every,
                       segment=segment, chunk_paths=chunk_paths, seed=seed, scheduler=scheduler, workers=workers)
    return Spectrum("mc", observable, w.omega, w.S, w.variance, w.mean,
                    details={"ci": w.ci, "chunks": w.chunks, **w.settings})
