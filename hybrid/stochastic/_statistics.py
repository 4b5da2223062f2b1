"""Streaming, mergeable ensemble statistics with batch-means confidence intervals.

Each chunk of paths returns integer histograms and one row of integer counts and float sums. Histograms add as
integers; the per-chunk rows are kept (small: one row per chunk), so that every estimate is a ratio of sums over
chunks computed with ``math.fsum`` (exactly rounded, hence independent of the order in which chunks finished) and
its confidence interval comes from the spread of the chunk ratios (batch means, chunks being independent).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats as _st

from hybrid.errors import ParameterError
from hybrid.io import atomic_write_text  # noqa: F401  (re-exported by hybrid.stochastic)

# columns of the per-chunk count table
# (h_under/h_over: H < 0 / H > h_max or NaN; xy_out: outside the (x, y) window; v_under/v_over: crossing speed
# < 0 / > v_max; bad_e: impacts whose restitution coefficient fell outside (0, 1])
COUNTS = ("samples", "below", "impacts_left", "impacts_right", "h_over", "xy_out", "v_over", "violations", "stuck",
          "nonfinite", "h_under", "v_under", "bad_e")
# columns of the per-chunk sum table (bad_e_speed, bad_e_value: the chunk's first impact with a bad e, else 0:
# NaN would make equal tables compare unequal)
SUMS = ("H", "x2", "y2", "impact_speed", "bad_e_speed", "bad_e_value")


@dataclass(frozen=True)
class Estimate:
    """A Monte Carlo estimate: ``value`` and ``ci``, the half-width of a 95 % batch-means interval.

    Examples
    --------
    >>> e = Estimate(1.0, 0.1, 32)
    >>> e.covers(1.05), float(e)
    (True, 1.0)
    """

    value: float
    ci: float
    batches: int = 0

    def covers(self, exact: float, bias: float = 0.0) -> bool:
        """True when ``|value - exact| <= ci + bias``."""
        return abs(self.value - exact) <= self.ci + bias

    def __float__(self) -> float:
        return float(self.value)

    def __format__(self, spec: str) -> str:
        spec = spec or ".6g"
        if not math.isfinite(self.ci):  # one batch: no interval, said in words rather than "± inf"
            return f"{self.value:{spec}} (no CI: {self.batches} batch{'es' if self.batches != 1 else ''})"
        return f"{self.value:{spec}} ± {self.ci:{spec}}"

    def __str__(self) -> str:
        return format(self, "")


def ratio_estimate(num: np.ndarray, den: np.ndarray, level: float = 0.95) -> Estimate:
    """Sum(num) / sum(den) with a batch-means interval from the per-batch ratios (delta method, t quantile).

    Examples
    --------
    >>> e = ratio_estimate(np.array([1.0, 3.0]), np.array([1.0, 1.0]))
    >>> e.value, round(e.ci, 3)
    (2.0, 12.706)
    """
    num = np.asarray(num, dtype=float)
    den = np.asarray(den, dtype=float)
    total = math.fsum(den)
    if total == 0:
        return Estimate(float("nan"), float("nan"), len(num))
    value = math.fsum(num) / total
    n = len(num)
    if n < 2:
        return Estimate(value, float("inf"), n)
    resid = num - value * den
    var = n / (n - 1) * math.fsum(resid * resid) / (total * total)
    return Estimate(value, float(_st.t.ppf(0.5 + level / 2, n - 1) * math.sqrt(var)), n)


def joint_frame(x_edges, y_edges, counts, outside: int, total: int):
    """A joint histogram ``counts`` (ny, nx) in long form: x_lo, x_hi, y_lo, y_hi, count, density (normalised by
    all ``total`` samples), and a last row with NaN edges and density counting the ``outside`` samples: the shape of
    every joint histogram written (oscillator and automaton ensembles alike).

    Examples
    --------
    >>> f = joint_frame(np.array([0.0, 1.0]), np.array([0.0, 2.0]), np.array([[3]]), 1, 4)
    >>> f["count"].tolist(), f["density"].tolist()[0]
    ([3, 1], 0.375)
    """
    import pandas as pd

    xe, ye = np.asarray(x_edges, float), np.asarray(y_edges, float)
    counts = np.asarray(counts)
    ny, nx = counts.shape
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny))
    area = np.outer(np.diff(ye), np.diff(xe))
    density = counts / (total * area) if total else np.zeros_like(area)
    nan = [np.nan]
    return pd.DataFrame({
        "x_lo": np.concatenate([xe[ix.ravel()], nan]), "x_hi": np.concatenate([xe[ix.ravel() + 1], nan]),
        "y_lo": np.concatenate([ye[iy.ravel()], nan]), "y_hi": np.concatenate([ye[iy.ravel() + 1], nan]),
        "count": np.concatenate([counts.ravel(), [outside]]), "density": np.concatenate([density.ravel(), nan]),
    })


class EnsembleStatistics:
    """Histograms and moments of an ensemble; chunks merge exactly.

    Attributes
    ----------
    h_edges, h_counts : arrays
        Histogram of H on [0, h_max] (``bins`` bins), sampled every ``stride`` steps after burn-in.
    xy_edges, xy_counts : (x_edges, y_edges), array (ny, nx) or None
        Joint histogram of (x, y); rows are y, columns x.
    v_edges, v_counts : arrays
        Histogram of impact speeds |y-| (every impact after burn-in).
    chunk_ids, chunk_counts, chunk_sums : arrays
        One row per finished chunk (columns :data:`COUNTS`, :data:`SUMS`).
    path_steps, wall_time, compile_time, seed, settings

    Examples
    --------
    >>> s = EnsembleStatistics.empty({"h_max": 4.0, "bins": 4, "xy_bins": None, "v_max": 2.0, "v_bins": 2,
    ...                               "seed": 1, "t_sample": 1.0, "chunk_paths": 1})
    >>> s.h_counts.tolist(), s.done_chunks
    ([0, 0, 0, 0], 0)
    """

    def __init__(self, settings, h_counts, xy_counts, v_counts, chunk_ids, chunk_paths, chunk_counts, chunk_sums,
                 wall_time=0.0, compile_time=float("nan")):
        self.settings = dict(settings)
        self.h_counts = np.asarray(h_counts, dtype=np.int64)
        self.xy_counts = None if xy_counts is None else np.asarray(xy_counts, dtype=np.int64)
        self.v_counts = np.asarray(v_counts, dtype=np.int64)
        self.chunk_ids = np.asarray(chunk_ids, dtype=np.int64)
        self.chunk_paths = np.asarray(chunk_paths, dtype=np.int64)
        self.chunk_counts = np.asarray(chunk_counts, dtype=np.int64).reshape(-1, len(COUNTS))
        self.chunk_sums = np.asarray(chunk_sums, dtype=float).reshape(-1, len(SUMS))
        self.wall_time = float(wall_time)
        self.compile_time = float(compile_time)

    # ------------------------------------------------------------------ construction
    @classmethod
    def empty(cls, settings: dict) -> EnsembleStatistics:
        """No chunks yet, histograms sized by ``settings``."""
        xy = settings.get("xy_bins")
        return cls(settings, np.zeros(settings["bins"], np.int64),
                   None if xy is None else np.zeros((xy[1], xy[0]), np.int64),
                   np.zeros(settings["v_bins"], np.int64), [], [], np.zeros((0, len(COUNTS))), np.zeros((0, len(SUMS))))

    def add_chunks(self, ids, npaths, hist, xyh, vh, cnt, sm) -> None:
        """Add finished chunks (their rows from the kernel); a chunk id already present is refused."""
        ids = np.asarray(ids, dtype=np.int64)
        if np.intersect1d(ids, self.chunk_ids).size or len(np.unique(ids)) != len(ids):
            raise ParameterError(f"chunks {np.intersect1d(ids, self.chunk_ids).tolist()} would be counted twice")
        self.h_counts += hist.sum(axis=0)
        if self.xy_counts is not None:
            self.xy_counts += xyh.sum(axis=0)
        self.v_counts += vh.sum(axis=0)
        self.chunk_ids = np.concatenate([self.chunk_ids, ids])
        self.chunk_paths = np.concatenate([self.chunk_paths, np.asarray(npaths, dtype=np.int64)])
        self.chunk_counts = np.vstack([self.chunk_counts, cnt])
        self.chunk_sums = np.vstack([self.chunk_sums, sm])
        order = np.argsort(self.chunk_ids, kind="stable")  # a canonical order, whatever finished first
        self.chunk_ids, self.chunk_paths = self.chunk_ids[order], self.chunk_paths[order]
        self.chunk_counts, self.chunk_sums = self.chunk_counts[order], self.chunk_sums[order]

    def merge(self, other: EnsembleStatistics) -> EnsembleStatistics:
        """A new object with both ensembles (same model, histogram edges and step; disjoint chunks or another seed).

        Examples
        --------
        >>> a = EnsembleStatistics.empty({"h_max": 4.0, "bins": 4, "xy_bins": None, "v_max": 2.0, "v_bins": 2,
        ...                               "seed": 1, "t_sample": 1.0, "chunk_paths": 1})
        >>> a.merge(a).done_chunks
        0
        """
        for key in ("model", "h_max", "bins", "xy_bins", "xy_range", "v_max", "v_bins", "t_sample", "dt", "scheme",
                    "stride"):
            if self.settings.get(key) != other.settings.get(key):
                raise ParameterError(
                    f"cannot merge ensembles with different {key}: {self.settings.get(key)!r} vs "
                    f"{other.settings.get(key)!r}"
                )
        out = EnsembleStatistics(self.settings, self.h_counts.copy(),
                                 None if self.xy_counts is None else self.xy_counts.copy(), self.v_counts.copy(),
                                 self.chunk_ids, self.chunk_paths, self.chunk_counts, self.chunk_sums,
                                 self.wall_time + other.wall_time, self.compile_time)
        ids = other.chunk_ids
        if other.settings.get("seed") != self.settings.get("seed"):
            ids = ids + (int(self.chunk_ids.max()) + 1 if len(self.chunk_ids) else 0)  # another seed: new batches
            out.settings["seed"] = f"{self.settings.get('seed')}+{other.settings.get('seed')}"
        out.add_chunks(ids, other.chunk_paths, other.h_counts[None], None if other.xy_counts is None
                       else other.xy_counts[None], other.v_counts[None], other.chunk_counts, other.chunk_sums)
        out.settings["paths"] = int(out.chunk_paths.sum())
        return out

    # ------------------------------------------------------------------ raw totals
    @property
    def done_chunks(self) -> int:
        """Number of finished chunks."""
        return len(self.chunk_ids)

    def total(self, name: str) -> int:
        """Total of a count column (see :data:`COUNTS`), e.g. ``stats.total('violations')``."""
        return int(self.chunk_counts[:, COUNTS.index(name)].sum())

    @property
    def violations(self) -> int:
        """Steps that ended with x outside the barriers (must be 0 for every scheme except a broken one)."""
        return self.total("violations")

    @property
    def seed(self):
        return self.settings.get("seed")

    @property
    def paths(self) -> int:
        """Paths in the finished chunks."""
        return int(self.chunk_paths.sum())

    @property
    def path_steps(self) -> int:
        """Steps taken by all finished paths (burn-in included)."""
        return self.paths * int(self.settings.get("steps_per_path", 0))

    @property
    def throughput(self) -> float:
        """Path-steps per second of wall time (compilation excluded)."""
        return self.path_steps / self.wall_time if self.wall_time > 0 else float("nan")

    # ------------------------------------------------------------------ histograms
    @property
    def h_edges(self) -> np.ndarray:
        return np.linspace(0.0, self.settings["h_max"], self.settings["bins"] + 1)

    def _out(self, name: str) -> int:
        return self.total(name) if len(self.chunk_counts) else 0

    def outside(self) -> dict:
        """Samples outside each histogram's range: counts, total and fraction, per histogram.

        ``H``: ``below`` (H < 0) and ``above`` (H > h_max, or not finite); ``xy`` (when collected): ``outside`` the
        (x, y) window; ``speed``: ``below`` (crossing speed < 0, Euler-Maruyama only) and ``above`` v_max. Every
        sample is in exactly one bin or one of these counts.
        """
        out = {}
        below, above = self._out("h_under"), self._out("h_over")
        n = int(self.h_counts.sum()) + below + above
        out["H"] = {"below": below, "above": above, "outside": below + above, "total": n,
                    "fraction": (below + above) / n if n else 0.0}
        if self.xy_counts is not None:
            o = self._out("xy_out")
            n = int(self.xy_counts.sum()) + o
            out["xy"] = {"outside": o, "total": n, "fraction": o / n if n else 0.0}
        below, above = self._out("v_under"), self._out("v_over")
        n = int(self.v_counts.sum()) + below + above
        out["speed"] = {"below": below, "above": above, "outside": below + above, "total": n,
                        "fraction": (below + above) / n if n else 0.0}
        return out

    def h_density(self) -> np.ndarray:
        """p(H) on the bins, normalised by every sample: it integrates to the share inside [0, h_max]."""
        n = self.outside()["H"]["total"]
        return self.h_counts / (n * np.diff(self.h_edges)) if n else np.zeros(len(self.h_counts))

    @property
    def xy_edges(self):
        if self.xy_counts is None:
            return None
        (x0, x1), (y0, y1) = self.settings["xy_range"]
        nx, ny = self.settings["xy_bins"]
        return np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)

    def xy_density(self) -> np.ndarray | None:
        """p(x, y), shape (ny, nx), normalised by every sample: it integrates to the share inside the window."""
        if self.xy_counts is None:
            return None
        xe, ye = self.xy_edges
        n = self.outside()["xy"]["total"]
        area = np.outer(np.diff(ye), np.diff(xe))
        return self.xy_counts / (n * area) if n else np.zeros_like(area)

    @property
    def v_edges(self) -> np.ndarray:
        return np.linspace(0.0, self.settings["v_max"], self.settings["v_bins"] + 1)

    def v_density(self) -> np.ndarray:
        """Density of the impact speeds |y-| on the bins of [0, v_max], normalised by every impact."""
        n = self.outside()["speed"]["total"]
        return self.v_counts / (n * np.diff(self.v_edges)) if n else np.zeros(len(self.v_counts))

    # ------------------------------------------------------------------ estimates
    def _col(self, name):
        return self.chunk_counts[:, COUNTS.index(name)].astype(float)

    def _sum(self, name):
        return self.chunk_sums[:, SUMS.index(name)]

    @property
    def mean_energy(self) -> Estimate:
        """E[H]."""
        return ratio_estimate(self._sum("H"), self._col("samples"))

    @property
    def mean_x2(self) -> Estimate:
        """E[x**2]."""
        return ratio_estimate(self._sum("x2"), self._col("samples"))

    @property
    def mean_y2(self) -> Estimate:
        """E[y**2]."""
        return ratio_estimate(self._sum("y2"), self._col("samples"))

    @property
    def prob_below_barrier(self) -> Estimate:
        """P(H < G(delta)) (G at the lower barrier energy when the barriers are asymmetric)."""
        return ratio_estimate(self._col("below"), self._col("samples"))

    def _path_time(self):
        return self.chunk_paths * float(self.settings["t_sample"])

    @property
    def impact_rate(self) -> Estimate:
        """Impacts (both walls) per path per unit time, after burn-in."""
        return ratio_estimate(self._col("impacts_left") + self._col("impacts_right"), self._path_time())

    @property
    def impact_rate_left(self) -> Estimate:
        """Impacts on the left wall per unit time."""
        return ratio_estimate(self._col("impacts_left"), self._path_time())

    @property
    def impact_rate_right(self) -> Estimate:
        """Impacts on the right wall per unit time."""
        return ratio_estimate(self._col("impacts_right"), self._path_time())

    @property
    def mean_impact_speed(self) -> Estimate:
        """E[|y-|] over impacts."""
        return ratio_estimate(self._sum("impact_speed"), self._col("impacts_left") + self._col("impacts_right"))

    @property
    def impacts(self) -> int:
        """Number of impacts after burn-in."""
        return self.total("impacts_left") + self.total("impacts_right")

    # ------------------------------------------------------------------ output
    def to_pandas(self):
        """The H histogram as a DataFrame with columns H_lo, H_hi, count, density.

        The first row (H_lo = -inf, H_hi = 0) counts the samples with H < 0, the last (H_lo = h_max, H_hi = inf)
        those above h_max; their density is NaN. The density integrates to the share of samples on the bins.
        """
        import pandas as pd

        e = self.h_edges
        out = self.outside()["H"]
        inf = float("inf")
        return pd.DataFrame({
            "H_lo": np.concatenate([[-inf], e[:-1], [e[-1]]]), "H_hi": np.concatenate([[e[0]], e[1:], [inf]]),
            "count": np.concatenate([[out["below"]], self.h_counts, [out["above"]]]),
            "density": np.concatenate([[np.nan], self.h_density(), [np.nan]]),
        })

    def to_csv(self, path) -> Path:
        """Write :meth:`to_pandas` atomically (full float precision)."""
        return atomic_write_text(path, self.to_pandas().to_csv(index=False, float_format="%.17g"))

    def joint_to_pandas(self):
        """The (x, y) histogram in long form: x_lo, x_hi, y_lo, y_hi, count, density (:func:`joint_frame`).

        A last row with NaN edges and density counts the samples outside the window.
        """
        if self.xy_counts is None:
            raise ParameterError("no joint histogram was collected (xy_bins=None)")
        out = self.outside()["xy"]
        return joint_frame(*self.xy_edges, self.xy_counts, out["outside"], out["total"])

    def summary(self) -> dict:
        """Main figures as a JSON-friendly dict."""
        out = {"path_steps": self.path_steps, "wall_time": self.wall_time, "compile_time": self.compile_time,
               "Mpath_steps_per_s": self.throughput / 1e6, "impacts": self.impacts, "violations": self.violations}
        for name in ("mean_energy", "mean_x2", "mean_y2", "prob_below_barrier", "impact_rate"):
            e = getattr(self, name)
            out[name] = {"value": e.value, "ci": e.ci}
        out["outside_histograms"] = self.outside()
        return out

    # ------------------------------------------------------------------ checkpoint form
    def to_arrays(self) -> dict:
        """Every field as numpy arrays (for the checkpoint file)."""
        d = {"settings": np.array(json.dumps(self.settings, sort_keys=True)), "h_counts": self.h_counts,
             "v_counts": self.v_counts, "chunk_ids": self.chunk_ids, "chunk_paths": self.chunk_paths,
             "chunk_counts": self.chunk_counts, "chunk_sums": self.chunk_sums,
             "times": np.array([self.wall_time, self.compile_time])}
        if self.xy_counts is not None:
            d["xy_counts"] = self.xy_counts
        return d

    @classmethod
    def from_arrays(cls, d) -> EnsembleStatistics:
        settings = json.loads(str(d["settings"]))
        return cls(settings, d["h_counts"], d["xy_counts"] if "xy_counts" in d else None, d["v_counts"],
                   d["chunk_ids"], d["chunk_paths"], d["chunk_counts"], d["chunk_sums"], *d["times"])

    def __repr__(self) -> str:
        return (f"EnsembleStatistics(scheme={self.settings.get('scheme')!r}, dt={self.settings.get('dt')}, "
                f"paths={self.paths}, E[H]={self.mean_energy}, impacts={self.impacts})")

    def _repr_html_(self) -> str:
        from hybrid.display import summary_html

        return summary_html(f"EnsembleStatistics ({self.settings.get('scheme')}, dt={self.settings.get('dt')})", {
            "paths": self.paths, "path-steps": f"{self.path_steps:.4g}", "E[H] (95% CI)": str(self.mean_energy),
            "P(H < G(delta))": str(self.prob_below_barrier), "impacts per unit time": str(self.impact_rate),
            "impacts": self.impacts, "wall time (s)": self.wall_time})


