"""The one executor of every Monte Carlo ensemble: chunks, threads or Dask, and the one checkpoint format.

Paths are cut into chunks of ``chunk_paths`` paths (:func:`default_chunk_paths`: a number that depends on the paths
and steps only, never on the threads or workers). Chunk k draws from its own xoshiro256** stream seeded by
``SeedSequence(seed).spawn(n_chunks)[k]`` and fills its own row of every per-chunk array, so the numbers do not
depend on where or in which order chunks run: threads, a Dask cluster and a resumed checkpoint give the same bits.

:func:`run_chunks` runs the pending chunks of an :class:`AutomatonJob` (:func:`execute`, over :func:`map_tasks`:
local threads calling the ``nogil`` kernel, or Dask) and writes the checkpoint every ``checkpoint_every`` chunks, at
the end and on an interrupt. Both front ends use it: :func:`~hybrid.stochastic.simulate_automaton` (rows of the
automaton's statistics) and :func:`~hybrid.stochastic.simulate_ensemble` (an oscillator's automaton job, its rows
turned into :class:`~hybrid.stochastic.EnsembleStatistics`). The Welch spectra's chunks run on :func:`map_tasks` too.

A checkpoint (:func:`write`, :func:`read`) is an ``.npz`` of named arrays with the format number, the run's identity
(canonical JSON of every setting that decides the numbers, parameters as exact hex floats), a mask of the finished
chunks and a SHA-256 checksum; the CUDA scheduler stores its per-path state in the same format. A checkpoint of
another run is refused naming the settings that differ.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from hybrid.errors import CheckpointError, ParameterError
from hybrid.io import atomic_write

from . import _kernel_modules, _rng

CHECKPOINT_FILE = "automaton_checkpoint.npz"
"""The checkpoint of an automaton ensemble (per-chunk rows) or of a CUDA run (per-path state)."""
ENSEMBLE_CHECKPOINT_FILE = "mc_checkpoint.npz"
"""The checkpoint of an oscillator ensemble on threads or Dask (its :class:`EnsembleStatistics` arrays)."""
CHECKPOINT_FORMAT = 4
"""4: one format for every route (identity as JSON of the settings, done mask, checksum)."""

MAX_CHUNKS = 2**20
"""Most chunks of a CPU run: each needs its own spawned seed (about 30 s and 32 MB of states per million)."""
CHUNK_WORK = 2_000_000
"""Path-steps a chunk should hold at least (where the paths allow): its fixed cost (a stream, its arrays, a call and
a row of every per-chunk output) is then below 1 % of its work."""
CHUNK_SPREAD = 64
"""Chunks that :func:`default_chunk_paths` keeps at least, where that leaves 8 paths per chunk or more: enough to
balance up to 16 threads at 4 chunks each. A constant, not the machine's thread count: the chunk size decides the
numbers, so a default run gives the same numbers on every machine."""


def default_chunk_paths(paths: int, steps: float | None = None) -> int:
    """Paths per chunk, from the paths and the steps of each (shown as ``chunk_paths`` in the run's settings).

    8 (the kernel interleaves 8 lanes), fewer when that would leave fewer than 8 chunks. Where the paths are many
    and short, larger chunks (multiples of 8) of about :data:`CHUNK_WORK` path-steps, while at least
    :data:`CHUNK_SPREAD` chunks remain: 2**20 paths of 1,000 steps run in 525 chunks of 2,000 paths, not in
    131,072 chunks of 8 whose fixed costs and per-chunk rows outweigh the work.

    Examples
    --------
    >>> default_chunk_paths(256), default_chunk_paths(10), default_chunk_paths(256, 10**6)
    (8, 1, 8)
    >>> default_chunk_paths(2**20, 1000), default_chunk_paths(4096, 100)
    (2000, 64)
    """
    chunk = max(1, min(8, paths // 8))
    if steps is not None and steps >= 1:  # steps in floats: t_end / dt may exceed every integer type
        by_work = math.ceil(CHUNK_WORK / steps)
        by_spread = paths // CHUNK_SPREAD
        chunk = max(chunk, min(by_work, by_spread) // 8 * 8)
    return max(chunk, -(-paths // MAX_CHUNKS))


def chunk_sizes(paths: int, chunk_paths: int) -> np.ndarray:
    """Paths of each chunk: ``chunk_paths`` each, the last one the rest.

    Examples
    --------
    >>> chunk_sizes(10, 4).tolist()
    [4, 4, 2]
    """
    n_chunks = -(-paths // chunk_paths)
    return np.minimum(chunk_paths, paths - np.arange(n_chunks, dtype=np.int64) * chunk_paths).astype(np.int64)


def check_chunk_count(paths: int, chunk_paths: int) -> int:
    """The number of chunks; refuse more than :data:`MAX_CHUNKS` (each chunk spawns its own random stream).

    Examples
    --------
    >>> check_chunk_count(10**6, 8)
    125000
    """
    n_chunks = -(-paths // chunk_paths)
    if n_chunks > MAX_CHUNKS:
        raise ParameterError(
            f"paths={paths} in chunks of {chunk_paths} makes {n_chunks} chunks, above the limit {MAX_CHUNKS} (each "
            f"spawns its own random stream); pass chunk_paths >= {-(-paths // MAX_CHUNKS)} (the numbers then "
            "depend on that chunk size, as always)"
        )
    return n_chunks

PER_CHUNK = ("hist", "jhist", "vhist", "counts", "sums", "events", "gstat", "phist", "psums", "pcount", "vsum",
             "fbad", "elog", "nlog")
"""The kernel's per-chunk outputs, in its argument order."""


COUNT_NAMES = ("samples", "event_overflow", "outside", "nonfinite", "joint_outside", "bad_reset")
"""Names of the per-chunk counters, in the kernel's order."""


def checksum(arrays: dict) -> str:
    """SHA-256 over every array's name, dtype, shape and bytes (an edited file with doubled counts is refused)."""
    h = hashlib.sha256()
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def prepare_directory(directory: Path) -> None:
    """Before any work: the checkpoint path must be a directory that can be created and written."""
    if directory.exists() and not directory.is_dir():
        raise CheckpointError(f"checkpoint {str(directory)!r} is a file, not a directory; give a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CheckpointError(f"cannot create the checkpoint directory {str(directory)!r} ({exc.strerror or exc})") \
            from None


def read_checked(path: Path, fmt: int, hint: str) -> dict:
    """The arrays of the checkpoint ``path`` (``checksum`` removed) after its format and checksum are verified."""
    try:
        with np.load(path, allow_pickle=False) as d:
            arrays = {k: d[k] for k in d.files}
    except Exception as exc:  # not a zip, truncated, bad member: numpy raises many types
        raise CheckpointError(f"checkpoint {path} cannot be read ({type(exc).__name__}): it is corrupt; {hint}") \
            from None
    stored = str(arrays.pop("checksum", ""))
    if "format" not in arrays or int(arrays["format"]) != fmt:
        raise CheckpointError(f"checkpoint {path} has an old or unknown format (need {fmt}); {hint}")
    if stored != checksum(arrays):
        raise CheckpointError(f"checkpoint {path} fails its checksum (edited or corrupt); {hint}")
    return arrays


@contextmanager
def dask_client(scheduler):
    """A ``distributed.Client`` for ``scheduler`` ("dask": a LocalCluster of this machine, "dask=ADDRESS", or a
    Client, which is used as it is); what it opened is closed on exit."""
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover
        raise ParameterError("scheduler='dask' needs dask.distributed: pip install 'dask[distributed]'") from exc
    if not isinstance(scheduler, str):
        yield scheduler
        return
    name, _, address = scheduler.partition("=")
    if name != "dask":
        raise ParameterError(f"unknown scheduler {scheduler!r}; use threads, dask, dask=ADDRESS or a Client")
    own = []
    try:
        if address:
            own.append(Client(address))
        else:
            own.append(LocalCluster(n_workers=min(2, os.cpu_count() or 1), threads_per_worker=1, processes=True,
                                    dashboard_address=None))
            own.append(Client(own[-1]))
        yield own[-1]
    finally:
        for obj in reversed(own):  # the client before its cluster
            obj.close()


def chunk_shapes(n_obs: int, width: int, joint_bins: tuple, n_trans: int, v_bins: int, n_phases: int,
                 chunk_paths: int, n_log: int) -> dict:
    """``(shape, dtype, fill)`` of each per-chunk output of ``run_chunk`` (:data:`PER_CHUNK`).

    ``width``: histogram bins + 2 (underflow, overflow) of the widest observable; ``joint_bins``: (nx, ny);
    ``n_log``: event-log rows per path (0: none).

    Examples
    --------
    >>> chunk_shapes(2, 12, (1, 1), 2, 100, 1, 8, 0)["elog"][0]
    (8, 0, 3)
    """
    i64, n_tr = np.int64, max(n_trans, 1)
    return {
        "hist": ((n_obs, width), i64, 0), "jhist": ((int(joint_bins[1]), int(joint_bins[0])), i64, 0),
        "vhist": ((n_tr, int(v_bins) + 1), i64, 0), "counts": ((len(COUNT_NAMES),), i64, 0),
        "sums": ((n_obs,), float, 0.0), "events": ((n_tr,), i64, 0), "gstat": ((n_tr, 4), float, 0.0),
        "phist": ((n_phases, n_obs, width), i64, 0), "psums": ((n_phases, n_obs), float, 0.0),
        "pcount": ((n_phases,), i64, 0), "vsum": ((n_tr,), float, 0.0), "fbad": ((1,), float, 0.0),
        "elog": ((chunk_paths, n_log, 3), float, np.nan), "nlog": ((chunk_paths,), i64, 0),
    }


class AutomatonJob:
    """Everything a chunk needs besides its id and stream: the kernel source and its arguments (picklable).

    ``shapes`` maps each name of :data:`PER_CHUNK` to ``(shape, dtype, fill)`` of one chunk's array.
    """

    def __init__(self, name: str, src: str, args: dict, npaths: np.ndarray, shapes: dict, label: str | None = None,
                 user_law=None):
        self.name, self.src, self.args, self.npaths, self.shapes = name, src, args, npaths, shapes
        self.label = label  # the kernel's name in the compile notice (hybrid.stochastic._kernel_modules.COMPILE_LOG)
        self.user_law = user_law  # a numba-compiled restitution callable: the module is built in memory

    def module(self):
        module, _ = _kernel_modules.load_source(self.name, self.src, getattr(self, "user_law", None),
                                         label=getattr(self, "label", None))
        return module

    def zero_rows(self, n_chunks: int) -> dict:
        """Zeroed per-chunk arrays of every output for ``n_chunks`` chunks (the rows a device run fills)."""
        return {k: np.zeros((n_chunks, *shape), dtype=dtype) for k, (shape, dtype, _) in self.shapes.items()}

    def empty(self) -> dict:
        out = {k: np.full(shape, fill, dtype=dtype) for k, (shape, dtype, fill) in self.shapes.items()}
        if "gstat" in out:  # [sum, count, min, max] of the guard changes: the extremes start empty
            out["gstat"][:, 2], out["gstat"][:, 3] = np.inf, -np.inf
        return out

    def run(self, k: int, rng_state: np.ndarray, burn: int | None = None, samples: int | None = None,
            module=None, track: bool = False) -> dict:
        """Run chunk ``k`` from ``rng_state`` (burn-in and samples default to the run's); its arrays.

        ``track`` records the guard statistics of the step rule (the pilot's job)."""
        module = self.module() if module is None else module
        a, out = self.args, self.empty()
        burn = a["n_burn"] if burn is None else burn
        samples = a["n_samp"] if samples is None else samples
        zx, zk, zf = _rng.ziggurat_tables()
        try:
            self._call(module, k, rng_state, burn, samples, track, zx, zk, zf, out)
        except ZeroDivisionError as exc:  # numba raises it for a float division by zero in the model's expressions
            raise ParameterError(
                f"the kernel of {self.name} divided by zero ({exc}): an expression of the model is singular at these "
                "parameters or states (a damping of 0 under a fluctuation-dissipation noise D/c, say); change the "
                "parameters or the model") from None
        return out

    def _call(self, module, k, rng_state, burn, samples, track, zx, zk, zf, out):
        """The kernel's ``run_chunk`` on chunk ``k`` with the run's arguments, filling ``out``."""
        a = self.args
        module.run_chunk(rng_state, self.npaths[k], burn, samples, a["stride"], a["dt"], 0.0, a["x0"], a["mode0"],
                         a["p"], zx, zk, zf, a["obs_lo"], a["obs_scale"], a["obs_bins"], out["hist"],
                         a["jx"], a["jy"], a["j_lo"], a["j_scale"], a["j_bins"], out["jhist"], a["v_scale"],
                         a["v_bins"], out["vhist"], out["counts"], out["sums"], out["events"],
                         out["gstat"], track, a["phases"], a["phase_steps"], out["phist"], out["psums"], out["pcount"],
                         out["vsum"], out["fbad"], out["elog"], out["nlog"], module.chunk_work())


def _remote(job: AutomatonJob, k: int, rng_state: np.ndarray):
    """Dask task: load (or generate and compile) the kernel on the worker, run one chunk."""
    return k, job.run(k, rng_state)


_IDENTITY_NAMES = {"kernel": "generated kernel", "source": "generated kernel", "law": "restitution law",
                   "params": "model parameters"}


def identity(settings: dict) -> str:
    """The run's identity: canonical JSON of everything that decides the numbers (floats as exact hex).

    Examples
    --------
    >>> identity({"dt": 0.1, "seed": 1})
    '{"dt": "0x1.999999999999ap-4", "seed": 1}'
    """
    def exact(v):
        if isinstance(v, float):
            return float.hex(v)
        if isinstance(v, dict):
            return {str(k): exact(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [exact(x) for x in v]
        if isinstance(v, np.generic):
            return exact(v.item())
        return v if v is None or isinstance(v, (bool, int, str)) else str(v)

    return json.dumps(exact(settings), sort_keys=True)


def check_directory(directory: Path, resume: bool, name: str = CHECKPOINT_FILE) -> None:
    """Before any work: a directory that can be written, and no checkpoint to overwrite unless resuming."""
    prepare_directory(directory)
    if not resume and (directory / name).exists():
        raise ParameterError(f"{directory / name} exists; pass resume=True (--resume) or another directory")


def write(directory: Path, run_id: str, done: np.ndarray, rows: dict, name: str = CHECKPOINT_FILE) -> None:
    """Write the checkpoint ``directory/name`` atomically: ``rows``, the done-mask, format, identity, checksum."""
    arrays = {**rows, "done": np.asarray(done, bool), "format": np.array(CHECKPOINT_FORMAT),
              "identity": np.array(run_id)}
    arrays["checksum"] = np.array(checksum(arrays))
    directory.mkdir(parents=True, exist_ok=True)
    # the shared writer: a unique temporary name (ends in .npz, so savez adds nothing), removed on failure
    atomic_write(directory / name, lambda tmp: np.savez(tmp, **arrays))


def read(directory: Path, run_id: str, name: str = CHECKPOINT_FILE) -> dict | None:
    """The arrays of the checkpoint ``directory/name`` (None when there is none), after its format, checksum and
    identity are checked; a checkpoint of another run is refused naming the settings that differ."""
    path = directory / name
    if not path.exists():
        return None
    arrays = read_checked(path, CHECKPOINT_FORMAT, "delete it or use another checkpoint directory")
    stored = str(arrays.pop("identity", ""))
    if stored != run_id:
        try:
            old, new = json.loads(stored), json.loads(run_id)
            diff = [_IDENTITY_NAMES.get(k, k) for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
        except (ValueError, AttributeError):
            diff = []
        raise CheckpointError(
            f"checkpoint {path} was made by another run with other settings ({', '.join(diff) or 'its identity'} "
            "differ); resume with the same arguments or use another --checkpoint directory")
    return arrays


def load(directory: Path, run_id: str, rows: dict, name: str = CHECKPOINT_FILE) -> np.ndarray | None:
    """Fill ``rows`` from the checkpoint and return its done-mask, or None when there is none."""
    arrays = read(directory, run_id, name)
    if arrays is None:
        return None
    for key, target in rows.items():
        if key not in arrays or arrays[key].shape != target.shape:
            raise CheckpointError(f"checkpoint {directory / name} does not fit this run ({key} has another shape); "
                                  "delete it or use another checkpoint directory")
        target[...] = arrays[key]
    return arrays["done"].astype(bool)


def map_tasks(fn, tasks: list, accept, *, workers: int, scheduler=None, local=None, label: str = "vibro",
              names=None) -> None:
    """``fn(*task)`` for every task of ``tasks`` on local threads or Dask: the one executor of the Monte Carlo runs.

    Parameters
    ----------
    fn : callable
        Run as ``fn(*task)``; on Dask it must be a module-level function (it is pickled with its arguments).
    tasks : list of tuple
        The arguments of each task. Each task's numbers must depend on the task alone, so that the order in which
        tasks finish decides nothing.
    accept : callable
        ``accept(i, result)`` takes the result of ``tasks[i]`` in the calling thread: locally in task order, on Dask
        as the tasks finish.
    workers : int
        Local Python threads (at most one per task); the functions they call must release the GIL to run in parallel.
    scheduler : None, "threads", "local", "dask", "dask=ADDRESS" or a ``distributed.Client``
    local : callable, optional
        What the threads call instead of ``fn``: one that may hold what Dask cannot ship (a kernel loaded in this
        process).
    label, names : str, sequence, optional
        Dask task keys are ``{label}-{names[i]}-{pid}-{ns}`` (``names`` defaults to the task indices), so that the
        dashboard names a run's chunks by their numbers. Each task has 3 retries: a killed worker's tasks run again
        elsewhere.

    Examples
    --------
    >>> out = {}
    >>> map_tasks(lambda a, b: a * b, [(1, 2), (3, 4)], out.__setitem__, workers=2)
    >>> out
    {0: 2, 1: 12}
    """
    if scheduler in (None, "threads", "local"):
        call = fn if local is None else local
        workers = max(1, min(workers, len(tasks)))
        if workers == 1:
            for i, task in enumerate(tasks):
                accept(i, call(*task))
            return
        pool = ThreadPoolExecutor(max_workers=workers)
        try:
            for i, out in enumerate(pool.map(lambda task: call(*task), tasks)):
                accept(i, out)
        finally:  # on Ctrl-C do not wait for the queued tasks (a checkpoint keeps what is done)
            pool.shutdown(wait=False, cancel_futures=True)
        return
    with dask_client(scheduler) as client:
        from distributed import as_completed  # present: the client was made

        names = range(len(tasks)) if names is None else names
        futures = {client.submit(fn, *task, pure=False, retries=3,
                                 key=f"{label}-{name}-{os.getpid()}-{time.time_ns()}"): i
                   for i, (task, name) in enumerate(zip(tasks, names))}
        for fut in as_completed(futures):
            accept(futures[fut], fut.result())


def execute(job: AutomatonJob, pending: list, states: np.ndarray, accept, *, threads: int, scheduler=None,
            module=None) -> None:
    """Run the ``pending`` chunks (:func:`map_tasks`); ``accept(k, arrays)`` takes each result in the calling thread.

    Locally, ``threads`` Python threads call the ``nogil`` kernel (``module``, default the job's), one chunk per
    call; on Dask each task carries the job (a few kB: scattered data would be lost with a killed worker) and the
    worker loads or compiles the kernel from its source.
    """
    local = scheduler in (None, "threads", "local")
    if local:
        module = job.module() if module is None else module
    elif getattr(job, "user_law", None) is not None:
        raise ParameterError(
            "a Python-callable restitution law is compiled in memory and cannot be shipped to Dask workers; "
            "declare it as a sympy expression of v (CustomRestitution('...')) or use the local threads"
        )
    map_tasks(_remote, [(job, k, states[k].copy()) for k in pending], lambda i, out: accept(*out),
              workers=threads, scheduler=scheduler,
              local=lambda job, k, state: (k, job.run(k, state, module=module)), label=f"vibro-mc-{job.name}",
              names=pending)


def run_chunks(job: AutomatonJob, pending: list, states: np.ndarray, accept, *, threads: int, scheduler=None,
               module=None, save=None, checkpoint_every: int = 4, progress=None) -> None:
    """Run the ``pending`` chunks (:func:`execute`) with checkpoints: ``accept(k, arrays)`` takes each result,
    ``save()`` (when given) writes the checkpoint every ``checkpoint_every`` chunks, at the end, and on any exit
    with chunks finished since the last one (an interrupt, an error: the finished chunks are kept for a resume).
    ``progress`` is a progress bar (``update(1)`` per chunk) or None."""
    since = 0

    def take(k, out):
        nonlocal since
        accept(k, out)
        since += 1
        if progress is not None:
            progress.update(1)
        if save is not None and since >= checkpoint_every:
            save()
            since = 0

    try:
        if pending:
            execute(job, pending, states, take, threads=threads, scheduler=scheduler, module=module)
    except BaseException:
        if save is not None and since:
            save()
        raise
    if save is not None:
        save()
