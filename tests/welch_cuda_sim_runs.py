"""The Monte Carlo spectrum (Welch) with ``scheduler="cuda"`` on numba's CUDA simulator, in one process
(tests/test_welch_cuda.py starts it once: ``NUMBA_ENABLE_CUDASIM=1`` must be set before numba is imported).
Usage::

    NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 python tests/welch_cuda_sim_runs.py OUTDIR [oracle]

writes OUTDIR/config_<k>.npz (a small run, :data:`SMALL`, under the launch configurations of :data:`CONFIGS`),
OUTDIR/driven.npz (the recorded states of the small run's first paths, and the CPU kernel's ``drive`` fed the
same Philox normals up to the same steps) and OUTDIR/cli.csv, OUTDIR/cli_rc.txt (``vibro spectrum --method mc
--scheduler cuda``); with ``oracle``, only OUTDIR/oracle.npz (the free linear oscillator's spectrum on the
simulated GPU, :data:`ORACLE`: about 10 s of simulator). Sizes are tiny: the simulator runs every thread as
Python (about 1e4 path-steps/s).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from auto_cuda_sim_runs import philox_increments  # noqa: E402

from hybrid.stochastic import _front, drive_automaton  # noqa: E402
from hybrid.stochastic._welch import cuda_recordings, welch_spectrum  # noqa: E402
from models import ImpactOscillator  # noqa: E402

C, D = 1.0, 0.5
"""The free linear oscillator x'' + c x' + x = sqrt(2 D) xi: a broad resonance, resolved by short segments."""
ORACLE = dict(dt=0.05, t_end=60.0, t_burn=4.0, paths=64, every=4, segment=32, chunk_paths=8, seed=11)
SMALL = dict(dt=0.05, t_end=16.0, t_burn=2.0, paths=8, every=2, segment=32, chunk_paths=4, seed=3)
CONFIGS = ({"threads_per_block": 32}, {"threads_per_block": 64, "launch_steps": 37, "batch_paths": 4})


def oscillator():
    return ImpactOscillator("x", "c*y", parameters={"c": C, "D": D}, barriers=None, name="free")


def save(path: Path, s) -> None:
    np.savez(path, omega=s.omega, S=s.S, ci=s.ci, variance=s.variance, mean=s.mean,
             segments=s.settings["segments"])


def main(out: Path, oracle: bool = False) -> None:
    warnings.simplefilter("ignore")
    out.mkdir(parents=True, exist_ok=True)
    m = oscillator()
    t0 = time.perf_counter()
    if oracle:
        save(out / "oracle.npz", welch_spectrum(m, "x", scheduler="cuda", **ORACLE))
        print(f"oracle: {time.perf_counter() - t0:.1f} s", flush=True)
        return
    for k, config in enumerate(CONFIGS):
        save(out / f"config_{k}.npz", welch_spectrum(m, "x", scheduler="cuda", **SMALL, **config))
    s = SMALL
    _, states = next(cuda_recordings(m, "splitting", s["dt"], s["t_end"], s["t_burn"], s["paths"], s["every"],
                                     s["chunk_paths"], s["seed"], (0.0, 0.0), threads_per_block=32))
    automaton = _front._generated(m, "baoab")[0]
    n_burn = int(round(s["t_burn"] / s["dt"]))
    rows = [0, 1, states.shape[1] - 1]
    steps = [n_burn + r * s["every"] for r in rows]
    dws = philox_increments(s["seed"], 2, steps[-1], 1, s["dt"])
    driven = np.array([drive_automaton(automaton, "baoab", s["dt"], dws[:, :n], (0.0, 0.0)) for n in steps])
    np.savez(out / "driven.npz", recorded=states[:2, rows], driven=driven.transpose(1, 0, 2))
    t0 = time.perf_counter()
    from vibro.cli import main as cli

    rc = cli(["spectrum", "--model", "duffing", "--method", "mc", "--scheduler", "cuda", "--paths", "16",
              "--dt", "0.05", "--t-end", "12", "--t-burn", "2", "--every", "2", "--segment", "16", "--seed", "4",
              "--out", str(out / "cli.csv")])
    (out / "cli_rc.txt").write_text(str(rc))
    print(f"small runs and cli: {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main(Path(sys.argv[1]), sys.argv[2:] == ["oracle"])
