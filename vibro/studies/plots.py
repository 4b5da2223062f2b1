"""Pictures of a user's own results: the CSV files that ``vibro pdf``, ``mc``, ``solve`` and ``orbit`` write.

A file is recognised by its columns, never by its name:

========================  ==========================================  =====================================
kind                      columns                                     written by
========================  ==========================================  =====================================
``energy``                ``H, p``                                    ``vibro pdf --out``, ``vibro solve --out``
``energy-histogram``      ``H_lo, H_hi, count, density``              ``vibro mc --out``
``joint``                 ``x, y, p`` (long form)                     ``vibro pdf --joint``
``joint-histogram``       ``x_lo, x_hi, y_lo, y_hi, count, density``  ``vibro mc --joint``
``impacts``               ``t, v_minus, H_minus, H_plus`` (+ more)    ``vibro orbit --out``
``paths``                 ``t, x, y`` (optionally ``path``)           a sample path or an orbit trajectory
========================  ==========================================  =====================================

Energy files are compared on one figure (linear and log panels); joint files become filled-contour panels on one
colour scale; impact logs show H against time and the impact speeds. G(Δ) and the barriers come from a JSON sidecar
beside the CSV when there is one (any key ``barrier_energy``, ``G_delta`` or ``g_barrier``; ``barriers`` or
``delta``), or from the caller.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybrid.errors import ParameterError, VibroWarning
from hybrid.io import atomic_write

FONT_PT = 9.0
"""Smallest font on a plot (ticks, legends, notes)."""
LABEL_PT = 10.0
"""Axis labels, titles, colour-bar labels."""

KINDS = {
    "energy": ("H", "p"),
    "energy-histogram": ("H_lo", "H_hi", "count", "density"),
    "joint": ("x", "y", "p"),
    "joint-histogram": ("x_lo", "x_hi", "y_lo", "y_hi", "count", "density"),
    "impacts": ("t", "v_minus", "H_minus", "H_plus"),
    "paths": ("t", "x", "y"),
    "survival": ("t", "R"),
    "spectrum": ("omega", "S"),
}
"""Each kind and the columns that identify it (a file may carry more columns)."""

GROUPS = {"energy": "energy", "energy-histogram": "energy", "joint": "joint", "joint-histogram": "joint",
          "impacts": "impacts", "paths": "paths", "survival": "survival", "spectrum": "spectrum"}
"""Kinds that can share one figure."""

_PRIORITY = ("joint-histogram", "energy-histogram", "impacts", "joint", "paths", "energy", "survival", "spectrum")
"""Most specific first: an mc histogram also has no 'p', a joint pdf also has 'x' and 'y'."""

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


def kind_of(columns) -> str:
    """The kind of a table from its column names.

    Raises
    ------
    ParameterError
        When the columns match no kind.

    Examples
    --------
    >>> kind_of(["H", "p"]), kind_of(["H_lo", "H_hi", "count", "density"]), kind_of(["x", "y", "p"])
    ('energy', 'energy-histogram', 'joint')
    >>> kind_of(["a", "b"])
    Traceback (most recent call last):
    ...
    hybrid.errors.ParameterError: columns a,b match no known output; expected one of: H,p | ...
    """
    cols = {str(c).strip() for c in columns}
    for kind in _PRIORITY:
        if set(KINDS[kind]) <= cols:
            return kind
    known = " | ".join(",".join(c) for c in KINDS.values())
    raise ParameterError(f"columns {','.join(map(str, columns))} match no known output; expected one of: {known}")


@dataclass
class Table:
    """One CSV file: its kind, its data, a label and what its sidecar says (G(Δ), barriers)."""

    path: Path
    kind: str
    frame: object
    label: str
    barrier_energy: float | None = None
    barriers: tuple[float, float] | None = None
    meta: dict = field(default_factory=dict)


def _find(data, names):
    """The first value under any of ``names`` anywhere in nested dicts/lists (depth first), or None."""
    if isinstance(data, dict):
        for k in names:
            if k in data and data[k] is not None:
                return data[k]
        for v in data.values():
            found = _find(v, names)
            if found is not None:
                return found
    elif isinstance(data, list):
        for v in data:
            found = _find(v, names)
            if found is not None:
                return found
    return None


def sidecar_of(path) -> dict:
    """The JSON sidecar beside ``path`` (``name.json`` or ``name.csv.json``), or ``{}`` when there is none.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()); _ = (d / "p.json").write_text('{"G_delta": 0.55}')
    >>> sidecar_of(d / "p.csv")
    {'G_delta': 0.55}
    """
    path = Path(path)
    for cand in (path.with_suffix(".json"), path.with_name(path.name + ".json")):
        if cand.is_file():
            try:
                data = json.loads(cand.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            return data if isinstance(data, dict) else {}
    return {}


def read_table(path, label: str | None = None) -> Table:
    """Read one CSV written by the project and recognise its kind by its columns.

    Raises
    ------
    ParameterError
        When the file is missing, is not a CSV, or has columns of no known kind.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> f = pathlib.Path(tempfile.mkdtemp()) / "p.csv"; _ = f.write_text("H,p\\n0,1\\n1,0.5\\n")
    >>> read_table(f).kind
    'energy'
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"{str(path)!r} does not exist")
    try:
        frame = pd.read_csv(path)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise ParameterError(f"{str(path)!r} is not a CSV table: {exc}".splitlines()[0]) from exc
    try:
        kind = kind_of(frame.columns)
    except ParameterError as exc:
        raise ParameterError(f"{path.name}: {exc}") from None
    if len(frame) == 0:
        raise ParameterError(f"{path.name}: no rows to plot")
    frame = _finite_rows(frame, KINDS[kind], path.name)
    meta = sidecar_of(path)
    g = _find(meta, ("barrier_energy", "G_delta", "g_barrier"))
    bars = _find(meta, ("barriers",))
    if bars is None:
        delta = _find(meta, ("delta",))
        bars = None if delta is None else (-float(delta), float(delta))
    return Table(path, kind, frame, label or path.stem, None if g is None else float(g),
                 None if bars is None else (float(bars[0]), float(bars[1])), meta)


