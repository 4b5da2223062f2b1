"""Where the chunks of an automaton ensemble run: threads or Dask, with checkpoints and resume.

Each chunk k fills its own row of every per-chunk array from its own random stream, so the rows do not depend on
where or in which order chunks run: threads, a Dask cluster and a resumed checkpoint give the same bits.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from hybrid.errors import CheckpointError, ParameterError
from hybrid.io import atomic_write

from . import _kernel_modules, _rng, _shared_exec

CHECKPOINT_FILE = "automaton_checkpoint.npz"
CHECKPOINT_FORMAT = 3
"""2: speed sums, first failed check, no sums of squares (never read); 3: the paths' event logs."""

PER_CHUNK = ("hist", "jhist", "vhist", "counts", "sums", "events", "gstat", "phist", "psums", "pcount", "vsum",
             "fbad", "elog", "nlog")
"""The kernel's per-chunk outputs, in its argument order."""


COUNT_NAMES = ("samples", "event_overflow", "outside", "nonfinite", "joint_outside", "bad_reset")
"""Names of the per-chunk counters, in the kernel's order."""


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
                         out["vsum"], out["fbad"], out["elog"], out["nlog"])


def _remote(job: AutomatonJob, k: int, rng_state: np.ndarray):
    """Dask task: load (or generate and compile) the kernel on the worker, run one chunk."""
    return k, job.run(k, rng_state)


def identity(settings: dict) -> str:
    """A digest of everything that decides the numbers (parameters in full precision)."""
    text = json.dumps(settings, sort_keys=True, default=lambda v: float.hex(v) if isinstance(v, float) else str(v))
    return hashlib.sha256(text.encode()).hexdigest()


def check_directory(directory: Path, resume: bool) -> None:
    """Before any work: a directory that can be written, and no checkpoint to overwrite unless resuming."""
    _shared_exec.prepare_directory(directory)
    if not resume and (directory / CHECKPOINT_FILE).exists():
        raise ParameterError(f"{directory / CHECKPOINT_FILE} exists; pass resume=True or another directory")


def write(directory: Path, run_id: str, done: np.ndarray, rows: dict) -> None:
    arrays = {**rows, "done": done, "format": np.array(CHECKPOINT_FORMAT), "identity": np.array(run_id)}
    arrays["checksum"] = np.array(_shared_exec.checksum(arrays))
    atomic_write(directory / CHECKPOINT_FILE, lambda tmp: np.savez(tmp, **arrays))


def load(directory: Path, run_id: str, rows: dict) -> np.ndarray | None:
    """Fill ``rows`` from the checkpoint and return its done-mask, or None when there is none."""
    path = directory / CHECKPOINT_FILE
    if not path.exists():
        return None
    hint = "delete it or use another checkpoint directory"
    arrays = _shared_exec.read_checked(path, CHECKPOINT_FORMAT, hint)
    if str(arrays["identity"]) != run_id:
        raise CheckpointError(f"checkpoint {path} was made by another run (automaton, parameters or settings "
                              "differ); resume with the same arguments or use another directory")
    for key, target in rows.items():
        if arrays[key].shape != target.shape:
            raise CheckpointError(f"checkpoint {path} does not fit this run ({key} has another shape); {hint}")
        target[...] = arrays[key]
    return arrays["done"].astype(bool)


def execute(job: AutomatonJob, pending: list, states: np.ndarray, accept, *, threads: int, scheduler=None) -> None:
    """Run the ``pending`` chunks; ``accept(k, arrays)`` takes each result in the calling thread."""
    if scheduler in (None, "threads", "local"):
        module = job.module()
        workers = max(1, min(threads, len(pending)))
        if workers == 1:
            for k in pending:
                accept(k, job.run(k, states[k].copy(), module=module))
            return
        pool = ThreadPoolExecutor(max_workers=workers)
        try:
            for k, out in zip(pending, pool.map(lambda k: job.run(k, states[k].copy(), module=module), pending)):
                accept(k, out)
        finally:  # on Ctrl-C do not wait for the queued chunks (the checkpoint keeps what is done)
            pool.shutdown(wait=False, cancel_futures=True)
        return
    with _shared_exec.dask_client(scheduler) as client:
        from distributed import as_completed  # present: the client was made

        futures = [client.submit(_remote, job, k, states[k].copy(), pure=False, retries=3,
                                 key=f"vibro-auto-{job.name}-{k}-{os.getpid()}-{time.time_ns()}") for k in pending]
        for fut in as_completed(futures):
            accept(*fut.result())
