"""Drawing: energy figures (linear and log panels) and joint figures (analytic beside Monte Carlo contours)."""

from __future__ import annotations

import textwrap

import numpy as np

from .mcdata import JOINT_GRID, mc_h_density, mc_xy_density, xy_range

COLOURS = ("#1f77b4", "#d62728", "#2ca02c")
MARKERS = ("o", "^", "s")  # the paper's ● ▲ ■

FONT_PT = 9.0
"""Smallest font anywhere in a figure (ticks, legend, caption): readable when the PNG is shown at its size."""
LABEL_PT = 10.0
"""Axis labels, panel titles and colour-bar labels."""


def _figure(width, height):
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height))


def _caption_lines(caption: str, width_in: float) -> list[str]:
    """``caption`` wrapped to the figure width at :data:`FONT_PT` (glyphs average ~0.55 em; 0.58 keeps a margin)."""
    chars = max(40, int((width_in - 0.3) * 72.0 / (0.58 * FONT_PT)))
    return textwrap.wrap(caption, chars, break_on_hyphens=False)  # keep names like "vibro-impact" whole


def _with_caption(width_in: float, plot_in: float, caption: str, top_in: float = 0.6, below_in: float = 0.6):
    """A figure whose height fits the plots and the whole caption; returns (fig, bottom, height) of the plot band.

    The caption is drawn at :data:`FONT_PT` under the plots; the figure grows with it rather than squeezing the
    plots or shrinking the text (earlier figures used 6.5 pt to fit).
    """
    lines = _caption_lines(caption, width_in)
    caption_in = len(lines) * FONT_PT * 1.3 / 72.0 + 0.2
    height_in = top_in + plot_in + below_in + caption_in
    fig = _figure(width_in, height_in)
    fig.text(0.15 / width_in, 0.1 / height_in, "\n".join(lines), ha="left", va="bottom", fontsize=FONT_PT,
             family="sans-serif", linespacing=1.3)
    return fig, (caption_in + below_in) / height_in, plot_in / height_in


def render_figure(spec, results, metrics, caption, path, dpi=110) -> None:
    """Draw figure ``spec`` from computed ``results`` into ``path`` (PNG).

    Energy figures: left panel linear, right panel log-scale p(H); per case a solid line (paper method), a dashed
    line (jump method), a dash-dot line (phase-plane FPK), Monte Carlo symbols and a dotted vertical line at
    H = G(Δ). Joint figures: filled contours of p(x, y) for the paper method, the jump method, the phase-plane FPK
    solution and Monte Carlo on one colour scale, barriers at x = ±Δ.
    """
    if spec.kind == "energy":
        _render_energy(spec, results, metrics, caption, path, dpi)
    else:
        _render_joint(spec, results, metrics, caption, path, dpi)


def _render_energy(spec, results, metrics, caption, path, dpi):

    fig, bottom, band = _with_caption(11.0, 4.2, caption)
    axes = [fig.add_axes([0.07, bottom, 0.41, band]), fig.add_axes([0.57, bottom, 0.41, band])]
    h_top = max(r.case.h_max for r in results)
    floor = np.inf
    for i, (res, m) in enumerate(zip(results, metrics)):
        col, mk = COLOURS[i % 3], MARKERS[i % 3]
        for ax in axes:
            for method, style in (("paper", "-"), ("jump", "--"), ("fpk", "-.")):
                sd = res.densities.get(method)
                if sd is not None:
                    ax.plot(sd.H, sd.p, style, color=col, lw=1.4,
                            label=f"{res.case.label}, {method}" if ax is axes[0] else None)
            if res.mc is not None:
                e = np.asarray(res.mc.h_edges)
                c = 0.5 * (e[1:] + e[:-1])
                p = mc_h_density(res.mc)
                ax.plot(c, np.where(p > 0, p, np.nan), mk, color=col, ms=3.5, mfc="none", mew=0.9,
                        label=f"{res.case.label}, Monte Carlo" if ax is axes[0] else None)
                if np.any(p > 0):
                    floor = min(floor, float(np.min(p[p > 0])))
            ax.axvline(m["G_delta"], color=col, ls=":", lw=1.0)
        axes[0].annotate("G(Δ)", (m["G_delta"], 0), xytext=(2, 2 + 9 * i), textcoords="offset points",
                         color=col, fontsize=FONT_PT, xycoords=("data", "axes fraction"))
    axes[0].set_title("p(H), linear scale", fontsize=LABEL_PT)
    axes[1].set_title("p(H), log scale (tails)", fontsize=LABEL_PT)
    axes[1].set_yscale("log")
    peak = max(float(np.max(r.densities["paper"].p)) for r in results)
    low = floor if np.isfinite(floor) else peak * 1e-5
    axes[1].set_ylim(max(low * 0.3, peak * 1e-6), peak * 2.0)
    # the linear panel stops where every analytic curve is below 1e-3 of the highest peak (the log panel shows all)
    visible = [float(np.max(np.asarray(sd.H)[np.asarray(sd.p) > 1e-3 * peak], initial=0.0))
               for r in results for sd in r.densities.values()]
    h_lin = min(h_top, 1.1 * max(visible + [max(m["G_delta"] for m in metrics)]))
    for ax in axes:
        ax.set_xlim(0, h_lin if ax is axes[0] else h_top)
        ax.set_xlabel("H", fontsize=LABEL_PT)
        ax.set_ylabel("p(H)", fontsize=LABEL_PT)
        ax.tick_params(labelsize=FONT_PT)
    axes[0].set_ylim(bottom=0)
    axes[0].legend(fontsize=FONT_PT, ncol=1, frameon=False)
    fig.suptitle(f"Fig. {spec.number}: {spec.title}", fontsize=11, y=1.0 - 0.12 / fig.get_figheight(), va="top")
    fig.savefig(path, dpi=dpi, format="png")