def _finite_rows(frame, columns, name: str):
    """The rows whose numbers in ``columns`` are all finite; text there is refused, dropped rows are counted in a
    warning (other columns, such as an impact log's ``barrier``, are kept as they are)."""
    import warnings

    import pandas as pd

    frame = frame.rename(columns=lambda c: str(c).strip())
    columns = list(columns)
    numeric = frame[columns].apply(pd.to_numeric, errors="coerce")
    text = numeric.isna() & frame[columns].notna()
    if text.to_numpy().any():
        column = columns[int(np.argmax(text.any().to_numpy()))]
        raise ParameterError(f"{name}: column {column!r} holds text where numbers belong (first at row "
                             f"{int(np.argmax(text[column].to_numpy())) + 2})")
    finite = np.isfinite(numeric.to_numpy(dtype=float)).all(axis=1)
    if not finite.any():
        raise ParameterError(f"{name}: no row holds only finite numbers (NaN or infinite values); nothing to plot")
    if not finite.all():
        warnings.warn(f"{name}: {int((~finite).sum())} of {len(frame)} rows hold NaN or infinite values and are "
                      "left out of the plot", VibroWarning, stacklevel=3)
    frame = frame.copy()
    frame[columns] = numeric
    return frame[finite].reset_index(drop=True)


def _figure(width, height):
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout="constrained")


def _style(ax, xlabel, ylabel):
    ax.set_xlabel(xlabel, fontsize=LABEL_PT)
    ax.set_ylabel(ylabel, fontsize=LABEL_PT)
    ax.tick_params(labelsize=FONT_PT)


def _energy_curve(t: Table):
    f = t.frame
    if t.kind == "energy":
        return np.asarray(f["H"], float), np.asarray(f["p"], float), "-"
    centre = 0.5 * (np.asarray(f["H_lo"], float) + np.asarray(f["H_hi"], float))
    return centre, np.asarray(f["density"], float), "o"


