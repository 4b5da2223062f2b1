"""Oscillator ensembles through the automaton kernel: ``ImpactOscillator`` as a front end of one generated path.

Every CPU ensemble of an oscillator (``simulate_ensemble``, ``drive_paths``, ``sample_paths``) builds
``model.to_automaton()`` and runs it on the kernel that :mod:`._auto_codegen` generates for every automaton, with
the automaton scheme of :data:`AUTOMATON_SCHEME_OF`:

* ``milstein`` as ``symplectic``: the velocity's Milstein step, then the free flight of the position at the new
  velocity with each wall crossing located exactly and the restitution law applied there;
* ``splitting`` as ``baoab``: kick by the force, half flight, the velocity's exact Ornstein-Uhlenbeck step, half
  flight, kick;
* ``em`` as ``em``: the straight segment of the step (the position's flight at the old velocity, the velocity's
  increment spread linearly), crossings located on it;
* ``naive`` as ``naive``: symplectic Euler-Maruyama whose crossing resets the state on the wall and drops the rest
  of the step (the anti-pattern, for charts).

The restitution law's numbers are lifted into parameters (one compiled kernel for every r or V_C); a law given as a
Python callable is compiled by numba and called by the reset (that module is built in memory). Each chunk's
automaton statistics are converted into the rows of :class:`EnsembleStatistics`, so checkpoints, merging,
confidence intervals and the result checks are shared.
"""

from __future__ import annotations

import dataclasses
import hashlib
import time
from pathlib import Path

import numpy as np
import sympy as sp

from hybrid.automaton import real_symbol
from hybrid.errors import ModelError, ParameterError

from . import _auto_codegen, _auto_exec, _kernel_modules, _rng
from ._statistics import COUNTS, SUMS

KERNELS = ("auto", "automaton")
"""Values of ``MonteCarloAlgorithm.kernel``: both run every CPU ensemble on the automaton kernel (``auto`` is kept
for the GPU, where ``automaton`` is refused)."""

_X, _Y = real_symbol("x"), real_symbol("y")
_SUMMED = ("x2", "y2", "below")
_JOINT = ("x", "y")  # the joint histogram's coordinates: neither summed nor histogrammed on their own


AUTOMATON_SCHEME_OF = {"milstein": "symplectic", "splitting": "baoab", "em": "em", "naive": "naive"}
"""The automaton scheme that takes each oscillator scheme's steps (same draws, same order of operations).

``em`` is the automaton's Euler-Maruyama on the straight segment of the step (for an oscillator: the position's
flight at the old velocity, the velocity's increment spread linearly over the step); after a crossing the rest of
the step is a fresh Euler-Maruyama step of what is left of it from the reset state. ``naive`` drops the rest of the
step at a crossing.

Examples
--------
>>> AUTOMATON_SCHEME_OF["splitting"]
'baoab'
"""


def check_model(model, scheme) -> None:
    """Refuse, in one line, what the automaton kernel cannot run: a scheme it has no counterpart of, a model without
    a closed-form potential (the energy H is an observable of every ensemble), a model the scheme refuses."""
    if scheme.name not in AUTOMATON_SCHEME_OF:
        raise ParameterError(f"scheme {scheme.name!r} has no automaton kernel; use one of "
                             f"{sorted(AUTOMATON_SCHEME_OF)}")
    if model.energy_expr is None:
        raise ModelError(
            f"sympy cannot integrate g = {model.g} in closed form, and the Monte Carlo kernel needs the potential G(x) "
            "for the energy H; declare a restoring force with an elementary antiderivative"
        )
    scheme.check(model)


def kernel_module(model, scheme: str):
    """The loaded automaton kernel of ``model`` for the oscillator scheme ``scheme`` (the ensembles' module: its
    ``drive`` and ``record_chunk`` are compiled at their first call only) and its parameter vector."""
    auto_scheme = AUTOMATON_SCHEME_OF[scheme]
    automaton, _, src, st = _generated(model, auto_scheme)
    name, user_law = kernel_name(model, auto_scheme, src)
    module, _ = _kernel_modules.load_source(name, src, user_law, label=f"{model.name}/{auto_scheme}")
    return module, np.array([automaton.parameters[k] for k in st.params], dtype=float)


