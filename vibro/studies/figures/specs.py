"""The table of the paper's Figures 2-16: every parameter, every choice we made, and the Monte Carlo sizes.

Each figure is a frozen :class:`FigureSpec` holding :class:`Case` rows (one curve or one surface each). The
values the captions omit or garble are chosen here, once, and each choice is written as a labelled sentence in
``FigureSpec.choices``; the sidecar JSON of every figure repeats them.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field

from hybrid.errors import ParameterError

VDP_READING = "van-der-pol"
"""Example 2 damping reading used by every Example 2 figure (docs/paper-readings.md): h = (c1 + c2 x**2) y."""

VDP_CHOICE = (
    "Example 2 damping: van der Pol reading h = (c1 + c2 x^2) y with c1 = -0.01, c2 = 0.005 (docs/paper-readings.md). "
    "The printed h = (c1 - c2 x^2) y is negative everywhere and has no limit cycle, which contradicts Figs. 15-16."
)


@dataclass(frozen=True)
class Case:
    """One curve (energy figures) or one surface (joint figures): a model with fixed parameters.

    Parameters
    ----------
    label : str
        Legend label, e.g. ``"Δ = 0.8"``.
    model : str
        Registered model name (``duffing`` or ``duffing-vdp``).
    params : tuple of (name, value)
        Parameter overrides of the model's defaults.
    vc : float
        Critical velocity V_C of Ma's restitution law.
    h_max : float
        Upper end of the energy axis: the density is negligible beyond it (checked in the sidecar).

    Examples
    --------
    >>> c = Case("Δ = 0.8", "duffing", (("delta", 0.8),), vc=0.4, h_max=5.0)
    >>> round(c.build().barrier_energy, 5)
    0.34048
    """

    label: str
    model: str
    params: tuple[tuple[str, float], ...]
    vc: float
    h_max: float

    @property
    def param_dict(self) -> dict[str, float]:
        """The parameter overrides as a dict."""
        return {k: float(v) for k, v in self.params}

    def build(self):
        """The model (an :class:`models.ImpactOscillator`) with these parameters and Ma(V_C)."""
        from models import DuffingImpact, DuffingVanDerPolImpact, Ma

        law = Ma(vc=self.vc)
        if self.model == "duffing":
            return DuffingImpact(restitution=law, **self.param_dict)
        if self.model == "duffing-vdp":
            return DuffingVanDerPolImpact(restitution=law, reading=VDP_READING, **self.param_dict)
        raise ParameterError(f"figure case {self.label!r}: unknown model {self.model!r}")

    @property
    def delta(self) -> float:
        """Barrier distance of this case."""
        return float(self.build().params["delta"])

    def describe(self) -> dict:
        """JSON-friendly description: the model's full parameter set, restitution, reading and h_max."""
        m = self.build()
        out = {"label": self.label, "model": self.model, "parameters": dict(m.params),
               "restitution": m.restitution.spec(), "h_max": self.h_max, "damping": str(m.h),
               "G_delta": m.barrier_energy}
        if self.model == "duffing-vdp":
            out["reading"] = VDP_READING
        return out


@dataclass(frozen=True)
class MCSize:
    """Monte Carlo size of one case: ``paths`` paths of length ``t_end`` (the first ``t_burn`` discarded).

    Examples
    --------
    >>> MCSize(64, 2200.0, 200.0).path_time
    128000.0
    """

    paths: int
    t_end: float
    t_burn: float

    @property
    def path_time(self) -> float:
        """Total recorded time, summed over paths."""
        return self.paths * (self.t_end - self.t_burn)


PRESETS = ("quick", "default", "full")
"""Size presets: ``quick`` for smoke tests, ``default`` for the README, ``full`` for publication-size runs."""


