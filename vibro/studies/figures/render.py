"""Drawing: energy figures (linear and log panels) and joint figures (analytic beside Monte Carlo contours)."""

from __future__ import annotations

import textwrap

import numpy as np

from .mcdata import JOINT_GRID, mc_h_density, mc_xy_density, xy_range

COLOURS = ("#1f77b4", "#d62728", "#2ca02c")
MARKERS = ("o", "^", "s")  # the paper's ● ▲ ■


def _figure(width, height):
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height))


def _caption(fig, caption, width_chars):
    text = "\n".join(textwrap.wrap(caption, width_chars))
    fig.text(0.01, 0.01, text, ha="left", va="bottom", fontsize=6.5, family="sans-serif")
    return text.count("\n") + 1


def render_figure(spec, results, metrics, caption, path, dpi=110) -> None:
    """Draw figure ``spec`` from computed ``results`` into ``path`` (PNG).

    Energy figures: left panel linear, right panel log-scale p(H); per case a solid line (paper method), a dashed
    line (jump method), Monte Carlo symbols and a dotted vertical line at H = G(Δ). Joint figures: filled contours
    of p(x, y) for the paper method, the jump method and Monte Carlo on one colour scale, barriers at x = ±Δ.
    """
    if spec.kind == "energy":
        _render_energy(spec, results, metrics, caption, path, dpi)
    else:
        _render_joint(spec, results, metrics, caption, path, dpi)


def _render_energy(spec, results, metrics, caption, path, dpi):

    fig = _figure(11.0, 5.6)
    nlines = _caption(fig, caption, 190)
    bottom = min(0.45, 0.1 + 0.028 * nlines)
    axes = [fig.add_axes([0.06, bottom, 0.42, 0.88 - bottom]), fig.add_axes([0.56, bottom, 0.42, 0.88 - bottom])]
    h_top = max(r.case.h_max for r in results)
    floor = np.inf
    for i, (res, m) in enumerate(zip(results, metrics)):
        col, mk = COLOURS[i % 3], MARKERS[i % 3]
        for ax in axes:
            for method, style in (("paper", "-"), ("jump", "--")):
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
                         color=col, fontsize=7, xycoords=("data", "axes fraction"))
    axes[0].set_title("p(H), linear scale", fontsize=9)
    axes[1].set_title("p(H), log scale (tails)", fontsize=9)
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
        ax.set_xlabel("H", fontsize=9)
        ax.set_ylabel("p(H)", fontsize=9)
        ax.tick_params(labelsize=8)
    axes[0].set_ylim(bottom=0)
    axes[0].legend(fontsize=6.5, ncol=1, frameon=False)
    fig.suptitle(f"Fig. {spec.number}: {spec.title}", fontsize=10, y=0.98)
    fig.savefig(path, dpi=dpi, format="png")


def _render_joint(spec, results, metrics, caption, path, dpi):

    res = results[0]
    (x0, x1), (y0, y1) = xy_range(res.case)
    xs, ys = np.linspace(x0, x1, JOINT_GRID), np.linspace(y0, y1, JOINT_GRID)
    panels = [("a  analytic, paper method (eq. 31)", xs, ys, np.asarray(res.densities["paper"].joint(xs, ys))),
              ("b  analytic, jump method (eq. 31)", xs, ys, np.asarray(res.densities["jump"].joint(xs, ys)))]
    if res.mc is not None:
        xe, ye = (np.asarray(e) for e in res.mc.xy_edges)
        label = "c  Monte Carlo" + ("" if spec.in_paper_mc else " (our addition; not in the paper)")
        panels.append((label, xe, ye, mc_xy_density(res.mc)))  # cell edges: drawn as the histogram's cells
    vmax = max(float(np.nanmax(p)) for *_, p in panels)
    levels = np.linspace(0.0, vmax, 16)
    fig = _figure(4.0 * len(panels) + 1.0, 5.4)
    nlines = _caption(fig, caption, int(60 * len(panels)))
    bottom = min(0.45, 0.1 + 0.03 * nlines)
    width = 0.86 / len(panels)
    cs = None
    for i, (title, px, py, p) in enumerate(panels):
        ax = fig.add_axes([0.05 + i * width, bottom, width - 0.05, 0.86 - bottom])
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
        ax.set_title(title, fontsize=8)
        ax.set_xlabel("x", fontsize=9)
        if i == 0:
            ax.set_ylabel("y", fontsize=9)
        ax.tick_params(labelsize=7)
    cax = fig.add_axes([0.93, bottom, 0.015, 0.86 - bottom])
    fig.colorbar(cs, cax=cax).ax.tick_params(labelsize=7)
    fig.suptitle(f"Fig. {spec.number}: {spec.title}", fontsize=10, y=0.98)
    fig.savefig(path, dpi=dpi, format="png")