def generate_source(model, scheme, cache: bool = True) -> tuple[str, tuple[float, ...], object | None]:
    """The source of the Monte Carlo kernel of ``model`` and ``scheme`` (a name or Scheme), generated from
    ``model.to_automaton()``, with the restitution law's numbers and its numba-compiled callable (or None).

    The law's numbers are parameters of the kernel (``_law0, ...``), so the source is the same for every value;
    ``cache`` is kept for compatibility (a callable law's kernel is never cached on disk).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> src, law_values, _ = generate_source(DuffingImpact(), "milstein")
    >>> "def run_chunk" in src, law_values[0]
    (True, 0.4)
    """
    from ._schemes import get_scheme

    sch = get_scheme(scheme)
    _kernel_modules.refuse_forced(model)
    check_model(model, sch)
    automaton, _, src, _ = _generated(model, AUTOMATON_SCHEME_OF[sch.name])
    _, user_law = kernel_name(model, AUTOMATON_SCHEME_OF[sch.name], src)
    law = tuple(float(v) for k, v in automaton.parameters.items() if k.startswith("_law"))
    return src, law, user_law


@dataclasses.dataclass
class Kernel:
    """A loaded Monte Carlo kernel: its module (``run_chunk``, ``drive``, ``record_chunk``), source, identity and
    the wall time of :func:`build_kernel` (generation and compile, or load from numba's disk cache)."""

    module: object
    path: object
    param_names: tuple
    law_values: tuple
    scheme: str
    source: str
    compile_time: float = float("nan")
    identity: dict = dataclasses.field(default_factory=dict)

    @property
    def run_chunk(self):
        return self.module.run_chunk


def build_kernel(model, scheme, cache: bool = True, warm: bool = True) -> Kernel:
    """Generate and load (and with ``warm`` compile, or load from numba's cache) the kernel of ``model`` and
    ``scheme``: the one :func:`~hybrid.stochastic.simulate_ensemble` runs.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> k = build_kernel(DuffingImpact(), "splitting")  # doctest: +SKIP
    """
    from ._schemes import get_scheme

    t0 = time.perf_counter()
    sch = get_scheme(scheme)
    src, law, _ = generate_source(model, sch, cache)
    if warm:  # the smallest run: one path, one step
        s = dict(n_chunks=1, chunk_paths=1, paths=1, xy_bins=None, xy_range=None, bins=1, v_bins=1, n_burn=0,
                 n_samp=1, stride=1, dt=1e-3, x0=[0.0, 0.0], seed=0)
        kern = compile_job(*plan(model, s, 1.0, 1.0, (1.0, 1.0), sch.name))
        module, identity = kern.module, kern.identity
    else:
        module, _ = kernel_module(model, sch.name)
        identity = {}
    return Kernel(module, getattr(module, "__file__", None), tuple(model.params), law, sch.name, src,
                  time.perf_counter() - t0, identity)


class AutomatonKernel:
    """What the oscillator runner needs of a kernel: the loaded module, its path, identity and build time."""

    def __init__(self, module, identity: dict, compile_time: float):
        self.module, self.identity, self.compile_time = module, identity, compile_time
        self.path = getattr(module, "__file__", None)


class AutomatonChunks:
    """An oscillator ensemble's automaton job and the conversion of its chunks' statistics into oscillator rows.

    The restitution law gives e at the first impact whose coefficient fell outside (0, 1].
    """

    def __init__(self, job: _auto_exec.AutomatonJob, settings: dict, law, transitions: tuple):
        self.job, self.law = job, law
        self.name = job.name
        self.seed = settings["seed"]
        self.bins, self.v_bins = settings["bins"], settings["v_bins"]
        self.xy_bins = settings["xy_bins"]
        self.left = transitions.index("left") if "left" in transitions else -1
        self.right = transitions.index("right") if "right" in transitions else -1

    def rows(self, ids, outs):
        """The automaton kernel's per-chunk outputs ``outs`` (dicts of its arrays) of chunks ``ids`` as the
        per-chunk arrays of :class:`EnsembleStatistics`: ``(ids, paths, hist, xy, v, counts, sums)``."""
        n, bins, vb = len(ids), self.bins, self.v_bins
        nx, ny = self.xy_bins if self.xy_bins is not None else (1, 1)
        hist = np.zeros((n, bins), np.int64)
        xyh = np.zeros((n, ny, nx), np.int64)
        vh = np.zeros((n, vb), np.int64)
        cnt = np.zeros((n, len(COUNTS)), np.int64)
        sm = np.zeros((n, len(SUMS)))
        c, s = COUNTS.index, SUMS.index
        for i, out in enumerate(outs):
            h, counts, sums, events = out["hist"][0], out["counts"], out["sums"], out["events"]
            hist[i] = h[1: bins + 1]
            if self.xy_bins is not None:
                xyh[i] = out["jhist"]
            vh[i] = out["vhist"][:, :vb].sum(axis=0)
            row = {"samples": counts[0], "below": int(round(sums[3])), "h_over": h[bins + 1], "h_under": h[0],
                   "xy_out": counts[4], "v_over": out["vhist"][:, vb].sum(), "violations": counts[2],
                   "stuck": counts[1], "nonfinite": counts[3], "bad_e": counts[5], "v_under": 0,
                   "impacts_left": events[self.left] if self.left >= 0 else 0,
                   "impacts_right": events[self.right] if self.right >= 0 else 0}
            for key, value in row.items():
                cnt[i, c(key)] = value
            sm[i, s("H")], sm[i, s("x2")], sm[i, s("y2")] = sums[0], sums[1], sums[2]
            sm[i, s("impact_speed")] = out["vsum"].sum()
            if counts[5]:
                v = float(out["fbad"][0])
                sm[i, s("bad_e_speed")] = v
                sm[i, s("bad_e_value")] = float(np.asarray(self.law.coefficient(np.array([v])), dtype=float)[0])
        ids = np.asarray(ids, np.int64)
        return ids, self.job.npaths[ids], hist, xyh, vh, cnt, sm


