"""Symbolic derivation of the energy-envelope averaging (paper section 4) from a model's sympy declaration.

For a model x'' + g(x) + eps h(x, y) = eps**(1/2) f_k(x, y) xi_k(t) the Itô form (eqs. 15-17) is
dY = m(X, Y) dt + sigma(X, Y) dB with the Wong-Zakai term in m. With the energy H = y**2/2 + G(x), Itô's rule
gives (eq. 19)

    dH = [y m_nc(x, y) + sigma**2(x, y)/2] dt + y sigma(x, y) dB,      m_nc = m + g (the non-conservative part).

Averaging over one orbit with dt = dx/|y| and both branches y = +s and y = -s, s = sqrt(2H - 2G(x)) > 0:

    T(H)        = int 2/s dx
    m_bar(H)    = (1/T) int a(x, s) dx,  a = [s m_nc(x, s) - s m_nc(x, -s) + (sigma2(x, s) + sigma2(x, -s))/2] / s
    sigma2_bar  = (1/T) int b(x, s) dx,  b = s (sigma2(x, s) + sigma2(x, -s))

over x in [-A, A] (G(A) = H, eqs. 21-23) or [-delta, delta] with the impact loss -dH/T (eqs. 24-26). When h and
sigma do not depend on the sign of y this is the paper's eq. 21 (2/T times the +y branch).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy as sp

from hybrid.automaton import lambdify_numeric
from models import X, Y

S = sp.Symbol("s", positive=True)
"""Orbit speed symbol s = |y| = sqrt(2H - 2G(x)) > 0 used in the averaging integrands."""
H_SYM = sp.Symbol("H", nonnegative=True)
"""Energy symbol."""
_A = sp.Symbol("A", positive=True)
_DELTA = sp.Symbol("Delta", positive=True)
_T = sp.Function("T")(H_SYM)
_DH = sp.Symbol(r"\delta H", real=True)


@dataclass(frozen=True)
class _Kernels:
    """Compiled numpy kernels w(x, s, *params); each averaged integral is int w(x, s)/s dx."""

    drift: object  # s * a(x, s)
    diffusion: object  # s * b(x, s)
    names: tuple[str, ...]

    def __call__(self, which: str, x, s, params):
        fn = self.drift if which == "drift" else self.diffusion
        out = fn(x, s, *[params[k] for k in self.names])
        return np.broadcast_to(np.asarray(out, dtype=float), np.broadcast(x, s).shape)


class AveragingEquations:
    """The Itô equations of a model and the averaged coefficients of its energy, as sympy expressions.

    Build it with :func:`averaging_equations`. Print it (``str``) for a readable summary or call :meth:`latex`.

    Attributes
    ----------
    drift : sympy expression
        m(x, y) of eq. 16, with the Wong-Zakai term.
    diffusion_squared : sympy expression
        sigma**2(x, y) of eq. 17.
    nonconservative_drift : sympy expression
        m_nc = m + g.
    energy_drift, energy_diffusion_squared : sympy expressions
        Drift y m_nc + sigma**2/2 and squared diffusion y**2 sigma**2 of the energy (eq. 19), in x and y.
    drift_integrand, diffusion_integrand : sympy expressions of x and s
        a(x, s) and b(x, s) above (both velocity branches summed).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> eq = averaging_equations(DuffingImpact())
    >>> eq.drift_integrand
    2*D/s - 2*c*s
    >>> eq.diffusion_integrand
    4*D*s
    """

    def __init__(self, model):
        model.require_autonomous()
        self.model = model
        self.drift = model.ito_drift
        self.diffusion_squared = model.diffusion_squared
        self.nonconservative_drift = sp.expand(self.drift + model.g)
        self.energy_drift = sp.expand(Y * self.nonconservative_drift + self.diffusion_squared / 2)
        self.energy_diffusion_squared = sp.expand(Y**2 * self.diffusion_squared)
        plus = {Y: S}
        minus = {Y: -S}
        m_nc, sig2 = self.nonconservative_drift, self.diffusion_squared
        self._w_drift = sp.expand(
            S * m_nc.xreplace(plus) - S * m_nc.xreplace(minus) + (sig2.xreplace(plus) + sig2.xreplace(minus)) / 2
        )
        self._w_diffusion = sp.expand(S**2 * (sig2.xreplace(plus) + sig2.xreplace(minus)))
        self.drift_integrand = sp.expand(self._w_drift / S)
        self.diffusion_integrand = sp.expand(self._w_diffusion / S)
        # compiled kernels, shared by every copy that averaging_equations makes for other parameter values (they take
        # the parameters as arguments): a per-copy cache recompiled them for each model object, 1462 lambdify calls
        # (4.7 s of CPU) in one diagnose of Fig. 14, whose search builds a new elastic model per energy range
        self._compiled = {}

    # ------------------------------------------------------------------ display
    @cached_property
    def speed(self) -> sp.Expr:
        """s = sqrt(2H - 2G(x)) with the model's potential (an unevaluated integral when G has no closed form)."""
        G = self.model.potential_expr
        if G is None:
            t = sp.Dummy("t")
            G = sp.Integral(self.model.g.xreplace({X: t}), (t, 0, X))
        return sp.sqrt(2 * H_SYM - 2 * G)

    def averaged(self, impacts: bool = False) -> dict[str, sp.Expr]:
        """The averaged drift, diffusion and period as unevaluated integrals (eqs. 21-23, or 24-26 with impacts).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> sorted(averaging_equations(DuffingImpact()).averaged())
        ['T', 'diffusion', 'drift']
        """
        lim = (X, -_DELTA, _DELTA) if impacts else (X, -_A, _A)
        sub = {S: self.speed}
        T = sp.Integral(2 / self.speed, lim)
        drift = sp.Integral(self.drift_integrand.xreplace(sub), lim) / _T
        if impacts:
            drift = drift - _DH / _T
        diff = sp.Integral(self.diffusion_integrand.xreplace(sub), lim) / _T
        return {"drift": drift, "diffusion": diff, "T": T}

    def latex(self) -> str:
        """A LaTeX block (``align``) with eqs. 16, 17, 19 and the averaged coefficients for this model.

        Examples
        --------
        >>> from models import DuffingImpact
        >>> r"\\bar{m}" in averaging_equations(DuffingImpact()).latex()
        True
        """
        L = sp.latex
        inner = self.averaged(False)
        outer = self.averaged(True)
        ys = sp.Symbol("y")
        lines = [
            rf"m(x, y) &= {L(self.drift)}",
            rf"\sigma^2(x, y) &= {L(self.diffusion_squared)}",
            rf"dH &= \left[{L(self.energy_drift)}\right] dt + \sqrt{{{L(self.energy_diffusion_squared)}}}\, dW,"
            rf"\quad {L(ys)} = \pm {L(self.speed)}",
            rf"\bar{{m}}(H) &= {L(inner['drift'])} \quad (H < G(\Delta))",
            rf"\bar{{\sigma}}^2(H) &= {L(inner['diffusion'])} \quad (H < G(\Delta))",
            rf"T(H) &= {L(inner['T'])} \quad (H < G(\Delta))",
            rf"\bar{{m}}(H) &= {L(outer['drift'])} \quad (H > G(\Delta))",
            rf"\bar{{\sigma}}^2(H) &= {L(outer['diffusion'])} \quad (H > G(\Delta))",
            rf"T(H) &= {L(outer['T'])} \quad (H > G(\Delta))",
        ]
        return "\\begin{align}\n" + " \\\\\n".join(lines) + "\n\\end{align}"

    def __str__(self) -> str:
        s = sp.sstr
        return "\n".join([
            f"model: {self.model.name}",
            f"Itô drift      m(x, y)    = {s(self.drift)}",
            f"diffusion      sigma^2    = {s(self.diffusion_squared)}",
            f"energy (eq.19) dH = [{s(self.energy_drift)}] dt + sqrt({s(self.energy_diffusion_squared)}) dW,"
            f"  y = +-s, s = {s(self.speed)}",
            f"averaged drift     m_bar(H)  = (1/T) int [{s(self.drift_integrand)}] dx  (- dH/T with impacts)",
            f"averaged diffusion s2_bar(H) = (1/T) int [{s(self.diffusion_integrand)}] dx",
            "period             T(H)      = int [2/s] dx",
            "over x in [-A, A], G(A) = H, when H < G(delta); over [-delta, delta] when H > G(delta)",
        ])

    def _repr_latex_(self) -> str:  # Jupyter display
        return "$$" + self.latex().replace("align", "aligned") + "$$"

    def pretty(self) -> str:
        """Multi-line 2-D rendering (sympy ``pretty``) of the averaged drift and diffusion below G(delta).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> "T(H)" in averaging_equations(DuffingImpact()).pretty()
        True
        """
        inner = self.averaged(False)
        return "\n\n".join(f"{name} =\n{sp.pretty(expr, use_unicode=False)}" for name, expr in
                             (("m_bar(H)", inner["drift"]), ("sigma2_bar(H)", inner["diffusion"]),
                              ("T(H)", inner["T"])))

    def __repr__(self) -> str:
        return f"AveragingEquations({self.model.name!r})"

    # ------------------------------------------------------------------ compile
    @property
    def kernels(self) -> _Kernels:
        """numpy kernels of s*a and s*b as functions of (x, s, *parameter values) (compiled once per declaration)."""
        if "kernels" not in self._compiled:
            self._compiled["kernels"] = self._compile_kernels()
        return self._compiled["kernels"]

    def _compile_kernels(self) -> _Kernels:
        names = tuple(self.model.params)
        syms = [self.model.parameter_symbols[k] for k in names]
        args = [X, S, *syms]
        # dummify: the orbit variable s and a user's parameter named s are two symbols with one name
        drift = lambdify_numeric(args, self._w_drift, dummify=True)
        diffusion = lambdify_numeric(args, self._w_diffusion, dummify=True)
        return _Kernels(drift, diffusion, names)

    @property
    def potential_kernels(self):
        """(G, g) as numpy functions of (x, *parameter values); None when G has no closed form (compiled once per
        declaration)."""
        if "potential" not in self._compiled:
            self._compiled["potential"] = self._compile_potential()
        return self._compiled["potential"]

    def _compile_potential(self):
        G = self.model.potential_expr
        if G is None:
            return None
        names = tuple(self.model.params)
        args = [X, *[self.model.parameter_symbols[k] for k in names]]
        return (lambdify_numeric(args, G), lambdify_numeric(args, self.model.g), names)


