"""``vibro orbit``: an event-exact free orbit, its impact log, and a check against eqs. 11, 13 and 14."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from hybrid.errors import ModelError, ParameterError

DEFAULT_STATE = (0.0, 2.2)


def initial_state(args) -> tuple[float, float]:
    """(x0, v0) from ``--x0 X [V]`` and ``--v0 V``, one spelling of the state across commands.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> initial_state(SimpleNamespace(x0=[0.5], v0=None)), initial_state(SimpleNamespace(x0=None, v0=1.0))
    ((0.5, 2.2), (0.0, 1.0))
    """
    values = list(args.x0) if args.x0 is not None else [DEFAULT_STATE[0]]
    if len(values) > 2:
        raise ParameterError(f"--x0 gives {len(values)} values; an oscillator's state is the position and the "
                             "velocity: --x0 X V")
    if len(values) == 2 and args.v0 is not None:
        raise ParameterError("--x0 X V already sets the velocity; drop --v0")
    v0 = values[1] if len(values) == 2 else (args.v0 if args.v0 is not None else DEFAULT_STATE[1])
    state = (float(values[0]), float(v0))
    if not all(math.isfinite(v) for v in state):
        flags = "--x0" if args.v0 is None else "--x0/--v0"
        raise ParameterError(f"{flags}: the initial state (x, v) = ({state[0]:g}, {state[1]:g}) must be finite")
    return state


def register(subparsers) -> None:
    """Add the ``orbit`` subcommand.

    Examples
    --------
    >>> from vibro.cli import build_parser
    >>> args = build_parser().parse_args(["orbit", "--x0", "0", "2.2", "--t-end", "5"])
    >>> args.backend, initial_state(args)
    ('heyoka', (0.0, 2.2))
    """
    from .common import add_model_arguments

    p = subparsers.add_parser(
        "orbit", help="deterministic orbit with exact impacts; compare with eqs. 11, 13, 14",
        description="Simulate the noise-free orbit (the model's noise is ignored) with impacts located exactly, "
                    "write the impact log and compare the measured energy losses and quasi-periods with the "
                    "paper's eq. 11 (loss per impact), eq. 13 (loss per quasi-period, 'paper' same-e reading "
                    "and the exact two-impact loss) and eq. 14 (quasi-period).",
    )
    add_model_arguments(p)
    p.add_argument("--x0", type=float, nargs="+", default=None, metavar="X [V]",
                   help="initial state, as in vibro mc: the position, or the position and the velocity (default: "
                        f"{DEFAULT_STATE[0]:g} {DEFAULT_STATE[1]:g}); the position must lie inside the gap")
    p.add_argument("--v0", type=float, default=None,
                   help=f"initial velocity alone, for --x0 X (default {DEFAULT_STATE[1]:g})")
    p.add_argument("--t-end", type=float, default=60.0, dest="t_end",
                   help="final time (default 60); cost ∝ impacts up to t-end")
    p.add_argument("--backend", choices=["heyoka", "scipy"], default="heyoka",
                   help="integrator: heyoka (Taylor, ~0.1 ms per impact after a one-off JIT compile of a few "
                        "seconds) or scipy (solve_ivp DOP853, ~2-6 ms per impact)")
    p.add_argument("--rtol", type=float, default=None, help="tolerance (heyoka: machine eps; scipy: 1e-10)")
    p.add_argument("--max-impacts", type=int, default=1_000_000, dest="max_impacts",
                   help="stop with status max_impacts after this many impacts; bounds the cost, which grows with "
                        "the number of impacts")
    p.add_argument("--max-steps", type=int, default=10_000_000, dest="max_steps",
                   help="step budget: an orbit estimated above it is refused before it starts (with the estimate), "
                        "and one that still reaches it stops with status max_steps")
    p.add_argument("--out", default=None, metavar="FILE.csv",
                   help="write the impact log here (atomically; not written if absent)")
    p.add_argument("--rows", type=int, default=6, help="table rows per comparison (default 6)")
    p.set_defaults(func=run)


def _rel(a: float, b: float) -> float:
    return abs(a - b) / abs(b) if b != 0 else (0.0 if a == 0 else math.inf)


def eq14_not_applicable(model, side) -> str | None:
    """Why eq. 14 does not describe this impact sequence, or None when it does.

    Eq. 14 (the quasi-period T(H) as the time from impact k to k + 2) assumes two walls at one level, hit
    alternately; with one stop (or a stop at the equilibrium) impacts k and k + 2 are two returns apart, and the
    comparison would print a deviation of ~100 % that says nothing about the orbit.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> eq14_not_applicable(DuffingImpact(), ["right", "left", "right"]) is None
    True
    """
    left, right = model.barriers
    if not (np.isfinite(left) and np.isfinite(right)):
        stop = "right" if np.isfinite(right) else "left"
        return (f"it assumes two symmetric walls hit alternately, and this model has one stop (the {stop} one at "
                f"x = {right if np.isfinite(right) else left:g})")
    side = list(side)
    if any(a == b for a, b in zip(side, side[1:])):
        return "it assumes two symmetric walls hit alternately, and this orbit hits one wall twice in a row"
    return None


def comparison_tables(model, df, rows: int = 6) -> tuple[str, dict]:
    """Text tables of measured against predicted losses and quasi-periods, and the largest relative errors.

    ``df`` is an impact log from :meth:`ImpactLog.to_pandas`. The returned dict holds the maximum relative
    deviation for each formula: over the whole log for ``eq11``, ``eq13_paper``, ``eq13_exact``; over the first
    ``4 * rows + 1`` quasi-periods only for ``eq14`` and ``eq14_two_level`` (each T(H) is a quadrature), None
    where eq. 14 does not apply (:func:`eq14_not_applicable`).

    Examples
    --------
    >>> from models import DuffingImpact, Ma
    >>> from hybrid.deterministic import simulate_orbit
    >>> m = DuffingImpact(c=0, D=0, restitution=Ma(0.4))
    >>> text, worst = comparison_tables(m, simulate_orbit(m, (0.0, 2.2), 10.0).to_pandas())
    >>> worst["eq11"] < 1e-10, worst["eq13_exact"] < 1e-10, worst["eq13_paper"] > 1e-2
    (True, True, True)
    """
    from averaging.quadrature import period

    law, Gd = model.restitution, model.barrier_energy

    out = []
    worst = {"eq11": 0.0, "eq13_paper": 0.0, "eq13_exact": 0.0, "eq14": 0.0, "eq14_two_level": 0.0}
    n = len(df)
    t, Hm, Hp, side = df.t.to_numpy(), df.H_minus.to_numpy(), df.H_plus.to_numpy(), df.barrier.to_numpy()

    out.append("energy loss per impact, eq. 11: dH = (1 - e^2)(H- - G(delta))")
    out.append(f"{'k':>4} {'t':>12} {'barrier':>7} {'H-':>12} {'dH measured':>14} {'eq. 11':>14} {'rel.dev':>9}")
    for k in range(n):
        pred = law.impact_loss(Hm[k] - Gd)
        meas = Hm[k] - Hp[k]
        dev = _rel(meas, pred) if pred > 0 else abs(meas)
        worst["eq11"] = max(worst["eq11"], dev)
        if k < rows:
            out.append(f"{k:>4} {t[k]:>12.6f} {side[k]:>7} {Hm[k]:>12.8f} {meas:>14.6e} {pred:>14.6e} {dev:>9.2e}")

    out.append("")
    out.append("loss per quasi-period (impacts k, k+1), eq. 13: 'paper' (1 - e^4)(H - G), "
               "'exact' (1 - e1^2 e2^2)(H - G), e2 = e(e1 v)")
    out.append(f"{'k':>4} {'H-':>12} {'measured':>14} {'eq.13 paper':>14} {'rel.dev':>9} {'exact 2-imp':>14} "
               f"{'rel.dev':>9}")
    for k in range(n - 1):
        meas = Hm[k] - Hp[k + 1]
        paper, exact = law.two_impact_loss(Hm[k] - Gd, "paper"), law.two_impact_loss(Hm[k] - Gd, "exact")
        dp = _rel(meas, paper) if paper > 0 else abs(meas)
        de = _rel(meas, exact) if exact > 0 else abs(meas)
        worst["eq13_paper"] = max(worst["eq13_paper"], dp)
        worst["eq13_exact"] = max(worst["eq13_exact"], de)
        if k < rows:
            out.append(f"{k:>4} {Hm[k]:>12.8f} {meas:>14.6e} {paper:>14.6e} {dp:>9.2e} {exact:>14.6e} {de:>9.2e}")

    out.append("")
    reason = eq14_not_applicable(model, side)
    if reason:  # a deviation from a formula that does not hold here would read as a 100 % error of the solver
        out.append(f"quasi-period, eq. 14: not compared: {reason}")
        worst["eq14"] = worst["eq14_two_level"] = None
    else:
        out.append("quasi-period: time from impact k to k+2 (same barrier) against eq. 14 T(H+_k) and the two-level "
                   "value (T(H+_k) + T(H+_k+1))/2")
        out.append(f"{'k':>4} {'H+':>12} {'measured':>14} {'eq.14':>14} {'rel.dev':>9} {'two-level':>14} "
                   f"{'rel.dev':>9}")
        m_rows = min(n - 2, 4 * rows + 1)  # the worst case over the first rows is enough
        T = period(model, Hp[: m_rows + 1]) if m_rows > 0 else []
        for k in range(m_rows):
            meas = t[k + 2] - t[k]
            T1 = float(T[k])
            two = 0.5 * (T1 + float(T[k + 1]))
            d1, d2 = _rel(meas, T1), _rel(meas, two)
            worst["eq14"] = max(worst["eq14"], d1)
            worst["eq14_two_level"] = max(worst["eq14_two_level"], d2)
            if k < rows:
                out.append(f"{k:>4} {Hp[k]:>12.8f} {meas:>14.10f} {T1:>14.10f} {d1:>9.2e} {two:>14.10f} {d2:>9.2e}")
    out.append("")
    worst = {k: None if v is None else float(v) for k, v in worst.items()}
    out.append("largest relative deviation: " + ", ".join(f"{k} {'not applicable' if v is None else f'{v:.2e}'}"
                                                          for k, v in worst.items()))
    return "\n".join(out), worst


def run(args: argparse.Namespace) -> int:
    """Run ``vibro orbit``; return 0 on success, 1 when the orbit stopped early (Zeno, chattering, max_steps, a
    missed impact that left the admissible set, failure)."""
    from averaging.quadrature import period
    from hybrid.deterministic import simulate_orbit
    from hybrid.io import write_csv_atomically

    from .common import model_from_args

    if not math.isfinite(args.t_end) or args.t_end < 0:
        raise ParameterError(f"--t-end {args.t_end!r} must be a finite time >= 0")
    if args.rtol is not None and not (0 < args.rtol < 1):
        raise ParameterError(f"--rtol {args.rtol!r} must lie in (0, 1)")
    if args.rows < 0:
        raise ParameterError(f"--rows {args.rows} must be >= 0")
    if args.out is not None:
        from .common import output_plan

        output_plan(args).file(args.out, "--out", sidecar=True)
    x0, v0 = initial_state(args)
    model = model_from_args(args)
    model.restitution.validate()
    res = simulate_orbit(model, (x0, v0), args.t_end, backend=args.backend, rtol=args.rtol,
                         max_impacts=args.max_impacts, max_steps=args.max_steps)
    df = res.to_pandas()
    params = " ".join(f"{k}={v:g}" for k, v in model.params.items())
    print(f"vibro orbit: {model.name} {params}, restitution {model.restitution.spec()}, backend {res.backend}")
    if model.params.get("D", 0.0) or model.substitute(model.h) != 0:
        print("note: the noise is ignored; eqs. 11-14 assume a free orbit (h = 0), so expect deviations when h != 0")
    print(f"status {res.status}: {res.message}; {res.n_impacts} impacts, {res.n_steps} steps, "
          f"{res.wall_time:.3f} s (compile {res.compile_time:.3f} s)")
    if args.out is not None:
        from vibro.provenance import record, write_sidecar

        write_csv_atomically(df, args.out)
        settings = {"backend": res.backend, "rtol": args.rtol, "x0": x0, "v0": v0, "t_end": args.t_end,
                    "max_impacts": args.max_impacts, "max_steps": args.max_steps}
        results = {"status": res.status, "message": res.message, "impacts": res.n_impacts, "steps": res.n_steps,
                   "wall_time_s": res.wall_time}
        write_sidecar(args.out, record("orbit", model=model, settings=settings, results=results))
        print(f"wrote {args.out} ({len(df)} impacts) and its provenance {Path(args.out).with_suffix('.json')}")
    if getattr(model, "is_forced", False):  # eqs. 11-14 describe the free, autonomous orbit
        print(f"no comparison with eqs. 11-14: the model is forced (F = {model.forcing})")
        return 0 if res.status in ("ok", "max_impacts") else 1
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # a wall at 1e300 overflows G: said below
            Gd = model.barrier_energy
    except ModelError as exc:  # asymmetric barriers: no single impact level for eqs. 11-14
        print(f"no comparison with eqs. 11-14: {exc}")
        return 0 if res.status in ("ok", "max_impacts") else 1
    H0 = float(model.energy(x0, v0))
    if not math.isfinite(Gd):  # no wall, or one so far that G there overflows: eqs. 11-14 have no impact level
        why = ("the model has no walls" if not model.has_barriers else
               "the walls are so far that G(delta) overflows double precision")
        with np.errstate(over="ignore", invalid="ignore"):  # G at such walls is inf: no wall for the quadrature
            free = float(period(model, H0)[0])
        print(f"no comparison with eqs. 11-14: {why}, so the orbit has no impacts; free period (eq. 8) "
              f"T(H0) = {free:.12g} at H0 = {H0:.12g}")
        return 0 if res.status in ("ok", "max_impacts") else 1
    print(f"G(delta) = {Gd:.12g}, H0 = {H0:.12g}")
    if len(df) == 0:
        if H0 == 0.0:
            print("no impacts: the orbit starts at rest at the equilibrium (H0 = 0), where it stays")
        elif H0 < Gd:
            print(f"no impacts: H0 < G(delta); free period (eq. 8) T(H0) = {float(period(model, H0)[0]):.12g}")
        else:
            print("no impacts before t_end")
    else:
        text, _ = comparison_tables(model, df, rows=args.rows)
        print()
        print(text)
    return 0 if res.status in ("ok", "max_impacts") else 1
