"""The driver: validate the input, run a backend from transition to transition, apply resets, log, stop."""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from hybrid.automaton import HybridAutomaton
from hybrid.errors import ModelError, ParameterError, RestitutionError, VibroError
from hybrid.sizes import check_size

from ._base import OrbitBackend
from ._convert import finite_array, to_callable
from ._heyoka import HeyokaBackend
from ._result import ImpactLog, OrbitResult, Trajectory
from ._scipy import ScipyBackend
from ._zeno import ZenoDetector

MAX_LOG_BYTES = 4 * 2**30
"""Largest impact log ``max_impacts`` may ask for (about 4 GiB), so that a huge value is refused up front."""

_DEFAULT_MAX_STEPS = 10_000_000

STEPS_PER_RADIAN = 0.25
"""Fewest integration steps per radian of the flow's fastest rate, for the work estimate of an orbit (measured on
harmonic and Duffing orbits: heyoka 0.33-0.67, scipy DOP853 at rtol 1e-10 2.2-3.1); a low figure, so that a
refused orbit is surely beyond ``max_steps``."""

_SAMPLE_BYTES = 250
"""Memory of one dense-output sample while the run lasts (tuple, float, small array, mode) besides 16 bytes per
state in the final arrays."""


def _log_bytes_per_impact(d: int, n_obs: int) -> int:
    """Estimated memory of one impact-log row while the run lasts (Python lists of small arrays and floats)."""
    return 2 * (112 + 8 * d) + 2 * 56 * (1 + n_obs) + 4 * 8 + 24 + 8 * (2 * d + 2 * n_obs + 1)


BACKENDS: dict[str, type[OrbitBackend]] = {"heyoka": HeyokaBackend, "scipy": ScipyBackend}
"""Registered deterministic backends; ``simulate_orbit(backend=...)`` takes a name or an OrbitBackend subclass."""


def _as_automaton(system, params):
    """(automaton, parameter values, oscillator model or None).

    A model is anything with ``to_automaton()`` (the models layer sits above this one, so no isinstance check).
    """
    if not isinstance(system, HybridAutomaton) and callable(getattr(system, "to_automaton", None)):
        model = system.with_params(**params) if params else system
        return model.to_automaton(), dict(model.params), model
    if isinstance(system, HybridAutomaton):
        return system, system.resolve_parameters(params), None
    raise ModelError(
        f"simulate_orbit needs an ImpactOscillator model or a HybridAutomaton, got {type(system).__name__}"
    )


def _check_time(t0, t_end):
    for name, value in (("t0", t0), ("t_end", t_end)):
        try:
            value = float(value)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"{name}={value!r} is not a number") from exc
        if not math.isfinite(value):
            raise ParameterError(f"{name}={value!r} must be a finite time")
    if float(t_end) < float(t0):
        raise ParameterError(f"t_end={t_end!r} is before t0={t0!r}; give an end time >= the start time")
    return float(t0), float(t_end)


def _check_inside(automaton, model, state, mode, values, t0=0.0):
    names = [s.name for s in automaton.states]
    if model is not None:
        left, right = model.barriers
        x, v = state
        with np.errstate(all="ignore"):
            H = float(model.energy(x, v))
        if not np.isfinite(H):
            raise ParameterError(f"initial state x0={x:g}, v0={v:g} has energy {H!r}: it overflows double "
                                 "precision; start from a state of moderate size")
        if not (left <= x <= right):
            raise ParameterError(
                f"initial position x0={x:g} is outside the gap [{left:g}, {right:g}] between the barriers; "
                "start with left <= x0 <= right"
            )
        if (x == right and v > 0) or (x == left and v < 0):
            raise ParameterError(
                f"initial state x0={x:g}, v0={v:g} sits on a barrier moving outwards; reverse the velocity"
            )
    for tr in automaton.transitions_from(mode):
        if tr.direction == 0:
            continue
        g = to_callable([tr.guard], automaton.states, [*automaton.parameters, "t"])(state, [*values.values(), t0])[0]
        if tr.direction * g > 1e-12 * max(1.0, float(np.max(np.abs(state)))):
            raise ParameterError(
                f"initial state {dict(zip(names, state.tolist()))} is already past the guard of transition "
                f"{tr.name!r} ({tr.guard} = {g:.6g}, fires when it crosses zero going "
                f"{'up' if tr.direction > 0 else 'down'}); start on the other side"
            )


