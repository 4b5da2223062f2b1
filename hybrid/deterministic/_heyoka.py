"""heyoka backend: Taylor integration with terminal events located to machine precision.

The flows and guards are compiled once per automaton *structure* (:func:`automaton_fingerprint`) and tolerance;
parameter values are heyoka runtime parameters (``heyoka.par[i]``), so changing the barrier distance, V_C or the
damping reuses the compiled integrator. Automata with several modes share one integrator: every mode has a weight
parameter (1 for the current mode, 0 otherwise) multiplying its flow, and a guard of an inactive mode reads
``w * guard + (1 - w) = 1``, which never crosses zero. Every transition is a terminal event without callback:
the integration stops at the crossing, the driver applies the reset in Python and resumes. heyoka's automatic
cooldown keeps the event that just fired from firing again at the same instant. The time ``t`` in flows and guards is
heyoka's own time expression (``heyoka.time``), so a forcing or a moving guard is part of the Taylor expansion.

Limitation: with several modes every flow is evaluated (times its 0/1 weight), so a flow that is not finite
somewhere (a division by zero in an inactive mode) spoils the others; use the scipy backend for such automata.
"""

from __future__ import annotations

import copy
import time
from collections import OrderedDict

import numpy as np

from hybrid.errors import ModelError, ParameterError

from ._base import Advance, OrbitBackend
from ._convert import automaton_fingerprint, to_callable, to_heyoka

_EPS = float(np.finfo(float).eps)
_CACHE: OrderedDict = OrderedDict()
_CACHE_SIZE = 32


def _compile(automaton, tol):
    """A fresh heyoka integrator for ``automaton`` (state and parameters are set later)."""
    import heyoka as hy

    names = [s.name for s in automaton.states]
    variables = hy.make_vars(*names)
    if len(names) == 1:
        variables = [variables]
    symbols = dict(zip(names, variables))
    index = parameter_indices(automaton)
    symbols.update({p: hy.par[i] for p, i in index.items() if not p.startswith("mode:")})
    symbols["t"] = hy.time  # forcing and moving guards: heyoka's own time, exact in the Taylor expansion
    multi = len(automaton.modes) > 1
    weights = [hy.par[index[f"mode:{m.name}"]] for m in automaton.modes] if multi else []

    rhs = []
    for i in range(len(names)):
        terms = []
        for k, m in enumerate(automaton.modes):
            f = to_heyoka(m.flow[i], symbols)
            terms.append(weights[k] * f if multi else f)
        rhs.append(hy.sum(terms) if len(terms) > 1 else terms[0])
    directions = {1: hy.event_direction.positive, -1: hy.event_direction.negative, 0: hy.event_direction.any}
    events = []
    mode_index = {m.name: k for k, m in enumerate(automaton.modes)}
    for tr in automaton.transitions:
        g = to_heyoka(tr.guard, symbols)
        if multi:
            w = weights[mode_index[tr.source]]
            g = w * g + (hy.expression(1.0) - w)
        events.append(hy.t_event(g, direction=directions[tr.direction]))
    kwargs = {} if tol is None else {"tol": float(tol)}
    # heyoka sizes the parameter array from the highest index it meets; parameters used only in resets
    # get no slot (they are applied in Python)
    return hy.taylor_adaptive(list(zip(variables, rhs)), [0.0] * len(names), t_events=events, **kwargs)


def parameter_indices(automaton) -> dict:
    """heyoka runtime-parameter index of each parameter used by a flow or a guard, then of each mode weight.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> parameter_indices(DuffingImpact().to_automaton())
    {'a': 0, 'b': 1, 'c': 2, 'delta': 3}
    """
    used = set()
    for m in automaton.modes:
        for f in m.flow:
            used |= {s.name for s in f.free_symbols}
    for tr in automaton.transitions:
        used |= {s.name for s in tr.guard.free_symbols}
    names = [p for p in automaton.parameters if p in used]
    index = {p: i for i, p in enumerate(names)}
    if len(automaton.modes) > 1:
        index.update({f"mode:{m.name}": len(names) + k for k, m in enumerate(automaton.modes)})
    return index


def compiled_integrator(automaton, tol=None):
    """A private copy of the cached compiled integrator for ``automaton``, and the seconds spent compiling.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> ta, seconds = compiled_integrator(DuffingImpact().to_automaton())
    >>> ta2, again = compiled_integrator(DuffingImpact(delta=0.5).to_automaton())
    >>> again
    0.0
    """
    key = (automaton_fingerprint(automaton), tol)
    seconds = 0.0
    if key not in _CACHE:
        t0 = time.perf_counter()
        _CACHE[key] = _compile(automaton, tol)
        seconds = time.perf_counter() - t0
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    _CACHE.move_to_end(key)
    return copy.deepcopy(_CACHE[key]), seconds