def plan(model, settings: dict, h_scale: float, v_scale: float, xy_scales: tuple, scheme: str = "milstein") -> tuple:
    """The automaton job of the oscillator run ``settings``, nothing compiled: ``(AutomatonChunks, identity)``, so
    that a checkpoint of another run is refused before a kernel is built (:func:`compile_job` compiles).

    ``h_scale``, ``v_scale`` and ``xy_scales`` (x_scale, y_scale) are the oscillator runner's bin scales."""
    return _job(model, settings, h_scale, v_scale, xy_scales, scheme)


def compile_job(chunks, identity: dict, t0: float | None = None):
    """Compile (or load from the disk cache) the kernel of ``chunks``: an :class:`AutomatonKernel` whose
    ``compile_time`` counts from ``t0`` (default: now)."""
    t0 = time.perf_counter() if t0 is None else t0
    module = chunks.job.module()
    chunks.job.run(0, _rng.chunk_states(0, 1)[0], burn=1, samples=1, module=module)  # compile (or load) here
    return AutomatonKernel(module, identity, time.perf_counter() - t0)


def _job(model, settings: dict, h_scale: float, v_scale: float, xy_scales: tuple, scheme: str) -> tuple:
    """The automaton job of the run ``settings`` (nothing compiled) as :class:`AutomatonChunks`, and the kernel's
    identity (its source and the restitution law's numbers, for checkpoints)."""
    auto_scheme = AUTOMATON_SCHEME_OF[scheme]
    automaton, observables, src, st = _generated(model, auto_scheme)
    name, user_law = kernel_name(model, auto_scheme, src)
    s = settings
    cp, paths = s["chunk_paths"], s["paths"]
    npaths = _auto_exec.chunk_sizes(paths, cp)
    xy = s["xy_bins"]
    (xlo, _), (ylo, _) = s["xy_range"] if xy is not None else ((0.0, 1.0), (0.0, 1.0))
    nx, ny = xy if xy is not None else (1, 1)
    n_obs = len(observables)
    # one phase row (no sections) and no event log in oscillator ensembles
    shapes = _auto_exec.chunk_shapes(n_obs, s["bins"] + 2, (nx, ny), len(st.transitions), s["v_bins"], 1, cp, 0)
    names = list(observables)
    ones = np.ones(n_obs)
    scale = ones.copy()
    scale[0] = h_scale
    bins = np.ones(n_obs, dtype=np.int64)
    bins[0] = s["bins"]
    args = dict(
        n_burn=s["n_burn"], n_samp=s["n_samp"], stride=s["stride"], dt=s["dt"], x0=np.array(s["x0"], dtype=float),
        mode0=0, p=np.array([automaton.parameters[k] for k in st.params], dtype=float),
        obs_lo=np.zeros(n_obs), obs_scale=scale, obs_bins=bins,
        jx=names.index("x") if xy is not None else -1, jy=names.index("y") if xy is not None else -1,
        j_lo=np.array([xlo, ylo], dtype=float), j_scale=np.array(xy_scales, dtype=float),
        j_bins=np.array([nx, ny], dtype=np.int64), v_scale=v_scale, v_bins=s["v_bins"], phases=0, phase_steps=1,
    )
    job = _auto_exec.AutomatonJob(name, src, args, npaths, shapes, label=f"{model.name}/{auto_scheme}",
                                  user_law=user_law)
    # the law's numbers in full precision (they are parameters of the kernel, not in its source); a callable's code
    fn = getattr(model.restitution, "callable", None)
    law = ([float.hex(float(v)) for k, v in automaton.parameters.items() if k.startswith("_law")] if fn is None
           else [_kernel_modules.callable_digest(fn)])
    key = hashlib.sha256((src + _kernel_modules.dependency_hash(src)).encode()).hexdigest()[:32]
    identity = {"kernel": key, "law": [model.restitution.spec(), *law]}
    return AutomatonChunks(job, s, model.restitution, tuple(t.name for t in st.transitions)), identity


