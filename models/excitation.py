"""Coloured (band-limited) noise as filter states attached to any model.

A filter replaces each white noise of a model by the output ``z`` of a linear filter driven by white noise; the
filter's states join the model's state and its parameters join the model's parameters, so the result is a plain
:class:`hybrid.HybridAutomaton` that ``hybrid.stochastic.simulate_automaton`` (and ``vibro mc --filter``) runs.

Both filters are second order in form: for each noise k the automaton gains the output ``z_k`` and its time
integral ``z_k_int`` (``d z_int / dt = z``), and

    d z = (-omega_f**2 z_int - b z) dt + b L dW,       W standard Wiener, L L^T = the white noise's covariance

* **Ornstein-Uhlenbeck** (first order, ``ou_filter``): omega_f = 0, b = ``alpha``. ``z`` is then an OU process,
  ``dz = -alpha z dt + alpha L dW``, with autocovariance (alpha/2) L L^T exp(-alpha |s|) and spectral density
  S(w) = S_white alpha**2 / (alpha**2 + w**2). The integral ``z_int`` plays no part in the dynamics; it makes
  (z_int, z) a position-velocity pair, so the ``splitting`` scheme (no energy pumping) runs filtered models.
* **Band-pass** (second order, ``bandpass_filter``): b = 2 ``zeta`` ``omega_f``, the half-power bandwidth, and
  S(w) = S_white b**2 w**2 / ((omega_f**2 - w**2)**2 + b**2 w**2): gain 1 at the centre frequency omega_f.

**Normalisation.** The gain b makes the integral of the autocovariance equal that of the white noise the filter
replaces, and the gain at the pass band 1, so that as the bandwidth grows (alpha -> inf, or zeta -> inf) the
output tends to the model's white noise with the *same intensity*. For an :class:`ImpactOscillator` with
E[xi_k(t) xi_l(t+s)] = 2 D_kl delta(s) this means L L^T = 2 D: with a scalar D,

    dz = -alpha z dt + sqrt(2 alpha**2 D) dW,    Var z = alpha D,   S(w) = (D / pi) alpha**2 / (alpha**2 + w**2)

and for the band-pass Var z = 2 zeta omega_f D. For a general automaton, whose mode noise matrices multiply
independent standard white noises (E[w w] = delta), L = I: Var z = alpha / 2. The limit of coloured noise is the
Stratonovich reading of the white-noise model (Wong-Zakai), which is how ``simulate_automaton`` reads it by default.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import sympy as sp

from hybrid.automaton import HybridAutomaton, Mode, Transition, real_symbol
from hybrid.errors import ModelError, ParameterError

from .oscillator import ImpactOscillator, X, Y

FILTER_KINDS = ("bandpass", "ou")
"""Names accepted by :func:`attach_filter` (and ``vibro mc --filter``)."""


@dataclass(frozen=True)
class FilteredAutomaton(HybridAutomaton):
    """A :class:`HybridAutomaton` whose noise enters through filter states, with checked filter parameters.

    Built by :func:`ou_filter`, :func:`bandpass_filter` or :func:`attach_filter`; it is a ``HybridAutomaton`` for
    every engine. Beyond it, :meth:`resolve_parameters` refuses a bandwidth that is not a positive finite number
    (and a negative noise intensity of the model it wraps), so an override such as ``params={"alpha": -1}`` is
    refused in one line instead of diverging.

    Attributes
    ----------
    filter : mapping
        ``kind``, the filter's parameter and state names, the filtered noises and the base model's description.
    bandwidths : tuple of str
        The filter's parameters: each must be a positive finite number.
    positive, nonnegative : tuple of str
        The wrapped model's parameters that must be > 0 (barrier distances; inf allowed) or >= 0 (intensities).
    oscillator : ImpactOscillator or None
        The oscillator the filter was attached to (None for a general automaton): its potential, walls and
        restitution law, for the coloured-noise density solver (``averaging.phase_plane.coloured``).
    """

    filter: Mapping = field(default_factory=dict)
    bandwidths: tuple = ()
    positive: tuple = ()
    nonnegative: tuple = ()
    oscillator: object = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "filter", MappingProxyType(dict(self.filter)))
        self._check(dict(self.parameters))

    def _check(self, values: Mapping[str, float]) -> None:
        for k in self.bandwidths:
            if not (values[k] > 0 and math.isfinite(values[k])):  # NaN fails this test too
                raise ParameterError(f"{k}={values[k]!r} must be a positive finite number (a filter bandwidth or "
                                     "frequency)")
        for k in self.positive:
            if k in values and not values[k] > 0:
                raise ParameterError(f"{k}={values[k]!r} must be > 0 (a barrier distance; inf for none)")
        for k in self.nonnegative:
            if k in values and not values[k] >= 0:
                raise ParameterError(f"{k}={values[k]!r} must be >= 0 (a noise intensity)")

    def resolve_parameters(self, overrides: Mapping[str, float] | None = None) -> dict[str, float]:
        """Defaults updated with ``overrides``; raises :class:`ParameterError` on a bandwidth <= 0 or NaN.

        Examples
        --------
        >>> from models import DuffingImpact
        >>> ou_filter(DuffingImpact(), alpha=2.0).resolve_parameters({"alpha": 5})["alpha"]
        5.0
        """
        values = super().resolve_parameters(overrides)
        self._check(values)
        return values

    def describe(self) -> dict:
        """A JSON-friendly description: the filter and the automaton (see :func:`describe_automaton`)."""
        from .automata import describe_automaton

        return {**describe_automaton(self), "filter": dict(self.filter)}


def _bandwidth(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name}={value!r} is not a number") from exc
    if not (v > 0 and math.isfinite(v)):
        raise ParameterError(f"{name}={value!r} must be a positive finite number (a filter bandwidth or frequency)")
    return v


@dataclass
class _Base:
    """A model reduced to what a filter needs: per mode, the flow and the n x m matrix the white noises multiply."""

    states: tuple
    parameters: dict
    modes: list  # (name, flow tuple, input matrix n x m)
    transitions: list
    observables: dict
    initial_mode: str
    L: sp.Matrix  # m x m: the white noises are L w with w standard
    positive: tuple
    nonnegative: tuple
    description: dict


def _from_oscillator(model: ImpactOscillator) -> _Base:
    A = model.to_automaton()
    m = len(model.f)
    root_eps = sp.sqrt(model.epsilon)
    G = sp.zeros(2, m)
    for k, fk in enumerate(model.f):
        G[1, k] = root_eps * fk
    D = model.intensity
    if D.is_diagonal():
        L = sp.diag(*[sp.sqrt(2 * D[k, k]) for k in range(m)])
    else:
        try:
            L = (2 * D).cholesky(hermitian=False)
        except Exception as exc:  # sympy cannot factor it symbolically
            raise ModelError(f"cannot factor the intensity matrix 2 D = {(2 * D).tolist()} symbolically; give a "
                             "diagonal intensity (independent noises) to filter this model") from exc
    flow = tuple(A.modes[0].flow)
    return _Base(
        states=(X, Y), parameters=dict(model.params), modes=[("free", flow, G)], transitions=list(A.transitions),
        observables=dict(A.observables), initial_mode=A.initial_mode, L=L,
        positive=tuple(k for k in model._positive if k in model.params),
        nonnegative=tuple(k for k in model._nonnegative if k in model.params), description=model.describe(),
    )


def _noise_matrix(mode, n: int) -> sp.Matrix:
    if mode.noise is None:
        return sp.zeros(n, 1)
    rows = [list(r) if isinstance(r, (tuple, list)) else [r] for r in mode.noise]
    if len({len(r) for r in rows}) != 1:
        raise ModelError(f"mode {mode.name!r}: the noise rows must have equally many entries (one per noise)")
    return sp.Matrix(rows)


def _from_automaton(automaton: HybridAutomaton) -> _Base:
    from .automata import describe_automaton

    n = len(automaton.states)
    modes = [(md.name, tuple(md.flow), _noise_matrix(md, n)) for md in automaton.modes]
    widths = {G.shape[1] for _, _, G in modes}
    if len(widths) != 1:
        raise ModelError(f"every mode must have the same number of noises to attach a filter, got {sorted(widths)}")
    m = widths.pop()
    base = automaton.filter.get("base") if isinstance(automaton, FilteredAutomaton) else None
    return _Base(
        states=tuple(automaton.states), parameters=dict(automaton.parameters), modes=modes,
        transitions=list(automaton.transitions), observables=dict(automaton.observables),
        initial_mode=automaton.initial_mode, L=sp.eye(m),
        positive=tuple(getattr(automaton, "positive", ())) + tuple(getattr(automaton, "bandwidths", ())),
        nonnegative=tuple(getattr(automaton, "nonnegative", ())),
        description=base or describe_automaton(automaton),
    )


def _base_of(model) -> _Base:
    if isinstance(model, ImpactOscillator):
        return _from_oscillator(model)
    if isinstance(model, HybridAutomaton):
        return _from_automaton(model)
    raise ModelError(f"a filter attaches to an ImpactOscillator or a HybridAutomaton, got {type(model).__name__}")


def _extend_reset(reset, n_new: int):
    """A callable reset on the longer state: the filter states pass through an impact unchanged."""
    def extended(state, params, _reset=reset, _n=n_new):
        state = np.asarray(state, dtype=float)
        out = np.array(state, dtype=float)
        out[: state.size - _n] = _reset(state[: state.size - _n], params)
        return out

    return extended


def _build(model, kind: str, values: dict, names: dict, b_expr, w2_expr, state: str) -> FilteredAutomaton:
    base = _base_of(model)
    taken = {s.name for s in base.states} | set(base.parameters) | {"t"}
    clash = sorted({names.get(k, k) for k in values} & taken)
    if clash:
        raise ModelError(f"the filter's parameter names {clash} are already used by the model; rename them, e.g. "
                         f"{kind}_filter(model, ..., names={{'{clash[0]}': '{clash[0]}_f'}})")
    n = len(base.states)
    m = base.L.shape[1]
    if all(G.is_zero_matrix for _, _, G in base.modes):
        raise ModelError("the model has no noise to filter (every noise coefficient is zero)")
    if not isinstance(state, str) or not state.isidentifier():
        raise ModelError(f"state={state!r} must be a Python identifier (the name of the filter output)")
    zs = [real_symbol(state if m == 1 else f"{state}{k + 1}") for k in range(m)]
    qs = [real_symbol(f"{z.name}_int") for z in zs]
    new = [s for pair in zip(qs, zs) for s in pair]
    clash = sorted({s.name for s in new} & taken)
    if clash:
        raise ModelError(f"the filter's state names {clash} are already used by the model; pass state='...' with "
                         "another name")
    z = sp.Matrix(zs)
    modes = []
    for name, flow, G in base.modes:
        drive = G * z  # the filter output takes the place of the white noise where it acted
        new_flow = [sp.sympify(flow[i]) + drive[i] for i in range(n)]
        noise = [[sp.Integer(0)] * m for _ in range(n)]
        for k in range(m):
            new_flow += [zs[k], -w2_expr * qs[k] - b_expr * zs[k]]
            noise += [[sp.Integer(0)] * m, [b_expr * base.L[k, j] for j in range(m)]]
        modes.append(Mode(name, tuple(new_flow), tuple(tuple(r) for r in noise)))
    transitions = []
    for tr in base.transitions:
        reset = _extend_reset(tr.reset, 2 * m) if callable(tr.reset) else tuple(tr.reset) + tuple(new)
        transitions.append(Transition(tr.name, tr.source, tr.target, tr.guard, tr.direction, reset, tr.priority))
    params = {**base.parameters, **{names.get(k, k): v for k, v in values.items()}}
    info = {"kind": kind, "parameters": {k: names.get(k, k) for k in values}, "outputs": [s.name for s in zs],
            "integrals": [s.name for s in qs], "noises": m, "base": base.description}
    return FilteredAutomaton(
        states=tuple(base.states) + tuple(new), parameters=params, modes=modes, transitions=transitions,
        initial_mode=base.initial_mode, observables=base.observables, filter=info,
        bandwidths=tuple(names.get(k, k) for k in values), positive=base.positive, nonnegative=base.nonnegative,
        oscillator=model if isinstance(model, ImpactOscillator) else None,
    )


def ou_filter(model, alpha: float = 1.0, *, state: str = "z", names: Mapping[str, str] | None = None
              ) -> FilteredAutomaton:
    """The model driven by Ornstein-Uhlenbeck (exponentially correlated) noise instead of white noise.

    Every white noise of ``model`` is replaced by the output z of ``dz = -alpha z dt + alpha L dW`` (L L^T the white
    noise's covariance), normalised so that z tends to that white noise as ``alpha`` -> inf (module docstring).
    For an :class:`ImpactOscillator` with intensity D: ``dz = -alpha z dt + sqrt(2 alpha**2 D) dW``, Var z =
    alpha D, correlation time 1 / alpha.

    Parameters
    ----------
    model : ImpactOscillator or HybridAutomaton
        The white-noise model (every mode with the same number of noises).
    alpha : float
        Bandwidth (inverse correlation time) > 0; the default of the automaton parameter ``alpha``.
    state : str
        Name of the filter output state (``z``; ``z1, z2, ...`` for several noises); its integral is
        ``z_int`` (a bookkeeping state that makes the ``splitting`` scheme applicable).
    names : mapping, optional
        Rename the parameter, e.g. ``{"alpha": "alpha_f"}`` when the model already uses ``alpha``.

    Returns
    -------
    FilteredAutomaton
        States: the model's, then (z_int, z) per noise; parameters: the model's and ``alpha``.

    Raises
    ------
    ParameterError
        When ``alpha`` is not a positive finite number.
    ModelError
        When the model has no noise, or a name clashes.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> A = ou_filter(DuffingImpact(), alpha=4.0)
    >>> [s.name for s in A.states], A.parameters["alpha"]
    (['x', 'y', 'z_int', 'z'], 4.0)
    >>> A.modes[0].flow[1]
    -a*x - b*x**3 - c*y + z
    """
    a = _bandwidth("alpha", alpha)
    names = dict(names or {})
    sym = real_symbol(names.get("alpha", "alpha"))
    return _build(model, "ou", {"alpha": a}, names, sym, sp.Integer(0), state)


def bandpass_filter(model, zeta: float = 0.5, omega_f: float = 1.0, *, state: str = "z",
                    names: Mapping[str, str] | None = None) -> FilteredAutomaton:
    """The model driven by band-pass filtered noise: the velocity output of a damped linear oscillator.

    Every white noise of ``model`` is replaced by z with ``z_int'' + 2 zeta omega_f z_int' + omega_f**2 z_int =
    2 zeta omega_f L w`` and z = z_int' (module docstring): a pass band centred at ``omega_f`` with gain 1 and
    half-power width b = 2 zeta omega_f, spectral density S_white b**2 w**2 / ((omega_f**2 - w**2)**2 + b**2 w**2),
    tending to the white noise as zeta -> inf. For an :class:`ImpactOscillator` with intensity D, Var z = b D.

    Parameters
    ----------
    model : ImpactOscillator or HybridAutomaton
    zeta : float
        Damping ratio of the filter (> 0): the relative bandwidth.
    omega_f : float
        Centre frequency (> 0).
    state : str
        Name of the filter output (the filter's velocity); its integral is ``z_int``.
    names : mapping, optional
        Rename the parameters ``zeta`` and ``omega_f``.

    Returns
    -------
    FilteredAutomaton

    Raises
    ------
    ParameterError
        When ``zeta`` or ``omega_f`` is not a positive finite number.

    Examples
    --------
    >>> from models.automata import impact_pair
    >>> A = bandpass_filter(impact_pair(), zeta=0.3, omega_f=2.0)
    >>> [s.name for s in A.states][4:], A.filter["kind"]
    (['z1_int', 'z1', 'z2_int', 'z2'], 'bandpass')
    """
    zt, wf = _bandwidth("zeta", zeta), _bandwidth("omega_f", omega_f)
    names = dict(names or {})
    zsym, wsym = real_symbol(names.get("zeta", "zeta")), real_symbol(names.get("omega_f", "omega_f"))
    return _build(model, "bandpass", {"zeta": zt, "omega_f": wf}, names, 2 * zsym * wsym, wsym**2, state)


def attach_filter(model, kind: str, **settings) -> FilteredAutomaton:
    """Attach the filter named ``kind`` (``'ou'`` or ``'bandpass'``) with its keyword settings.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> attach_filter(DuffingImpact(), "ou", alpha=3.0).parameters["alpha"]
    3.0
    """
    if kind == "ou":
        return ou_filter(model, **settings)
    if kind == "bandpass":
        return bandpass_filter(model, **settings)
    raise ParameterError(f"unknown filter {kind!r}; use one of {list(FILTER_KINDS)}")


__all__ = ["FILTER_KINDS", "FilteredAutomaton", "attach_filter", "bandpass_filter", "ou_filter"]
