"""Automaton ensembles with ``scheduler="cuda"`` on numba's CUDA simulator, and their CPU references, all in one
process (tests/test_auto_cuda.py starts it once: importing numba-cuda's simulator and sympy costs more than the runs).

``NUMBA_ENABLE_CUDASIM=1`` must be set before numba is imported, hence the separate process. Usage::

    NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1 python tests/auto_cuda_sim_runs.py OUTDIR

writes, for every model of :func:`models` and every run of :data:`VARIANTS`, OUTDIR/<run>.pkl (the
AutomatonEnsemble) and OUTDIR/<run>_ckpt/ (the final checkpoint: every path's state); for every model also
OUTDIR/cpu_<name>.pkl (the CPU kernel's ensemble of 4x the paths, threads scheduler, its own xoshiro streams) and
OUTDIR/drive_<name>.npz (the CPU kernel's ``drive`` fed the Philox normals of the first paths);
OUTDIR/oscillator_example1.npz (Example 1 through ``simulate_ensemble(..., scheduler="cuda")``); and the outputs of
two ``vibro mc --scheduler cuda`` runs under OUTDIR/cli_*. With ``NUMBA_DISABLE_JIT=1`` the CPU kernel runs as
Python instead of being compiled (seconds instead of ~25 s per model): the same source, and bitwise the same numbers
(numba contracts no floating-point operation without fastmath). Sizes are tiny: the simulator runs every thread as
Python (about 1e4 path-steps/s).
"""

from __future__ import annotations

import math
import pickle
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import sympy as sp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hybrid.automaton import HybridAutomaton, Mode, Transition, real_symbol  # noqa: E402
from hybrid.errors import VibroError  # noqa: E402
from hybrid.stochastic import _auto_cuda, _cuda_rng, drive_automaton, simulate_automaton, simulate_ensemble  # noqa: E402
from hybrid.stochastic._auto_codegen import analyse  # noqa: E402
from models import DuffingImpact, ForcedDuffingImpact, ImpactOscillator, Newton  # noqa: E402
from models.automata import impact_pair, vibrating_table  # noqa: E402
from models.excitation import ou_filter  # noqa: E402


def models() -> dict:
    """name -> (automaton, scheme, keywords of simulate_automaton) of every model item 2 of issue 22 names."""
    duffing = DuffingImpact()  # Example 1: delta = 1, Ma's law V_C = 0.4
    stop = ImpactOscillator("x", "c*y", parameters={"c": 0.25, "D": 0.25}, barriers=(0, None),
                            restitution=Newton(1.0), name="linear")  # the stop at the equilibrium, r = 1
    forced = ForcedDuffingImpact(A=0.3, Omega=1.2)
    common = dict(paths=32, seed=5, check_dt=False, scheduler="cuda", threads_per_block=32)
    return {
        "example1": (duffing.to_automaton(), "symplectic",
                     dict(common, dt=0.05, t_end=15.0, t_burn=5.0, x0=(0.0, 0.0), histograms={"H": (0.0, 4.0, 40)})),
        "stop": (stop.to_automaton(), "splitting",
                 dict(common, dt=0.05, t_end=15.0, t_burn=5.0, x0=(0.5, 0.0), observables={"H": stop.energy_expr,
                      "x": "x"}, histograms={"H": (0.0, 4.0, 40), "x": (-0.3, 2.7, 30)})),
        "impact_pair": (impact_pair(), "splitting",
                        dict(common, dt=0.02, t_end=6.0, t_burn=1.0, x0=(0.0, 0.0, 0.0, 0.0), events=4,
                             histograms={"H": (0.0, 0.5, 20), "z": (-0.25, 0.25, 20)})),
        "table": (vibrating_table(D=0.02, A=0.1), "splitting",
                  dict(common, dt=0.02, t_end=6.0, t_burn=1.0, x0=(0.3, 0.0),
                       histograms={"height": (0.0, 1.0, 20), "H": (0.0, 2.0, 20)})),
        "forced": (forced.to_automaton(), "symplectic",
                   dict(common, dt=0.05, t_end=15.7, t_burn=5.0, x0=(0.0, 0.0), histograms={"H": (0.0, 4.0, 40)},
                        phases=4, period=forced.forcing_period)),
        "ou": (ou_filter(duffing, alpha=4.0), "splitting",
               dict(common, dt=0.05, t_end=15.0, t_burn=5.0, x0=(0.0, 0.0, 0.0, 0.0),
                    histograms={"H": (0.0, 4.0, 40)})),
        # a guard of the velocities (an energy level): located in the kicks and noise too (velocity_leg)
        "energy_level": (energy_level(), "splitting",
                         dict(common, paths=16, dt=0.05, t_end=10.0, t_burn=2.0, x0=(0.5, 0.0),
                              histograms={"H": (0.0, 1.0, 10)})),
        # three noises: the kernel's general draw (each normal's Philox draw where it differs from the last one's)
        "three_noises": (three_noises(), "milstein",
                         dict(common, dt=0.05, t_end=15.0, t_burn=5.0, x0=(0.0, 0.0, 0.0, 0.0),
                              histograms={"H": (0.0, 4.0, 40), "w": (-3.0, 3.0, 30)})),
    }


