"""Numba source for Monte Carlo of any :class:`~hybrid.automaton.HybridAutomaton` with noise.

The automaton's sympy expressions (Itô drift, noise matrix, guards, resets, checks, observables, the guards' rates
of change along the drift) become one numba function ``model(kind, which, x, t, p, out)`` with a branch per kind
(only the kinds the scheme calls) and, in it, per mode or transition (numba compiles each function on its own, so one
function for all of them compiles once, not nine times); the observables are ``_observe``. Parameter values are not
in the source (they arrive as the array ``p``), so changing a parameter never
recompiles. The scheme is a constant of the generated module, so only its own code is compiled. The source is
cached on disk by its hash (:func:`kernel_key`).

Time ``t`` may appear in flows, noise, guards and resets (forcing, moving barriers).

Crossings are located on the step's own interpolant: for ``em`` and ``milstein`` the straight segment from the
state before to the state after the step; for ``splitting``, ``symplectic`` and ``baoab`` the free flight of the
positions at constant velocity, which *is* the scheme's position update, so the location is exact for guards of the
positions. These three also move the velocities in sub-steps of their own at a fixed position and instant (kicks,
noise, the velocities' Milstein step, BAOAB's O step), so their sub-step states pair the positions of one instant
with the velocities of another (splitting's flight: the step end's positions with the middle's velocities, whose
energy is high by about y V'(x) dt / 2). A guard that depends on a velocity (an energy level) is therefore read on
consistent states only (``view_guard``): along each flight piece with the velocities moved linearly from those of
its start (the step's start, before the opening sub-step; after a firing, the reset of the consistent state there)
to those of its end (at the step's end after the closing kick; BAOAB's half step: the flight's own), the positions
the flight's own; on BAOAB's O step at the half step; on splitting's noise, at the step's end, with the closing kick
applied (``velocity_leg``). Its crossings are located on those states (``locate_view``), and the fast step reads it
at the same points. The opening sub-step and the closing kick move no such reading. Only where a guard depends on a
velocity does the source contain that code (:data:`_LOCATED_EVENTS`): the kernels of models whose guards are of the
positions and time only are those they were, to the byte.
A root is bracketed by the sign change and found by the Illinois (modified regula falsi) method to a relative
tolerance of 1e-13 of the step, at most 100 iterations. Several events in one step are handled in time order, at
most ``MAX_EVENTS`` of them; the excess is counted and reported.

Speed: paths run in 8 interleaved lanes, and each step runs first as generated straight-line code on scalars (the
mode's drift, only the nonzero noise entries, the guards at the end of the flight). Only a step at whose end a
guard may have fired (a direction +1 guard not below 0, or any sign change of a direction 0 guard) goes through the
general event loop ``event_step``, and that after the lane loop, so that the loop holds no call (a call's arguments
stay live across the loop and push its numbers out of the registers). The statistics, and the joint histogram,
run in lane loops of their own; one NaN test covers all observables of a sample; expressions of the parameters and
the step are bound once before the loops. On Example 1 (``benchmarks/mc_throughput.py``, section 4) the kernel
runs splitting at 1.18 and the explicit milstein at 0.95 of the oscillator kernel's throughput (that kernel has
since been removed; 0.47 and 0.25 before these measures), and the oscillator front end at 0.98 (``symplectic``,
with or without the joint histogram) and 1.11 (``baoab``, the oscillator's splitting).
The figures move by a few per cent with changes that add live numbers to ``run_chunk``: measure, do not guess.
"""

from __future__ import annotations

import hashlib
import textwrap
from dataclasses import dataclass

import sympy as sp

from hybrid.automaton import real_symbol
from hybrid.errors import ModelError

from ._kernel_modules import _Printer

TEMPLATE_VERSION = "8"
SCHEME_CODES = {"em": 0, "milstein": 1, "splitting": 2, "symplectic": 3, "baoab": 4, "naive": 5}
"""The generated module's ``SCHEME``: Euler-Maruyama, Milstein (commutative noise), splitting (kick, free flight,
noise, kick), symplectic Milstein (the velocities' Milstein step, then the positions' free flight), BAOAB (kick by
the force, half flight, exact Ornstein-Uhlenbeck step of the velocities, half flight, kick), naive (the velocities'
Euler-Maruyama step, then the positions' flight; at a crossing the reset is applied where the flight meets the guard
and the rest of the step is dropped: the event time is wrong by up to a step, the anti-pattern kept for charts)."""
MAX_EVENTS = 64
"""Events handled within one time step; more are counted as ``event_overflow`` (chattering or Zeno)."""
TIME = real_symbol("t")


@dataclass(frozen=True)
class AutomatonStructure:
    """What the generator derived from an automaton: Itô drift, noise matrix, positions and velocities.

    Attributes
    ----------
    states : tuple of str
    params : tuple of str
    modes : tuple of str
    drift : tuple of tuple of sympy expressions
        Itô drift per mode (Wong-Zakai corrected when the noise is Stratonovich).
    noise : tuple of sympy Matrix
        n x m noise matrix per mode (independent standard white noises).
    transitions : tuple
        The automaton's transitions, sorted by (source mode, priority).
    pairs : tuple of (int, int)
        (position index, velocity index) pairs with d position / dt = velocity in every mode.
    """

    states: tuple
    params: tuple
    modes: tuple
    drift: tuple
    noise: tuple
    transitions: tuple
    pairs: tuple
    n_noise: int


def noise_matrix(mode, n: int) -> sp.ImmutableMatrix:
    """The n x m noise matrix of ``mode``: its ``noise`` as a column (one noise) or as rows of m entries (immutable:
    the structure that holds it is shared by the memoised sources of :func:`generate_source`)."""
    if mode.noise is None:
        return sp.ImmutableMatrix(sp.zeros(n, 1))
    rows = [list(r) if isinstance(r, (tuple, list)) else [r] for r in mode.noise]
    widths = {len(r) for r in rows}
    if len(rows) != n or len(widths) != 1:
        raise ModelError(f"mode {mode.name!r}: the noise must be {n} rows of equally many entries (one per noise)")
    return sp.ImmutableMatrix(rows)


def analyse(automaton, convention: str = "stratonovich") -> AutomatonStructure:
    """Derive the Itô drift and the structure the schemes need.

    Parameters
    ----------
    automaton : HybridAutomaton
    convention : {'stratonovich', 'ito'}
        How the noise in the modes is meant. Physical white noise is the Stratonovich limit; its Itô drift gains
        the Wong-Zakai term 1/2 sum_k sum_j G_jk dG_ik/dx_j.

    Examples
    --------
    >>> import sympy as sp
    >>> from hybrid import HybridAutomaton, Mode
    >>> x, v = sp.symbols("x v")
    >>> A = HybridAutomaton((x, v), {"c": 0.1, "s": 0.3}, [Mode("m", (v, -x - sp.Symbol("c") * v), (0, "s*x"))])
    >>> analyse(A).pairs
    ((0, 1),)
    """
    if convention not in ("stratonovich", "ito"):
        raise ModelError(f"convention={convention!r}: use 'stratonovich' (physical white noise) or 'ito'")
    xs = automaton.states
    n = len(xs)
    drifts, noises, widths = [], [], set()
    for mode in automaton.modes:
        G = noise_matrix(mode, n)
        widths.add(G.shape[1])
        f = [sp.sympify(e) for e in mode.flow]
        if convention == "stratonovich":
            f = [f[i] + sp.Rational(1, 2) * sum(G[j, k] * sp.diff(G[i, k], xs[j])
                                                for k in range(G.shape[1]) for j in range(n)) for i in range(n)]
        drifts.append(tuple(sp.expand(e) for e in f))
        noises.append(G)
    if len(widths) != 1:
        raise ModelError(f"every mode must have the same number of noises, got {sorted(widths)}")
    m = widths.pop()
    pairs = []
    for i in range(n):
        flows = {sp.sympify(mode.flow[i]) for mode in automaton.modes}
        if len(flows) == 1:
            (fq,) = flows
            if fq in xs and all(noises[k][i, :].is_zero_matrix for k in range(len(noises))):
                pairs.append((i, xs.index(fq)))
    order = {mode.name: k for k, mode in enumerate(automaton.modes)}
    trans = tuple(sorted(automaton.transitions, key=lambda t: (order[t.source], t.priority)))
    return AutomatonStructure(
        states=tuple(s.name for s in xs), params=tuple(automaton.parameters), modes=tuple(order),
        drift=tuple(drifts), noise=tuple(noises), transitions=trans, pairs=tuple(pairs), n_noise=m,
    )