def plot_energy(tables, barrier_energy: float | None = None):
    """p(H) of several files on a linear and a log panel, with a dotted line at each known G(Δ).

    Densities (``energy``) are lines, Monte Carlo histograms (``energy-histogram``) are open symbols at the bin
    centres.

    Examples
    --------
    >>> import pandas as pd, pathlib
    >>> t = Table(pathlib.Path("p.csv"), "energy", pd.DataFrame({"H": [0, 1, 2], "p": [1, .5, .2]}), "p")
    >>> [ax.get_title() for ax in plot_energy([t], barrier_energy=0.55).axes]
    ['p(H), linear scale', 'p(H), log scale']
    """
    fig = _figure(10.0, 4.4)
    lin, log = fig.subplots(1, 2)
    positive, marked = [], []
    for i, t in enumerate(tables):
        col = COLOURS[i % len(COLOURS)]
        H, p, style = _energy_curve(t)
        for ax in (lin, log):
            kw = dict(ms=3.5, mfc="none", mew=0.9) if style == "o" else dict(lw=1.5)
            ax.plot(H, np.where(p > 0, p, np.nan) if ax is log else p, style, color=col,
                    label=t.label if ax is lin else None, **kw)
        positive.extend(p[p > 0].tolist())
        g = barrier_energy if barrier_energy is not None else t.barrier_energy
        if g is not None and not any(np.isclose(g, m) for m in marked):  # one mark per distinct G(Δ)
            mark = "k" if barrier_energy is not None else col
            for ax in (lin, log):
                ax.axvline(g, color=mark, ls=":", lw=1.1)
            lin.annotate("G(Δ)", (g, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -14 - 12 * len(marked)),
                         textcoords="offset points", color=mark, fontsize=FONT_PT)
            marked.append(g)
    lin.set_title("p(H), linear scale", fontsize=LABEL_PT)
    log.set_title("p(H), log scale", fontsize=LABEL_PT)
    log.set_yscale("log")
    if positive:
        top = max(positive)
        log.set_ylim(max(min(positive) * 0.5, top * 1e-8), top * 2.0)
    lin.set_ylim(bottom=0)
    for ax in (lin, log):
        _style(ax, "energy H", "p(H)")
    lin.legend(fontsize=FONT_PT, frameon=False)
    return fig


def _grid(t: Table):
    """(x, y, P) on a rectangular grid; P has rows y, columns x."""
    f = t.frame
    if t.kind == "joint":
        wide = f.pivot_table(index="y", columns="x", values="p", aggfunc="mean")
    else:
        f = f.assign(x=0.5 * (f["x_lo"] + f["x_hi"]), y=0.5 * (f["y_lo"] + f["y_hi"]))
        wide = f.pivot_table(index="y", columns="x", values="density", aggfunc="mean")
    return np.asarray(wide.columns, float), np.asarray(wide.index, float), wide.to_numpy(dtype=float)


def plot_joint(tables, barriers: tuple[float, float] | None = None):
    """Filled contours of p(x, y), one panel per file on one colour scale, the barriers as thick vertical lines.

    The colour bar sits right beside the last panel and is labelled.

    Examples
    --------
    >>> import pandas as pd, pathlib, numpy as np
    >>> X, Y = np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-2, 2, 5))
    >>> df = pd.DataFrame({"x": X.ravel(), "y": Y.ravel(), "p": np.exp(-X.ravel()**2 - Y.ravel()**2)})
    >>> fig = plot_joint([Table(pathlib.Path("j.csv"), "joint", df, "j")], barriers=(-1, 1))
    >>> fig.axes[-1].get_ylabel()
    'joint density p(x, y)'
    """
    grids = [_grid(t) for t in tables]
    vmax = max(float(np.nanmax(P)) for *_, P in grids)
    if not np.isfinite(vmax) or vmax <= 0:
        raise ParameterError("the joint density is zero or not finite everywhere: nothing to draw")
    levels = np.linspace(0.0, vmax, 16)
    fig = _figure(3.6 * len(tables) + 1.2, 4.4)
    axes = np.atleast_1d(fig.subplots(1, len(tables), sharey=True))
    cs = None
    for ax, t, (x, y, P) in zip(axes, tables, grids):
        cs = ax.contourf(x, y, np.nan_to_num(P), levels=levels, cmap="viridis")
        wall = barriers if barriers is not None else t.barriers
        if wall is not None:
            for xb in wall:
                ax.axvline(xb, color="k", lw=2.2)
            lo, hi = min(wall[0], x.min()), max(wall[1], x.max())
            ax.set_xlim(lo - 0.04 * (hi - lo), hi + 0.04 * (hi - lo))  # the walls must not hide under the frame
        ax.set_title(t.label + ("" if wall is not None else " (barriers unknown)"), fontsize=LABEL_PT)
        _style(ax, "x (displacement)", "y (velocity)" if ax is axes[0] else "")
    cbar = fig.colorbar(cs, ax=list(axes), pad=0.015, fraction=0.05)
    cbar.set_label("joint density p(x, y)", fontsize=LABEL_PT)
    cbar.ax.tick_params(labelsize=FONT_PT)
    return fig