def run_on_cuda(model, scheme: str, settings: dict, scales: dict, *, keyed: dict, precision: str = "f64",
                threads_per_block: int = 128, launch_steps=None, checkpoint=None, resume: bool = False,
                checkpoint_every: int = 4):
    """The oscillator ensemble of ``settings`` on the GPU: the automaton's CUDA target
    (:class:`~hybrid.stochastic._auto_cuda.CudaRun`, the same generated step code with counter-based normals)
    runs the job the CPU route runs, and its per-chunk rows become the rows of :class:`EnsembleStatistics`.
    ``keyed``: the settings that decide the numbers (the run's identity in the checkpoint, with the kernel's).

    Checkpoints are the automaton engine's (checksummed, tied to the run's settings, the kernel, the precision and
    the device source); the numbers do not depend on ``threads_per_block`` or ``launch_steps``. Returns the
    statistics before the runner's result checks.
    """
    from . import _auto_cuda
    from ._statistics import EnsembleStatistics

    t0 = time.perf_counter()
    chunks, identity = _job(model, settings, scales["h_scale"], scales["v_scale"],
                            (scales["x_scale"], scales["y_scale"]), scheme)
    auto_scheme = AUTOMATON_SCHEME_OF[scheme]
    automaton, observables, _, st = _generated(model, auto_scheme)
    device = _auto_cuda.CudaRun(chunks.job, automaton, auto_scheme, observables, "stratonovich", summed=_SUMMED,
                                phases=0, n_trans=len(st.transitions), seed=settings["seed"], precision=precision,
                                threads_per_block=threads_per_block)
    compile_time = time.perf_counter() - t0  # generation and load; numba-cuda compiles at the first launch
    settings["identity"] = {**identity, "params": {k: float.hex(float(model.params[k])) for k in tuple(model.params)}}
    ckdir = Path(checkpoint) if checkpoint is not None else None
    if ckdir is not None:
        if resume and (ckdir / _auto_exec.ENSEMBLE_CHECKPOINT_FILE).exists():
            raise ParameterError(f"{ckdir} holds a checkpoint of the CPU scheduler, whose random streams differ; "
                                 "resume it without --scheduler cuda, or use another --checkpoint directory")
        _auto_exec.check_directory(ckdir, resume)
    run_id = _auto_exec.identity({**keyed, **settings["identity"], "precision": precision,
                                  "device_source": device.name})
    rows = chunks.job.zero_rows(settings["n_chunks"])
    device_settings = device.run(rows, run_id=run_id, checkpoint=ckdir, resume=resume,
                                 checkpoint_every=checkpoint_every, launch_steps=launch_steps)
    ids = np.arange(settings["n_chunks"], dtype=np.int64)
    settings.update(device_settings)
    stats = EnsembleStatistics.empty(settings)
    stats.add_chunks(*chunks.rows(ids, [{k: v[i] for k, v in rows.items()} for i in ids]))
    stats.wall_time = device_settings["device_seconds"]
    stats.compile_time = compile_time
    return stats


_USER_LAWS: dict[int, object] = {}  # keeps user callables alive, so the id in a kernel name is never reused


def kernel_name(model, scheme: str, src: str) -> tuple[str, object | None]:
    """The module name of the automaton kernel ``src`` and, for a restitution law given as a Python callable, the
    callable compiled by numba (the module's name then carries the callable's digest, or its id where it has none).

    The source of such a kernel calls ``_user_law`` and is the same for every callable law, as the source of an
    expression law is the same for every value of its numbers; the module binds the compiled callable.
    """
    name = f"vibro_auto_{scheme}_{_auto_codegen.kernel_key(src)}"
    fn = getattr(model.restitution, "callable", None)
    if fn is None:
        return name, None
    _, _, jitted = _kernel_modules._law_code(model.restitution)  # a one-line RestitutionError where numba cannot
    _USER_LAWS.setdefault(id(fn), fn)
    return f"{name}_law{_kernel_modules.callable_digest(fn) or format(id(fn), 'x')}", jitted