class _Names:
    """sympy symbols -> code names: states x[i], parameters p[j], time t."""

    def __init__(self, st: AutomatonStructure):
        self.subs = {real_symbol(s): sp.Symbol(f"_x{i}") for i, s in enumerate(st.states)}
        self.subs.update({real_symbol(s): sp.Symbol(f"_p{j}") for j, s in enumerate(st.params)})
        self.subs[TIME] = sp.Symbol("t")
        self.printer = _Printer({"standard": "python3"})
        self.n, self.np = len(st.states), len(st.params)
        # loop invariants of run_chunk: the parameters and the step; their expressions are bound once, before the
        # loops (LLVM does not hoist them itself where that would reorder floating-point operations)
        self.invariant = {sp.Symbol(f"_p{j}") for j in range(self.np)} | {sp.Symbol(n) for n in ("dt", "sdt", "hdt")}
        self.hoisted: dict = {}
        self.preamble: list = []  # code run once before the loops (before the hoisted names: they may use it)
        self.preamble_names: list = []  # the names the preamble binds for the loops

    def hoist(self, e):
        """``e`` (in code names) with each largest sub-expression of the loop invariants replaced by a name
        ``_invK`` bound in :meth:`hoisted_lines`; in sums and products the invariant terms or factors are grouped.
        Nothing inside a Piecewise that depends on the state is bound: its branches are evaluated only when taken
        (a parameter-only division in a branch not taken must not run before the loops)."""
        if e.is_Atom:
            return e
        if isinstance(e, sp.Expr) and e.free_symbols <= self.invariant:
            return self._bind(e)
        if isinstance(e, (sp.Add, sp.Mul)):
            fixed = [a for a in e.args if a.free_symbols <= self.invariant]
            rest = [self.hoist(a) for a in e.args if not a.free_symbols <= self.invariant]
            if len(fixed) > 1 or (fixed and not fixed[0].is_Atom):
                fixed = [self._bind(e.func(*fixed))]
            return e.func(*fixed, *rest)
        if isinstance(e, sp.Piecewise):
            return e
        return e.func(*[self.hoist(a) for a in e.args])

    def _bind(self, e):
        if e not in self.hoisted:
            self.hoisted[e] = sp.Symbol(f"_inv{len(self.hoisted)}")  # a prefix no other generated name uses
        return self.hoisted[e]

    def param_lines(self) -> list[str]:
        """``_pj = p[j]``: the parameters as the kernels' scalars."""
        return [f"_p{j} = p[{j}]" for j in range(self.np)]

    def hoisted_lines(self) -> list[str]:
        return self.preamble + [f"{name} = {self.printer.doprint(e)}" for e, name in self.hoisted.items()]

    def hoisted_names(self) -> list[str]:
        """The names :meth:`hoisted_lines` binds for the loops (the preamble's temporaries left out)."""
        return self.preamble_names + [str(name) for name in self.hoisted.values()]

    def hoisted_texts(self) -> list[str]:
        """Each of :meth:`hoisted_names` as a reader knows it: the expression in the model's own names."""
        back = {code: real for real, code in self.subs.items()}
        return ([f"the exact OU factor {name}" for name in self.preamble_names]
                + [f"{name} = {sp.sstr(e.xreplace(back))}" for e, name in self.hoisted.items()])

    def hoisted_function(self) -> str:
        """A plain Python function ``hoisted_values(p, dt)`` of the module: the values of :meth:`hoisted_names`,
        evaluated once on the host (the CUDA kernel takes them as launch arguments, in its constant bank)."""
        names = self.hoisted_names()
        body = (["sdt = math.sqrt(dt)", "hdt = 0.5 * dt"] + self.param_lines() + self.hoisted_lines()
                + [f"return ({''.join(n + ', ' for n in names)})"])
        return "def hoisted_values(p, dt):\n" + textwrap.indent("\n".join(body), "    ") + "\n"

    def ou_factors(self, lines: list, tag: str, c) -> None:
        """Code for ``_oa{tag}`` = exp(-c dt) and ``_oc{tag}`` = sqrt((1 - exp(-2 c dt)) / (2 c dt)), the exact
        Ornstein-Uhlenbeck step y -> _oa y + _oc (G dW) with damping rate ``c`` (in code names; c dt -> 0 safe).
        Once before the loops where ``c`` is a loop invariant, else appended to ``lines``."""
        code = [f"_kd = ({self.printer.doprint(c)}) * dt",
                "if abs(_kd) < 1e-12:",
                f"    _oa{tag} = 1.0 - _kd",
                f"    _oc{tag} = 1.0",
                "else:",
                f"    _oa{tag} = math.exp(-_kd)",
                f"    _oc{tag} = math.sqrt(-math.expm1(-2.0 * _kd) / (2.0 * _kd))"]
        if c.free_symbols <= self.invariant:
            self.preamble.extend(code)
            self.preamble_names += [f"_oa{tag}", f"_oc{tag}"]
            self.invariant |= {sp.Symbol(f"_oa{tag}"), sp.Symbol(f"_oc{tag}")}
        else:
            lines.extend(code)

    def unpack(self) -> list[str]:
        return [f"_x{i} = x[{i}]" for i in range(self.n)] + self.param_lines()

    def scalar_block(self, target: str, outputs: list, extra: dict) -> str:
        """Straight-line code ``{target}0 = ...`` (scalars) of ``outputs`` on the kernel's scalars ``_x0, ...``."""
        exprs = [self.hoist(sp.sympify(e).xreplace(self.subs).xreplace(extra)) for e in outputs]
        reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_o"))
        body = [f"{s} = {self.printer.doprint(e)}" for s, e in reps]
        body += [f"{target}{i} = float({self.printer.doprint(e)})" for i, e in enumerate(reduced)]
        return "\n".join(body)

    def function(self, name: str, outputs: list, target: str | None) -> str:
        """An inline numba function ``name(x, t, p[, out])`` computing ``outputs`` (common sub-expressions once)."""
        exprs = [sp.sympify(e).xreplace(self.subs) for e in outputs]
        reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_c"))
        body = self.unpack()
        body += [f"{s} = {self.printer.doprint(e)}" for s, e in reps]
        if target is None:
            body.append(f"return {self.printer.doprint(reduced[0])}")
            sig = f"def {name}(x, t, p):"
        else:
            body += [f"{target}[{i}] = {self.printer.doprint(e)}" for i, e in enumerate(reduced)]
            sig = f"def {name}(x, t, p, {target}):"
        return "@nb.njit(**INNER)\n" + sig + "\n" + textwrap.indent("\n".join(body), "    ") + "\n"


    def model(self, kinds: list) -> str:
        """One numba function ``model(_kind, _which, x, t, p, out)`` for all the model's functions: ``kinds`` holds
        ``(name, cases, writes)`` per kind (``F_<name>`` selects it), whose branch ``k`` computes ``cases[k]`` (a list
        of expressions; common sub-expressions once per branch) into ``out`` (``writes``) or as the return value
        (a check returns 1.0 or 0.0). One function, not one per kind: numba compiles each function on its own,
        at 0.1 - 0.3 s apiece, however small (measured in docs/results/compile-time.md)."""
        lines = self.unpack()
        for kk, (kind, cases, writes) in enumerate(kinds):
            branch = []
            for k, outputs in enumerate(cases):
                exprs = [sp.sympify(e).xreplace(self.subs) for e in outputs]
                reps, reduced = sp.cse(exprs, symbols=sp.numbered_symbols(f"_c{kk}_{k}_"))
                body = [f"{s} = {self.printer.doprint(e)}" for s, e in reps]
                if not writes:
                    e = self.printer.doprint(reduced[0])
                    body.append(f"return 1.0 if {e} else 0.0" if kind == "CHECK" else f"return {e}")
                else:
                    body += [f"out[{i}] = {self.printer.doprint(e)}" for i, e in enumerate(reduced)]
                branch.append(f"{'if' if k == 0 else 'elif'} _which == {k}:")
                branch.append(textwrap.indent("\n".join(body) or "pass", "    "))
            if kind == "CHECK":
                branch.append("return 1.0")
            lines.append(f"{'if' if kk == 0 else 'elif'} _kind == F_{kind}:")
            lines.append(textwrap.indent("\n".join(branch) or "pass", "    "))
        lines.append("return 0.0")
        return ("@nb.njit(**INNER)\ndef model(_kind, _which, x, t, p, out):\n"
                + textwrap.indent("\n".join(lines), "    ") + "\n")


def ou_parts(st: AutomatonStructure, k: int) -> list:
    """BAOAB's pieces of mode ``k``: ``(v, F, c)`` per velocity state v, with drift_v = F(q, t) - c(q, t) v.

    Raises :class:`ModelError` where the mode's velocity drift is not of that form (damping that is nonlinear in
    the velocity, or couples velocities) or its noise depends on a velocity: BAOAB's O step would not be exact.
    """
    xs = [real_symbol(s) for s in st.states]
    vel = sorted({v for _, v in st.pairs})
    parts = []
    for v in vel:
        f = st.drift[k][v]
        others = [xs[u] for u in vel if u != v and sp.diff(f, xs[u]) != 0]
        if others or sp.simplify(sp.diff(f, xs[v], 2)) != 0:
            raise ModelError(
                f"scheme 'baoab' needs each velocity's drift to be F(positions, t) - c(positions, t) * itself; "
                f"d{st.states[v]}/dt = {f} in mode {st.modes[k]!r} is not: use scheme='symplectic' or 'splitting'")
        if any(sp.diff(st.noise[k][v, j], xs[u]) != 0 for j in range(st.n_noise) for u in vel):
            raise ModelError(
                f"scheme 'baoab' needs noise that does not depend on the velocities (mode {st.modes[k]!r}): use "
                "scheme='symplectic'")
        parts.append((v, sp.expand(f.subs(xs[v], 0)), sp.expand(-sp.diff(f, xs[v]))))
    return parts


def velocity_guards(st: AutomatonStructure) -> list:
    """Per transition of ``st``: whether its guard depends on a velocity (a state that is some position's rate).

    The splitting schemes change the velocities in sub-steps of their own, at a fixed position and instant; only
    these guards can cross zero there.

    Examples
    --------
    >>> import sympy as sp
    >>> from hybrid import HybridAutomaton, Mode, Transition
    >>> x, v = sp.symbols("x v")
    >>> wall = Transition("wall", "m", "m", x - 1, 1, (x, -v))
    >>> level = Transition("level", "m", "m", x**2 + v**2 - 1, 1, (x, v))
    >>> A = HybridAutomaton((x, v), {}, [Mode("m", (v, -x))], [wall, level])
    >>> velocity_guards(analyse(A))
    [False, True]
    """
    velocities = {real_symbol(st.states[v]) for _, v in st.pairs}
    return [bool(sp.sympify(tr.guard).free_symbols & velocities) for tr in st.transitions]


def _lg(G, xs, i: int, j: int, k: int):
    """L^j G_ik = sum_l G_lj dG_ik/dx_l, the Milstein coefficient of w_j w_k in the increment of state i."""
    return sum(G[l, j] * sp.diff(G[i, k], xs[l]) for l in range(len(xs)))


