"""Impact models beyond one oscillator, declared directly as hybrid automata (a few lines each).

Every function returns a :class:`hybrid.HybridAutomaton` with named parameters, an energy observable ``H`` and
the observables the examples plot. They run through ``hybrid.stochastic.simulate_automaton`` and
``hybrid.deterministic.simulate_orbit`` (both take the time ``t`` in flows, guards and resets).
"""

from __future__ import annotations

import sympy as sp

from hybrid.automaton import HybridAutomaton, Mode, Transition, real_symbol


def _symbols(names: str):
    return [real_symbol(n) for n in names.split()]


def impact_pair(**parameters: float) -> HybridAutomaton:
    """A primary mass on a spring with a second mass moving in a clearance inside it (a vibro-impact energy sink).

    States x1, x2, v1, v2. Mass m1 on spring k1 with damping c1; mass m2 on spring k2 (k2 = 0: free inside the
    clearance) with damping c2; the masses collide when |x2 - x1| reaches ``gap``, keeping momentum and reversing
    the relative velocity times r. Independent white noises on both masses at temperature ``theta``: the
    intensities 2 c_i theta obey fluctuation-dissipation, so elastic impacts (r = 1) keep the Gibbs density
    exp(-H / theta) on |x2 - x1| <= gap.

    Examples
    --------
    >>> A = impact_pair(r=0.7)
    >>> [t.name for t in A.transitions], A.parameters["r"]
    (['hit_right', 'hit_left'], 0.7)
    """
    x1, x2, v1, v2, k1, k2, m1, m2, c1, c2, th, gap, r = _symbols("x1 x2 v1 v2 k1 k2 m1 m2 c1 c2 theta gap r")
    defaults = {"k1": 1.0, "k2": 0.6, "m1": 1.0, "m2": 0.3, "c1": 0.3, "c2": 0.2, "theta": 0.05, "gap": 0.2,
                "r": 1.0}
    flow = (v1, v2, (-k1 * x1 - c1 * v1) / m1, (-k2 * x2 - c2 * v2) / m2)
    noise = ((0, 0), (0, 0), (sp.sqrt(2 * c1 * th) / m1, 0), (0, sp.sqrt(2 * c2 * th) / m2))
    u = v2 - v1  # relative velocity, reversed times r; the total momentum is kept
    reset = (x1, x2, v1 + (1 + r) * m2 / (m1 + m2) * u, v2 - (1 + r) * m1 / (m1 + m2) * u)
    energy = (m1 * v1**2 + m2 * v2**2 + k1 * x1**2 + k2 * x2**2) / 2
    return HybridAutomaton(
        (x1, x2, v1, v2), {**defaults, **parameters}, [Mode("free", flow, noise)],
        [Transition("hit_right", "free", "free", x2 - x1 - gap, +1, reset),
         Transition("hit_left", "free", "free", x1 - x2 - gap, +1, reset, priority=1)],
        observables={"H": energy, "z": x2 - x1},
        positive=("k1", "m1", "m2", "gap"), nonnegative=("k2", "c1", "c2", "theta", "r"),
    )


def vibrating_table(**parameters: float) -> HybridAutomaton:
    """A ball bouncing on a table that moves as s(t) = A sin(omega t), under gravity g and white noise D on the ball.

    States x (height), v. The ball hits the table when x - s(t) falls through 0 and leaves with the velocity
    s'(t) - r (v - s'(t)) (Newton's law relative to the moving table). The guard moves with time: the Monte Carlo
    kernel locates the crossing on the step's free flight at the table's position at that instant.

    Examples
    --------
    >>> vibrating_table(A=0.1).transitions[0].name
    'table'
    """
    x, v, g, D, r, A, w = _symbols("x v g D r A omega")
    t = real_symbol("t")
    defaults = {"g": 1.0, "D": 0.0, "r": 0.8, "A": 0.05, "omega": 2.0}
    table, table_v = A * sp.sin(w * t), A * w * sp.cos(w * t)
    return HybridAutomaton(
        (x, v), {**defaults, **parameters}, [Mode("air", (v, -g), (0, sp.sqrt(2 * D)))],
        [Transition("table", "air", "air", table - x, +1, (table, table_v - r * (v - table_v)))],
        observables={"height": x - table, "H": v**2 / 2 + g * x},
        nonnegative=("D", "r", "A", "omega"),
    )


def describe_automaton(automaton: HybridAutomaton) -> dict:
    """A JSON-friendly description of an automaton: states, parameters, modes, transitions, observables.

    Expressions are printed as text; a callable reset is named ``<callable>``. The command line stores it in the
    provenance sidecar of ``vibro mc`` for automaton models.

    Examples
    --------
    >>> d = describe_automaton(impact_pair())
    >>> d["states"], [t["name"] for t in d["transitions"]]
    (['x1', 'x2', 'v1', 'v2'], ['hit_right', 'hit_left'])
    """
    def text(e):
        return [text(v) for v in e] if isinstance(e, (tuple, list)) else str(e)

    return {
        "model": "automaton",
        "states": [s.name for s in automaton.states],
        "parameters": dict(automaton.parameters),
        "modes": [{"name": m.name, "flow": text(m.flow), "noise": None if m.noise is None else text(m.noise)}
                  for m in automaton.modes],
        "transitions": [{"name": t.name, "source": t.source, "target": t.target, "guard": str(t.guard),
                         "direction": t.direction, "priority": t.priority,
                         "reset": text(t.reset) if t.symbolic_reset else "<callable>"}
                        for t in automaton.transitions],
        "initial_mode": automaton.initial_mode,
        "observables": {k: str(v) for k, v in automaton.observables.items()},
    }


AUTOMATA = {"impact_pair": impact_pair, "vibrating_table": vibrating_table}
"""Built-in automaton models by name (``vibro mc --model impact_pair``): functions of keyword parameters."""

__all__ = ["AUTOMATA", "describe_automaton", "impact_pair", "vibrating_table"]