class HeyokaBackend(OrbitBackend):
    """Taylor integration (heyoka) with terminal events; tolerance ``rtol`` (default: machine epsilon).

    Examples
    --------
    >>> from models import DuffingImpact, Elastic
    >>> from hybrid.deterministic import simulate_orbit
    >>> r = simulate_orbit(DuffingImpact(c=0, D=0, restitution=Elastic()), (0.0, 2.0), 5.0, backend="heyoka")
    >>> r.backend
    'heyoka'
    """

    name = "heyoka"
    seconds_per_step = 3e-5  # measured 22-150 us per step with the per-step check (2 shared cores)

    def __init__(self, automaton, params, rtol=None, atol=None, dense=False, **options):
        if options:
            raise ParameterError(f"heyoka backend: unknown options {sorted(options)}")
        if rtol is not None:
            try:
                rtol = float(rtol)
            except (TypeError, ValueError) as exc:
                raise ParameterError(f"heyoka tolerance rtol={rtol!r} is not a number") from exc
            # below machine epsilon double precision cannot deliver the accuracy (and heyoka's Taylor order,
            # hence its compile time, grows without bound)
            if not (_EPS <= rtol < 1):
                raise ParameterError(f"heyoka tolerance rtol={rtol!r} must lie in [{_EPS:.3g}, 1) (double precision "
                                     "cannot deliver less than machine epsilon); e.g. 1e-15, or omit it for "
                                     f"{_EPS:.3g}")
        if atol is not None:  # it used to be ignored silently
            raise ParameterError(f"heyoka has one tolerance, rtol; atol={atol!r} is not used: drop it or use "
                                 "backend='scipy'")
        super().__init__(automaton, params, rtol=rtol, atol=atol, dense=dense)
        try:
            self.ta, self.compile_time = compiled_integrator(automaton, rtol)
        except ModelError:
            raise
        except Exception as exc:  # heyoka refuses the system: say which backend works instead
            raise ModelError(f"heyoka cannot compile this automaton ({exc}); use backend='scipy'") from exc
        self._index = parameter_indices(automaton)
        self._multi = len(automaton.modes) > 1
        self._modes = [m.name for m in automaton.modes]
        self._write_pars({p: self.params[p] for p in self._index if not p.startswith("mode:")})
        self.mode = automaton.initial_mode
        pnames = list(automaton.parameters)
        self._values = [self.params[p] for p in pnames]
        self._guards = [to_callable([t.guard], automaton.states, [*pnames, "t"]) for t in automaton.transitions]
        self._active = {
            m.name: [j for j, t in enumerate(automaton.transitions) if t.source == m.name] for m in automaton.modes
        }
        self._escape: set = set()

    def _zero_guards(self, state, mode, skip) -> set:
        """Transitions of ``mode`` whose guard is exactly zero at ``state`` (``skip`` is in heyoka's cooldown)."""
        values = [*self._values, float(self.ta.time)]
        return {j for j in self._active[mode] if j != skip and self._guards[j](state, values)[0] == 0.0}

    def _write_pars(self, values: dict) -> None:
        pars = self.ta.pars
        for name, value in values.items():
            i = self._index[name]
            if i < len(pars):  # a weight of a mode with a zero flow and no guard may have no slot
                pars[i] = value

    def _set_mode(self, mode: str) -> None:
        self.mode = mode
        if self._multi:
            self._write_pars({f"mode:{m}": float(m == mode) for m in self._modes})

    def start(self, t0, state, mode):
        self.ta.time = float(t0)
        self.ta.state[:] = state
        if self.automaton.transitions:
            self.ta.reset_cooldowns()
        self._set_mode(mode)
        self._escape = self._zero_guards(self.ta.state, mode, None)
        if self.dense:
            self.samples.append((float(t0), np.array(state, dtype=float), mode))

    def restart(self, t, state, mode, fired=None):
        self.fresh = True
        self.ta.state[:] = state
        self._set_mode(mode)
        self._escape = self._zero_guards(self.ta.state, mode, fired)

    def _after_step(self, ta) -> bool:
        """heyoka's step callback: record the step (dense output) and stop when the state left the admissible set."""
        if self.dense:
            self.samples.append((ta.time, ta.state.copy(), self.mode))
        self._outside, self._before = self.check_step(ta.time, ta.state, self.mode, self._before)
        self.fresh = False
        return self._outside is None

    def _propagate(self, t_end, max_steps=0) -> Advance:
        import heyoka as hy

        self._outside = None
        self._before = self.signed_guards(self.ta.state, self.mode, self.ta.time)
        out = self.ta.propagate_until(float(t_end), max_steps=int(max_steps), callback=self._after_step)
        outcome, steps = out[0], int(out[3])
        state = self.ta.state.copy()
        if outcome == hy.taylor_outcome.time_limit:
            return Advance(self.ta.time, state, None, steps)
        if outcome == hy.taylor_outcome.cb_stop:
            return Advance(self.ta.time, state, None, steps, outside=self._outside)
        if outcome == hy.taylor_outcome.step_limit:
            return Advance(self.ta.time, state, None, steps, step_limit=True)
        code = int(outcome)
        if -len(self.automaton.transitions) <= code < 0:
            return Advance(self.ta.time, state, -code - 1, steps)
        return Advance(self.ta.time, state, None, steps,
                       failed=f"heyoka stopped with outcome {outcome!r} at t={self.ta.time:.17g}, state={state}")

    def advance(self, t_end, max_steps=0):
        steps = 0
        if self._escape:
            # heyoka misses crossings in a step whose event polynomial starts at exactly zero: leave the guard
            # with a tiny step first, ignoring a 'crossing' at the start point itself (that is not a crossing)
            t_start = self.ta.time
            target = min(t_start + 1e-10 * max(1.0, abs(t_start)), t_end)
            for _ in range(len(self._escape) + 1):
                res = self._propagate(target)
                steps += res.steps
                if res.fired in self._escape and res.t == t_start:
                    continue  # now in heyoka's cooldown
                break
            self._escape = set()
            self.fresh = True  # the escape step is part of leaving the start point
            if res.fired is not None or res.failed or res.outside or res.t >= t_end:
                res.steps = steps
                return res
        if max_steps and steps >= max_steps:
            return Advance(self.ta.time, self.ta.state.copy(), None, steps, step_limit=True)
        res = self._propagate(t_end, max_steps - steps if max_steps else 0)
        res.steps += steps
        return res

    def settings(self):
        return {"rtol": self.rtol if self.rtol is not None else float(np.finfo(float).eps), "order": self.ta.order}