def with_user_law(automaton):
    """``automaton`` with the walls' numerical reset (a callable restitution law) made symbolic: y -> -e(|y|) y
    with e the function :data:`~hybrid.stochastic._kernel_modules.USER_LAW` that the kernel binds, checked in (0, 1]."""
    from hybrid.automaton import HybridAutomaton, Transition

    e = sp.Function(_kernel_modules.USER_LAW)(sp.Abs(_Y))
    transitions = [Transition(t.name, t.source, t.target, t.guard, t.direction, (_X, _Y), t.priority)
                   for t in automaton.transitions]
    out = HybridAutomaton(automaton.states, dict(automaton.parameters), list(automaton.modes), transitions,
                          initial_mode=automaton.initial_mode, observables=dict(automaton.observables))
    for tr in transitions:  # set past the declaration's checks, which refuse unknown functions in a user's model
        object.__setattr__(tr, "reset", (_X, -e * _Y))
        object.__setattr__(tr, "check", sp.And(e > 0, e <= 1))
    return out


_GENERATED: dict = {}


def _generated(model, scheme: str = "symplectic"):
    """The lifted automaton, its observables, the kernel source and structure of ``model`` (memoised: the sympy
    work costs 40-90 ms, as much as a short run)."""
    user = getattr(model.restitution, "callable", None) is not None
    law = (sp.Function(_kernel_modules.USER_LAW)(sp.Abs(_Y)) if user
           else sp.sympify(model.restitution.expression(sp.Abs(_Y))))
    # srepr keeps every float in full precision (str and the fingerprint keep 15 digits)
    declared = (model.g, model.h, tuple(model.f), sp.Matrix(model.intensity), model.epsilon, model.barrier_exprs)
    key = (scheme, type(model).__name__, sp.srepr(declared), type(model.restitution).__name__, sp.srepr(law),
           tuple(float.hex(float(a)) for a in sp.preorder_traversal(law) if isinstance(a, sp.Float)),
           tuple((k, float.hex(float(v))) for k, v in model.params.items()))
    if key not in _GENERATED:
        automaton = with_user_law(model.to_automaton()) if user else lift_law_numbers(model.to_automaton())
        energy = model.energy_expr
        walls = [b for b in (model.barrier_exprs or ()) if b.is_finite is not False and b not in (sp.oo, -sp.oo)]
        if walls:
            g_bar = sp.Min(*[model.potential_expr.subs(_X, w) for w in walls])
            below = sp.Piecewise((1, energy < g_bar), (0, True))
        else:
            below = sp.Integer(1)
        observables = {"H": energy, "x2": _X**2, "y2": _Y**2, "below": below, "x": _X, "y": _Y}
        # a callable law's module is built in memory: numba cannot cache its machine code on disk
        src, st = _auto_codegen.generate_source(automaton, scheme, observables, summed=_SUMMED,
                                                joint_only=_JOINT, cache=not user)
        if len(_GENERATED) > 256:
            _GENERATED.clear()
        _GENERATED[key] = (automaton, observables, src, st)
    return _GENERATED[key]


def lift_law_numbers(automaton):
    """The automaton with every number in its resets and checks (the restitution law's r, V_C, ...) made a parameter
    ``_law0, _law1, ...``: the kernel's source, and so its compiled code, is then the same for every value.

    Examples
    --------
    >>> from models import DuffingImpact, Newton
    >>> a = lift_law_numbers(DuffingImpact(restitution=Newton(0.7)).to_automaton())
    >>> [k for k in a.parameters if k.startswith("_law")]
    ['_law0']
    """
    from hybrid.automaton import HybridAutomaton, Transition

    values: dict = {}

    def lift(expr):
        if expr is None:
            return None
        subs = {}
        for atom in sp.preorder_traversal(expr):
            if isinstance(atom, sp.Float) and atom not in subs:
                if atom not in values:
                    values[atom] = real_symbol(f"_law{len(values)}")
                subs[atom] = values[atom]
        return expr.xreplace(subs)

    transitions = [Transition(t.name, t.source, t.target, t.guard, t.direction,
                              tuple(lift(r) for r in t.reset) if t.symbolic_reset else t.reset, t.priority,
                              check=lift(t.check)) for t in automaton.transitions]
    params = dict(automaton.parameters)
    params.update({sym.name: float(num) for num, sym in values.items()})
    return HybridAutomaton(automaton.states, params, list(automaton.modes), transitions,
                           initial_mode=automaton.initial_mode, observables=dict(automaton.observables))
