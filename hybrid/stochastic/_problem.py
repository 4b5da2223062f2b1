"""What to simulate, how, and where: the three groups of settings of a Monte Carlo ensemble.

The split follows the separation of problem and algorithm in SciML's ``EnsembleProblem`` / ``solve``: the problem
(model, initial state, time window, observed statistics) says *what* is computed and does not change when the
scheme or the machine does; the algorithm (scheme, step) says how the SDE is discretised and decides the
discretisation bias; the execution (paths, seed, chunks, scheduler, checkpoint, work limits) says where and how
much. Only the first two groups and ``paths``, ``seed`` and ``chunk_paths`` change a number; the rest never does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hybrid.errors import VibroWarning
from hybrid.sizes import MAX_MEMORY, MAX_PATH_STEPS  # the shared size estimator's default limits


class StepSizeWarning(VibroWarning):
    """The step is legal but coarse: the result carries a visible discretisation bias."""


class ChatteringWarning(VibroWarning):
    """Impacts happen on a sizeable share of the steps: the paths chatter against a wall at the step scale."""


def positive_int(name: str, value) -> int:
    """``value`` as a positive int (an integral float such as 4.0 too), or a one-line :class:`ParameterError`.

    Examples
    --------
    >>> positive_int("paths", 4.0)
    4
    """
    from hybrid.errors import ParameterError

    if isinstance(value, bool):
        raise ParameterError(f"{name}={value!r} must be a positive integer")
    try:
        iv = int(value)
    except (TypeError, ValueError, OverflowError) as exc:  # OverflowError: inf
        raise ParameterError(f"{name}={value!r} must be a positive integer") from exc
    if iv != value or iv <= 0:
        raise ParameterError(f"{name}={value!r} must be a positive integer")
    return iv


CHATTER_IMPACTS_PER_STEP = 0.05
"""Above this many impacts per sampled path-step against inelastic walls, the impacts are not resolved by the step."""


@dataclass(frozen=True)
class EnsembleProblem:
    """What an ensemble computes: paths of ``model`` from ``x0``, statistics over ``[t_burn, t_end]``.

    Parameters
    ----------
    model : ImpactOscillator
    x0 : (float, float)
        Initial state of every path.
    t_end, t_burn : float
        End time and burn-in (statistics start after ``t_burn``).
    h_max, bins : float, int
        Histogram of the energy H on [0, h_max].
    xy_bins, xy_range : (nx, ny) or None, ((x_lo, x_hi), (y_lo, y_hi)) or None
        Joint histogram of (x, y) (``xy_bins=None`` skips it; the default range follows the barriers).
    v_bins, v_max : int, float or None
        Histogram of impact speeds on [0, v_max] (default 2 sqrt(2 h_max)).
    stride : int
        Statistics every ``stride`` steps.

    Examples
    --------
    >>> from models import DuffingImpact
    >>> EnsembleProblem(DuffingImpact(), t_end=50.0, t_burn=10.0).with_(h_max=6.0).h_max
    6.0
    """

    model: Any
    x0: tuple = (0.0, 0.0)
    t_end: float = 2200.0
    t_burn: float = 200.0
    h_max: float = 4.0
    bins: int = 400
    xy_bins: tuple | None = (80, 80)
    xy_range: tuple | None = None
    v_bins: int = 200
    v_max: float | None = None
    stride: int = 1

    def with_(self, **changes) -> EnsembleProblem:
        """A copy with some fields changed."""
        return _replace(self, changes)


@dataclass(frozen=True)
class MonteCarloAlgorithm:
    """How the SDE is discretised: the scheme (``milstein``, ``splitting``, ``em``, ``naive``) and the step.

    Parameters
    ----------
    scheme : str or Scheme
    dt : float
    check_dt : bool
        Apply the step rule (refuse a step that can jump across the gap, warn on a coarse one).
    precision : {"f64", "f32"}
        Floating point of the kernel (``f32`` only on the ``cuda`` scheduler).
    kernel : {"auto", "automaton"}
        The CPU kernel: the one generated from ``model.to_automaton()``, for every scheme (as the automaton's
        ``symplectic``, ``baoab``, ``em`` and ``naive``) and every restitution law.

    Examples
    --------
    >>> MonteCarloAlgorithm("splitting", dt=0.01).scheme
    'splitting'
    """

    scheme: Any = "milstein"
    dt: float = 1e-3
    check_dt: bool = True
    precision: str = "f64"
    kernel: str = "auto"

    def with_(self, **changes) -> MonteCarloAlgorithm:
        """A copy with some fields changed."""
        return _replace(self, changes)


@dataclass(frozen=True)
class Execution:
    """Where and how much: paths, seed, chunking, scheduler, checkpoints and the work limits.

    ``paths``, ``seed`` and ``chunk_paths`` fix the numbers (chunk k draws from stream k of the seed); the
    scheduler, the thread count, checkpoints and the CUDA launch shape never change them.

    Parameters
    ----------
    paths, seed : int
    chunk_paths : int or None
        Paths per chunk (default :func:`~hybrid.stochastic.default_chunk_paths`).
    scheduler : None, "threads", "dask", "dask=ADDRESS", "cuda" or a ``distributed.Client``
    progress : bool
    checkpoint, resume, checkpoint_every : path or None, bool, int
    max_path_steps, max_memory : float
        Refuse, before starting, more path-steps or more bytes of histograms than this.
    threads_per_block, launch_steps : int, int or None
        ``cuda`` only.

    Examples
    --------
    >>> Execution(paths=64, seed=3).with_(scheduler="dask").scheduler
    'dask'
    """

    paths: int = 256
    seed: int = 1
    chunk_paths: int | None = None
    scheduler: Any = None
    progress: bool = False
    checkpoint: Any = None
    resume: bool = False
    checkpoint_every: int = 4
    max_path_steps: float = MAX_PATH_STEPS
    max_memory: float = MAX_MEMORY
    threads_per_block: int = 128
    launch_steps: int | None = None

    def with_(self, **changes) -> Execution:
        """A copy with some fields changed."""
        return _replace(self, changes)


def _replace(obj, changes: dict):
    from hybrid.errors import ParameterError

    fields = list(obj.__dataclass_fields__)
    unknown = sorted(set(changes) - set(fields))
    if unknown:
        raise ParameterError(f"{type(obj).__name__} has no field(s) {unknown}; its fields are {fields}")
    kwargs = {name: getattr(obj, name) for name in fields}
    kwargs.update(changes)
    return type(obj)(**kwargs)
