"""``simulate_ensemble(..., scheduler="cuda")`` runs of Example 1 on numba's CUDA simulator, in a process of their own
(tests/test_cuda.py starts it once). The oscillator's CUDA route is the automaton's CUDA target
(hybrid/stochastic/_auto_cuda.py) running ``model.to_automaton()``.

``NUMBA_ENABLE_CUDASIM=1`` must be set before numba is imported, hence the separate process. Usage::

    NUMBA_ENABLE_CUDASIM=1 python tests/cuda_sim_runs.py OUTDIR

writes OUTDIR/<run>.npz (statistics arrays) and OUTDIR/tpb32_ckpt/ (its final checkpoint: every path's state) for
the runs in ``RUNS``, and OUTDIR/resumed.npz.
Sizes are tiny: the simulator executes every thread as Python (about 1e4 path-steps/s).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hybrid.stochastic import _auto_cuda, simulate_ensemble  # noqa: E402
from hybrid.stochastic._auto_exec import CHECKPOINT_FILE  # noqa: E402
from models import DuffingImpact  # noqa: E402

# Example 1 (Fig. 2, delta = 1, Ma V_C = 0.4); coarse step on purpose (the CPU comparison uses the same step)
BASE = dict(dt=0.05, paths=64, t_end=20.0, t_burn=5.0, seed=7, bins=40, h_max=4.0, v_bins=20,
            xy_bins=(12, 8), xy_range=((-1.5, 1.5), (-4.0, 4.0)), check_dt=False, scheduler="cuda")
RUNS = {
    "tpb32": dict(scheme="splitting", threads_per_block=32),
    "tpb64": dict(scheme="splitting", threads_per_block=64, launch_steps=37),  # odd: launches start on odd steps
    "f32": dict(scheme="splitting", threads_per_block=32, precision="f32"),
    "milstein": dict(scheme="milstein", threads_per_block=32),
    # statistics every 3rd step: one launch vs launches of 7 steps (the sampling phase carries across launches)
    "stride3": dict(scheme="splitting", threads_per_block=32, paths=32, stride=3),
    "stride3_split": dict(scheme="splitting", threads_per_block=32, paths=32, stride=3, launch_steps=7),
}


class Interrupt(Exception):
    pass


def interrupted_then_resumed(out: Path) -> None:
    """Interrupt the run of launches of 50 steps (checkpoint after each) at the end of its second launch, before
    that launch's checkpoint is written; the checkpoint then holds 50 steps, and resume recomputes from there."""
    ck = out / "resume_ckpt"
    real = _auto_cuda._after_launch
    args = dict(BASE, scheme="splitting", threads_per_block=32, launch_steps=50, checkpoint=ck, checkpoint_every=1)

    def stopping(n_done):
        if n_done == 100:
            raise Interrupt

    _auto_cuda._after_launch = stopping
    try:
        simulate_ensemble(DuffingImpact(), **args)
        raise SystemExit("the interruption did not happen")
    except Interrupt:
        pass
    finally:
        _auto_cuda._after_launch = real
    with np.load(ck / CHECKPOINT_FILE) as d:
        partial = int(d["n_done"][0])
    stats = simulate_ensemble(DuffingImpact(), **args, resume=True)
    np.savez(out / "resumed.npz", partial=partial, **stats.to_arrays())


def main(out: Path) -> None:
    warnings.simplefilter("ignore")
    out.mkdir(parents=True, exist_ok=True)
    for name, extra in RUNS.items():
        t0 = time.perf_counter()
        kw = dict(BASE, **extra)
        if name == "tpb32":
            kw["checkpoint"] = out / "tpb32_ckpt"
        stats = simulate_ensemble(DuffingImpact(), **kw)
        np.savez(out / f"{name}.npz", seconds=time.perf_counter() - t0, **stats.to_arrays())
    interrupted_then_resumed(out)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