def three_noises():
    """An oscillator against a wall at x = 1 (Newton's law, r = 0.8), driven by white noise and by an OU process u,
    beside an independent OU process w: three noises."""
    x, v, u, w = (real_symbol(n) for n in ("x", "v", "u", "w"))
    c, d, a, s, r = (real_symbol(n) for n in ("c", "D", "a", "s", "r"))
    noise = ((0, 0, 0), (sp.sqrt(2 * d), 0, 0), (0, sp.sqrt(2 * a * s), 0), (0, 0, 1))
    return HybridAutomaton((x, v, u, w), {"c": 0.1, "D": 0.1, "a": 2.0, "s": 0.1, "r": 0.8},
                           [Mode("m", (v, -x - c * v + u, -a * u, -w), noise)],
                           [Transition("wall", "m", "m", x - 1, 1, (x, -r * v, u, w))],
                           observables={"H": (x**2 + v**2) / 2, "w": w})


def energy_level():
    """A damped oscillator whose velocity is halved where its energy reaches 1/2 from below."""
    x, v, c, d = (real_symbol(n) for n in ("x", "v", "c", "D"))
    return HybridAutomaton((x, v), {"c": 0.1, "D": 0.2}, [Mode("m", (v, -x - c * v), (0, sp.sqrt(2 * d)))],
                           [Transition("level", "m", "m", x**2 + v**2 - 1, 1, (x, v / 2))],
                           observables={"H": (x**2 + v**2) / 2})


# extra runs of two models: another launch configuration, single precision, and an interrupted and resumed run
VARIANTS = {
    "impact_pair_tpb64": ("impact_pair", dict(threads_per_block=64, launch_steps=37)),
    "forced_tpb64": ("forced", dict(threads_per_block=64, launch_steps=23)),
    "impact_pair_f32": ("impact_pair", dict(precision="f32")),
}


class Interrupt(Exception):
    pass


def interrupted_then_resumed(out: Path, name: str) -> None:
    """Launches of 40 steps with a checkpoint after every second one; the run is stopped after launch 3 (before its
    checkpoint, so the file holds 80 steps) and resumed from there."""
    automaton, scheme, kw = models()[name]
    ck = out / f"{name}_resume_ckpt"
    args = dict(kw, launch_steps=40, checkpoint=ck, checkpoint_every=2)
    real = _auto_cuda._after_launch

    def stopping(n_done):
        if n_done == 120:
            raise Interrupt

    _auto_cuda._after_launch = stopping
    try:
        simulate_automaton(automaton, scheme, **args)
        raise SystemExit("the interruption did not happen")
    except Interrupt:
        pass
    finally:
        _auto_cuda._after_launch = real
    with np.load(ck / "automaton_checkpoint.npz") as d:
        partial = int(d["n_done"][0])
    ens = simulate_automaton(automaton, scheme, **args, resume=True)
    ens.settings["partial_steps"] = partial
    with open(out / f"{name}_resumed.pkl", "wb") as f:
        pickle.dump(ens, f)


DRIVEN = 6
"""Paths of the CPU kernel's ``drive`` fed the GPU's normals."""
CPU_FACTOR = 4
"""The CPU reference has this many times the GPU's paths."""


