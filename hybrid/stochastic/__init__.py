"""Compiled Monte Carlo ensembles of impact oscillators: schemes, kernels, streaming statistics, runner.

The model's sympy expressions are compiled into a numba kernel per scheme (cached on disk); chunks of paths run on
numba threads or Dask with one random stream per chunk, so the same seed gives bitwise the same statistics anywhere.

Examples
--------
>>> from hybrid.stochastic import SCHEMES
>>> sorted(SCHEMES)
['em', 'milstein', 'naive', 'splitting']
"""

from ._codegen import Kernel, build_kernel, cache_dir, generate_source
from ._rng import chunk_states, normals, ziggurat_tables
from ._runner import (
    StepSizeWarning,
    check_step,
    default_chunk_paths,
    drive_paths,
    sample_paths,
    simulate_ensemble,
    speed_scale,
)
from ._schemes import SCHEMES, EulerMaruyama, Milstein, NaiveFlip, Scheme, Splitting, get_scheme
from ._statistics import EnsembleStatistics, Estimate, atomic_write_text, ratio_estimate

__all__ = [
    "SCHEMES", "EnsembleStatistics", "Estimate", "EulerMaruyama", "Kernel", "Milstein", "NaiveFlip", "Scheme",
    "Splitting", "StepSizeWarning", "atomic_write_text", "build_kernel", "cache_dir", "check_step", "chunk_states",
    "default_chunk_paths", "drive_paths", "generate_source", "get_scheme", "normals", "ratio_estimate",
    "sample_paths", "simulate_ensemble", "speed_scale", "ziggurat_tables",
]
