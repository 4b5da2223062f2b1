"""``vibro solve`` on forced and coloured-noise models: the method chosen, the escalation, the estimate after the run
and the true L1 error of p(H), at three tolerances.

Cases and references (the true L1 on solve's own 40 bins where a closed form exists, else on the reference's bins):

- the linear forced oscillator without walls (x'' + 0.5 x' + x = 0.4 cos 1.3 t + xi, D = 0.05): the time average
  of its exact sections (2 c H / D noncentral chi-square), sampled at 64 times of the period;
- example 08's forced Duffing impact oscillator (D = 0.02): the stored Monte Carlo of ``vibro mc --phases 16``
  (benchmarks/data/fpk_forced_mc.npz), averaged over the 16 phases; its noise is the L1 between the seeds' averages
  over sqrt(2), over sqrt(seeds);
- the linear oscillator under OU noise (c = 0.5, D = 0.25, alpha = 2): the Lyapunov Gaussian;
- example 10's OU-filtered Duffing impact oscillator: the stored Monte Carlo (benchmarks/data/fpk_coloured_mc.npz,
  noise 0.0004).

CPU is ``time.process_time`` of ``solve`` in this process (2 shared cores). Run: ``python
benchmarks/solve_forced_coloured.py [--quick] [--only=forced|coloured]``.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.stats import ncx2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import fpk_coloured, fpk_forced  # noqa: E402
from models import ImpactOscillator  # noqa: E402
from models.excitation import ou_filter  # noqa: E402
from vibro.solve import solve  # noqa: E402
from vibro.studies.workprecision import linear_ou_energy_masses  # noqa: E402

C, A, W, D = 0.5, 0.4, 1.3, 0.05


def linear_forced():
    model = ImpactOscillator("x", "c*y", forcing="A*cos(W*t)", barriers=None,
                             parameters={"c": C, "A": A, "W": W, "D": D})
    z = A / (1.0 - W**2 + 1j * C * W)

    def true(sol):
        e = sol.edges
        exact = []
        for t in 2.0 * np.pi / W * np.arange(64) / 64:
            xp, yp = (z * np.exp(1j * W * t)).real, (1j * W * z * np.exp(1j * W * t)).real
            exact.append(np.diff(ncx2.cdf(2.0 * e * C / D, 2, (xp**2 + yp**2) * C / D)))
        return float(np.abs(sol.masses - np.mean(exact, axis=0)).sum()), 0.0

    return model, true


def example_08():
    data = np.load(fpk_forced.DATA)
    edges = data["edges"][::fpk_forced.MERGE]
    runs = []
    for key in sorted(k for k in data.files if k.startswith("D0.02_seed") and not k.endswith("_summary")):
        counts = data[key].astype(float)
        inside = counts[:, 1:-1].reshape(fpk_forced.PHASES, -1, fpk_forced.MERGE).sum(axis=2)
        runs.append((inside / counts.sum(axis=1, keepdims=True)).mean(axis=0))  # the time average
    runs = np.array(runs)
    ref = runs.mean(axis=0)
    pairs = [np.abs(runs[i] - runs[j]).sum() / np.sqrt(2.0) for i in range(len(runs)) for j in range(i)]
    noise = float(np.mean(pairs) / np.sqrt(len(runs)))

    def true(sol):
        return float(np.abs(sol.result.mean.bin_masses(edges) - ref).sum()), noise

    return fpk_forced.duffing(0.02), true


def linear_ou():
    c, d, alpha = 0.5, 0.25, 2.0
    model = ou_filter(ImpactOscillator("x", "c*y", parameters={"c": c, "D": d}, barriers=None, name="linear"),
                      alpha=alpha)

    def true(sol):
        return float(np.abs(sol.masses - linear_ou_energy_masses(c, d, alpha, sol.edges)).sum()), 0.0

    return model, true


def example_10():
    edges, ref, noise = fpk_coloured.mc_reference()

    def true(sol):
        return float(np.abs(sol.result.bin_masses(edges) - ref).sum()), noise

    return fpk_coloured.model(), true


def main(quick: bool, only: str | None = None) -> None:
    cases = [("linear forced (closed form)", linear_forced), ("example 08, D = 0.02 (Monte Carlo)", example_08),
             ("linear, OU alpha = 2 (Lyapunov)", linear_ou), ("example 10, OU alpha = 1 (Monte Carlo)", example_10)]
    if only is not None:  # "forced" or "coloured"
        cases = cases[:2] if only == "forced" else cases[2:]
    tols = (0.05, 0.02) if quick else (0.05, 0.02, 0.01)
    print("| case | tol | method, settings | estimated L1 | true L1 | reference noise | CPU s | escalation |")
    print("|---|---|---|---|---|---|---|---|")
    for label, build in cases:
        model, true = build()
        for tol in tols:
            t0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sol = solve(model, tol)
            cpu = time.process_time() - t0
            l1, noise = true(sol)
            st = sol.choice.settings
            what = f"{sol.method} {st.get('scheme', '')} {st.get('grid', '')}" + (
                f", {st['steps']} + {2 * st['steps']} steps" if "steps" in st else "")
            steps = " -> ".join(f"{a[1].get('grid')}{' ' + str(a[1]['steps']) if 'steps' in a[1] else ''} "
                                f"({a[2]:.3g})" for a in sol.attempts) if len(sol.attempts) > 1 else "-"
            print(f"| {label} | {tol:g} | {what} | {sol.estimated_error:.3g} | {l1:.3g} | "
                  f"{noise:.2g} | {cpu:.1f} | {steps} |", flush=True)


if __name__ == "__main__":
    main("--quick" in sys.argv, next((a.split("=")[1] for a in sys.argv if a.startswith("--only=")), None))