def _check_coefficient(model, t, before, after) -> None:
    """Refuse an impact whose applied coefficient -v+/v- is outside (0, 1] (the law is checked on a grid only)."""
    vm, vp = float(before[1]), float(after[1])
    if vm == 0.0:
        return  # a grazing contact: no coefficient is applied
    e = -vp / vm
    if not (0.0 < e <= 1.0 + 1e-12):
        raise RestitutionError(
            f"restitution law {model.restitution!r} gave e = {e:.17g} at the impact at t={t:.12g} with speed "
            f"|v-| = {abs(vm):.17g}, outside (0, 1]; fix the law so that 0 < e(v) <= 1 at every speed"
        )


@functools.lru_cache(maxsize=64)
def _jacobian_function(flow: tuple, states: tuple, params: tuple):
    """The flow's Jacobian as a numpy function of (states, parameters, t), or None when it has none (cached: one
    symbolic derivative per automaton structure, not per orbit)."""
    import sympy as sp

    plain = {s: sp.Symbol(s.name) for s in states}
    args = [plain[s] for s in states] + [sp.Symbol(p) for p in params] + [sp.Symbol("t")]
    try:
        jac = sp.Matrix(flow).jacobian(list(states)).xreplace(plain)
        jac = jac.xreplace({s: sp.Symbol(s.name) for s in jac.free_symbols})
        return sp.lambdify(args, jac, modules="numpy")
    except Exception:  # noqa: BLE001 - no Jacobian (an exotic function): no estimate; max_steps still bounds
        return None


def _flow_rates(automaton, mode, points, values, t0) -> float:
    """Largest spectral radius of the flow's Jacobian over ``points`` (1/time): the fastest rate of the motion.

    Points where the Jacobian is not finite (a square root at its branch point) are skipped: they say nothing
    about the step size.
    """
    n = len(automaton.states)
    fn = _jacobian_function(tuple(automaton.mode(mode).flow), tuple(automaton.states), tuple(automaton.parameters))
    pars = [values[p] for p in automaton.parameters] + [t0]
    rate = 0.0
    if fn is None:
        return rate
    with np.errstate(all="ignore"):
        for point in points:
            try:
                J = np.array(fn(*point, *pars), dtype=float)
            except Exception:  # noqa: BLE001 - e.g. DiracDelta from sign(x) has no numpy form: skip the point
                continue
            if J.shape == (n, n) and np.all(np.isfinite(J)):
                rate = max(rate, float(np.max(np.abs(np.linalg.eigvals(J)))))
    return rate


def _reachable_points(model, state) -> list:
    """The start and, for an oscillator model, the turning points of its energy level (clipped to the walls):
    where the restoring force is stiffest on that level."""
    points = [np.asarray(state, dtype=float)]
    if model is not None:
        try:
            with np.errstate(all="ignore"):
                H0 = float(model.energy(state[0], state[1]))
                lo, hi = (float(np.ravel(v)[0]) for v in model.turning_points(H0))
        except (VibroError, ArithmeticError, ValueError):
            return points
        points += [np.array([x, 0.0]) for x in (lo, hi) if np.isfinite(x)]
    return points