def _fast_step(st: AutomatonStructure, names: _Names, k: int, scheme: str, parts: list, moved: list) -> str:
    """Straight-line code of one step in mode ``k`` on the scalars ``_x0, _x1, ...`` when no guard may fire.

    ``parts``: BAOAB's ``(v, F, c)`` of the mode (:func:`ou_parts`; empty for the other schemes). ``moved``: per
    transition, whether the scheme's velocity sub-steps can move its guard (:func:`velocity_guards`).

    It computes the end of the step's flight into ``_y*`` and tests the guards leaving the mode there: a
    direction +1 guard still below 0 (-1: above 0) cannot have fired, so the step is committed here with the
    state in registers; otherwise ``_slow`` is set, nothing is committed, and the kernel runs the step again
    through the general event loop, which locates and handles every crossing. Only the nonzero noise entries
    appear, so a noise on one coordinate costs one multiply-add.
    """
    n, m = len(st.states), st.n_noise
    xs = [real_symbol(s) for s in st.states]
    dt, t1 = sp.Symbol("dt"), sp.Symbol("_t1")
    w = [sp.Symbol(f"_w{j}") for j in range(m)]
    ys = [sp.Symbol(f"_y{i}") for i in range(n)]
    f, G = st.drift[k], st.noise[k]
    pre = f"_f{k}_"

    def block(out, targets, exprs, tag, extra=None):
        """Append to ``out`` the assignments ``targets = exprs`` (common sub-expressions once)."""
        exprs = [sp.sympify(e).xreplace(names.subs) for e in exprs]
        if extra:
            exprs = [e.xreplace(extra) for e in exprs]
        exprs = [names.hoist(e) for e in exprs]
        reps, red = sp.cse(exprs, symbols=sp.numbered_symbols(pre + tag))
        out.extend(f"{s_} = {names.printer.doprint(e)}" for s_, e in reps)
        out.extend(f"{tg} = {names.printer.doprint(e)}" for tg, e in zip(targets, red))

    def increment(i, milstein):
        """The Ito increment of state i over the step: drift, noise and, for Milstein, 1/2 L^j G_ik (w_j w_k - dt)."""
        e = f[i] * dt + sum(G[i, j] * w[j] for j in range(m) if G[i, j] != 0)
        if milstein:
            for j in range(m):
                for kk in range(m):
                    lg = _lg(G, xs, i, j, kk)
                    if lg != 0:
                        e += sp.Rational(1, 2) * lg * (w[j] * w[kk] - (dt if j == kk else 0))
        return e

    lines, commit = [], [f"_x{i} = _y{i}" for i in range(n)]
    code_t1 = {sp.Symbol("t"): t1}
    to_y = {sp.Symbol(f"_x{i}"): ys[i] for i in range(n)}
    vel = sorted({v for _, v in st.pairs})
    leaving = [j for j, tr in enumerate(st.transitions) if tr.source == st.modes[k]]
    # guards of the velocities are read on states whose positions and velocities belong to one instant, as in the
    # event loop: at the end of the flight with the closing kick applied (splitting: without the noise), after
    # BAOAB's O step at the half step, and at the step's end; the sub-steps after the flight then run before the
    # test instead of after the commit
    moving = [j for j in leaving if moved[j]]
    before = {j: [] for j in leaving}  # the names of a guard's values before the end of the flight, in order
    later = {j: [] for j in leaving}  # and after it
    post = []  # the code of the sub-steps after the flight, when a guard of the velocities must see them

    def read(out, tag, which, extra, into):
        """Append to ``out`` the guard values ``_{tag}{j}`` of the transitions ``which``, recorded in ``into``."""
        for j in which:
            block(out, [f"_{tag}{j}"], [st.transitions[j].guard], f"{tag}{j}_", extra)
            into[j].append(f"_{tag}{j}")

    def closing(targets, exprs, name, tag, last=True):
        """A sub-step ``_y += exprs`` (into ``_{name}*``) at the end of the step: after the commit, or before the
        test (``post``), the ``last`` one followed by a reading ``_g{name}*`` of the guards of the velocities."""
        if moving:
            block(post, [f"_{name}{i}" for i in targets], exprs, tag, {**to_y, **code_t1})
            post.extend(f"_y{i} = _y{i} + _{name}{i}" for i in targets)
            if last:
                read(post, f"g{name}", moving, {**to_y, **code_t1}, later)
        else:
            block(commit, [f"_{name}{i}" for i in targets], exprs, tag, code_t1)
            commit.extend(f"_x{i} += _{name}{i}" for i in targets)

    if scheme == "baoab":
        hdt, tm = sp.Symbol("hdt"), sp.Symbol("_tm")
        code_tm = {sp.Symbol("t"): tm}
        lines.append("_tm = t + hdt")
        block(lines, [f"_y{v}" for v, _, _ in parts], [xs[v] + hdt * F for v, F, _ in parts], "a")
        lines.extend(f"_y{q} = _x{q} + hdt * _y{v}" for q, v in st.pairs)
        read(lines, "m", leaving, {**to_y, **code_tm}, before)  # the guards at the half step, g(mid)
        for v, _, c in parts:  # O: exact OU step of each velocity at the half step's positions
            names.ou_factors(lines, f"{k}_{v}", sp.sympify(c).xreplace(names.subs).xreplace({**to_y, **code_tm}))
            noise_v = sum(G[v, j] * w[j] for j in range(m) if G[v, j] != 0)
            block(lines, [f"_y{v}"], [sp.Symbol(f"_oa{k}_{v}") * ys[v] + sp.Symbol(f"_oc{k}_{v}") * noise_v], "o",
                  {**to_y, **code_tm})
        read(lines, "go", moving, {**to_y, **code_tm}, before)
        lines.extend(f"_y{q} = _y{q} + hdt * _y{v}" for q, v in st.pairs)
        # the closing kick (it moves no position, so no guard of the positions)
        closing([v for v, _, _ in parts], [hdt * F for _, F, _ in parts], "k", "b")
    elif scheme in ("em", "milstein"):
        block(lines, [f"_y{i}" for i in range(n)], [xs[i] + increment(i, scheme == "milstein") for i in range(n)],
              "a")
    else:
        if scheme in ("symplectic", "naive"):  # velocities by a Milstein (naive: Euler-Maruyama) step, then the
            # positions' flight at the new ones
            block(lines, [f"_y{i}" for i in vel], [xs[i] + increment(i, scheme == "symplectic") for i in vel], "a")
        else:  # splitting: kick, free flight (positions only, at the kicked velocities), noise, kick
            block(lines, [f"_y{i}" for i in vel], [xs[i] + dt / 2 * f[i] for i in vel], "a")
            # the noise and the closing kick at the end of the step (as in the event loop)
            noisy = [i for i in range(n) if any(G[i, j] != 0 for j in range(m))]
            closing(noisy, [sum(G[i, j] * w[j] for j in range(m) if G[i, j] != 0) for i in noisy], "n", "n",
                    last=False)
            closing(vel, [dt / 2 * f[i] for i in vel], "k", "b")
        lines.extend(f"_y{q} = _x{q} + dt * _y{v}" for q, v in st.pairs)
    # a guard of the velocities at the end of the flight: splitting's state there with the closing kick applied
    # (its velocities are those of the middle of the step); BAOAB's is read after its closing kick only
    to_u = dict(to_y)
    if moving and scheme == "splitting":
        block(lines, [f"_u{v}" for v in vel], [xs[v] + dt / 2 * f[v] for v in vel], "u", {**to_y, **code_t1})
        to_u.update({sp.Symbol(f"_x{v}"): sp.Symbol(f"_u{v}") for v in vel})
    quiet = ["not track"]  # the conditions under which no guard can have fired in the step
    for j in leaving:
        if moved[j] and scheme == "baoab":
            values = before[j] + later[j]
        else:
            block(lines, [f"_g{j}"], [st.transitions[j].guard], f"g{j}_", {**to_u, **code_t1})
            values = before[j] + [f"_g{j}"] + later[j]  # a guard's values after each sub-step that moves it
        d = int(st.transitions[j].direction)
        if d > 0:
            quiet.extend(f"{g} < 0.0" for g in values)
        elif d < 0:
            quiet.extend(f"{g} > 0.0" for g in values)
        else:
            block(lines, [f"_h{j}"], [st.transitions[j].guard], f"h{j}_")
            chain = [f"_h{j}"] + values
            quiet.append(" and ".join(f"not crosses(0, {g0}, {g1})" for g0, g1 in zip(chain, chain[1:])))
    lines.extend(post)
    # one combined test: a single well-predicted branch in the hot loop
    lines.append(f"if {' and '.join(quiet)}:")
    lines.extend("    " + c for c in commit)
    lines.append("else:")
    lines.append("    _slow = True")
    return "\n".join(lines)


_SOURCES: dict = {}
"""Memo of :func:`generate_source`: the key of its inputs (:func:`_source_key`) -> (source, structure)."""


def _source_key(automaton, scheme, observables, convention, cache, summed, phases, joint_only) -> str | None:
    """Every input of the generated CPU source, as text with the floats in full precision (``srepr``): the states with
    their assumptions, the parameters' names in order (their values are runtime arguments of the kernel), the modes
    and the transitions (None where a reset is a Python callable, which the generator refuses)."""
    if any(not tr.symbolic_reset for tr in automaton.transitions):
        return None
    declared = (tuple(automaton.states), tuple(automaton.parameters),
                tuple((m.name, m.flow, m.noise) for m in automaton.modes),
                tuple((t.name, t.source, t.target, t.guard, t.direction, t.reset, t.priority, t.check)
                      for t in automaton.transitions),
                tuple((str(k), sp.sympify(v)) for k, v in observables.items()))
    return repr((sp.srepr(declared), scheme, convention, cache, summed, phases, joint_only))


def generate_source(automaton, scheme: str, observables: dict, convention: str = "stratonovich",
                    cache: bool = True, summed=(), phases: bool = False,
                    joint_only=(), template: str | None = None, fields: dict | None = None
                    ) -> tuple[str, AutomatonStructure]:
    """The numba module source of ``scheme`` for ``automaton`` and the structure it was derived from.

    Memoised on every input of the CPU source (:func:`_source_key`): the sympy work costs 0.05-0.4 s, as much as a
    short run, and a parameter sweep or a study calls it again with the same structure (the parameters' values are
    runtime arguments). The CUDA target's calls (``template``, ``fields``) are not memoised.

    ``observables`` maps names to sympy expressions of the states, parameters and ``t``; those named in
    ``summed`` are only summed (means and the joint histogram), not histogrammed; those named in ``joint_only``
    only feed the joint histogram (no sum, no histogram of their own: both stay zero). Phase sections are compiled in
    only with ``phases=True`` (they cost about 10 % of the compile time).

    ``template`` replaces the CPU module's text (``_TEMPLATE``) by another built from the same pieces and filled with
    the same fields, plus ``fields`` of its own: the CUDA target (:mod:`hybrid.stochastic._auto_cuda`) takes the
    model's functions, the event code and the fast step from here.
    """
    # one spelling of each option, for the key and the generator alike (the generator tests ``name in summed``)
    summed, joint_only = tuple(summed), tuple(joint_only)
    cache, phases = bool(cache), bool(phases)
    key = (_source_key(automaton, scheme, observables, convention, cache, summed, phases, joint_only)
           if template is None and fields is None else None)
    hit = _SOURCES.get(key) if key is not None else None  # get(): another thread may clear the memo meanwhile
    if hit is not None:
        return hit
    out = _generate_source(automaton, scheme, observables, convention, cache, summed, phases, joint_only, template,
                           fields)
    if key is not None:
        if len(_SOURCES) >= 256:  # bounded: a study of many structures starts the memo again
            _SOURCES.clear()
        _SOURCES[key] = out
    return out