@dataclass(frozen=True)
class FigureSpec:
    """One paper figure: what it shows, its cases, its choices, and its Monte Carlo settings.

    Parameters
    ----------
    number : int
        The paper's figure number (2-16).
    kind : {'energy', 'joint'}
        Energy densities p(H) (two methods plus Monte Carlo), or joint densities p(x, y).
    title : str
    cases : tuple of Case
    choices : tuple of str
        Every choice we made where the paper is silent or garbled, one labelled sentence each.
    claim : str
        What the paper says the figure shows (checked against our numbers in the sidecar).
    in_paper_mc : bool
        Whether the paper itself shows Monte Carlo for this figure (Figs. 15-16 do not).
    dt : float
        Monte Carlo time step.
    sizes : tuple of (preset, MCSize)
        Monte Carlo size per preset.
    bins : int
        Energy histogram bins on [0, h_max].
    xy_bins : int
        Joint histogram bins per axis.

    Examples
    --------
    >>> spec = FIGURES[2]
    >>> spec.kind, len(spec.cases), spec.size("quick").paths > 0
    ('energy', 3, True)
    """

    number: int
    kind: str
    title: str
    cases: tuple[Case, ...]
    choices: tuple[str, ...]
    claim: str
    in_paper_mc: bool = True
    dt: float = 0.01
    sizes: tuple[tuple[str, MCSize], ...] = ()
    bins: int = 60
    xy_bins: int = 48
    scheme: str = "milstein"
    notes: tuple[str, ...] = field(default=())

    def size(self, preset: str) -> MCSize:
        """The Monte Carlo size for ``preset`` (quick, default or full)."""
        table = dict(self.sizes)
        if preset not in table:
            raise ParameterError(f"unknown size preset {preset!r}; choose one of {PRESETS}")
        return table[preset]

    def to_dict(self) -> dict:
        """JSON-friendly form of the whole spec (the sidecar's ``spec`` entry)."""
        d = asdict(self)
        d["cases"] = [c.describe() for c in self.cases]
        d["sizes"] = {k: asdict(v) for k, v in self.sizes}
        return d

    def spec_hash(self, preset: str, extra: dict | None = None) -> str:
        """Hash of the spec, ``preset``, ``extra`` and :data:`FORMAT_VERSION` (reuse key of finished figures).

        Code changes are not hashed: bump :data:`FORMAT_VERSION` when they change the outputs.

        Examples
        --------
        >>> FIGURES[2].spec_hash("quick") == FIGURES[2].spec_hash("quick")
        True
        >>> FIGURES[2].spec_hash("quick") == FIGURES[2].spec_hash("default")
        False
        """
        payload = {"spec": asdict(self), "preset": preset, "extra": extra or {}, "format": FORMAT_VERSION}
        text = json.dumps(payload, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:20]


FORMAT_VERSION = 6
"""Bumped when the outputs change (file shape, or the numbers of the analytic curves), so that older finished
figures are recomputed; Monte Carlo runs stay reused from their own cache. 4: the jump method's tail near h_max.
5: fonts of at least 9 pt, labelled colour bars beside the panels; the Monte Carlo cache holds npz + JSON, no
pickles (old .pkl entries are never loaded, so those runs are redone). 6: the phase-plane FPK density (p(H) curve,
joint panel, L1 distances) beside the averaging methods."""


def _sizes(default_paths: int, default_t: float, burn: float, quick_t: float = 60.0, full_factor: int = 8):
    return (
        ("quick", MCSize(8, burn + quick_t, burn)),
        ("default", MCSize(default_paths, burn + default_t, burn)),
        ("full", MCSize(default_paths * full_factor, burn + default_t, burn)),
    )


def _duffing(label, vc, h_max, **params):
    return Case(label, "duffing", tuple(sorted(params.items())), vc, h_max)


def _vdp(label, vc, h_max, **params):
    return Case(label, "duffing-vdp", tuple(sorted(params.items())), vc, h_max)


# ---------------------------------------------------------------------------------------------- the table
_EX1 = {"a": 1.0, "b": 0.2}
_EX2 = {"a": 1.0, "b": 0.2, "c1": -0.01, "c2": 0.005}

_FIG2_CASES = tuple(
    _duffing(f"Δ = {d}", 0.4, h, c=0.025, D=0.05, delta=d, **_EX1) for d, h in ((0.8, 5.0), (1.0, 5.0), (1.2, 5.5))
)
_FIG6_CASES = tuple(
    _duffing(f"V_C = {vc}", vc, h, c=0.025, D=0.01, delta=0.6, **_EX1)
    for vc, h in ((0.05, 2.0), (0.8, 2.0), (2.5, 3.5))
)
_FIG6_CHOICE = (
    "Fig. 6 caption prints 'D=0.01 and V_C=0.6' while V_C is the varied value; we read it as D = 0.01, Δ = 0.6 "
    "(as in the captions of Figs. 7-9), c = 0.025, and V_C ∈ {0.05, 0.8, 2.5} from Figs. 7-9."
)
_ENERGY_SIZES = _sizes(64, 4000.0, 300.0)
_JOINT_SIZES = _sizes(64, 4000.0, 300.0)

