"""Guards that depend on a velocity fire in the splitting schemes' velocity sub-steps too (issue 24, item 0).

``splitting``, ``symplectic`` and ``baoab`` move the velocities in sub-steps of their own (kicks, noise, the
Milstein velocity step, the Ornstein-Uhlenbeck step) at a fixed position. An energy level H - H_c crossed there
used to be missed: on Example 1's oscillator with levels as a chain of modes, the mean first passage to H = 0.25
came out 16.5 with baoab (em 5.3, converged Monte Carlo 5.17), and 34 of 64 paths hit a wall (H >= 0.55) before
their H = 0.5 level had fired. Such guards are now read on states whose positions and velocities belong to one
instant (along the flight, and at the step's end; tests/test_first_passage_velocity_guards.py has the oracles).

The oracles: the converged mean first-passage time, and an invariant that needs no reference (from rest, no path
can reach a wall before it crosses H = 0.5, so the walls of the modes below that level never fire).
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from hybrid import HybridAutomaton, Mode, Transition
from hybrid.stochastic import simulate_automaton
from hybrid.stochastic._auto_codegen import generate_source
from models import DuffingImpact, Ma

FIRST_PASSAGE_025 = 5.17
"""Mean first-passage time from rest to H = 0.25 on Example 1 (c = 0.025, D = 0.05), converged Monte Carlo. At
dt = 0.002 the level, watched at the steps' ends, is reached about 0.14 later (em and baoab both 5.31 +- 0.16 with
2048 paths; 5.25 at dt = 0.0005)."""


def energy_chain(levels=(0.25, 0.5), direction=1):
    """Example 1's automaton with its mode copied into a chain: mode k goes to k + 1 when H crosses levels[k]
    (identity reset); every mode keeps the walls, as transitions '<wall><k>'."""
    base = DuffingImpact(restitution=Ma(vc=0.4)).to_automaton()
    H = base.observables["H"]
    free = base.modes[0]
    modes = [Mode(f"m{k}", free.flow, free.noise) for k in range(len(levels) + 1)]
    transitions = []
    for k in range(len(levels) + 1):
        if k < len(levels):
            transitions.append(Transition(f"level{k}", f"m{k}", f"m{k + 1}", H - sp.Float(levels[k]), direction,
                                          base.states))
        transitions += [Transition(f"{t.name}{k}", f"m{k}", f"m{k}", t.guard, t.direction, t.reset,
                                   priority=t.priority + 1, check=t.check) for t in base.transitions]
    return HybridAutomaton(base.states, dict(base.parameters), modes, transitions, observables={"H": H})


def _first_passages(scheme, automaton, paths=256):
    ens = simulate_automaton(automaton, scheme, dt=0.002, paths=paths, t_end=40.0, x0=(0.0, 0.0), seed=3,
                             events=16, histograms={"H": None}, check_dt=False)
    # every path reaches H = 0.25; those that reach H = 0.5 (most: its mean first passage is 11.5) do so later
    first0, first1 = ens.first_event_times("level0"), ens.first_event_times("level1")
    reached = np.isfinite(first1)
    assert np.all(np.isfinite(first0)) and reached.mean() > 0.9 and np.all(first0[reached] < first1[reached])
    # the invariant: no wall below H = 0.5, and no wall of any mode before a path's H = 0.5 firing
    walls = [ens.transitions.index(f"{side}{k}") for side in ("left", "right") for k in range(3)]
    assert all(ens.events[j] == 0 for j in walls[:2] + walls[3:5]), dict(zip(ens.transitions, ens.events))
    log = ens.event_log
    hit = np.isin(log[:, :, 1], walls)
    first_wall = np.where(hit.any(axis=1), log[np.arange(paths), np.argmax(hit, axis=1), 0], np.inf)
    assert np.all(first_wall > np.where(reached, first1, -np.inf)) and np.all(np.isinf(first_wall[~reached]))
    # the first passage to H = 0.25 against the converged mean
    se = np.std(first0) / np.sqrt(paths)
    assert abs(np.mean(first0) - FIRST_PASSAGE_025) < 3 * se, (np.mean(first0), se)
    return ens


def test_baoab_fires_an_energy_level_crossed_in_its_kicks_and_o_steps():
    # measured: mean first passage 4.94 (standard error 0.24), 99 % of the paths reach H = 0.5; before, paths
    # still had not reached H = 0.25 at t = 40 (on the reproducer the mean was 16.5, with 34 of 64 paths at
    # a wall before their H = 0.5 firing)
    _first_passages("baoab", energy_chain())


@pytest.mark.slow  # a kernel each
@pytest.mark.parametrize("scheme", ["splitting", "symplectic"])
def test_splitting_and_symplectic_fire_an_energy_level_crossed_in_their_velocity_steps(scheme):
    # measured: 4.94 (standard error 0.24) for both (16.3 and 17.0 before, on the reproducer)
    _first_passages(scheme, energy_chain())


@pytest.mark.slow  # a kernel of its own
def test_direction_zero_energy_levels_give_the_directed_levels_numbers():
    # from rest each level is first crossed upwards and the next mode's level lies higher, so a direction 0 guard
    # fires where the +1 guard does: the same paths, bitwise (its kicks and O steps test a sign change both ways)
    directed = _first_passages("baoab", energy_chain())
    undirected = _first_passages("baoab", energy_chain(direction=0))
    np.testing.assert_array_equal(directed.event_log, undirected.event_log)
    np.testing.assert_array_equal(directed.chunk_sums, undirected.chunk_sums)


def test_only_guards_of_velocities_change_the_generated_kernel():
    # the kernels of models whose guards are of positions and time only are the ones they were (no compile here:
    # the sources); the velocity sub-steps locate crossings only where a guard depends on a velocity
    plain = DuffingImpact(restitution=Ma(vc=0.4)).to_automaton()
    levels = energy_chain()
    for scheme in ("splitting", "symplectic", "baoab"):
        assert "def velocity_leg" not in generate_source(plain, scheme, {})[0]
        assert "def velocity_leg" in generate_source(levels, scheme, {})[0]
    # em and milstein step the whole state on one segment, on which every crossing is located already
    assert "def velocity_leg" not in generate_source(levels, "em", {})[0]


PLAIN_SOURCES = {
    ("ma:vc=0.4", "em"): "e521398b399b2198", ("ma:vc=0.4", "milstein"): "c3834ccdc2a1645f",
    ("ma:vc=0.4", "splitting"): "321dd1a13de45de7", ("ma:vc=0.4", "symplectic"): "a2928c0b69d9ba87",
    ("ma:vc=0.4", "baoab"): "291221d23e49e2e5",
    ("newton:e=0.8", "em"): "ed10ead616a4f713", ("newton:e=0.8", "milstein"): "d14cbd436edbafab",
    ("newton:e=0.8", "splitting"): "3d00d5de9f2d7279", ("newton:e=0.8", "symplectic"): "4ace9115216cffa5",
    ("newton:e=0.8", "baoab"): "c6871f9375452bc6",
}
"""Hashes of Example 1's kernel sources as generated before the velocity sub-steps located crossings (commit
0735d7b, sympy 1.14), with these changes since: ``drive`` reports failed checks and event overflows, and
``record_chunk`` (sample_paths) runs the lanes' step of ``run_chunk`` (branch fix/engine); the model's nine
functions (drift, noise, guard, reset, ...) are one function ``model(kind, ...)``, compiled once instead of nine
times, with the same expressions (branch fix/i22compile: the histograms, sums and event counts of em, milstein,
splitting, naive, the impact pair and a forced model with phases are bitwise those before); counters start as
``np.int64(0)``, ``min`` is a conditional expression and ``run_chunk`` takes its work arrays from ``chunk_work()``
(a shorter compile; the statistics of em, milstein, splitting, naive, baoab, the impact pair, a forced model with
phases, the energy chain's event logs, ``sample_paths`` and ``drive_paths`` bitwise those before); template 7: the
inner functions have no Python or C entry points, bins are ``np.int64(b)`` and the guard statistics' extremes are
conditionals (the same statistics of em, milstein, splitting and naive ensembles, the impact pair's splitting with a
joint histogram, baoab and em with event logs, a forced model with phases, ``sample_paths`` and ``drive_paths``
bitwise those of template 6); template 8: the lanes' normals are drawn in a loop of their own, the lane loops'
arrays are allocated in ``run_chunk``, bins are unsigned indices and, where an observable is only summed, each lane
keeps its own sums until the chunk ends (the same eleven runs bitwise those of template 7, but for the sums of the
oscillator ensembles, which differ by rounding: 2e-14 relative at most in those runs; 6e-14 on the impact pair with
a summed, sign-changing observable). A model whose guards are of
positions only must compile that kernel. A change of sympy's printer also moves them; then compare
the sources of the two commits and pin anew."""


@pytest.mark.parametrize("law,scheme", sorted(PLAIN_SOURCES))
def test_plain_kernels_are_generated_as_before(law, scheme):
    from hybrid.stochastic._auto_codegen import source_hash
    from models import Newton

    automaton = DuffingImpact(restitution=Ma(vc=0.4) if law.startswith("ma") else Newton(0.8)).to_automaton()
    src = generate_source(automaton, scheme, {"H": automaton.observables["H"]})[0]
    assert source_hash(src) == PLAIN_SOURCES[(law, scheme)]