def _generate_source(automaton, scheme, observables, convention, cache, summed, phases, joint_only, template,
                     fields) -> tuple[str, AutomatonStructure]:
    st = analyse(automaton, convention)
    names = _Names(st)
    n, m = len(st.states), st.n_noise
    xs = [real_symbol(s) for s in st.states]
    lgns = []
    for G in st.noise:
        # L^j G_ik = sum_l G_lj dG_ik/dx_l, stored as [i, j, k] (row-major n x m x m)
        lgns.append([_lg(G, xs, i, j, kk) for i in range(n) for j in range(m) for kk in range(m)]
                    if scheme in ("milstein", "symplectic") else [])
    rates = []
    for tr in st.transitions:
        if not tr.symbolic_reset:
            raise ModelError(
                f"transition {tr.name!r}: the Monte Carlo kernel needs a symbolic reset (a tuple of expressions); "
                "callable resets run in the orbit backends only"
            )
        # rate of change of the guard along the drift: the impact speed for a wall guard x - w
        src_mode = st.modes.index(tr.source)
        rates.append(sum(sp.diff(tr.guard, xs[i]) * st.drift[src_mode][i] for i in range(n))
                     + sp.diff(tr.guard, TIME))
    # BAOAB's force and damping rate per velocity
    parts = [ou_parts(st, k) if scheme == "baoab" else [] for k in range(len(st.modes))]
    kinds = [("DRIFT", [list(f) for f in st.drift], True),
             ("NOISE", [list(G) for G in st.noise], True)]  # row-major n x m
    if scheme in ("milstein", "symplectic"):  # only the kinds the scheme's code calls
        kinds.append(("LGN", lgns, True))
    trs = st.transitions
    kinds += [("GUARD", [[tr.guard] for tr in trs], False),
              ("RESET", [list(tr.reset) for tr in trs], True),
              ("GRATE", [[r] for r in rates], False),
              ("CHECK", [[tr.check if tr.check is not None else sp.true] for tr in trs], False)]
    if scheme == "baoab":
        force, damping = [], []
        for k in range(len(st.modes)):
            fk, ck = [sp.Integer(0)] * n, [sp.Integer(0)] * n
            for v, F, c in parts[k]:
                fk[v], ck[v] = F, c
            force.append(fk)
            damping.append(ck)
        kinds += [("BFORCE", force, True), ("ODAMP", damping, True)]
    funcs = [names.model(kinds)]
    obs = list(observables.values())
    funcs.append(names.function("_observe", obs if obs else [sp.Integer(0)], "out"))
    # the splitting schemes move the velocities in sub-steps of their own (kicks, noise, BAOAB's O step) at a fixed
    # position and instant: a guard that depends on a velocity is located in those too (only there does the
    # source differ from that of a model whose guards are of the positions and time only)
    moved = velocity_guards(st) if scheme in ("splitting", "symplectic", "baoab") else [False] * len(trs)
    located = any(moved)
    if located:
        funcs.append(_VELOCITY_LEG.format(vguards=tuple(int(v) for v in moved),
                                          fire=textwrap.indent(_FIRE.format(when="t"), " " * 8)))
    # per mode: the transitions leaving it (indices into st.transitions), in priority order
    leaving = [[j for j, tr in enumerate(st.transitions) if tr.source == mode] for mode in st.modes]
    first = [min(ix) if ix else 0 for ix in leaving]
    count = [len(ix) for ix in leaving]
    targets = [st.modes.index(tr.target) for tr in st.transitions]
    directions = [int(tr.direction) for tr in st.transitions]
    self_loops = [int(tr.source == tr.target) for tr in st.transitions]
    positions = [q for q, _ in st.pairs]
    velocity_of = {q: v for q, v in st.pairs}
    fast = []
    for k in range(len(st.modes)):
        fast.append(f"{'if' if k == 0 else 'elif'} mode == {k}:")
        fast.append(textwrap.indent(_fast_step(st, names, k, scheme, parts[k], moved), "    "))
    # the fast step's guard tests settle the admissible-set check of a sample, unless the splitting's noise and
    # kick, or BAOAB's closing kick, after the flight move a guard that depends on velocities
    fast_checks_set = scheme not in ("splitting", "baoab") or not located
    ind = textwrap.indent
    observe = names.scalar_block("_ob", obs if obs else [sp.Integer(0)], {sp.Symbol("t"): sp.Symbol("_t1")})
    step = dict(  # the pieces of _LANE_STEP
        load=ind("\n".join([f"_x{i} = _L{i}[_l]" for i in range(n)]
                            + ["mode = ML[_l]" if len(st.modes) > 1 else "mode = 0"]), " " * 16),
        draw=ind("\n".join(f"z, s0, s1, s2, s3 = next_normal(s0, s1, s2, s3, zx, zk, zf)\nDWL[{k}, _l] = sdt * z"
                           for k in range(m)), " " * 16),
        read_dw=ind("\n".join(f"_w{k} = DWL[{k}, _l]" for k in range(m)) + "\n_slow = False", " " * 16),
        fast=ind("\n".join(fast), " " * 16),
        lane_to_x=ind("\n".join(f"x[{i}] = _L{i}[_l]" for i in range(n)), " " * 16),
        load_dw=ind("\n".join(f"dw[{k}] = DWL[{k}, _l]" for k in range(m)), " " * 16),
        reload=ind("\n".join(f"_L{i}[_l] = x[{i}]" for i in range(n)), " " * 16),
        store=ind("\n".join(f"_L{i}[_l] = _x{i}" for i in range(n)), " " * 16),
    )
    template = _TEMPLATE if template is None else template
    to_array = ind("\n".join(f"x[{i}] = _x{i}" for i in range(n)), " " * 20)  # the lane's registers into x
    ranges = [f"_lo{o} = obs_lo[{o}]\n_sc{o} = obs_scale[{o}]\n_nb{o} = obs_bins[{o}]\n_sum{o} = 0.0"
              for o in range(len(obs))]  # the observables' histogram ranges and sums as the kernels' scalars
    src = (_located(template) if located else template).format(
        **(fields or {}),
        unpack=ind("\n".join(names.param_lines() + names.hoisted_lines() + ranges) or "pass", " " * 4),
        binning=ind(_binning(list(observables), summed, joint_only), " " * 16),
        **_sample_statistics(list(observables), summed, joint_only, step["load"], ind(observe, " " * 16), to_array,
                             step["lane_to_x"]),
        to_ob=ind("\n".join(f"ob[{o}] = _ob{o}" for o in range(len(obs))) or "pass", " " * 20),
        flush=ind("\n".join(f"sums[{o}] += _sum{o}" for o in range(len(obs))) or "pass",
                  " " * 4),
        alloc=ind("\n".join(f"_L{i} = np.empty(LANES)" for i in range(n)), " " * 4),
        lane_rows=ind("\n".join(f"_L{i} = LW[{i}]" for i in range(n)), " " * 4),
        init=ind("\n".join(f"_L{i}[_l] = x0[{i}]" for i in range(n)), " " * 12),
        phase_block=ind(_PHASES.format(pack=ind("\n".join(f"XL[_l, {i}] = _L{i}[_l]" for i in range(n)), " " * 8))
                        if phases else "pass  # no phase sections in this kernel (generate_source(phases=True))",
                        " " * 12),
        **step,  # the lane step's pieces stay fields of the module template too
        to_array=to_array,
        observe=ind(observe, " " * 16),
        fast_checks_set=fast_checks_set,
        scheme_code=SCHEME_CODES[scheme], legs=2 if scheme == "baoab" else 1,
        version=TEMPLATE_VERSION, scheme=scheme, cache=cache, n=n, m=m, n_obs=max(len(obs), 1),
        n_trans=len(st.transitions), max_events=MAX_EVENTS,
        funcs="\n\n".join(funcs),
        lane_step=_LANE_STEP.format(**step),
        # the CUDA kernel's unpacking: the loop invariants come evaluated, as the launch argument hv, and the bin
        # counts also in the kernel's float type (_to_device compares the bin coordinates with those)
        unpack_args=ind("\n".join(names.param_lines()
                                  + [f"{name} = hv[{k}]" for k, name in enumerate(names.hoisted_names())] + ranges
                                  + [f"_nbf{o} = _fty(_nb{o})" for o in range(len(obs))]) or "pass", " " * 4),
        hoisted_function=names.hoisted_function(), hoisted_names=tuple(names.hoisted_names()),
        hoisted_texts=tuple(names.hoisted_texts()),
        unpack_step=ind("\n".join(names.param_lines() + names.hoisted_lines())
                        or "pass", " " * 4),
        lane_to_out=ind("\n".join(f"out[_g + _l, (step + 1) // every, {i}] = _L{i}[_l]" for i in range(n)),
                        " " * 20),
        # where a guard depends on a velocity the opening sub-step is the plain one too: no guard is read on its
        # state, whose velocities are of another instant than its positions (the flight reads the guard from the
        # velocities at the step's start)
        opening=ind(_NAIVE_OPENING if scheme == "naive" else _PLAIN_OPENING,
                    " " * 4),
        fire=ind(_FIRE.format(when="t + best_s * tau") + (_NAIVE_DROP if scheme == "naive" else ""), " " * 12),
        o_step=ind(_LOCATED_O_STEP if located else _PLAIN_O_STEP, " " * 12),
        closing=ind(_LOCATED_CLOSING if located else _PLAIN_CLOSING, " " * 4),
        first=tuple(first) + (0,), count=tuple(count) + (0,), targets=tuple(targets) + (0,),
        directions=tuple(directions) + (0,), self_loops=tuple(self_loops) + (0,),
        positions=tuple(positions) + (0,), n_pos=len(positions),
        velocities=tuple(velocity_of[q] for q in positions) + (0,),
    )
    return src, st


# the phase sections of a step (out of line: inside the kernel's loop they slowed the time average by about 10 %)
_PHASES = """\
if phase_now:
    for _l in range(nl):
{pack}
    record_phase(((step + 1) // phase_steps) % n_phase, XL, nl, _t1, p, x, ob, obs_lo, obs_scale, obs_bins,
                 phist, psums, pcount)"""


def _sample_statistics(names: list, summed, joint_only, load: str, observe: str, to_array: str, lane_to_x: str
                       ) -> dict:
    """The CPU kernel's statistics of a sample: the fields ``sample_statistics`` (from the lanes' observables to the
    admissible-set check; each lane's observables end in ``OL`` for the joint histogram) and ``lane_totals`` (once
    per chunk, the lanes' own sums and NaN counts into the chunk's).

    Where an observable is only summed (the oscillator front end's x**2, y**2, ...), the lanes' observables, bin
    coordinates, sums and NaN counts go into per-lane arrays (``BL``, ``SM``, ``NL``) in a loop of conditional
    expressions only (no ``if``), which runs on vectors of lanes, and the histograms' increments follow in a loop of
    their own: Example 1 ran 1.17-1.19x faster. Each lane's sums join the chunk's at its end, so they round
    differently from the other variant's. Where every observable has a histogram, one loop bins and sums each lane at
    once, as on the GPU (:func:`_binning`; the two loops ran 0.92x as fast on a forced model with one observable).
    Either way a NaN observable is counted, not summed or binned, and an infinite one falls in the underflow or
    overflow bin and is summed.
    """
    ind = textwrap.indent
    kept = [o for o, name in enumerate(names) if name not in joint_only]
    binned = [o for o in kept if names[o] not in summed]
    to_ol = [f"OL[{o}, _l] = _ob{o}" for o in range(len(names))]
    if len(binned) == len(kept):  # every kept observable has a histogram: one loop, sums in registers
        checks = SAMPLE_CHECKS.format(to_array=to_array,
                                      binning=ind(_binning(names, summed, joint_only, "np.uint64(_b) + BIN1"),
                                                  " " * 16),
                                      to_ob=ind("\n".join(to_ol) or "pass", " " * 20))
        return dict(sample_statistics="\n".join(["            for _l in range(nl):", load, observe,
                                                  "                _nsamp += 1", checks.rstrip("\n")]),
                    lane_arrays="", lane_totals="")
    lane = to_ol + [f"BL[{o}, _l] = (_ob{o} - _lo{o}) * _sc{o}" for o in binned]
    lane += [f"SM[{o}, _l] += _ob{o} if _ob{o} == _ob{o} else 0.0" for o in kept]
    lane.append("NL[0, _l] += " + " + ".join(f"(1.0 if _ob{o} != _ob{o} else 0.0)" for o in kept))
    scatter = []
    for o in binned:
        scatter += [f"_b = BL[{o}, _l]", f"if _b >= 0.0 and _b < _nb{o}:", f"    hist[{o}, np.uint64(_b) + BIN1] += 1",
                    "elif _b < 0.0:", f"    hist[{o}, 0] += 1", f"elif OL[{o}, _l] == OL[{o}, _l]:",
                    f"    hist[{o}, _nb{o} + 1] += 1"]
    load = "\n".join(line for line in load.split("\n") if "mode = " not in line)  # no observable reads the mode
    text = ["for _l in range(nl):", load, observe, ind("\n".join(lane), " " * 4), "_nsamp += nl"]
    text = [ind(t, " " * 12) if k in (0, 3, 4) else t for k, t in enumerate(text)]
    if scatter:
        text.append(ind("\n".join(["for _l in range(nl):"] + [ind(line, "    ") for line in scatter]), " " * 12))
    text += ["            if not FAST_CHECKS_SET:  # splitting's or baoab's kicks after the flight can move a guard",
             "                for _l in range(nl):", ind(textwrap.dedent(lane_to_x), " " * 20),
             "                    if outside(ML[_l], x, _t1, p):", "                        counts[2] += 1"]
    totals = ["for _l in range(LANES):  # the lanes' sums and NaN counts", "    counts[3] += np.int64(NL[0, _l])"]
    totals += [f"    _sum{o} += SM[{o}, _l]" for o in kept]
    arrays = ["BL = np.empty((N_OBS, LANES))", "SM = np.empty((N_OBS, LANES))", "NL = np.empty((1, LANES))",
              "for _l in range(LANES):", "    NL[0, _l] = 0.0", "    for o in range(N_OBS):", "        SM[o, _l] = 0.0"]
    return dict(sample_statistics="\n".join(text), lane_arrays=ind("\n".join(arrays), " " * 4),
                lane_totals=ind("\n".join(totals), " " * 4))