def estimate_orbit(automaton, model, values, state, mode, t0, t_end, *, backend_cls, dense, min_dwell,
                   max_steps) -> float:
    """Refuse, before any integrator is built, an orbit whose estimated work or dense output is above its limit.

    The steps are estimated as (t_end - t0) x the flow's fastest rate on the starting energy level (the spectral
    radius of its Jacobian) x :data:`STEPS_PER_RADIAN`. For an oscillator between two walls, a start so fast that it
    crosses the gap in less than ``min_dwell`` is refused too (its first impacts would stop the run as chattering).

    Parameters
    ----------
    automaton, model, values : HybridAutomaton, ImpactOscillator or None, dict
        As :func:`simulate_orbit` resolved them.
    state, mode, t0, t_end :
        The checked initial state, mode and time window.
    backend_cls : type
        Its ``seconds_per_step`` (if any) turns the estimate into a duration in the message.
    dense, min_dwell, max_steps :
        As in :func:`simulate_orbit`.

    Returns
    -------
    float
        The estimated number of steps.

    Raises
    ------
    SizeError
        Steps above ``max_steps``, or a dense output above :data:`MAX_LOG_BYTES`.
    ParameterError
        A start that crosses the gap faster than ``min_dwell``.
    """
    span = t_end - t0
    rate = _flow_rates(automaton, mode, _reachable_points(model, state), values, t0)
    steps = span * rate * STEPS_PER_RADIAN
    what = f"the orbit up to t_end={t_end:g}"
    cost = getattr(backend_cls, "seconds_per_step", None)
    check_size(what, work=steps, work_unit="integration steps", max_work=max_steps, seconds_per_unit=cost,
               detail=f"{STEPS_PER_RADIAN:g} steps per radian of the flow's fastest rate {rate:.3g}/time on the "
                      "starting level" + (f", ~{cost:.0e} s per step" if cost else ""),
               fix=(f"shorten t_end to at most {t0 + max_steps / max(rate * STEPS_PER_RADIAN, 1e-300):.3g} or "
                    "raise max_steps (--max-steps)"),
               max_memory=None)
    if dense:
        samples = min(steps, max_steps)
        check_size(f"the dense output of {what}", memory=samples * (_SAMPLE_BYTES + 16 * len(state)),
                   max_memory=MAX_LOG_BYTES, detail=f"{samples:.3g} steps kept",
                   fix="shorten t_end, lower max_steps, or run without dense=True")
    if model is not None:
        _check_first_crossing(model, abs(float(state[1])), min_dwell)
    return steps


def _check_first_crossing(model, speed, min_dwell) -> None:
    """Refuse a start so fast that the rebound from the first wall crosses the gap in less than ``min_dwell``.

    At such speeds the flight across the gap is free (its time is far below the oscillation's), so the second
    impact follows the first after width / (e(v) v): the run would stop there with status 'chattering'.
    """
    left, right = model.barriers
    if not (np.isfinite(left) and np.isfinite(right)) or not speed > 0:
        return
    width = right - left
    if width / speed >= min_dwell:
        return  # even without losses the first crossing is slow enough
    try:
        e = float(np.ravel(model.restitution.coefficient(speed))[0])
    except (VibroError, ArithmeticError, ValueError, TypeError):
        e = 1.0
    rebound = e * speed
    if rebound > 0 and width / rebound < min_dwell:
        raise ParameterError(
            f"the start v0={speed:g} hits a wall at about that speed and rebounds at {rebound:.3g} (e = {e:.3g}), "
            f"crossing the gap [{left:g}, {right:g}] in {width / rebound:.3g} time units, less than "
            f"min_dwell={min_dwell:g}: its first impacts would stop the orbit as chattering; start with a smaller "
            "speed (or lower min_dwell)")


