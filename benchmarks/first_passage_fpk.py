"""First passage of Example 1's energy by fpk (three grids), paper and jump; R(t) at the Monte Carlo's times.

    python benchmarks/first_passage_fpk.py [benchmarks/data/first_passage_mc_dt0.002.json]

Prints one JSON object: per level, the mean time on each grid with its CPU seconds (time.process_time, one core),
the two-grid error estimate, the decay rate, R(t) at the times the Monte Carlo file lists, and the averaged means.
"""

from __future__ import annotations

import json
import sys
import time

from averaging import mean_first_passage_time
from averaging.phase_plane import first_passage_fpk
from models import DuffingImpact, Ma

LEVELS = (0.25, 0.5, 1.0, 1.5, 2.0)
GRIDS = ((60, 64), (120, 128), (240, 256))


def main(mc_file=None):
    mc = json.load(open(mc_file))["levels"] if mc_file else {}
    model = DuffingImpact(restitution=Ma(vc=0.4))
    out = {}
    for H_c in LEVELS:
        row = {"paper": mean_first_passage_time(model, H_c, 0.0, method="paper"),
               "jump": mean_first_passage_time(model, H_c, 0.0, method="jump"), "grids": {}}
        for grid in GRIDS:
            t0 = time.process_time()
            r = first_passage_fpk(model, f"H < {H_c}", grid=grid, check=True, survival=False)
            row["grids"][f"{grid[0]}x{grid[1]}"] = {"mean": r.mean_time, "estimate": r.error_estimate,
                                                    "cpu_seconds_with_check": time.process_time() - t0,
                                                    "cpu_seconds": r.details["cpu_seconds"]}
        times = [float(t) for t in mc.get(str(H_c), {}).get("R_at", {})]
        r = first_passage_fpk(model, f"H < {H_c}", grid=(120, 128), check=False,
                              t_max=max(times + [5 * row["paper"]]) * 1.01, steps=2000)
        row["decay_rate"] = r.decay_rate
        row["R_at"] = {f"{t:.6g}": float(r.survival(t)) for t in times}
        out[str(H_c)] = row
        print(json.dumps({str(H_c): row}), flush=True, file=sys.stderr)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