def plot_impacts(tables, barrier_energy: float | None = None):
    """Impact logs: the energy before and after each impact against time, and the impact speeds.

    Examples
    --------
    >>> import pandas as pd, pathlib
    >>> df = pd.DataFrame({"t": [0.5, 1.7], "v_minus": [1.9, -1.4], "H_minus": [2.4, 1.5], "H_plus": [1.6, 1.2]})
    >>> [ax.get_ylabel() for ax in plot_impacts([Table(pathlib.Path("i.csv"), "impacts", df, "i")]).axes]
    ['energy H', 'impact speed |v-|']
    """
    fig = _figure(10.0, 4.2)
    left, right = fig.subplots(1, 2)
    for i, t in enumerate(tables):
        col = COLOURS[i % len(COLOURS)]
        f = t.frame
        tt, hm, hp = (np.asarray(f[c], float) for c in ("t", "H_minus", "H_plus"))
        # H is constant between impacts of a free orbit: a staircase through (t_k, H-_k) -> (t_k, H+_k)
        stairs_t = np.repeat(tt, 2)
        stairs_h = np.column_stack([hm, hp]).ravel()
        left.plot(stairs_t, stairs_h, "-", color=col, lw=1.2, label=f"{t.label} (joined between impacts)")
        left.plot(tt, hm, "v", color=col, ms=4, mfc="none", label="before impact" if i == 0 else None)
        left.plot(tt, hp, "^", color=col, ms=4, label="after impact" if i == 0 else None)
        speed = np.abs(np.asarray(f["v_minus"], float))
        right.plot(tt, speed, "o", color=col, ms=4, label=t.label)
        g = barrier_energy if barrier_energy is not None else t.barrier_energy
        if g is not None:
            left.axhline(g, color=col, ls=":", lw=1.1, label="G(Δ)" if i == 0 else None)
    left.set_title("energy at the impacts", fontsize=LABEL_PT)
    right.set_title("impact speeds", fontsize=LABEL_PT)
    _style(left, "time t", "energy H")
    _style(right, "time t", "impact speed |v-|")
    right.set_ylim(bottom=0)
    left.legend(fontsize=FONT_PT, frameon=False)
    return fig


def plot_survival(tables):
    """Survival R(t) = P(T > t) of ``vibro passage`` files, linear and log, with their bands and Poisson estimates.

    Examples
    --------
    >>> import pandas as pd, pathlib
    >>> df = pd.DataFrame({"t": [0, 1, 2], "R": [1, 0.5, 0.25]})
    >>> len(plot_survival([Table(pathlib.Path("R.csv"), "survival", df, "R")]).axes)
    2
    """
    fig = _figure(10.0, 4.2)
    ax_lin, ax_log = fig.subplots(1, 2, sharex=True)
    for i, t in enumerate(tables):
        col = COLOURS[i % len(COLOURS)]
        f = t.frame
        for ax in (ax_lin, ax_log):
            ax.plot(f["t"], f["R"], color=col, lw=1.2, label=t.label)
            if {"R_lo", "R_hi"} <= set(f.columns):
                ax.fill_between(f["t"], f["R_lo"], f["R_hi"], color=col, alpha=0.2, lw=0)
            if "R_poisson" in f.columns:
                ax.plot(f["t"], f["R_poisson"], color=col, lw=1.0, ls="--",
                        label=f"{t.label} (Poisson)" if ax is ax_lin else None)
    positive = [float(v) for t in tables for v in t.frame["R"] if v > 0]
    ax_log.set_yscale("log")
    if positive:
        ax_log.set_ylim(max(min(positive), 1e-12), 1.5)
    _style(ax_lin, "time t", "R(t) = P(T > t)")
    _style(ax_log, "time t", "R(t), log scale")
    ax_lin.legend(fontsize=FONT_PT, frameon=False)
    return fig


def plot_spectrum(tables):
    """One-sided power spectral densities of ``vibro spectrum`` files, linear and log.

    Examples
    --------
    >>> import pandas as pd, pathlib
    >>> df = pd.DataFrame({"omega": [0, 1, 2], "S": [0.1, 1.0, 0.1]})
    >>> len(plot_spectrum([Table(pathlib.Path("S.csv"), "spectrum", df, "S")]).axes)
    2
    """
    fig = _figure(10.0, 4.2)
    ax_lin, ax_log = fig.subplots(1, 2, sharex=True)
    for i, t in enumerate(tables):
        col = COLOURS[i % len(COLOURS)]
        f = t.frame.sort_values("omega")
        for ax in (ax_lin, ax_log):
            ax.plot(f["omega"], f["S"], color=col, lw=1.2, label=t.label)
    ax_log.set_yscale("log")
    _style(ax_lin, "frequency omega", "S(omega)")
    _style(ax_log, "frequency omega", "S(omega), log scale")
    ax_lin.legend(fontsize=FONT_PT, frameon=False)
    return fig


