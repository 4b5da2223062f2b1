"""The kernel cache key covers every input of the generated code, the modules it imports included.

numba's disk cache checks a generated kernel file, not the modules it imports (the random-number generator):
a changed generator must give the kernel another name, so that no stale machine code is loaded.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
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


_X, _V, _S = sp.symbols("x v s")


def _memo_automaton(wall=0.1, value=0.3, noise=_S * _V, direction=1, check=None, names=("s", "q")):
    params = {k: {"s": value, "q": 2.0}[k] for k in names}
    return HybridAutomaton((_X, _V), params, [Mode("m", (_V, -sp.Symbol("q") * _X), (0, noise))],
                           [Transition("wall", "m", "m", _X - wall, direction, (_X, -_V), check=check)])


_MEMO_OBS = {"H": _V**2 / 2 + _X**2 / 2, "x": _X}
_MEMO_VARIANTS = {  # one input of the source changed each: (automaton, scheme, observables, keyword arguments)
    "a guard's float in its last bit": (_memo_automaton(wall=float(np.nextafter(0.1, 1.0))), "splitting",
                                        _MEMO_OBS, {}),
    "the noise": (_memo_automaton(noise=2 * _S * _V), "splitting", _MEMO_OBS, {}),
    "a direction": (_memo_automaton(direction=0), "splitting", _MEMO_OBS, {}),
    "a check": (_memo_automaton(check=_V < 0), "splitting", _MEMO_OBS, {}),
    "the parameters' order": (_memo_automaton(names=("q", "s")), "splitting", _MEMO_OBS, {}),
    "the scheme": (_memo_automaton(), "em", _MEMO_OBS, {}),
    "an observable": (_memo_automaton(), "splitting", {"H": _V**2 / 2, "x": _X}, {}),
    "the convention": (_memo_automaton(), "splitting", _MEMO_OBS, {"convention": "ito"}),
    "the summed set": (_memo_automaton(), "splitting", _MEMO_OBS, {"summed": ("H",)}),
    "the joint-only set": (_memo_automaton(), "splitting", _MEMO_OBS, {"joint_only": ("x",)}),
    "phase sections": (_memo_automaton(), "splitting", _MEMO_OBS, {"phases": True}),
    "the disk cache": (_memo_automaton(), "splitting", _MEMO_OBS, {"cache": False}),
}


def test_the_source_memo_shares_a_structure_whatever_the_parameter_values():
    """generate_source is memoised: another parameter value gives the very same object (values are runtime
    arguments), and a hit is the text that a fresh generation prints."""
    first = _auto_codegen.generate_source(_memo_automaton(), "splitting", _MEMO_OBS)
    assert _auto_codegen.generate_source(_memo_automaton(value=0.7), "splitting", _MEMO_OBS) is first
    _auto_codegen._SOURCES.clear()
    assert _auto_codegen.generate_source(_memo_automaton(value=0.7), "splitting", _MEMO_OBS)[0] == first[0]


@pytest.mark.parametrize("change", list(_MEMO_VARIANTS))
def test_the_source_memo_misses_when_any_input_of_the_source_changes(change):
    base = _auto_codegen.generate_source(_memo_automaton(), "splitting", _MEMO_OBS)[0]
    automaton, scheme, obs, kwargs = _MEMO_VARIANTS[change]
    assert _auto_codegen.generate_source(automaton, scheme, obs, **kwargs)[0] != base