def simulate_orbit(
    system,
    x0,
    t_end: float,
    backend: str | type[OrbitBackend] = "heyoka",
    *,
    t0: float = 0.0,
    mode: str | None = None,
    params: dict | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    dense: bool = False,
    min_dwell: float = 1e-9,
    max_impacts: int = 1_000_000,
    max_steps: int = _DEFAULT_MAX_STEPS,
    zeno_window: int = 6,
    zeno_rtol: float = 1e-3,
    **options,
) -> OrbitResult:
    """Simulate the deterministic (noise-free) orbit of an impact oscillator or a general hybrid automaton.

    The flow of the current mode is integrated until a guard crosses zero in its declared direction; the crossing
    is located exactly (heyoka: terminal Taylor events; scipy: root of the dense output), the reset is applied, the
    transition is logged and the integration resumes, until ``t_end``. Flows, guards, resets and observables may use
    the absolute time ``t`` (a forcing, a moving barrier): heyoka reads it as its own time variable, scipy as the
    right-hand side's t, and a reset sees the time of its event.

    Parameters
    ----------
    system : ImpactOscillator or HybridAutomaton
        For a model, its noise is ignored (the flow is x' = y, y' = -g - eps h) and impacts follow its
        restitution law.
    x0 : sequence of float
        Initial state (for a model: (x0, v0) with x0 inside the gap).
    t_end : float
        Final time (>= t0).
    backend : {'heyoka', 'scipy'} or OrbitBackend subclass
    t0 : float
    mode : str, optional
        Initial mode (the automaton's ``initial_mode`` by default).
    params : dict, optional
        Parameter overrides (for a model, as in ``model.with_params``).
    rtol, atol : float, optional
        Tolerances. heyoka: ``rtol`` is the Taylor tolerance (default machine epsilon; ``atol`` is refused).
        scipy: defaults 1e-10 and rtol/100.
    dense : bool
        Keep the state after every step (``result.trajectory``).
    min_dwell : float
        Minimum time between two transitions; a shorter interval stops the run with status ``'chattering'``.
    max_impacts : int
        Stop with status ``'max_impacts'`` after this many transitions. Refused when the impact log it allows
        would exceed :data:`MAX_LOG_BYTES`.
    max_steps : int
        Step budget (default 10**7). An orbit whose estimated steps (:func:`estimate_orbit`) exceed it is refused
        before any integrator is built, with the estimate; one that reaches it anyway stops with status
        ``'max_steps'``. Raise it for long runs.
    zeno_window, zeno_rtol : int, float
        Zeno detection: ``zeno_window`` successive ratios r < 1 of inter-impact intervals whose deficits 1 - r
        agree within ``zeno_rtol`` (relative) predict an accumulation t_k + dt_k r / (1 - r); if it falls before
        ``t_end`` the run stops with status ``'zeno'`` and ``zeno_time`` set. ``zeno_window=0`` switches
        detection off.
    **options
        Backend options (scipy: ``method='DOP853'``, ``max_step``).

    Returns
    -------
    OrbitResult
        After every integration step the state is checked against the directed guards of its mode; a state past
        one (an impact the integrator missed) stops the run with status ``'left_admissible_set'``, never ``'ok'``.

    Raises
    ------
    ParameterError
        Non-finite or reversed times, a state of the wrong length, a state outside the gap or past a guard,
        bad tolerances (below what double precision delivers), unknown backend, ``max_impacts`` or ``max_steps``
        out of range, a start that crosses the gap faster than ``min_dwell``.
    SizeError
        Estimated steps above ``max_steps``, a dense output or an impact log above :data:`MAX_LOG_BYTES`.
    RestitutionError
        For a model: an impact whose applied coefficient e = -v+/v- lies outside (0, 1] (a law that is only
        valid on the grid :meth:`RestitutionLaw.validate` checks); the message gives the speed and e.

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> res = simulate_orbit(DuffingImpact(c=0, D=0, restitution=Ma(0.4)), x0=(0.0, 2.2), t_end=20.0)
    >>> res.status, res.n_impacts
    ('ok', 11)
    >>> df = res.impacts.to_pandas()
    >>> bool(abs((df.H_minus - df.H_plus)[0] - (1 - df.e[0]**2) * (df.H_minus[0] - 0.55)) < 1e-12)
    True
    """
    wall0 = time.perf_counter()
    automaton, values, model = _as_automaton(system, params)
    t0, t_end, state, mode = _validate(automaton, model, values, x0, t0, t_end, mode, min_dwell, max_impacts,
                                       max_steps, zeno_window, zeno_rtol)
    backend_cls = _backend_class(backend)
    estimate_orbit(automaton, model, values, state, mode, t0, t_end, backend_cls=backend_cls, dense=dense,
                   min_dwell=min_dwell, max_steps=max_steps)
    engine = backend_cls(automaton, values, rtol=rtol, atol=atol, dense=dense, **options)
    zeno = ZenoDetector(int(zeno_window), float(zeno_rtol)) if zeno_window else None
    run = _EventLoop(automaton, values, model, engine, zeno, dense)
    run.run(t0, t_end, state, mode, min_dwell=min_dwell, max_impacts=max_impacts, max_steps=max_steps)
    settings = {"backend": engine.name, "t0": t0, "t_end": t_end, "min_dwell": min_dwell, "max_impacts": max_impacts,
                "max_steps": max_steps, "zeno_window": zeno_window, "zeno_rtol": zeno_rtol,
                "parameters": dict(values), **engine.settings()}
    return run.result(settings, wall0)


