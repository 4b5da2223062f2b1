"""The backend interface shared by the deterministic simulators.

A backend integrates the flow of one mode until ``t_end`` or until a guard of that mode crosses zero, whichever
comes first, and stops exactly there. The driver (:func:`~hybrid.deterministic.simulate_orbit`) applies the reset,
logs the transition, watches for Zeno behaviour and restarts the backend. To add a backend, subclass
:class:`OrbitBackend`, implement ``start``, ``advance`` and ``restart``, and add it to ``BACKENDS``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybrid.automaton import HybridAutomaton, real_symbol

TIME = real_symbol("t")
"""The time symbol: flows, guards and resets may use it (forcing, moving barriers)."""


@dataclass
class Advance:
    """What :meth:`OrbitBackend.advance` reports.

    ``fired`` is the index (into ``automaton.transitions``) of the transition whose guard stopped the integration,
    or None when ``t_end`` was reached; ``failed`` carries a message when the integrator gave up; ``outside``
    carries a message when a step ended past a guard without the event firing (the state left the admissible set);
    ``step_limit`` is True when the step budget given to :meth:`OrbitBackend.advance` ran out first.
    """

    t: float
    state: np.ndarray
    fired: int | None
    steps: int
    failed: str | None = None
    outside: str | None = None
    step_limit: bool = False


ADMISSIBLE_RTOL = 1e-9
"""A step is reported as a missed event when a directed guard ends past zero by more than this times max(1, |state|).