def _binning(names: list, summed, joint_only=(), index: str = "np.int64(_b) + 1") -> str:
    """A sample's statistics: sums in registers (written once per chunk), histograms with under/overflow bins.

    A NaN observable is counted, not summed or binned. One test settles it for all of them (the sum of the
    observables is NaN if any is, and a NaN from inf - inf only sends the sample the careful way), so a finite
    sample costs one well-predicted branch.
    """
    kept = [(o, name) for o, name in enumerate(names) if name not in joint_only]
    if not kept:
        return "pass"
    fast = [(_SUMMING_FINITE if name in summed else _BINNING_FINITE).format(o=o, index=index) for o, name in kept]
    slow = [(_SUMMING if name in summed else _BINNING).format(o=o, index=index) for o, name in kept]
    total = " + ".join(f"_ob{o}" for o, _ in kept)
    return "\n".join([f"_tot = {total}", "if _tot == _tot:", textwrap.indent("\n".join(fast), "    "), "else:",
                      textwrap.indent("\n".join(slow), "    ")])


# bins by np.int64(b), not int(b): numba compiles int() of a float as a function of its own (in every CPU kernel)
_BINNING_FINITE = """\
_b = (_ob{o} - _lo{o}) * _sc{o}
if _b >= 0.0 and _b < _nb{o}:
    hist[{o}, {index}] += 1
elif _b < 0.0:
    hist[{o}, 0] += 1
else:
    hist[{o}, _nb{o} + 1] += 1
_sum{o} += _ob{o}"""


_SUMMING_FINITE = "_sum{o} += _ob{o}"


# NaN fails every comparison, so it is tested for only where the value is not in a bin (it is counted, not summed)
_BINNING = """\
_v = _ob{o}
_b = (_v - _lo{o}) * _sc{o}
if _b >= 0.0 and _b < _nb{o}:
    hist[{o}, {index}] += 1
elif _b < 0.0:
    hist[{o}, 0] += 1
elif _v == _v:
    hist[{o}, _nb{o} + 1] += 1
else:
    counts[3] += 1
    _v = 0.0
_sum{o} += _v"""


_SUMMING = """\
_v = _ob{o}
if _v != _v:
    counts[3] += 1
    _v = 0.0
_sum{o} += _v"""


def source_hash(src: str) -> str:
    """Short hash of a generated source text alone (the tests pin some kernels' sources by it)."""
    import numba as nb
    import numpy as np

    return hashlib.sha256((src + nb.__version__ + np.__version__).encode()).hexdigest()[:16]


def kernel_key(src: str) -> str:
    """The kernel's cache key: its source, the source of every project module it imports (the random-number
    generator, shared helpers: numba's disk cache does not look at them), the numba, llvmlite, numpy and Python
    versions, and the numba settings that change the machine code but not numba's own cache index
    (``NUMBA_OPT``, ``NUMBA_BOUNDSCHECK``, ``NUMBA_DEBUGINFO``): a kernel compiled with bounds checks is not loaded by
    a run without them, nor the other way round.

    Examples
    --------
    >>> len(kernel_key("import math"))
    16
    """
    import sys

    import llvmlite
    from numba.core import config

    from ._kernel_modules import dependency_hash

    settings = f"{llvmlite.__version__} {sys.version_info[:2]} {config.OPT} {config.BOUNDSCHECK} " \
               f"{config.DEBUGINFO_DEFAULT}"
    return hashlib.sha256((source_hash(src) + dependency_hash(src) + settings).encode()).hexdigest()[:16]


_TEMPLATE_HEAD = '''\
"""Generated by hybrid.stochastic._auto_codegen (template {version}), scheme {scheme}. Do not edit."""
import math

import numba as nb
import numpy as np

from hybrid.stochastic._rng import next_normal

CACHE = {cache}
# the functions that only the kernels call: no entry points from Python or C (each costs about 0.05 s of a
# cold compile). Called from Python, such a function crashes the interpreter: call run_chunk, drive or
# record_chunk, which keep theirs
INNER = dict(cache=CACHE, no_cpython_wrapper=True, no_cfunc_wrapper=True)
N = {n}
M = {m}
N_OBS = {n_obs}
N_TRANS = {n_trans}
MAX_EVENTS = {max_events}
FIRST = np.array({first}, dtype=np.int64)
COUNT = np.array({count}, dtype=np.int64)
TARGET = np.array({targets}, dtype=np.int64)
DIRECTION = np.array({directions}, dtype=np.int64)
SELF_LOOP = np.array({self_loops}, dtype=np.int64)
POS = np.array({positions}, dtype=np.int64)
VEL = np.array({velocities}, dtype=np.int64)
N_POS = {n_pos}
LANES = 8
LEGS = {legs}
WORK = 6 * N + N * M + N * M * M
# event_step's outputs packed in two arrays (every array argument of a call in the hot loop costs registers):
# iw = [counts 0..5, events per transition, the event-log count], fw = [speed sums per transition, first failed
# check's speed, guard statistics (4 per transition)]
IW_EVENTS = 6
IW_NLOG = 6 + N_TRANS
IW = 7 + N_TRANS
FW_FBAD = N_TRANS
FW_GSTAT = N_TRANS + 1
FW = N_TRANS + 1 + 4 * N_TRANS
FAST_CHECKS_SET = {fast_checks_set}
SCHEME = {scheme_code}
# model()'s kinds (np.int64, not literals: numba compiles one model() for all of them)
F_DRIFT, F_NOISE, F_LGN, F_GUARD, F_RESET, F_GRATE, F_CHECK, F_BFORCE, F_ODAMP = [np.int64(k) for k in range(9)]


{funcs}


'''
# the event code: crossings, their location and event_step (the CUDA target compiles it for the device too)
def _illinois_body(step: str, flight: str, guard: str, at_zero: str = "", end: str = "") -> str:
    """The body of a root finder of a guard on the step's interpolant (``interpolate`` over ``step`` with
    ``flight``), bracketed on [0, 1]: the Illinois (modified regula falsi) method, to 1e-13 of the step in at most 100
    iterations, the state at the root left in ``xs`` and never beyond the guard. ``guard`` reads the guard at the
    share s; ``locate`` and ``locate_view`` differ only there. ``at_zero`` and ``end`` are comment lines."""
    return f'''    if g0 == 0.0:{at_zero}
        interpolate(xa, va, xb, 0.0, {step}, {flight}, xs)
        return 0.0
    a, b = 0.0, 1.0
    fa, fb = g0, g1
    side = np.int64(0)
    s = 1.0
    fs = g1
    for _ in range(100):
        s = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
        if not (s > a and s < b):
            s = 0.5 * (a + b)
        interpolate(xa, va, xb, s, {step}, {flight}, xs)
        fs = {guard}
        if fs == 0.0 or (b - a) < 1e-13:
            break
        if (fs < 0.0) == (fa < 0.0):
            a, fa = s, fs
            if side == -1:
                fb *= 0.5
            side = -1
        else:
            b, fb = s, fs
            if side == 1:
                fa *= 0.5
            side = 1
{end}    if (fs < 0.0) != (g0 < 0.0) and fs != 0.0:
        s = a
        interpolate(xa, va, xb, s, {step}, {flight}, xs)
    return s
'''