def _validate(automaton, model, values, x0, t0, t_end, mode, min_dwell, max_impacts, max_steps, zeno_window,
              zeno_rtol):
    """Check every setting and the initial state before a backend is built: (t0, t_end, state, mode)."""
    t0, t_end = _check_time(t0, t_end)
    state = finite_array(x0, "the initial state x0")
    names = [s.name for s in automaton.states]
    if state.size != len(names):
        raise ParameterError(f"x0 has {state.size} values but the state is {names}; give one value per state")
    mode = automaton.initial_mode if mode is None else mode
    automaton.mode(mode)  # unknown mode -> ModelError
    if not (isinstance(min_dwell, (int, float)) and math.isfinite(min_dwell) and min_dwell >= 0):
        raise ParameterError(f"min_dwell={min_dwell!r} must be a finite time >= 0")
    if isinstance(max_impacts, bool) or not (isinstance(max_impacts, (int, np.integer)) and max_impacts >= 1):
        raise ParameterError(f"max_impacts={max_impacts!r} must be an integer >= 1")
    row = _log_bytes_per_impact(len(names), len(automaton.observables))
    check_size(f"the impact log that max_impacts={max_impacts} allows", memory=float(max_impacts) * row,
               max_memory=MAX_LOG_BYTES, detail=f"~{row} bytes per impact",
               fix=f"use at most {MAX_LOG_BYTES // row} impacts")
    if isinstance(max_steps, bool) or not (isinstance(max_steps, (int, np.integer)) and max_steps >= 1):
        raise ParameterError(f"max_steps={max_steps!r} must be an integer >= 1 (default {_DEFAULT_MAX_STEPS})")
    if isinstance(zeno_window, bool) or not isinstance(zeno_window, (int, np.integer)) or \
            not (zeno_window == 0 or 2 <= zeno_window <= 10_000):
        raise ParameterError(f"zeno_window={zeno_window!r} must be an integer in [2, 10000], or 0 to switch "
                             "detection off")
    # a NaN spread limit would make every run of decreasing intervals look geometric
    if not (isinstance(zeno_rtol, (int, float)) and math.isfinite(zeno_rtol) and zeno_rtol >= 0):
        raise ParameterError(f"zeno_rtol={zeno_rtol!r} must be a finite relative spread >= 0, e.g. 1e-3")
    _check_inside(automaton, model, state, mode, values, t0)
    return t0, t_end, state, mode


def _backend_class(backend) -> type[OrbitBackend]:
    """The backend class for a registered name or an OrbitBackend subclass."""
    if isinstance(backend, str):
        if backend not in BACKENDS:
            raise ParameterError(f"unknown backend {backend!r}; use one of {sorted(BACKENDS)}")
        return BACKENDS[backend]
    if isinstance(backend, type) and issubclass(backend, OrbitBackend):
        return backend
    raise ParameterError(f"backend must be a name in {sorted(BACKENDS)} or an OrbitBackend subclass")


