"""The kernel cache key covers every input of the generated code, the modules it imports included.

numba's disk cache checks a generated kernel file, not the modules it imports (the random-number generator):
a changed generator must give the kernel another name, so that no stale machine code is loaded.
"""

from __future__ import annotations

import inspect

import numpy as np
import sympy as sp

from hybrid import HybridAutomaton, Mode, Transition
from hybrid.stochastic import _auto_codegen, _kernel_modules


def _changed_source(monkeypatch, module_name):
    """Make ``inspect.getsource`` see one more line in ``module_name`` (and forget the hashes already taken)."""
    real = inspect.getsource
    monkeypatch.setattr(inspect, "getsource",
                        lambda obj: real(obj) + ("\n# changed\n" if obj.__name__ == module_name else ""))
    _kernel_modules._module_source_hash.cache_clear()


def test_a_changed_random_number_generator_changes_the_automaton_kernel_key(monkeypatch):
    x, v = sp.symbols("x v")
    automaton = HybridAutomaton((x, v), {"s": 0.3}, [Mode("m", (v, -x), (0, sp.Symbol("s")))])
    src = _auto_codegen.generate_source(automaton, "em", {})[0]
    assert "from hybrid.stochastic._rng import" in src
    before, text = _auto_codegen.kernel_key(src), _auto_codegen.source_hash(src)
    try:
        _changed_source(monkeypatch, "hybrid.stochastic._rng")
        assert _auto_codegen.kernel_key(src) != before
        assert _auto_codegen.source_hash(src) == text  # the source itself is the same text
    finally:
        _kernel_modules._module_source_hash.cache_clear()


def test_a_changed_random_number_generator_changes_the_oscillator_kernel_name(monkeypatch):
    # an oscillator's kernel is its automaton's: the module name carries the same key
    from hybrid.stochastic import _front, generate_source
    from models import DuffingImpact

    model = DuffingImpact()
    src = generate_source(model, "milstein")[0]
    before = _front.kernel_name(model, "symplectic", src)[0]
    try:
        _changed_source(monkeypatch, "hybrid.stochastic._rng")
        assert _front.kernel_name(model, "symplectic", src)[0] != before
    finally:
        _kernel_modules._module_source_hash.cache_clear()


def test_numba_settings_that_change_the_machine_code_change_the_kernel_key(monkeypatch):
    # numba's cache index knows the CPU, not NUMBA_BOUNDSCHECK or NUMBA_OPT: a kernel compiled with bounds checks
    # must not be loaded by a run without them (nor the other way round)
    from numba.core import config

    src = "from hybrid.stochastic._rng import next_normal"
    before = _auto_codegen.kernel_key(src)
    monkeypatch.setattr(config, "BOUNDSCHECK", True)
    checked = _auto_codegen.kernel_key(src)
    monkeypatch.setattr(config, "OPT", 0)
    assert len({before, checked, _auto_codegen.kernel_key(src)}) == 3


def test_a_callable_law_names_its_kernel_by_its_code_not_by_the_function_object():
    from hybrid.stochastic import _front
    from models import CustomRestitution, DuffingImpact

    def names(*laws):
        return [_front.kernel_name(DuffingImpact(restitution=CustomRestitution(law)), "symplectic", "src")[0]
                for law in laws]

    def law(v):
        return 0.7 + 0.0 * v

    twin = eval(compile("lambda v: 0.7 + 0.0 * v", "<law>", "eval"))  # another object, the same code and constants
    other = eval(compile("lambda v: 0.8 + 0.0 * v", "<law>", "eval"))
    a, b, c = names(law, twin, other)
    assert a == b != c and a.startswith(names(other)[0][:-32])


def test_the_source_memo_keys_every_input_and_ignores_parameter_values():
    """generate_source is memoised on the automaton's structure and the options: another parameter value shares
    the source (values are runtime arguments); a float of a guard changed in its last bit, another scheme, observable
    or summed set do not; a hit is the text that a fresh generation prints."""
    x, v = sp.symbols("x v")

    def automaton(wall=0.1, value=0.3):
        return HybridAutomaton((x, v), {"s": value}, [Mode("m", (v, -x), (0, sp.Symbol("s")))],
                               [Transition("wall", "m", "m", x - wall, 1, (x, -v))])

    obs = {"H": v**2 / 2 + x**2 / 2}
    first = _auto_codegen.generate_source(automaton(), "splitting", obs)
    assert _auto_codegen.generate_source(automaton(value=0.7), "splitting", obs) is first
    _auto_codegen._SOURCES.clear()
    assert _auto_codegen.generate_source(automaton(value=0.7), "splitting", obs)[0] == first[0]
    next_float = float(np.nextafter(0.1, 1.0))
    others = [_auto_codegen.generate_source(automaton(wall=next_float), "splitting", obs),
              _auto_codegen.generate_source(automaton(), "em", obs),
              _auto_codegen.generate_source(automaton(), "splitting", {"H": v**2 / 2}),
              _auto_codegen.generate_source(automaton(), "splitting", obs, summed=("H",))]
    assert all(o[0] != first[0] for o in others)
    assert float.hex(-next_float) in {float.hex(float(a)) for a in sp.preorder_traversal(others[0][1].transitions[0]
                                                                                           .guard)
                                      if isinstance(a, sp.Float)}