_FIGS: list[FigureSpec] = [
    FigureSpec(
        2, "energy", "Example 1: p(H) for three barrier positions Δ", _FIG2_CASES,
        ("Fig. 2 as printed: a = 1, b = 0.2, c = 0.025, D = 0.05, V_C = 0.4, Δ ∈ {0.8, 1.0, 1.2}.",),
        "The peak of p(H) falls as Δ grows and the decay of the tail slows; p(H) has an inflexion at H = G(Δ).",
        sizes=_ENERGY_SIZES,
    ),
]
for _n, _case in zip((3, 4, 5), _FIG2_CASES):
    _FIGS.append(FigureSpec(
        _n, "joint", f"Example 1: joint p(x, y) at {_case.label} (Fig. 2 parameters)", (_case,),
        ("Parameters of Fig. 2: a = 1, b = 0.2, c = 0.025, D = 0.05, V_C = 0.4.",),
        "Analytic joint density (eq. 31) agrees with Monte Carlo.", sizes=_JOINT_SIZES,
    ))
_FIGS.append(FigureSpec(
    6, "energy", "Example 1: p(H) for three critical velocities V_C", _FIG6_CASES, (_FIG6_CHOICE,),
    "'a larger yield velocity V_C corresponds to a smaller energy peak'. Physically a larger V_C means "
    "fewer plastic impacts, so less dissipation; Figs. 8 and 9 (V_C = 0.8, 2.5) are almost indistinguishable.",
    sizes=_ENERGY_SIZES,
))
for _n, _case in zip((7, 8, 9), _FIG6_CASES):
    _FIGS.append(FigureSpec(
        _n, "joint", f"Example 1: joint p(x, y) at {_case.label} (Fig. 6 parameters)", (_case,), (_FIG6_CHOICE,),
        "Analytic joint density agrees with Monte Carlo; Figs. 8 and 9 are almost indistinguishable.",
        sizes=_JOINT_SIZES,
    ))