_CACHE: dict[str, AveragingEquations] = {}
_FINGERPRINTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def fingerprint(model) -> str:
    """``model.fingerprint()``, memoised per model object (printing sympy expressions is slow).

    Examples
    --------
    >>> from models import DuffingImpact
    >>> m = DuffingImpact()
    >>> fingerprint(m) == m.fingerprint()
    True
    """
    try:
        return _FINGERPRINTS[model]
    except (KeyError, TypeError):
        fp = model.fingerprint()
        try:
            _FINGERPRINTS[model] = fp
        except TypeError:  # not weak-referenceable
            pass
        return fp


def averaging_equations(model) -> AveragingEquations:
    """The symbolic averaging of ``model`` (cached by the model's symbolic fingerprint).

    Parameters
    ----------
    model : ImpactOscillator

    Returns
    -------
    AveragingEquations

    Examples
    --------
    >>> from models import ImpactOscillator
    >>> m = ImpactOscillator("x", "c*y", noise=("y",), parameters={"c": 0.1, "D": 0.01}, barriers=None)
    >>> averaging_equations(m).drift          # Wong-Zakai term D*y
    D*y - c*y - x
    """
    key = fingerprint(model)
    eq = _CACHE.get(key)
    if eq is None:
        eq = AveragingEquations(model)
        _CACHE[key] = eq
    if eq.model is not model:
        # same declaration, other parameter values: the kernels take parameters as arguments, keep them
        fresh = object.__new__(AveragingEquations)
        fresh.__dict__.update(eq.__dict__)
        fresh.model = model
        return fresh
    return eq
