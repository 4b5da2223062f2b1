"""Monte Carlo reference of the OU-filtered Duffing impact oscillator for ``benchmarks/fpk_coloured.py``.

Model (``MODEL`` below): x'' + c x' + a x + b x**3 = z, walls at +-delta with Newton restitution r, z the output of
the Ornstein-Uhlenbeck filter ``dz = -alpha z dt + sqrt(2 alpha**2 D) dW`` (``models.excitation.ou_filter``).
Each run is ``simulate_automaton(..., "splitting")`` from rest with a burn-in; the histograms of H, x, y, z and the
joint (x, y) histogram are stored with the run's settings in ``benchmarks/data/fpk_coloured_mc.npz``. Two seeds at
dt = 0.01 give the Monte Carlo noise; one seed at dt = 0.005 bounds the time-step bias.

Run: ``nice -n 10 python benchmarks/fpk_coloured_mc.py [RUN ...]`` (runs: ``dt0.01_seed1``, ``dt0.01_seed2``,
``dt0.005_seed3``; default all; each about 5 minutes on the 2 shared cores). Existing runs in the file are kept.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hybrid.stochastic import simulate_automaton  # noqa: E402
from models import DuffingImpact, Newton  # noqa: E402
from models.excitation import ou_filter  # noqa: E402

DATA = ROOT / "benchmarks" / "data" / "fpk_coloured_mc.npz"
PARAMS = {"c": 0.2, "D": 0.1, "delta": 0.6}
ALPHA = 1.0
RESTITUTION = 0.8
RANGES = {"H": (0.0, 3.0, 600), "x": (-0.6, 0.6, 120), "y": (-2.5, 2.5, 200), "z": (-2.0, 2.0, 200)}
JOINT = ("x", "y", (-0.6, 0.6, 48), (-2.5, 2.5, 100))
RUNS = {"dt0.01_seed1": (0.01, 1, 2.0e5), "dt0.01_seed2": (0.01, 2, 2.0e5), "dt0.005_seed3": (0.005, 3, 1.0e5)}
PATHS, T_BURN = 64, 100.0


def model():
    """The OU-filtered Duffing impact oscillator of the benchmark."""
    return ou_filter(DuffingImpact(restitution=Newton(RESTITUTION), **PARAMS), alpha=ALPHA)


def run(name: str) -> dict:
    dt, seed, t_end = RUNS[name]
    c0, w0 = time.process_time(), time.perf_counter()
    ens = simulate_automaton(model(), "splitting", dt=dt, paths=PATHS, t_end=t_end, t_burn=T_BURN,
                             x0=(0.0, 0.0, 0.0, 0.0), seed=seed, chunk_paths=4,
                             observables={"H": "y**2/2 + a*x**2/2 + b*x**4/4", "x": "x", "y": "y", "z": "z",
                                          "z2": "z**2"},
                             histograms={**RANGES, "z2": None}, joint=JOINT)
    out = {f"{name}_{k}": np.asarray(ens.counts[k]) for k in RANGES}
    out[f"{name}_joint"] = np.asarray(ens.joint[4])
    eh = ens.mean("H")
    info = {"dt": dt, "seed": seed, "t_end": t_end, "t_burn": T_BURN, "paths": PATHS, "chunk_paths": 4,
            "scheme": "splitting", "samples": int(ens.flags["samples"]), "E[H]": eh.value, "E[H]_ci95": eh.ci,
            "E[z^2]": ens.mean("z2").value, "E[z^2]_ci95": ens.mean("z2").ci, "impacts": int(np.sum(ens.events)),
            "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0}
    out[f"{name}_info"] = np.array(json.dumps(info))
    print(name, info, flush=True)
    return out


def main(names) -> None:
    stored = dict(np.load(DATA)) if DATA.exists() else {}
    for name in names:
        stored.update(run(name))
        stored["model"] = np.array(json.dumps({"base": "DuffingImpact", **PARAMS, "filter": "ou", "alpha": ALPHA,
                                               "restitution": f"newton:e={RESTITUTION}"}))
        stored["ranges"] = np.array(json.dumps({**RANGES, "joint": JOINT}))
        DATA.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(DATA, **stored)


if __name__ == "__main__":
    main(sys.argv[1:] or list(RUNS))