def _render_joint(spec, results, metrics, caption, path, dpi):

    res = results[0]
    (x0, x1), (y0, y1) = xy_range(res.case)
    xs, ys = np.linspace(x0, x1, JOINT_GRID), np.linspace(y0, y1, JOINT_GRID)
    panels = [("a  analytic, paper method (eq. 31)", xs, ys, np.asarray(res.densities["paper"].joint(xs, ys))),
              ("b  analytic, jump method (eq. 31)", xs, ys, np.asarray(res.densities["jump"].joint(xs, ys)))]
    if "fpk" in res.densities:
        # the third-order upwind flux leaves round-off negatives (~1e-10) in the far tail: drawn as 0
        fpk = np.maximum(np.asarray(res.densities["fpk"].joint(xs, ys)), 0.0)
        panels.append(("c  phase-plane FPK (no averaging)", xs, ys, fpk))
    if res.mc is not None:
        xe, ye = (np.asarray(e) for e in res.mc.xy_edges)
        label = f"{'abcd'[len(panels)]}  Monte Carlo" + ("" if spec.in_paper_mc else
                                                          " (our addition; not in the paper)")
        panels.append((label, xe, ye, mc_xy_density(res.mc)))  # cell edges: drawn as the histogram's cells
    vmax = max(float(np.nanmax(p)) for *_, p in panels)
    levels = np.linspace(0.0, vmax, 16)
    # in inches: left margin, panels with a gap for the next panel's tick labels, then the colour bar right beside
    # the last panel (it used to sit at the figure's edge, far from the data) and room for its label
    left, panel, gap, bar_gap, bar, right = 0.75, 3.2, 0.5, 0.12, 0.18, 1.0
    width_in = left + len(panels) * panel + (len(panels) - 1) * gap + bar_gap + bar + right
    fig, bottom, tall = _with_caption(width_in, 3.9, caption)
    cs = None
    for i, (title, px, py, p) in enumerate(panels):
        ax = fig.add_axes([(left + i * (panel + gap)) / width_in, bottom, panel / width_in, tall])
        if len(px) == p.shape[1] + 1 and cs is not None:
            # histogram cells, each painted with the colour of the contour band its value falls in
            band = np.clip(np.searchsorted(levels, p, side="right") - 1, 0, len(levels) - 2)
            mid = 0.5 * (levels[band] + levels[band + 1])
            ax.pcolormesh(px, py, mid, cmap=cs.cmap, norm=cs.norm, shading="flat")
        else:
            cs = ax.contourf(px, py, p, levels=levels, cmap="viridis", extend="neither")
        d = res.case.delta
        for xb in (-d, d):
            ax.axvline(xb, color="k", lw=2.0)
        ax.set_xlim(x0 - 0.04 * (x1 - x0), x1 + 0.04 * (x1 - x0))
        ax.set_ylim(y0, y1)
        ax.set_title(title, fontsize=LABEL_PT)
        ax.set_xlabel("x (displacement)", fontsize=LABEL_PT)
        if i == 0:
            ax.set_ylabel("y (velocity)", fontsize=LABEL_PT)
        ax.tick_params(labelsize=FONT_PT)
    x_bar = left + len(panels) * panel + (len(panels) - 1) * gap + bar_gap
    cax = fig.add_axes([x_bar / width_in, bottom, bar / width_in, tall])
    cbar = fig.colorbar(cs, cax=cax)
    cbar.set_label("joint density p(x, y)", fontsize=LABEL_PT)
    cbar.ax.tick_params(labelsize=FONT_PT)
    fig.suptitle(f"Fig. {spec.number}: {spec.title}", fontsize=11, y=1.0 - 0.12 / fig.get_figheight(), va="top")
    fig.savefig(path, dpi=dpi, format="png")