_TEMPLATE_EVENTS = '''\
@nb.njit(**INNER)
def crosses(d, g0, g1):
    # a state just reset onto the guard (g0 = 0) fires again only if the step carries it strictly beyond (with
    # Euler-Maruyama the velocity on the segment need not match the motion of the positions)
    if d >= 0 and ((g0 < 0.0 and g1 >= 0.0) or (g0 == 0.0 and g1 > 0.0)):
        return True
    if d <= 0 and ((g0 > 0.0 and g1 <= 0.0) or (g0 == 0.0 and g1 < 0.0)):
        return True
    return False


@nb.njit(**INNER)
def interpolate(xa, va, xb, s, dt, free_flight, xs):
    # the step's interpolant at fraction s: the free flight of the positions at the velocities va (splitting), or
    # the straight segment from xa to xb
    if free_flight:
        for i in range(N):
            xs[i] = xa[i]
        for k in range(N_POS):
            xs[POS[k]] = xa[POS[k]] + s * dt * va[VEL[k]]
    else:
        for i in range(N):
            xs[i] = xa[i] + s * (xb[i] - xa[i])


@nb.njit(**INNER)
def locate(j, xa, va, xb, t0, dt, p, free_flight, g0, g1, xs):
    # Illinois regula falsi for the guard on the interpolant, bracketed on [0, 1]; returns s
''' + _illinois_body("dt", "free_flight", "model(F_GUARD, j, xs, t0 + s * dt, p, xs)",
                  at_zero="  # already on the guard (just reset there) and carried beyond: fires at once",
                  end="    # the state at s must not be beyond the guard: take the bracket end on the side it came "
                      "from\n") + '''

@nb.njit(**INNER)
def event_step(mode, x, t, t_end, dt, dw, p, rec, vhist, v_scale, v_bins, track, iw, fw, ws, elog):
    """One whole step of the path ``x`` in ``mode`` through the general event loop; returns the mode after it.

    Every crossing inside the step is located on the step's interpolant and reset there, in time order, at most
    MAX_EVENTS of them (the excess is counted in iw[1]). The kernel comes here only for steps where a guard
    may fire (and for every step of the step rule's pilot, ``track``), so its cost does not matter.
    """
    xa = ws[0:N]
    va = ws[N:2 * N]
    xb = ws[2 * N:3 * N]
    xs = ws[3 * N:4 * N]
    xr = ws[4 * N:5 * N]
    f = ws[5 * N:6 * N]
    G = ws[6 * N:6 * N + N * M]
    L = ws[6 * N + N * M:WORK]
    free_flight = SCHEME >= 2  # a constant of the module: the other schemes' code is never compiled
    t_step = t
{opening}
    span = dt / LEGS  # BAOAB flies in two halves with its OU step between them
    for leg in range(LEGS):
        if n_ev >= MAX_EVENTS:  # the first leg overflowed: counted once, the state kept
            break
        frac = 1.0  # share of the leg still to run
        while True:
            tau = frac * span
            for i in range(N):
                xa[i] = x[i]
                va[i] = x[i]
            if free_flight:
                for i in range(N):
                    xb[i] = xa[i]
                for k in range(N_POS):
                    xb[POS[k]] = xa[POS[k]] + tau * xa[VEL[k]]
            else:
                model(F_DRIFT, mode, xa, t, p, f)
                model(F_NOISE, mode, xa, t, p, G)
                for i in range(N):
                    acc = f[i] * tau
                    for k in range(M):
                        acc += G[i * M + k] * dw[k] * frac
                    xb[i] = xa[i] + acc
                if SCHEME == 1:
                    model(F_LGN, mode, xa, t, p, L)
                    for i in range(N):
                        acc = 0.0
                        for jn in range(M):
                            for k in range(M):
                                prod = dw[jn] * dw[k] * frac * frac
                                if jn == k:
                                    prod -= tau
                                acc += L[(i * M + jn) * M + k] * prod
                        xb[i] += 0.5 * acc
            # earliest crossing among the transitions leaving this mode
            best = np.int64(-1)  # not the literal -1: numba would compile grate, check and reset for it too
            best_s = 2.0
            for jj in range(COUNT[mode]):
                j = FIRST[mode] + jj
                g0 = model(F_GUARD, j, xa, t, p, xa)
                g1 = model(F_GUARD, j, xb, t + tau, p, xb)
                if track:
                    dg = g1 - g0
                    gs = FW_GSTAT + 4 * j
                    fw[gs] += dg * dg
                    fw[gs + 1] += 1.0
                    if g0 < fw[gs + 2]:
                        fw[gs + 2] = g0
                    if g0 > fw[gs + 3]:
                        fw[gs + 3] = g0
                if crosses(DIRECTION[j], g0, g1):
                    sj = locate(j, xa, va, xb, t, tau, p, free_flight, g0, g1, xs)
                    if sj < best_s:
                        best_s = sj
                        best = j
            if best < 0:
                for i in range(N):
                    x[i] = xb[i]
                break
            interpolate(xa, va, xb, best_s, tau, free_flight, xs)
{fire}
            t += best_s * tau
            frac *= 1.0 - best_s
            n_ev += 1
            if n_ev >= MAX_EVENTS:
                # chattering or Zeno inside one step: stop resolving it, keep the state, count it
                if rec:
                    iw[1] += 1
                break
        if SCHEME == 4 and leg == 0:
            # O: the velocities' exact Ornstein-Uhlenbeck step at the positions of the half step
            t = t_step + span  # as the fast step's t + hdt, to the bit
{o_step}

{closing}
    return mode


'''
# pieces the kernel templates share (the CPU chunk and record loops, and the CUDA kernel's step loop)
_LANE_GROUP = """\
    for _g in range(0, npaths, LANES):
        nl = npaths - _g if npaths - _g < LANES else LANES  # not min(): its overload is compiled apart
        for _l in range(nl):
{init}
            ML[_l] = mode0
"""
"""The start of a group of LANES paths: each lane's initial state and mode."""


SAMPLE_GUARD = """\
                if not FAST_CHECKS_SET:  # splitting's or baoab's kicks after the flight can move a guard
{to_array}
                    if outside(mode, x, _t1, p):
                        counts[2] += 1
{binning}
"""
"""At a sample: the admissible set where the fast step did not settle it, the observables' histograms and sums."""
JOINT_START = """\
                if jx >= 0:
{to_ob}
"""
"""At a sample, after :data:`SAMPLE_GUARD`: the start of the joint histogram (the observables of its axes in ``ob``)."""
SAMPLE_CHECKS = SAMPLE_GUARD + JOINT_START


def step_head(indent: int, counter: str, step: str, next_step: str, phases: bool = True) -> str:
    """The head of one step of the step loop: whether it is recorded, its start and end times, whether it closes a
    phase section or a sample (``counter`` counts the recorded steps since the last sample). ``step`` and
    ``next_step`` are the step and step + 1 as the loop's time arithmetic wants them (the CUDA kernel casts them to
    its float type). ``phases=False``: a loop without phase sections (the CUDA kernel of a run without them), whose
    ``phase_now`` stays False."""
    lines = ["rec = step >= n_burn",
             f"t = t0 + {step} * dt",
             f"_t1 = t0 + {next_step} * dt",
             "phase_now = False",
             "sample = False",
             "if rec:",
             *(["    phase_now = n_phase > 0 and (step + 1) % phase_steps == 0"] if phases else []),
             f"    {counter} += 1",
             f"    if {counter} >= stride:",
             f"        {counter} = 0",
             "        sample = True"]
    return "".join(" " * indent + line + "\n" for line in lines)


_TEMPLATE_DRIVE = '''\
@nb.njit(cache=CACHE)
def drive(x0, mode0, dws, dt, t0, p, out, elog, nlog, bad):
    """Final states ``out`` (paths, N) of paths driven by given Brownian increments ``dws`` (paths, steps, M),
    every step through ``event_step`` (for convergence tests: sums of fine increments drive a coarse grid along
    the same Brownian path). ``elog[path]`` receives (time, transition, speed) of the path's first events and
    ``nlog[path]`` the number of its events; ``bad`` [firings whose check failed, the first one's speed, steps
    over MAX_EVENTS]; returns the events handled."""
    n_paths = dws.shape[0]
    n_steps = dws.shape[1]
    x = np.empty(N)
    ws = np.empty(WORK)  # event_step's work arrays in one (each array argument costs registers at the call)
    dw = np.empty(M)
    vhist = np.zeros((N_TRANS + 1, 1), dtype=np.int64)
    iw = np.zeros(IW, dtype=np.int64)
    fw = np.zeros(FW)
    total = 0
    for ip in range(n_paths):
        for i in range(N):
            x[i] = x0[i]
        mode = mode0
        iw[IW_NLOG] = 0
        for k in range(n_steps):
            for j in range(M):
                dw[j] = dws[ip, k, j]
            mode = event_step(mode, x, t0 + k * dt, t0 + (k + 1) * dt, dt, dw, p, True, vhist, 0.0, 0, False, iw, fw,
                              ws, elog[ip])
        nlog[ip] = iw[IW_NLOG]
        total += iw[IW_NLOG]
        for i in range(N):
            out[ip, i] = x[i]
    bad[0] = iw[5]
    bad[1] = fw[FW_FBAD]
    bad[2] = iw[1]
    return total


@nb.njit(nogil=True, cache=CACHE)
def record_chunk(state, npaths, n_steps, every, dt, t0, x0, mode0, p, zx, zk, zf, out, bad):
    """The paths of one chunk as ``run_chunk`` steps them (the same draws in the same order, the same code), with
    no statistics: ``out[i, r]`` is the state of path i after r * every steps (r = 0: the start), ``bad`` as in
    ``drive``."""
    s0, s1, s2, s3 = state[0], state[1], state[2], state[3]
    sdt = math.sqrt(dt)
    hdt = 0.5 * dt
    x = np.empty(N)
    ws = np.empty(WORK)
    dw = np.empty(M)
    ML = np.empty(LANES, dtype=np.int64)
    PL = np.empty(LANES, dtype=np.int64)
    SL = np.empty((1, LANES))
    DWL = np.empty((M, LANES))
    iw = np.zeros(IW, dtype=np.int64)
    fw = np.zeros(FW)
    vhist = np.zeros((N_TRANS + 1, 1), dtype=np.int64)
    v_scale = 0.0
    v_bins = np.int64(0)  # np.int64, np.bool_: not literals, so that event_step is the one run_chunk compiled
    elogs = np.empty((npaths, 0, 3))
    nlogs = np.zeros(npaths, dtype=np.int64)
    counts = np.zeros(6, dtype=np.int64)
    rec = np.bool_(True)
    track = np.bool_(False)
    sample = np.bool_(False)
{alloc}
{unpack_step}
''' + _LANE_GROUP + '''            for i in range(N):
                out[_g + _l, 0, i] = x0[i]
        for step in range(n_steps):
            t = t0 + step * dt
            _t1 = t0 + (step + 1) * dt
{lane_step}
            if (step + 1) % every == 0:
                for _l in range(nl):
{lane_to_out}
    bad[0] = iw[5]
    bad[1] = fw[FW_FBAD]
    bad[2] = iw[1]
    state[0], state[1], state[2], state[3] = s0, s1, s2, s3


@nb.njit(**INNER)
def record_phase(kp, XL, nl, t, p, x, ob, obs_lo, obs_scale, obs_bins, phist, psums, pcount):
    """The lanes' observables into phase section ``kp`` (out of line: inside the kernel's loop it slowed the
    time average's statistics by about 10 %)."""
    for _l in range(nl):
        for i in range(N):
            x[i] = XL[_l, i]
        _observe(x, t, p, ob)
        pcount[kp] += 1
        for o in range(N_OBS):
            v = ob[o]
            if v != v:
                continue
            psums[kp, o] += v
            b = (v - obs_lo[o]) * obs_scale[o]
            if b < 0.0:
                phist[kp, o, 0] += 1
            elif b >= obs_bins[o]:
                phist[kp, o, obs_bins[o] + 1] += 1
            else:
                phist[kp, o, np.int64(b) + 1] += 1


'''
_TEMPLATE_OUTSIDE = '''\
@nb.njit(**INNER)
def outside(mode, x, t, p):
    # the admissible set: no self-loop guard of the mode may be beyond its firing side
    for jj in range(COUNT[mode]):
        j = FIRST[mode] + jj
        if SELF_LOOP[j] == 1:
            gj = model(F_GUARD, j, x, t, p, x)
            if (DIRECTION[j] > 0 and gj > 1e-9) or (DIRECTION[j] < 0 and gj < -1e-9):
                return True
    return False


'''
_TEMPLATE_CHUNK = '''\
@nb.njit(nogil=True, cache=CACHE)
def run_chunk(state, npaths, n_burn, n_samp, stride, dt, t0, x0, mode0, p, zx, zk, zf,
              obs_lo, obs_scale, obs_bins, hist, jx, jy, j_lo, j_scale, j_bins, jhist,
              v_scale, v_bins, vhist, counts, sums, events, gstat, track, n_phase, phase_steps,
              phist, psums, pcount, vsum, fbad, elogs, nlogs, work):
    """Paths of one chunk; histograms (with underflow bin 0 and overflow bin last), sums and event counts.

    Paths run in groups of LANES interleaved lanes (their independent dependency chains overlap in the CPU), each
    step first on scalars in registers (the generated straight-line step of its mode), and through
    ``event_step`` only where a guard may fire. Every lane draws its normals from the chunk's one stream in a
    fixed order, so a chunk's numbers do not depend on anything but its stream and its size.

    Phase sections (``n_phase`` > 0): after every ``phase_steps``-th step (counted from t0, burn-in included) the
    observables also go into ``phist[k]``, ``psums[k]`` and ``pcount[k]`` with k = (steps / phase_steps) mod
    n_phase, so that section k holds the states at t0 + (k / n_phase + i) * period exactly.

    The scheme is the module's ``SCHEME`` (``_auto_codegen.SCHEME_CODES``).
    counts: [samples, event_overflow, outside, nonfinite, joint_outside, bad_reset]; events[j]: firings of
    transition j after burn-in; vhist[j]: |rate of change of guard j| (the speed) at its firings, overflow in the
    last bin, and vsum[j] the sum of those speeds; fbad[0]: the speed at the first firing whose check failed.
    gstat[j], only when ``track`` (the step rule's pilot, which runs every step through ``event_step``), every
    step with burn-in: [sum of (g1 - g0)**2 over the steps tried, their number, min g0, max g0], how far one
    step moves a guard against the span of the guard over the paths. elogs[i] (K rows): time, transition and speed
    of the first K events of the chunk's path i from t0 (burn-in included; K may be 0), nlogs[i]: all its events.
    """
    s0, s1, s2, s3 = state[0], state[1], state[2], state[3]
    sdt = math.sqrt(dt)
    hdt = 0.5 * dt
    # the other work arrays come from chunk_work(): an allocation in the kernel costs its compile time
    # ws: event_step's work arrays in one (each array argument costs registers at the call); DWL: the lanes'
    # increments of this step; SL, PL: which lanes go through event_step, and their list; OL, BL: the lanes'
    # observables and bin coordinates at a sample; SM, NL: each lane's sums and NaN count
    x, ws, dw, ob, XL, ML, PL, iw, fw, LW = work
    # the arrays of the lane loops are allocated here, all of one type (one allocation function to compile): LLVM
    # then knows that they overlap no other array and runs those loops on vectors of lanes (from chunk_work(),
    # Example 1's path-steps/s were 0.79 of this)
    SL = np.empty((1, LANES))
    DWL = np.empty((M, LANES))
    OL = np.empty((N_OBS, LANES))
{lane_arrays}
    for j in range(N_TRANS):
        fw[FW_GSTAT + 4 * j + 2] = np.inf
        fw[FW_GSTAT + 4 * j + 3] = -np.inf
    _nsamp = np.int64(0)  # counters start as np.int64, not as literal 0: a literal costs type inference a pass
{lane_rows}
{unpack}
''' + _LANE_GROUP + '''        cs = np.int64(0)
        for step in range(n_burn + n_samp * stride):
''' + step_head(12, "cs", "step", "(step + 1)") + '''{lane_step}
            # statistics in loops of their own: the stepping loop above, and the time average's loop, stay short
{phase_block}
            if not sample:
                continue
{sample_statistics}
            if jx >= 0:  # the joint histogram
                for _l in range(nl):
                    bx = (OL[jx, _l] - j_lo[0]) * j_scale[0]
                    by = (OL[jy, _l] - j_lo[1]) * j_scale[1]
                    if bx >= 0.0 and bx < j_bins[0] and by >= 0.0 and by < j_bins[1]:
                        jhist[np.uint64(by), np.uint64(bx)] += 1
                    else:
                        counts[4] += 1
    counts[0] += _nsamp
{lane_totals}
    # event_step's packed outputs into the chunk's arrays
    counts[1] += iw[1]
    if iw[5] and counts[5] == 0:
        fbad[0] = fw[FW_FBAD]
    counts[5] += iw[5]
    for j in range(N_TRANS):
        events[j] += iw[IW_EVENTS + j]
        vsum[j] += fw[j]
        gs = FW_GSTAT + 4 * j
        gstat[j, 0] += fw[gs]
        gstat[j, 1] += fw[gs + 1]
        if fw[gs + 2] < gstat[j, 2]:  # not min() and max(): each is a function numba compiles apart
            gstat[j, 2] = fw[gs + 2]
        if fw[gs + 3] > gstat[j, 3]:
            gstat[j, 3] = fw[gs + 3]
{flush}
    state[0], state[1], state[2], state[3] = s0, s1, s2, s3


def chunk_work():
    """Fresh work arrays for one ``run_chunk`` call, in the order it unpacks them."""
    return (np.empty(N), np.empty(WORK), np.empty(M), np.empty(N_OBS), np.empty((LANES, N)),
            np.empty(LANES, dtype=np.int64), np.empty(LANES, dtype=np.int64), np.zeros(IW, dtype=np.int64),
            np.zeros(FW), np.empty((N, LANES)))


# bins as unsigned indices, for which numba adds no test of a negative index (a uint64 constant, which numba freezes;
# read when run_chunk compiles, after the module has run)
BIN1 = np.uint64(1)
'''
_TEMPLATE = _TEMPLATE_HEAD + _TEMPLATE_EVENTS + _TEMPLATE_DRIVE + _TEMPLATE_OUTSIDE + _TEMPLATE_CHUNK