_FIGS += [
    FigureSpec(
        10, "energy", "Example 1: p(H) for three noise intensities D",
        tuple(_duffing(f"D = {D}", 0.6, h, c=0.025, D=D, delta=1.0, **_EX1) for D, h in ((0.02, 3.0), (0.05, 5.0),
                                                                                          (0.1, 8.0))),
        ("Fig. 10 does not print the varied D; we chose D ∈ {0.02, 0.05, 0.1} with Δ = 1.0, V_C = 0.6, c = 0.025.",),
        "Larger noise intensity spreads p(H) to higher energies and lowers its peak.", sizes=_ENERGY_SIZES,
    ),
    FigureSpec(
        11, "energy", "Example 1: p(H) for three damping coefficients c",
        tuple(_duffing(f"c = {c}", 0.05, h, c=c, D=0.01, delta=1.0, **_EX1) for c, h in ((0.01, 2.5), (0.025, 2.0),
                                                                                         (0.05, 1.5))),
        ("Fig. 11 does not print the varied c; we chose c ∈ {0.01, 0.025, 0.05} with Δ = 1.0, V_C = 0.05, D = 0.01.",),
        "Larger damping concentrates p(H) at lower energies (higher peak).", sizes=_sizes(64, 6000.0, 500.0),
    ),
    FigureSpec(
        12, "energy", "Example 2 (Duffing-van der Pol): p(H) for three critical velocities V_C",
        tuple(_vdp(f"V_C = {vc}", vc, h, D=0.01, delta=1.0, **_EX2) for vc, h in ((0.05, 3.0), (0.4, 4.0),
                                                                                  (2.5, 8.0))),
        (VDP_CHOICE,
         "Fig. 12 caption prints 'Δ = 1.0 and V_C = 0.4' while V_C is the varied value; we take Δ = 1.0, D = 0.01 "
         "(the Example 2 default) and V_C ∈ {0.05, 0.4, 2.5}."),
        "Larger V_C means fewer plastic impacts: less dissipation, so p(H) moves to higher energies.",
        sizes=_sizes(64, 6000.0, 500.0),
    ),
    FigureSpec(
        13, "energy", "Example 2: p(H) for three noise intensities D",
        tuple(_vdp(f"D = {D}", 0.4, h, D=D, delta=1.0, **_EX2) for D, h in ((0.005, 3.0), (0.01, 3.0), (0.02, 3.5))),
        (VDP_CHOICE, "Fig. 13 does not print the varied D; we chose D ∈ {0.005, 0.01, 0.02} with Δ = 1.0, "
         "V_C = 0.4."),
        "Analytic p(H) agrees with Monte Carlo for each D.", sizes=_sizes(64, 6000.0, 500.0),
    ),
    FigureSpec(
        14, "energy", "Example 2: p(H) for three barrier positions Δ (D = 0.5 as printed)",
        tuple(_vdp(f"Δ = {d}", 0.4, h, D=0.5, delta=d, **_EX2) for d, h in ((0.8, 14.0), (1.0, 14.0), (1.2, 14.0))),
        (VDP_CHOICE, "Fig. 14 does not print the varied Δ; we chose Δ ∈ {0.8, 1.0, 1.2} (as in Fig. 2) with "
         "V_C = 0.4 and D = 0.5 as printed.",
         "D = 0.5 reaches H ~ 14 (speed ~ 5): Monte Carlo step dt = 0.005 so that the step rule holds."),
        "Analytic p(H) agrees with Monte Carlo for each Δ.", dt=0.005, sizes=_ENERGY_SIZES,
    ),
    FigureSpec(
        15, "joint", "Example 2: joint p(x, y) at Δ = 3.0 (complete limit cycle)",
        (_vdp("Δ = 3.0", 0.4, 12.0, D=0.01, delta=3.0, **_EX2),),
        (VDP_CHOICE, "Fig. 15 caption prints 'Δ = 3.0 ... and Δ = 0.6'; we read D = 0.01, V_C = 0.4, Δ = 3.0.",
         "The paper shows the analytic density only; the Monte Carlo panel is our addition."),
        "No impacts at Δ = 3.0: the density is a complete ring around the limit cycle.", in_paper_mc=False,
        sizes=_sizes(64, 6000.0, 500.0),
    ),
    FigureSpec(
        16, "joint", "Example 2: joint p(x, y) at Δ = 1.0 (limit cycle truncated by the barriers)",
        (_vdp("Δ = 1.0", 0.4, 4.0, D=0.01, delta=1.0, **_EX2),),
        (VDP_CHOICE, "Fig. 16 caption prints 'Δ = 1.0 ... and Δ = 0.6'; we read D = 0.01, V_C = 0.4, Δ = 1.0.",
         "The paper shows the analytic density only; the Monte Carlo panel is our addition."),
        "The barriers cut the limit cycle: the ring is truncated at x = ±Δ (a stochastic P-bifurcation from Fig. 15).",
        in_paper_mc=False, sizes=_sizes(64, 6000.0, 500.0),
    ),
]

FIGURES: dict[int, FigureSpec] = {s.number: s for s in _FIGS}
"""Figure number -> spec, for the paper's Figures 2-16."""
ENERGY_FIGURES = tuple(n for n, s in FIGURES.items() if s.kind == "energy")
"""Numbers of the energy-density figures."""


def figure_spec(number) -> FigureSpec:
    """The spec of figure ``number`` (2-16), with a clear error otherwise.

    Examples
    --------
    >>> figure_spec("12").cases[0].model
    'duffing-vdp'
    >>> figure_spec(1)
    Traceback (most recent call last):
    ...
    hybrid.errors.ParameterError: figure 1 is not reproduced: choose a number from 2 to 16, or 'all'
    """
    try:
        n = int(str(number).strip())
    except ValueError:
        n = None
    if n not in FIGURES:
        raise ParameterError(f"figure {number} is not reproduced: choose a number from 2 to 16, or 'all'")
    return FIGURES[n]
