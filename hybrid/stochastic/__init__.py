"""Compiled Monte Carlo ensembles of impact oscillators: schemes, kernels, streaming statistics, runner.

Usage::

    from hybrid.stochastic import simulate_ensemble
    stats = simulate_ensemble(model, scheme="splitting", dt=0.02, paths=256, t_end=2200.0, t_burn=200.0, seed=1)
    stats.h_density(), stats.mean_energy.value, stats.mean_energy.ci, stats.impact_rate, stats.to_pandas()

How it works:

* ``_codegen``: the model's sympy expressions (Itô drift, sigma**2 and its y-derivative, G, the restitution law;
  a Piecewise becomes a conditional expression) are printed into one numba module per (model structure, law
  structure, scheme). Parameter values (delta, c, D, V_C, ...) are runtime arguments. The module is written to
  ``$VIBRO_CACHE_DIR`` (default ``~/.cache/vibro-impact``) and numba's ``cache=True`` stores the machine code, so
  another process loads it (``stats.compile_time`` reports generation + compile or load).
* ``_schemes``: :data:`SCHEMES` (``em``, ``milstein``, ``splitting``, ``naive``), each with declared strong/weak
  orders; every wall crossing is located on the step's free-flight segment and the law applied there, as often as
  needed within one step.
* ``_rng``: xoshiro256** and a 256-layer ziggurat, one stream per chunk from ``SeedSequence(seed).spawn``.
* ``_statistics``: integer histograms (H, (x, y), impact speeds) and one row of counts and sums per chunk; estimates
  are ratios of ``math.fsum`` sums with batch-means (per-chunk) 95 % intervals.
* ``_problem``: :class:`EnsembleProblem` (what), :class:`MonteCarloAlgorithm` (how) and :class:`Execution`
  (where, how much), the argument groups of :func:`solve_ensemble`; :func:`simulate_ensemble` takes them flat.
* ``_runner``: chunks of paths run on ``numba.get_num_threads()`` threads (a ``nogil`` kernel; each call interleaves
  8 paths so that their dependency chains overlap) or on Dask; checkpoints and resume. A ``prange`` kernel gave the
  same numbers but doubled the compile time (about 18 s instead of 7 s cold), hence the thread pool.
* ``_cuda`` / ``_cuda_rng``: ``scheduler="cuda"``, the same generated step code in a numba-cuda kernel (one thread
  per path, Philox-4x32-10 normals, block-shared histograms, launches with checkpoints); docs/gpu.md.

Examples
--------
>>> from hybrid.stochastic import SCHEMES
>>> sorted(SCHEMES)
['em', 'milstein', 'naive', 'splitting']
"""

from ._codegen import Kernel, build_kernel, cache_dir, generate_source
from ._problem import EnsembleProblem, Execution, MonteCarloAlgorithm
from ._rng import chunk_states, normals, ziggurat_tables
from ._runner import (
    ChatteringWarning,
    StepSizeWarning,
    check_step,
    default_chunk_paths,
    drive_paths,
    sample_paths,
    simulate_ensemble,
    solve_ensemble,
    speed_scale,
)
from ._schemes import SCHEMES, EulerMaruyama, Milstein, NaiveFlip, Scheme, Splitting, get_scheme
from ._statistics import EnsembleStatistics, Estimate, atomic_write_text, ratio_estimate

__all__ = [
    "SCHEMES", "ChatteringWarning", "EnsembleProblem", "EnsembleStatistics", "Estimate", "EulerMaruyama", "Execution",
    "Kernel", "Milstein", "MonteCarloAlgorithm",
    "NaiveFlip", "Scheme",
    "Splitting", "StepSizeWarning", "atomic_write_text", "build_kernel", "cache_dir", "check_step", "chunk_states",
    "default_chunk_paths", "drive_paths", "generate_source", "get_scheme", "normals", "ratio_estimate",
    "sample_paths", "simulate_ensemble", "solve_ensemble", "speed_scale", "ziggurat_tables",
]

# Monte Carlo of any hybrid automaton with noise (n states, modes, guards, resets)
from ._auto_runner import AUTOMATON_SCHEMES, AutomatonEnsemble, drive_automaton, simulate_automaton  # noqa: E402
from ._front import AUTOMATON_SCHEME_OF  # noqa: E402

__all__ += ["AUTOMATON_SCHEMES", "AUTOMATON_SCHEME_OF", "AutomatonEnsemble", "drive_automaton", "simulate_automaton"]
from ._passage import PassageEnsemble, simulate_first_passage  # noqa: E402
from ._snapshots import SnapshotEnsemble, simulate_snapshots  # noqa: E402
from ._splitting import RareEventEstimate, splitting_probability  # noqa: E402

__all__ += ["PassageEnsemble", "RareEventEstimate", "SnapshotEnsemble", "simulate_first_passage",
            "simulate_snapshots", "splitting_probability"]