_LANE_STEP = '''\
            # the lanes' increments first, in lane order, in a loop of their own: the stepping loop then calls no
            # generator (the normals' rare branch calls exp and log), so that it can keep its values in registers and
            # run on vectors of lanes
            for _l in range(nl):
{draw}
            nslow = np.int64(0)
            for _l in range(nl):
{load}
{read_dw}
{fast}
                SL[0, _l] = 1.0 if _slow else 0.0  # redone by event_step below (no call, no branch here)
                nslow += 1 if _slow else 0
{store}
            # the lanes whose guard may have fired, in lane order (event_step draws no normals, so the order of
            # the draws, and every number, is that of a call inside the loop)
            npend = np.int64(0)
            if nslow:
                for _l in range(nl):
                    if SL[0, _l] != 0.0:
                        PL[npend] = _l
                        npend += 1
            for _q in range(npend):
                _l = PL[_q]
{lane_to_x}
{load_dw}
                iw[IW_NLOG] = nlogs[_g + _l]  # the path's own event count: its log's next row
                mode = event_step(ML[_l], x, t, _t1, dt, dw, p, rec, vhist, v_scale, v_bins, track, iw, fw, ws,
                                  elogs[_g + _l])
                nlogs[_g + _l] = iw[IW_NLOG]
                ML[_l] = mode
{reload}
                # the admissible set at a sample; a fast step settles it itself (its guards are tested inside)
                if sample and FAST_CHECKS_SET and outside(mode, x, _t1, p):
                    counts[2] += 1'''
"""One step of the ``nl`` lanes of a group (the generated fast step, then ``event_step`` for the lanes whose guard
may have fired), shared by ``run_chunk`` and ``record_chunk``: a recorded path is a path of the ensemble."""


def noise_increment(indent: int, state: str, into: str, t: str) -> str:
    """Source lines adding the noise's increment G(``state``, ``t``) dW to every component of ``into``."""
    lines = [f"model(F_NOISE, mode, {state}, {t}, p, G)", "for i in range(N):", "    acc = 0.0",
             "    for k in range(M):", "        acc += G[i * M + k] * dw[k]", f"    {into}[i] += acc"]
    return "".join(" " * indent + line + "\n" for line in lines)


# event_step's pieces: the sub-steps that move the velocities only (the opening kick or Milstein step, BAOAB's O step,
# the closing noise and kick), as they are where no guard depends on a velocity (no crossing can happen in them), and
# the firing of a transition (shared with velocity_leg)
_MILSTEIN_VELOCITIES = """\
model(F_DRIFT, mode, {state}, t, p, f)
model(F_NOISE, mode, {state}, t, p, G)
model(F_LGN, mode, {state}, t, p, L)
for kv in range(N_POS):
    i = VEL[kv]
    acc = f[i] * dt
    for k in range(M):
        acc += G[i * M + k] * dw[k]
    for jn in range(M):
        for k in range(M):
            prod = dw[jn] * dw[k]
            if jn == k:
                prod -= dt
            acc += 0.5 * L[(i * M + jn) * M + k] * prod
    {store}"""
"""The symplectic scheme's Milstein step of the velocities from ``state``, once for the plain opening of the step
and once for the located velocity sub-step."""


_PLAIN_OPENING = """\
if SCHEME == 2:
    # kick: velocities by half the drift
    model(F_DRIFT, mode, x, t, p, f)
    for k in range(N_POS):
        x[VEL[k]] += 0.5 * dt * f[VEL[k]]
elif SCHEME == 4:
    # BAOAB: kick by the force (the drift without its damping); half flight, O, half flight below; kick
    model(F_BFORCE, mode, x, t, p, f)
    for k in range(N_POS):
        x[VEL[k]] += 0.5 * dt * f[VEL[k]]
elif SCHEME == 3:
    # symplectic: the velocities' whole Milstein step first (drift, noise and its correction at the start)
""" + textwrap.indent(_MILSTEIN_VELOCITIES.format(state="x", store="xr[i] = acc"), " " * 4) + """
    for kv in range(N_POS):
        x[VEL[kv]] += xr[VEL[kv]]
n_ev = np.int64(0)"""


_NAIVE_OPENING = """\
# naive: the velocities' Euler-Maruyama step first (drift and noise at the start)
model(F_DRIFT, mode, x, t, p, f)
model(F_NOISE, mode, x, t, p, G)
for kv in range(N_POS):
    i = VEL[kv]
    acc = f[i] * dt
    for k in range(M):
        acc += G[i * M + k] * dw[k]
    x[i] += acc
n_ev = np.int64(0)"""


_NAIVE_DROP = """
frac = 0.0  # naive: the rest of the step's flight is dropped (the event time is wrong by up to a step)"""


_FIRE = """\
speed = abs(model(F_GRATE, best, xs, {when}, p, xs))
if model(F_CHECK, best, xs, {when}, p, xs) == 0.0:
    # the transition's declared condition fails (an impact with e outside (0, 1]): counted, first speed kept
    if iw[5] == 0:
        fw[FW_FBAD] = speed
    iw[5] += 1
k_log = iw[IW_NLOG]
if k_log < elog.shape[0]:  # the path's event log (empty unless asked for)
    elog[k_log, 0] = {when}
    elog[k_log, 1] = best
    elog[k_log, 2] = speed
iw[IW_NLOG] += 1
if rec:
    iw[IW_EVENTS + best] += 1
    fw[best] += speed
    vb = speed * v_scale
    if vb < v_bins:
        vhist[best, np.int64(vb)] += 1
    else:
        vhist[best, v_bins] += 1
model(F_RESET, best, xs, {when}, p, xr)
for i in range(N):
    x[i] = xr[i]
mode = TARGET[best]"""