class _EventLoop:
    """Integrate to the next transition, apply its reset, log it, apply the stop rules; then build the result."""

    def __init__(self, automaton, values, model, engine, zeno, dense):
        self.automaton, self.values, self.model, self.engine = automaton, values, model, engine
        self.zeno, self.dense = zeno, dense
        self.pnames = [*automaton.parameters, "t"]  # resets and observables may read the time (a moving table)
        self.pvalues = [values[p] for p in automaton.parameters]
        self.resets = {tr.name: (to_callable(tr.reset, automaton.states, self.pnames) if tr.symbolic_reset
                                 else tr.reset) for tr in automaton.transitions}
        self.obs_names = list(automaton.observables)
        self.observe = (to_callable([automaton.observables[k] for k in self.obs_names], automaton.states,
                                    self.pnames) if self.obs_names else (lambda s, p: ()))
        self.rows = {k: [] for k in ("t", "transition", "source", "target", "before", "after", "ob_before",
                                     "ob_after")}
        self.status, self.message, self.zeno_time, self.n_steps = "ok", "", None, 0
        self.t, self.state, self.mode = math.nan, None, None

    def run(self, t0, t_end, state, mode, *, min_dwell, max_impacts, max_steps) -> None:
        engine, rows = self.engine, self.rows
        engine.start(t0, state, mode)
        self.message = f"reached t_end={t_end:g}"
        t_last, t = -math.inf, t0
        while True:
            step = engine.advance(t_end, max_steps - self.n_steps)
            self.n_steps += step.steps
            t, state = step.t, step.state
            self.t, self.state, self.mode = t, state, mode
            if step.failed:
                self.status, self.message = "failed", step.failed
                return
            if step.outside:
                self.status, self.message = "left_admissible_set", step.outside
                return
            if step.step_limit:
                self.status = "max_steps"
                self.message = (f"stopped after max_steps={max_steps} integration steps at t={t:.12g} before "
                                f"t_end={t_end:g}; raise max_steps (or shorten t_end) to go on")
                return
            if step.fired is None:
                return
            tr = self.automaton.transitions[step.fired]
            new = self._reset(tr, t, state)
            if new.shape != state.shape or not np.all(np.isfinite(new)):
                self.status = "failed"
                self.message = f"reset of transition {tr.name!r} at t={t:.17g} gave {new} from {state}"
                return
            if self.model is not None:
                _check_coefficient(self.model, t, state, new)
            now = [*self.pvalues, t]
            for key, value in (("t", t), ("transition", tr.name), ("source", tr.source), ("target", tr.target),
                               ("before", state), ("after", new), ("ob_before", self.observe(state, now)),
                               ("ob_after", self.observe(new, now))):
                rows[key].append(value)
            state, mode = new, tr.target
            self.state, self.mode = state, mode
            if self.dense:
                engine.samples.append((t, new.copy(), mode))
            dt, t_last = t - t_last, t
            if self.zeno is not None:
                predicted = self.zeno.add(t)
                if predicted is not None and predicted <= t_end:
                    self.status, self.zeno_time = "zeno", predicted
                    self.message = (f"Zeno: transition times accumulate geometrically (ratio {self.zeno.ratio:.6g}) "
                                    f"at t = {predicted:.12g}; stopped after {len(rows['t'])} transitions at "
                                    f"t = {t:.12g}")
                    return
            if dt < min_dwell:
                self.status = "chattering"
                self.message = (f"two transitions {dt:.3g} apart at t={t:.12g} (< min_dwell={min_dwell:g}): "
                                "chattering or a grazing sequence; stopped")
                return
            if len(rows["t"]) >= max_impacts:
                self.status = "max_impacts"
                self.message = f"stopped after max_impacts={max_impacts} transitions at t={t:.12g}"
                return
            engine.restart(t, state, mode, step.fired)

    def _reset(self, tr, t, state) -> np.ndarray:
        try:
            if tr.symbolic_reset:
                return np.array(self.resets[tr.name](state, [*self.pvalues, t]), dtype=float)
            return np.asarray(self.resets[tr.name](state.copy(), {**self.values, "t": t}), dtype=float)
        except VibroError:
            raise
        except Exception as exc:  # a user reset or restitution callable that fails: one line, with where
            raise ModelError(f"the reset of transition {tr.name!r} failed at t={t:.12g}, state {state.tolist()} "
                             f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from exc

    def result(self, settings: dict, wall0: float) -> OrbitResult:
        rows, model, engine = self.rows, self.model, self.engine
        names = [s.name for s in self.automaton.states]
        d = len(names)
        log = ImpactLog(
            t=np.array(rows["t"], dtype=float), transition=np.array(rows["transition"], dtype=object),
            source=np.array(rows["source"], dtype=object), target=np.array(rows["target"], dtype=object),
            before=np.array(rows["before"], dtype=float).reshape(-1, d),
            after=np.array(rows["after"], dtype=float).reshape(-1, d),
            observables_before={k: np.array([o[i] for o in rows["ob_before"]], dtype=float)
                                for i, k in enumerate(self.obs_names)},
            observables_after={k: np.array([o[i] for o in rows["ob_after"]], dtype=float)
                               for i, k in enumerate(self.obs_names)},
            state_names=tuple(names), oscillator=model is not None,
        )
        if model is not None and "H" not in log.observables_before and len(log):
            # G has no closed form: the model's numerical energy (quadrature) fills the H columns
            log.observables_before["H"] = np.asarray(model.energy(log.before[:, 0], log.before[:, 1]), dtype=float)
            log.observables_after["H"] = np.asarray(model.energy(log.after[:, 0], log.after[:, 1]), dtype=float)
        trajectory = None
        if self.dense:
            trajectory = Trajectory(
                t=np.array([s[0] for s in engine.samples], dtype=float),
                y=np.array([s[1] for s in engine.samples], dtype=float).reshape(-1, d),
                mode=np.array([s[2] for s in engine.samples], dtype=object), state_names=tuple(names),
            )
        if model is not None:
            settings["restitution"] = model.restitution.spec()
            settings["model"] = model.name
        return OrbitResult(
            status=self.status, message=self.message, t=float(self.t), state=np.array(self.state, dtype=float),
            mode=self.mode, impacts=log, n_steps=self.n_steps, n_impacts=len(rows["t"]), zeno_time=self.zeno_time,
            trajectory=trajectory, backend=engine.name, settings=settings, compile_time=engine.compile_time,
            wall_time=time.perf_counter() - wall0,
        )
