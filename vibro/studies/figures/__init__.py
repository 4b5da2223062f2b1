"""Reproduce the paper's Figures 2-16: averaging (paper and jump methods) beside Monte Carlo.

Use ``vibro figure N --out-dir DIR`` or :func:`run_figure`. Each figure writes ``figNN.png``, ``figNN.csv`` (every
plotted curve and point, long format) and ``figNN.json`` (parameters, choices, methods, seeds, versions, wall time
and the L1 distance of each analytic curve from its Monte Carlo histogram). The sidecar is written last; a figure
whose sidecar matches the current spec hash is reused.

Examples
--------
>>> from vibro.studies.figures import FIGURES, figure_spec
>>> sorted(FIGURES)[0], sorted(FIGURES)[-1]
(2, 16)
>>> figure_spec(2).cases[0].label
'Δ = 0.8'
"""

from vibro.solve.metrics import bin_average, halves_noise_l1, joint_bin_average, l1_joint, l1_on_bins

from .runner import ANALYTIC_METHODS, FigureResult, output_names, run_figure, run_figures, xy_range
from .specs import ENERGY_FIGURES, FIGURES, PRESETS, VDP_READING, Case, FigureSpec, MCSize, figure_spec

__all__ = [
    "ANALYTIC_METHODS", "ENERGY_FIGURES", "FIGURES", "PRESETS", "VDP_READING", "Case", "FigureResult", "FigureSpec",
    "MCSize", "bin_average", "figure_spec", "halves_noise_l1", "joint_bin_average", "l1_joint", "l1_on_bins",
    "output_names", "run_figure", "run_figures", "xy_range",
]