_O_STEP = """\
model(F_ODAMP, mode, {state}, t, p, f)
model(F_NOISE, mode, {state}, t, p, G)
for kv in range(N_POS):
    i = VEL[kv]
    kd = f[i] * dt
    if abs(kd) < 1e-12:
        a = 1.0 - kd
        c = 1.0
    else:
        a = math.exp(-kd)
        c = math.sqrt(-math.expm1(-2.0 * kd) / (2.0 * kd))
    acc = 0.0
    for k in range(M):
        acc += G[i * M + k] * dw[k]
    {store}"""
"""BAOAB's exact Ornstein-Uhlenbeck step of the velocities from ``state`` (plain and located)."""

_PLAIN_O_STEP = _O_STEP.format(state="x", store="x[i] = a * x[i] + c * acc")


_PLAIN_CLOSING = """\
if SCHEME == 2:
    # the time from the step count, not the sum of the event-split pieces: forcing phases stay exact
""" + noise_increment(4, "x", "x", "t_end") + """    model(F_DRIFT, mode, x, t_end, p, f)
    for k in range(N_POS):
        x[VEL[k]] += 0.5 * dt * f[VEL[k]]
elif SCHEME == 4:
    model(F_BFORCE, mode, x, t_end, p, f)
    for k in range(N_POS):
        x[VEL[k]] += 0.5 * dt * f[VEL[k]]"""


def _velocity_leg_call(kind: str, when: str) -> str:
    """event_step's call of ``velocity_leg`` for the sub-step ``kind`` at the instant ``when``."""
    return (f"mode, n_ev = velocity_leg(np.int64({kind}), mode, x, {when}, dt, dw, p, rec, vhist, v_scale, v_bins, "
            "iw, fw, ws, elog, n_ev)")


def _replace_once(text: str, old: str, new: str) -> str:
    """``text`` with its one ``old`` replaced: a template that no longer holds it exactly once must fail loudly here,
    not generate a kernel that silently skips the located sub-step."""
    if text.count(old) != 1:
        raise AssertionError(f"the template changed: {old[:60]!r} is there {text.count(old)} times")
    return text.replace(old, new)


_LOCATED_O_STEP = _velocity_leg_call("OU", "t")


# splitting's noise is located on the states the closing kick makes of the line (velocity_leg); the closing kick
# then moves no guard of the velocities on those states
_LOCATED_CLOSING = _replace_once(_PLAIN_CLOSING, noise_increment(4, "x", "x", "t_end"), f"""\
    {_velocity_leg_call("NOISE", "t_end")}
""")


# the event loop where a guard depends on a velocity: such a guard reads the flight's states with the velocities of
# their own instant (the work array's last 4 N numbers: ua, ub, the state read and a drift)
_LOCATED_EVENTS = (
    ("WORK = 6 * N + N * M + N * M * M\n",
     "WORK = 6 * N + N * M + N * M * M + 4 * N  # and the consistent states of the guards of the velocities\n"),
    ("    t_step = t\n",
     """    t_step = t
    ua = ws[WORK - 4 * N:WORK - 3 * N]  # the velocities of a flight piece's start, at its instant
    ub = ws[WORK - 3 * N:WORK - 2 * N]  # and of its end
    xv = ws[WORK - 2 * N:WORK - N]
    fv = ws[WORK - N:WORK]
    for i in range(N):
        ua[i] = x[i]  # the step's start, before the opening sub-step
"""),
    ("        frac = 1.0  # share of the leg still to run\n",
     """        frac = 1.0  # share of the leg still to run
        if leg == 1:  # BAOAB's second half flight starts from the O step's state, at the half step
            for i in range(N):
                ua[i] = x[i]
"""),
    ("""            best_s = 2.0
            for jj in range(COUNT[mode]):
                j = FIRST[mode] + jj
                g0 = model(F_GUARD, j, xa, t, p, xa)
                g1 = model(F_GUARD, j, xb, t + tau, p, xb)
""", """            best_s = 2.0
            # the velocities at the end of the flight piece, at its instant: after the closing kick (splitting:
            # without the noise, which velocity_leg adds) at the step's end, the flight's own at BAOAB's half step
            for i in range(N):
                ub[i] = xb[i]
            if SCHEME == 2 or (SCHEME == 4 and leg == 1):
                model(F_DRIFT if SCHEME == 2 else F_BFORCE, mode, xb, t_end, p, fv)
                for k in range(N_POS):
                    ub[VEL[k]] = xb[VEL[k]] + 0.5 * dt * fv[VEL[k]]
            for jj in range(COUNT[mode]):
                j = FIRST[mode] + jj
                if VGUARD[j] == 1:  # from ua to ub along the flight, the positions the flight's own
                    g0 = view_guard(j, mode, xa, ua, ub, 0.0, t, dt, p, True, False, xv, fv)
                    g1 = view_guard(j, mode, xb, ua, ub, 1.0, t + tau, dt, p, True, False, xv, fv)
                else:
                    g0 = model(F_GUARD, j, xa, t, p, xa)
                    g1 = model(F_GUARD, j, xb, t + tau, p, xb)
"""),
    ("""                    sj = locate(j, xa, va, xb, t, tau, p, free_flight, g0, g1, xs)
""", """                    if VGUARD[j] == 1:
                        sj = locate_view(j, mode, xa, va, xb, ua, ub, t, tau, dt, p, free_flight, True, False, g0,
                                         g1, xs, xv, fv)
                    else:
                        sj = locate(j, xa, va, xb, t, tau, p, free_flight, g0, g1, xs)
"""),
    ("""{fire}
            t += best_s * tau
""", """            # the next piece's velocities at its start: the reset of the consistent state at the firing
            for i in range(N):
                xv[i] = xs[i]
            for k in range(N_POS):
                xv[VEL[k]] = ua[VEL[k]] + best_s * (ub[VEL[k]] - ua[VEL[k]])
            model(F_RESET, best, xv, t + best_s * tau, p, ua)
{fire}
            t += best_s * tau
"""),
)


def _located(template: str) -> str:
    """``template`` (the CPU module's or the device's) with the event loop of :data:`_LOCATED_EVENTS`."""
    for old, new in _LOCATED_EVENTS:
        template = _replace_once(template, old, new)
    return template


_VELOCITY_LEG = '''\
NOISE, OU = 2, 4  # the sub-steps that move the velocities only and are located: splitting's noise, BAOAB's O
VGUARD = np.array({vguards}, dtype=np.int64)  # 1 where the guard depends on a velocity


@nb.njit(**INNER)
def view_guard(j, mode, xs, ua, ub, s, t, dt, p, lin, kicked, xv, fv):
    """Guard j of the velocities on the state ``xs`` read with velocities of its own instant: with ``lin``, those
    at the share s of the flight piece from ``ua`` to ``ub``; with ``kicked``, xs's after splitting's closing kick
    (a state at the step's end whose velocities are still those of the middle). The state read is left in ``xv``."""
    for i in range(N):
        xv[i] = xs[i]
    if lin:
        for k in range(N_POS):
            v = VEL[k]
            xv[v] = ub[v] if s == 1.0 else ua[v] + s * (ub[v] - ua[v])
    if kicked:
        model(F_DRIFT, mode, xs, t, p, fv)
        for k in range(N_POS):
            xv[VEL[k]] = xs[VEL[k]] + 0.5 * dt * fv[VEL[k]]
    return model(F_GUARD, j, xv, t, p, xv)


@nb.njit(**INNER)
def locate_view(j, mode, xa, va, xb, ua, ub, t0, tau, dt, p, flight, lin, kicked, g0, g1, xs, xv, fv):
    # locate()'s Illinois regula falsi for a guard of the velocities read by view_guard on the interpolant
''' + _illinois_body("tau", "flight",
                     "view_guard(j, mode, xs, ua, ub, s, t0 + s * tau, dt, p, lin, kicked, xv, fv)") + '''

@nb.njit(**INNER)
def velocity_leg(kind, mode, x, t, dt, dw, p, rec, vhist, v_scale, v_bins, iw, fw, ws, elog, n_ev):
    """One sub-step of ``x`` that moves the velocities only, at the instant ``t``; returns (mode, events so far).

    kind: NOISE (G dw, at the step's end) for splitting, OU (the exact Ornstein-Uhlenbeck step, at the half step)
    for BAOAB. Only a guard of the velocities can cross in it: its crossings are located on the straight line in the
    velocities from the state before to the state after (for splitting's noise, on the states the closing kick makes
    of that line: their velocities are the step end's), the earliest on the line first, and fired as in the flights;
    the rest of the sub-step then runs from the reset state in its mode, scaled by the share of the line left. Past
    MAX_EVENTS the sub-step runs without locating.
    """
    xa = ws[0:N]
    xb = ws[2 * N:3 * N]
    xs = ws[3 * N:4 * N]
    xr = ws[4 * N:5 * N]
    f = ws[5 * N:6 * N]
    G = ws[6 * N:6 * N + N * M]
    xv = ws[WORK - 2 * N:WORK - N]
    fv = ws[WORK - N:WORK]
    straight = np.bool_(False)  # locate's flight flag: the straight line (np.bool_: not a literal, no 2nd compile)
    kicked = np.bool_(SCHEME == 2)
    frac = 1.0  # share of the sub-step still to run
    while True:
        for i in range(N):
            xa[i] = x[i]
            xb[i] = x[i]
        # the whole sub-step from xa, in the same operations as where no guard depends on a velocity (the scheme
        # outside: numba compiles only the scheme's own sub-steps, and their callees)
        if SCHEME == 2:
''' + noise_increment(12, "xa", "xb", "t") + '''        else:
''' + textwrap.indent(_O_STEP.format(state="xa", store="xb[i] = a * xa[i] + c * acc"), " " * 12) + '''
        if frac < 1.0:  # after a firing: the share of the line left
            for i in range(N):
                xb[i] = xa[i] + frac * (xb[i] - xa[i])
        if n_ev >= MAX_EVENTS:  # the step overflowed before: no more locating
            break
        best = np.int64(-1)
        best_s = 2.0
        for jj in range(COUNT[mode]):
            j = FIRST[mode] + jj
            if VGUARD[j] == 0:  # a guard of the positions and time only: not moved by this sub-step
                continue
            g0 = view_guard(j, mode, xa, xa, xa, 0.0, t, dt, p, straight, kicked, xv, fv)
            g1 = view_guard(j, mode, xb, xb, xb, 1.0, t, dt, p, straight, kicked, xv, fv)
            if crosses(DIRECTION[j], g0, g1):
                sj = locate_view(j, mode, xa, xa, xb, xa, xa, t, 0.0, dt, p, straight, straight, kicked, g0, g1, xs,
                                 xv, fv)
                if sj < best_s:
                    best_s = sj
                    best = j
        if best < 0:
            break
        interpolate(xa, xa, xb, best_s, 0.0, straight, xs)
{fire}
        frac *= 1.0 - best_s
        n_ev += 1
        if n_ev >= MAX_EVENTS:  # chattering or Zeno inside one step: keep the state, count it
            if rec:
                iw[1] += 1
            return mode, n_ev
    for i in range(N):
        x[i] = xb[i]
    return mode, n_ev
'''
