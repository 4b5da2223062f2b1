"""First passage, survival and spectra: ``vibro.first_passage`` and ``vibro.spectrum`` over their methods.

* ``first_passage(model, domain, x0, method=...)``: ``fpk`` (the phase-plane generator, any domain), ``paper`` and
  ``jump`` (the averaged energy, domains H < H_c), ``mc`` (an event-exact Monte Carlo ensemble of the model's
  automaton with the domain's exit as a guard); ``splitting`` is not built yet.
* ``spectrum(model, observable, method=...)``: ``fpk`` (the resolvent of the phase-plane generator); the Monte
  Carlo (Welch) spectrum is not built yet.

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
NOT_BUILT = {
    "splitting": "method 'splitting' (multilevel splitting for rare events) is not built yet; use fpk or mc",
    "spectrum-mc": "method 'mc' (the Monte Carlo Welch spectrum) is not built yet; use fpk",
}


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
    method : {'fpk', 'paper', 'jump', 'mc', 'auto'}
        ``fpk`` (default; ``auto`` is fpk): the phase-plane generator, accurate with hard impacts;
        ``paper``/``jump``: the averaged energy (H < H_c only; 15-18 % short at H_c = 2 on Example 1);
        ``mc``: Monte Carlo (options ``paths``, ``dt``, ``t_max``, ``seed``, ``scheme``, ``events``).
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
    if method == "splitting":
        raise ParameterError(NOT_BUILT["splitting"])
    start = _start(x0)
    if method == "fpk":
        return first_passage_fpk(model, domain, start, **options)
    dom = domain if isinstance(domain, Domain) else Domain(domain, model)
    if not isinstance(start, str) and not dom.contains(*start):
        raise ParameterError(f"the start (x, y) = ({start[0]:g}, {start[1]:g}) lies outside the domain {dom.text!r}")
    if method == "mc":
        return first_passage_mc(model, dom, start, **options)
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


MC_EVENTS = 1000
"""Firings kept per path by ``method='mc'`` (walls and the exit); a path with more before its exit is censored."""


def first_passage_mc(model, domain: Domain, start, *, paths: int = 2000, dt: float = 0.002,
                     t_max: float | None = None, seed: int = 1, scheme: str = "baoab", events: int = MC_EVENTS,
                     points: int = 400) -> FirstPassage:
    """First passage by Monte Carlo: the model's automaton with one more transition, the exit (guard phi = 0 of
    the domain phi < 0, upwards), into a copy of its mode; crossings are located inside the step for every scheme.

    R(t) is the fraction of paths not yet out (95 % Wilson band in R_lo, R_hi); ``error_estimate`` is the 95 %
    half-width of the mean. Paths still inside at ``t_max`` (or whose exit lies beyond the ``events`` firings
    kept) are censored: the mean is then over the others and a :class:`PassageWarning` says how many.

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> m = DuffingImpact(restitution=Ma(0.4))
    >>> r = first_passage_mc(m, Domain("H < 0.25", m), (0.0, 0.0), paths=64, t_max=60.0)   # doctest: +SKIP
    """
    import sympy as sp

    from hybrid import HybridAutomaton, Mode, Transition
    from hybrid.stochastic import simulate_automaton
    from models import X, Y

    if isinstance(start, str):
        raise ParameterError("method 'mc' starts from a state; the stationary start is for method fpk")
    if t_max is None:
        raise ParameterError("method 'mc' needs t_max (the end of every path; paths still inside are censored)")
    base = model.to_automaton()
    if len(base.modes) != 1:
        raise ParameterError("method 'mc' takes a model with one mode (an unforced oscillator)")
    free = base.modes[0]
    energy = base.observables.get("H")
    phi = domain.phi
    if energy is not None:
        phi = phi.subs(sp.Symbol("H"), energy)
    phi = phi.subs({X: base.states[0], Y: base.states[1]})
    out = Mode("out", free.flow, free.noise)
    transitions = [Transition("exit", free.name, "out", phi, 1, base.states)]
    for t in base.transitions:
        transitions.append(Transition(t.name, t.source, t.target, t.guard, t.direction, t.reset,
                                      priority=t.priority + 1, check=t.check))
        transitions.append(Transition(f"{t.name}_out", "out", "out", t.guard, t.direction, t.reset,
                                      priority=t.priority + 1, check=t.check))
    automaton = HybridAutomaton(base.states, dict(base.parameters), [free, out], transitions,
                                observables=dict(base.observables))
    t0 = time.perf_counter()
    first_obs = next(iter(base.observables)) if base.observables else None
    ens = simulate_automaton(automaton, scheme, dt=dt, paths=paths, t_end=float(t_max), x0=tuple(start), seed=seed,
                             events=events, histograms={first_obs: None} if first_obs else None, check_dt=False)
    T = ens.first_event_times("exit")
    censored = ~np.isfinite(T)
    done = T[~censored]
    if len(done) < 2:
        raise ParameterError(f"fewer than two of {paths} paths left {domain.text!r} by t_max={t_max:g}: raise t_max")
    mean = float(done.mean())
    half = float(1.96 * done.std(ddof=1) / np.sqrt(len(done)))
    if censored.any():
        warnings.warn(f"{int(censored.sum())} of {paths} paths were censored (still inside at t_max={t_max:g} or "
                      f"more than {events} firings before the exit): the mean is over the others and short",
                      PassageWarning, stacklevel=2)
    t = np.linspace(0.0, float(t_max), int(points) + 1)
    Tc = np.where(censored, np.inf, T)
    R = np.array([np.mean(Tc > s) for s in t])
    lo, hi = _wilson(R, paths)
    dens = np.concatenate([[0.0], (R[:-1] - R[1:]) / np.diff(t)])
    details = {"paths": int(paths), "dt": float(dt), "scheme": scheme, "seed": int(seed),
               "censored": int(censored.sum()), "seconds": time.perf_counter() - t0, "ci": [mean - half, mean + half]}
    res = FirstPassage("mc", domain.text, start, mean, t, R, dens, float("nan"), half, details)
    res.R_lo, res.R_hi = lo, hi
    res.times = T
    return res


def _wilson(R, n, z=1.96):
    """95 % Wilson interval of a binomial proportion R out of n."""
    centre = (R + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(R * (1 - R) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return np.clip(centre - half, 0, 1), np.clip(centre + half, 0, 1)


def spectrum(model, observable: str = "x", method: str = "fpk", **options) -> Spectrum:
    """One-sided power spectral density of ``observable``, normalised so that int_0^inf S d omega = Var.

    Parameters
    ----------
    model : ImpactOscillator
    observable : str
        Expression in x, y, H and the model's parameters.
    method : {'fpk', 'auto'}
        ``fpk`` (``auto``): one complex sparse solve of the phase-plane generator's resolvent per frequency;
        ``mc`` (Welch) is not built yet.
    **options
        ``omega``, ``omega_max``, ``points``, ``refine``, ``grid``, ``h_max`` (see
        :func:`averaging.phase_plane.spectrum.spectrum_fpk`).

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
        raise ParameterError(NOT_BUILT["spectrum-mc"])
    return spectrum_fpk(model, observable, **options)