Event locations are exact to rounding (about 1e-16 relative), so this margin never flags a located impact, while a
missed event (an orbit tunnelling through a wall) is past by far more after the next step.
"""


class OrbitBackend:
    """Base class of the deterministic backends.

    Parameters
    ----------
    automaton : HybridAutomaton
    params : dict
        Parameter values, in ``automaton.parameters`` order.
    rtol, atol : float or None
        Tolerances (the backend's defaults when None).
    dense : bool
        Record the state after every step in :attr:`samples`.
    options : dict
        Backend-specific options (``method`` for scipy).
    """

    name = "base"
    order: int | None = None

    def __init__(self, automaton: HybridAutomaton, params: dict, rtol=None, atol=None, dense=False, **options):
        self.automaton = automaton
        self.params = dict(params)
        self.rtol = rtol
        self.atol = atol
        self.dense = dense
        self.options = options
        self.samples: list[tuple[float, np.ndarray, str]] = []
        self.compile_time = 0.0
        self.fresh = True  # no step taken since the last start or reset

    def _directed(self, mode: str):
        """(transition indices, fast callable state -> [direction * guard]) for the directed guards of ``mode``."""
        cache = self.__dict__.setdefault("_directed_fns", {})
        if mode not in cache:
            import sympy as sp

            a = self.automaton
            idx = [j for j in self._active[mode] if a.transitions[j].direction != 0]
            args = [sp.Symbol(f"_s{i}") for i in range(len(a.states))] + [sp.Symbol(f"_p{i}") for i in
                                                                             range(len(a.parameters))]
            args.append(sp.Symbol("_time"))  # guards may move with time (a vibrating table)
            by_name = dict(zip([s.name for s in a.states] + list(a.parameters) + ["t"], args))
            exprs = []
            for j in idx:
                g = a.transitions[j].guard
                exprs.append(a.transitions[j].direction * g.xreplace({s: by_name[s.name] for s in g.free_symbols}))
            try:
                fn = sp.lambdify(args, [sp.Float(1.0) * e for e in exprs], modules=["math"])
                fn(*([0.5] * len(args)))
            except (NameError, TypeError, KeyError):
                fn = sp.lambdify(args, exprs, modules=["numpy"])
            except (ValueError, ZeroDivisionError, OverflowError):
                pass  # the probe point is outside the domain; the math version is still fine
            cache[mode] = (idx, fn)
        return cache[mode]

    def signed_guards(self, state, mode, t: float = 0.0) -> tuple[list, list, float]:
        """(direction * guard for each directed guard of ``mode`` at time ``t``, the state as a list, t): > 0 is past.
        """
        y = state.tolist() if isinstance(state, np.ndarray) else [float(v) for v in state]  # a copy, not a view
        return self._directed(mode)[1](*y, *self._values, float(t)), y, float(t)

    def _signed_rate(self, j: int, mode: str, state, t: float = 0.0) -> float:
        """direction * d guard_j / dt along the flow of ``mode`` at ``state`` and time ``t`` (its Lie derivative)."""
        import sympy as sp

        from ._convert import to_callable

        rates = self.__dict__.setdefault("_rate_fns", {})
        if (mode, j) not in rates:
            a = self.automaton
            flow = a.mode(mode).flow
            guard = a.transitions[j].guard
            expr = sum(sp.diff(guard, s) * f for s, f in zip(a.states, flow)) + sp.diff(guard, TIME)
            rates[(mode, j)] = to_callable([expr], a.states, [*a.parameters, "t"])
        return self.automaton.transitions[j].direction * rates[(mode, j)](np.array(state), [*self._values, t])[0]

    def check_step(self, t: float, state, mode: str, before: tuple) -> tuple[str | None, tuple]:
        """(message or None, :meth:`signed_guards` at ``state``) after a step that ended at ``state``.

        The message says that the step crossed a directed guard without its event firing. ``before`` is
        :meth:`signed_guards` at the step start. A guard that was not past (direction * guard <= tol) and ends past
        it (> tol) was crossed in its firing direction: the integrator missed the event (an orbit tunnelling
        through a wall). Not missed: a guard past already at the start, and in the first step after a start or
        reset a guard at zero that the flow carries through (a marker transition, as at a start on it).
        """
        after = self.signed_guards(state, mode, t)
        new, y, _ = after
        tol = ADMISSIBLE_RTOL * max(1.0, max(abs(v) for v in y))
        if all(g <= tol for g in new):  # the usual case, fast
            return None, after
        old, y0, t0 = before
        idx = self._directed(mode)[0]
        for j, g0, g1 in zip(idx, old, new):
            if g1 <= tol:
                continue
            # in the first step after a (re)start, a guard that starts at zero may legitimately be left through its
            # firing side (a start on a marker, a marker with an identity reset): starting on a guard is no crossing
            if self.fresh and g0 > -tol and self._signed_rate(j, mode, y0, t0) > 0.0 and g1 == g1:
                continue
            if g0 <= tol or g1 != g1:
                tr = self.automaton.transitions[j]
                names = [s.name for s in self.automaton.states]
                return (f"the state {dict(zip(names, y))} at t={t:.17g} lies past the guard of transition "
                        f"{tr.name!r} ({tr.guard} = {tr.direction * g1:.6g}) without the event firing: the "
                        f"{self.name} integrator missed it (typically near a Zeno accumulation); the orbit after "
                        "this point is not valid"), after
        return None, after

    def start(self, t0: float, state: np.ndarray, mode: str) -> None:
        """Set the initial time, state and mode."""
        raise NotImplementedError

    def advance(self, t_end: float, max_steps: int = 0) -> Advance:
        """Integrate until ``t_end``, the first guard crossing of the current mode or ``max_steps`` steps (0: none).

        After every step no directed guard of the mode may have been crossed in its firing direction without the
        event firing (:meth:`check_step`); otherwise the integration stops with ``Advance.outside`` set.
        """
        raise NotImplementedError

    def restart(self, t: float, state: np.ndarray, mode: str, fired: int | None = None) -> None:
        """Continue from a state just after the reset of transition ``fired`` (same time), maybe in another mode.

        A guard that is zero at the restart point is not a crossing; the guard of ``fired`` must not fire again
        because of the rounding of the event location (a cooldown).
        """
        raise NotImplementedError

    def settings(self) -> dict:
        """The options in effect (for the result's metadata)."""
        return {"rtol": self.rtol, "atol": self.atol}