def plot_paths(tables):
    """Sample paths or trajectories: x(t) and y(t) on two panels (one line per path).

    Examples
    --------
    >>> import pandas as pd, pathlib
    >>> df = pd.DataFrame({"t": [0, 1, 2], "x": [0, .5, 0], "y": [1, 0, -1]})
    >>> len(plot_paths([Table(pathlib.Path("s.csv"), "paths", df, "s")]).axes)
    2
    """
    fig = _figure(10.0, 4.2)
    ax_x, ax_y = fig.subplots(1, 2, sharex=True)
    for i, t in enumerate(tables):
        col = COLOURS[i % len(COLOURS)]
        groups = t.frame.groupby("path") if "path" in t.frame.columns else [(None, t.frame)]
        for k, (_, g) in enumerate(groups):
            label = t.label if k == 0 else None
            ax_x.plot(g["t"], g["x"], color=col, lw=0.9, alpha=0.8, label=label)
            ax_y.plot(g["t"], g["y"], color=col, lw=0.9, alpha=0.8)
        if t.barriers is not None:
            for xb in t.barriers:
                ax_x.axhline(xb, color="k", lw=1.5)
    ax_x.set_title("displacement", fontsize=LABEL_PT)
    ax_y.set_title("velocity", fontsize=LABEL_PT)
    _style(ax_x, "time t", "x")
    _style(ax_y, "time t", "y")
    ax_x.legend(fontsize=FONT_PT, frameon=False)
    return fig


def plot_files(paths, out=None, *, labels=None, barrier_energy: float | None = None,
               barriers: tuple[float, float] | None = None, title: str | None = None, dpi: int = 100):
    """Read the CSV files, draw them on one figure by their kind, write the PNG atomically, return the Figure.

    Parameters
    ----------
    paths : list of path
        CSV files of one group: energy densities and histograms together, or joint densities, or impact logs,
        or sample paths.
    out : path, optional
        PNG to write (through :func:`hybrid.io.atomic_write`); nothing is written when None.
    labels : list of str, optional
        Legend labels, one per file (default: the file names).
    barrier_energy : float, optional
        G(Δ) to mark; overrides the sidecars.
    barriers : (float, float), optional
        Barrier positions for joint densities; override the sidecars.
    title : str, optional
        Figure title (default: the file names).
    dpi : int
        PNG resolution.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ParameterError
        Unknown columns, files of different groups, or bad arguments.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()); _ = (d / "p.csv").write_text("H,p\\n0,1\\n1,0.5\\n2,0.1\\n")
    >>> fig = plot_files([d / "p.csv"], d / "p.png", barrier_energy=0.55)
    >>> (d / "p.png").read_bytes()[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
    True
    """
    if not paths:
        raise ParameterError("give at least one CSV file to plot")
    if labels is not None and len(labels) != len(paths):
        raise ParameterError(f"{len(labels)} labels for {len(paths)} files: give one label per file")
    if barrier_energy is not None and not np.isfinite(barrier_energy):
        raise ParameterError(f"--barrier-energy {barrier_energy!r} must be a finite number")
    if barriers is not None and not (np.all(np.isfinite(barriers)) and barriers[0] < barriers[1]):
        raise ParameterError(f"--barriers {barriers!r} must be two finite numbers LEFT < RIGHT")
    if not (20 <= dpi <= 600):
        raise ParameterError(f"--dpi {dpi} is outside 20-600")
    tables = [read_table(p, None if labels is None else labels[i]) for i, p in enumerate(paths)]
    groups = {GROUPS[t.kind] for t in tables}
    if len(groups) > 1:
        kinds = ", ".join(f"{t.path.name}: {t.kind}" for t in tables)
        raise ParameterError(f"cannot draw different kinds on one figure ({kinds}); plot them separately")
    group = groups.pop()
    if group == "energy":
        fig = plot_energy(tables, barrier_energy)
    elif group == "joint":
        fig = plot_joint(tables, barriers)
    elif group == "impacts":
        fig = plot_impacts(tables, barrier_energy)
    elif group == "survival":
        fig = plot_survival(tables)
    elif group == "spectrum":
        fig = plot_spectrum(tables)
    else:
        fig = plot_paths(tables)
    fig.suptitle(title or ", ".join(t.path.name for t in tables), fontsize=LABEL_PT + 1)
    if out is not None:
        out = Path(out)
        if not out.resolve().parent.is_dir():
            raise ParameterError(f"--out {str(out)!r}: the folder does not exist")
        atomic_write(out, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    return fig
