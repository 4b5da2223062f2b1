"""Compiled Monte Carlo ensembles of impact oscillators: schemes, kernels, streaming statistics, runner.

Usage::

    from hybrid.stochastic import simulate_ensemble
    stats = simulate_ensemble(model, scheme="splitting", dt=0.02, paths=256, t_end=2200.0, t_burn=200.0, seed=1)
    stats.h_density(), stats.mean_energy.value, stats.mean_energy.ci, stats.impact_rate, stats.to_pandas()

How it works:

* ``_auto_codegen``: one code generator for every Monte Carlo kernel. A model's automaton (an
  :class:`~models.ImpactOscillator` builds its own with ``to_automaton()``) is printed into one numba module per
  (structure, scheme): drift, noise, guards, resets and observables; parameter values (delta, c, D, the restitution
  law's numbers) are runtime arguments. The module is written to ``$VIBRO_CACHE_DIR`` (default
  ``~/.cache/vibro-impact``) and numba's ``cache=True`` stores the machine code, so another process loads it
  (``stats.compile_time`` reports generation + compile or load).
* ``_front``: ``ImpactOscillator`` as a front end: :data:`AUTOMATON_SCHEME_OF` maps the oscillator schemes
  (:data:`SCHEMES`: ``em``, ``milstein``, ``splitting``, ``naive``, each with declared strong/weak orders) to the
  automaton's; every wall crossing is located on the step's interpolant and the law applied there, as often as
  needed within one step (``naive`` drops the rest of the step). A restitution law given as a Python callable is
  compiled by numba and called by the reset.
* ``_rng``: xoshiro256** and a 256-layer ziggurat, one stream per chunk from ``SeedSequence(seed).spawn``.
* ``_statistics``: integer histograms (H, (x, y), impact speeds) and one row of counts and sums per chunk; estimates
  are ratios of ``math.fsum`` sums with batch-means (per-chunk) 95 % intervals.
* ``_problem``: :class:`EnsembleProblem` (what), :class:`MonteCarloAlgorithm` (how) and :class:`Execution`
  (where, how much), the argument groups of :func:`solve_ensemble`; :func:`simulate_ensemble` takes them flat.
* ``_auto_exec``: the one executor of every ensemble: chunks of paths on threads (a ``nogil`` kernel) or on Dask,
  the one checksummed checkpoint format (also the CUDA scheduler's), resume.
* ``_runner``: the oscillator front end (settings, step rule, result checks) of the automaton job;
  ``_auto_runner``: ``simulate_automaton`` and ``drive_automaton``. :func:`sample_paths` stores the very paths of
  the ensemble with the same seed; :func:`drive_paths` feeds given normals.
* ``_auto_cuda`` / ``_cuda_rng``: ``scheduler="cuda"`` for automata and oscillators alike (an oscillator runs its
  automaton: ``_front.run_on_cuda``), the automaton generator's step code as numba-cuda device functions (one
  thread per path, Philox-4x32-10 normals, block-shared histograms, launches with checkpoints); docs/gpu.md.

Examples
--------
>>> from hybrid.stochastic import SCHEMES
>>> sorted(SCHEMES)
['em', 'milstein', 'naive', 'splitting']
"""

from ._auto_exec import default_chunk_paths
from ._front import Kernel, build_kernel, generate_source
from ._kernel_modules import cache_dir
from ._problem import ChatteringWarning, EnsembleProblem, Execution, MonteCarloAlgorithm, StepSizeWarning
from ._rng import chunk_states, normals, ziggurat_tables
from ._runner import check_step, drive_paths, sample_paths, simulate_ensemble, solve_ensemble, speed_scale
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
from ._splitting import RareEventEstimate, RareEventWarning, splitting_probability  # noqa: E402

__all__ += ["PassageEnsemble", "RareEventEstimate", "RareEventWarning", "SnapshotEnsemble", "simulate_first_passage",
            "simulate_snapshots", "splitting_probability"]