def philox_increments(seed: int, paths: int, steps: int, m: int, dt: float) -> np.ndarray:
    """The Brownian increments (paths, steps, m) the CUDA kernel draws: sqrt(dt) times normal q = step * m + k of
    the path, half of the Philox draw (q // 2) (hybrid.stochastic._auto_cuda)."""
    k0, k1 = _cuda_rng.seed_key(seed)
    z = np.empty((paths, steps * m))
    for p in range(paths):
        for j in range((steps * m + 1) // 2):
            pair = _cuda_rng.normal_pair_f64(k0, k1, p, j)
            z[p, 2 * j:2 * j + 2] = pair[:min(2, steps * m - 2 * j)]
    return math.sqrt(dt) * z.reshape(paths, steps, m)


def cpu_references(out: Path, name: str, automaton, scheme: str, kw: dict) -> None:
    """The CPU kernel on the same model: an ensemble of its own streams, and ``drive`` along the GPU's normals."""
    cpu_kw = {k: v for k, v in kw.items() if k not in ("scheduler", "threads_per_block")}
    ens = simulate_automaton(automaton, scheme, **dict(cpu_kw, paths=CPU_FACTOR * kw["paths"], seed=kw["seed"] + 1))
    with open(out / f"cpu_{name}.pkl", "wb") as f:
        pickle.dump(ens, f)
    with np.load(out / f"{name}_ckpt" / "automaton_checkpoint.npz") as d:
        steps = int(d["n_done"][0])
    dt = pickle.load(open(out / f"{name}.pkl", "rb")).settings["dt"]
    m = analyse(automaton).n_noise
    dws = philox_increments(kw["seed"], DRIVEN, steps, m, dt)
    end, log, nlog = drive_automaton(automaton, scheme, dt, dws, kw["x0"], events=8)
    np.savez(out / f"drive_{name}.npz", end=end, log=log, nlog=nlog)


def oscillator_route(out: Path) -> None:
    """``simulate_ensemble(DuffingImpact(), "milstein", scheduler="cuda")`` with the "example1" run's step, times,
    seed and H bins: the oscillator's GPU route (its automaton, the law's numbers lifted into parameters)."""
    _, _, kw = models()["example1"]
    args = {k: v for k, v in kw.items() if k not in ("x0", "histograms")}
    stats = simulate_ensemble(DuffingImpact(), "milstein", h_max=4.0, bins=40, xy_bins=None, **args)
    np.savez(out / "oscillator_example1.npz", **stats.to_arrays())


def cli_runs(out: Path) -> None:
    """``vibro mc --scheduler cuda`` on an automaton model and on a forced model with phase sections."""
    from vibro.cli import main as cli

    common = ["--scheduler", "cuda", "--threads-per-block", "32", "--paths", "16", "--seed", "3"]
    rc = cli(["mc", "--model", "impact_pair", *common, "--scheme", "splitting", "--dt", "0.02", "--t-end", "3",
              "--t-burn", "1", "--range", "z=-0.25:0.25:10", "--out", str(out / "cli_pair.csv")])
    rc2 = cli(["mc", "--model", "duffing-forced", *common, "--param", "A=0.3", "--scheme", "splitting", "--dt",
               "0.05", "--t-end", "12", "--t-burn", "5", "--phases", "4", "--out", str(out / "cli_forced.csv")])
    (out / "cli_rc.txt").write_text(f"{rc} {rc2}")


def check_device_fresh(out: Path) -> None:
    """Every run's rows at t = 0 filled on the device (``device_fresh``) against the host's (``fresh``): the names
    of the arrays that differ, per call, into OUTDIR/device_fresh.txt (NaN equal to NaN)."""
    real = _auto_cuda.CudaRun.device_fresh

    def checked(self, paths):
        dev = real(self, paths)
        host = self.fresh(paths)
        bad = [k for k in self.ORDER if not np.array_equal(dev[k].copy_to_host(), host[k], equal_nan=True)
               or dev[k].copy_to_host().dtype != host[k].dtype]
        with open(out / "device_fresh.txt", "a") as f:
            f.write(f"{self.name} {paths} {' '.join(bad) or 'equal'}\n")
        return dev

    _auto_cuda.CudaRun.device_fresh = checked


def main(out: Path) -> None:
    warnings.simplefilter("ignore")
    out.mkdir(parents=True, exist_ok=True)
    check_device_fresh(out)
    table = models()
    runs = {name: (name, {}) for name in table} | VARIANTS
    for run, (name, extra) in runs.items():
        automaton, scheme, kw = table[name]
        t0 = time.perf_counter()
        ens = simulate_automaton(automaton, scheme, **dict(kw, **extra), checkpoint=out / f"{run}_ckpt")
        ens.settings["seconds"] = time.perf_counter() - t0
        with open(out / f"{run}.pkl", "wb") as f:
            pickle.dump(ens, f)
        print(f"{run}: {ens.settings['seconds']:.1f} s", flush=True)
    interrupted_then_resumed(out, "impact_pair")
    oscillator_route(out)
    for name, (automaton, scheme, kw) in table.items():
        t0 = time.perf_counter()
        cpu_references(out, name, automaton, scheme, kw)
        print(f"cpu {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    try:  # a request whose per-path rows cannot fit: refused with the estimate before any work
        automaton, scheme, kw = table["impact_pair"]
        simulate_automaton(automaton, scheme, **dict(kw, paths=10**9, t_end=0.04, t_burn=0.0, events=0,
                                                     max_path_steps=1e20))
        (out / "too_many.txt").write_text("not refused")
    except VibroError as exc:
        (out / "too_many.txt").write_text(f"{type(exc).__name__}: {exc}")
    t0 = time.perf_counter()
    cli_runs(out)
    print(f"cli: {time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
