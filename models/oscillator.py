"""The impact-oscillator base class: one declaration feeds every backend.

A model is the equation of motion of the paper (eq. 1)

    x'' + g(x) + eps * h(x, x') = F(t, x, x') + eps**(1/2) * f_k(x, x') * xi_k(t),   x_left < x < x_right,

with E[xi_k(t) xi_l(t + s)] = 2 D_kl delta(s), impacts v+ = -e(|v-|) v- at the barriers, and an optional
deterministic forcing F (``forcing="A*cos(Omega*t + phi)"``; zero in the paper). The user gives g, h,
f_k and D_kl as sympy expressions (or strings) of the state symbols ``x`` and ``y`` (y = x') and of named
parameters. The model derives the potential G, the energy H, the Itô drift and diffusion, the turning points and
the hybrid automaton.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from functools import cached_property
from types import MappingProxyType

import numpy as np
import sympy as sp

from hybrid.automaton import HybridAutomaton, Mode, Transition, _as_expr, lambdify_numeric, real_symbol
from hybrid.errors import ModelError, ParameterError

from .levels import solve_level
from .restitution import Elastic, RestitutionLaw

X = real_symbol("x")
"""Displacement symbol."""
T = real_symbol("t")
"""Time symbol (only the forcing F may use it)."""
Y = real_symbol("y")
"""Velocity symbol (y = dx/dt)."""


class ImpactOscillator:
    """A single-degree-of-freedom oscillator between rigid barriers, with white-noise forcing.

    Parameters
    ----------
    restoring : expression in x
        The restoring force g(x).
    damping : expression in x, y
        The damping force h(x, y) (multiplied by ``epsilon``).
    noise : sequence of expressions in x, y
        The noise coefficients f_k(x, y).
    intensity : expression, or m x m nested sequence of expressions
        The noise intensities D_kl (E[xi_k xi_l] = 2 D_kl delta). A scalar means D * identity.
    parameters : mapping
        Parameter names and default values. ``delta`` is the barrier distance when ``barriers='delta'``.
    barriers : 'delta', a pair (left, right), or None
        Barrier positions: symmetric at +-delta, asymmetric, one-sided (None on the side without a barrier, e.g.
        ``(None, "delta")``), a stop at the equilibrium (``(0, None)``: motion on x >= 0), or no barriers.
    restitution : RestitutionLaw
    epsilon : expression
        The small parameter of eq. 1 (1 in the paper's examples).
    forcing : expression in t (and x, y), optional
        A deterministic force F on the right-hand side, e.g. ``"A*cos(Omega*t + phi)"`` (harmonic forcing). Terms of
        ``restoring`` that contain ``t`` are moved here with their sign flipped, so ``restoring="x - A*cos(W*t)"``
        means g = x and F = A cos(W t). The energy H and the potential G stay those of the unforced g. A forced
        model runs in the orbit backends and in Monte Carlo through its automaton
        (``hybrid.stochastic.simulate_automaton``, ``vibro mc``); the averaging methods refuse it. The forcing
        frequencies (the factors of t inside sin and cos) must be finite and non-zero.
    nonnegative, positive : sequences of parameter names
        Parameters that must be >= 0 (noise intensities) or > 0 (barrier distances).
    name : str

    Examples
    --------
    >>> from models import ImpactOscillator, Newton
    >>> m = ImpactOscillator("k*x", "c*y", parameters={"k": 1, "c": 0.1, "D": 0.05, "delta": 1.0},
    ...                      restitution=Newton(0.8), name="linear")
    >>> m.potential_expr
    k*x**2/2
    >>> round(m.barrier_energy, 6)
    0.5
    """

    name = "oscillator"

    def __init__(
        self,
        restoring,
        damping=0,
        noise: Sequence = (1,),
        intensity="D",
        parameters: Mapping[str, float] | None = None,
        barriers="delta",
        restitution: RestitutionLaw | None = None,
        epsilon=1,
        nonnegative: Sequence[str] = ("D",),
        positive: Sequence[str] = ("delta",),
        name: str | None = None,
        forcing=0,
    ):
        if name is not None:
            self.name = name
        if isinstance(noise, (str, sp.Basic)) or not isinstance(noise, Sequence):
            raise ModelError(f"noise={noise!r} must be a sequence of coefficients f_k(x, y), e.g. noise=(1,)")
        if parameters is not None and not isinstance(parameters, Mapping):
            raise ModelError(f"parameters={parameters!r} must be a mapping of names to values, e.g. {{'D': 0.05}}")
        self._declaration = dict(
            restoring=restoring, damping=damping, noise=tuple(noise), intensity=intensity,
            barriers=barriers, epsilon=epsilon, nonnegative=tuple(nonnegative), positive=tuple(positive),
            forcing=forcing,
        )
        self.g = _as_expr(restoring, "restoring force g(x)")
        self.forcing = _as_expr(forcing, "forcing F(t)")
        if T in self.g.free_symbols:
            # the time-dependent terms of g are a forcing: F gets them with the opposite sign, G stays autonomous
            timed = sp.Add(*[a for a in sp.Add.make_args(sp.expand(self.g)) if T in a.free_symbols])
            self.g = sp.expand(self.g) - timed
            self.forcing = self.forcing - timed
        self.h = _as_expr(damping, "damping h(x, y)")
        self.f = tuple(_as_expr(fk, f"noise coefficient f_{k + 1}") for k, fk in enumerate(noise))
        if not self.f:
            raise ModelError("declare at least one noise coefficient (use noise=(1,) and D=0 for a free system)")
        m = len(self.f)
        if isinstance(intensity, (list, tuple)):
            if not all(isinstance(row, (list, tuple)) for row in intensity):
                raise ModelError(f"intensity={intensity!r} must be a scalar or an {m}x{m} nested sequence of "
                                 "expressions, e.g. [['D', 0], [0, 'D']]")
            rows = [[_as_expr(v, "noise intensity") for v in row] for row in intensity]
            if len(rows) != m or any(len(r) != m for r in rows):
                raise ModelError(f"intensity must be a {m}x{m} matrix for {m} noise coefficients")
            self.intensity = sp.Matrix(rows)
        else:
            self.intensity = _as_expr(intensity, "noise intensity") * sp.eye(m)
        if self.intensity != self.intensity.T:
            raise ModelError("the intensity matrix D_kl must be symmetric")
        self.epsilon = _as_expr(epsilon, "epsilon")
        if barriers is None:
            self.barrier_exprs = None
        elif barriers == "delta":
            d = real_symbol("delta")
            self.barrier_exprs = (-d, d)
        else:
            try:
                left, right = barriers
            except (TypeError, ValueError) as exc:
                raise ModelError(
                    f"barriers={barriers!r}: use 'delta', None, or a pair (left, right) in which None means no "
                    "barrier on that side, e.g. (0, None) for a stop at the equilibrium"
                ) from exc
            if left is None and right is None:
                self.barrier_exprs = None
            else:
                # None on one side: no barrier there (a one-sided stop)
                self.barrier_exprs = (-sp.oo if left is None else _as_expr(left, "left barrier"),
                                      sp.oo if right is None else _as_expr(right, "right barrier"))
        self.restitution = restitution if restitution is not None else Elastic()
        if not isinstance(self.restitution, RestitutionLaw):
            raise ModelError(
                f"restitution must be a RestitutionLaw (Elastic(), Newton(e), Ma(vc)), got {restitution!r}"
            )
        self._nonnegative = tuple(nonnegative)
        self._positive = tuple(positive)
        self.params = MappingProxyType(self._check_params(dict(parameters or {})))
        self._check_symbols()

    # ------------------------------------------------------------------ parameters
    def _check_params(self, values: dict) -> dict:
        out = {}
        for k, v in values.items():
            try:
                out[k] = float(v)
            except (TypeError, ValueError) as exc:
                raise ParameterError(f"parameter {k}={v!r} is not a number") from exc
            if not np.isfinite(out[k]) and not (k in self._positive and out[k] == np.inf):
                raise ParameterError(f"parameter {k}={v!r} is not finite")
        for k in self._nonnegative:
            if k in out and out[k] < 0:
                raise ParameterError(f"{k}={out[k]:g} is negative; a noise intensity must be >= 0")
        for k in self._positive:
            if k in out and not out[k] > 0:
                raise ParameterError(
                    f"{k}={out[k]:g} must be > 0 (a barrier distance); use a positive value, or inf for no barrier"
                )
        return out

    def _check_symbols(self) -> None:
        known = {"x", "y"} | set(self.params)
        if "t" in self.params:
            raise ModelError("the name 't' is reserved for time (the forcing F(t)); rename that parameter")
        unknown = {s.name for s in self.forcing.free_symbols} - known - {"t"}
        if unknown:
            raise ModelError(f"forcing F uses {sorted(unknown)}, which are neither t, x, y nor parameters "
                             f"{sorted(self.params)}; add them to parameters={{...}}")
        exprs = {"g": self.g, "h": self.h, "epsilon": self.epsilon}
        exprs.update({f"f_{k + 1}": f for k, f in enumerate(self.f)})
        exprs.update({"D": self.intensity})
        if self.barrier_exprs is not None:
            exprs.update({"left barrier": self.barrier_exprs[0], "right barrier": self.barrier_exprs[1]})
        for where, e in exprs.items():
            unknown = {s.name for s in e.free_symbols} - known
            if "t" in unknown:
                raise ModelError(f"{where} uses the time t: only the forcing may depend on time (forcing="
                                 "'A*cos(Omega*t)'); for a moving barrier declare a HybridAutomaton (see "
                                 "models.automata.vibrating_table)")
            if unknown:
                raise ModelError(
                    f"{where} uses {sorted(unknown)}, which are neither the states x, y nor parameters "
                    f"{sorted(self.params)}; add them to parameters={{...}}"
                )
        self._check_intensity()
        self._forcing_frequencies()
        if Y in self.g.free_symbols:
            raise ModelError("the restoring force g may depend on x only; put velocity terms in the damping h(x, y)")
        if self.barrier_exprs is not None:
            for b in self.barrier_exprs:
                if b.free_symbols & {X, Y}:
                    raise ModelError("barrier positions may depend on parameters only")
            left, right = self.barriers
            if not (left <= 0.0 <= right and left < right):
                raise ModelError(
                    f"barriers must enclose or touch the equilibrium x = 0 (left <= 0 <= right): got left={left:g}, "
                    f"right={right:g}"
                )
        self._check_restoring()
        self._check_damping_and_noise()

    def _check_damping_and_noise(self, samples: int = 41, reach: float = 50.0, speed: float = 10.0) -> None:
        """h(x, y) and every f_k(x, y) must be finite real numbers on the admissible states (sampled: x as for g,
        |y| <= ``speed``): a damping c*y/x or a noise sqrt(y) gives no stochastic differential equation at all, and
        its averaged coefficients come out as NaN or silently wrong (principal values)."""
        exprs = [("damping h(x, y)", self.h)] + [(f"noise coefficient f_{k + 1}", f) for k, f in enumerate(self.f)]
        cached = self.__dict__.get("_hf_of_parameters")
        if cached is None:
            names = sorted(self.params)
            checked = [(what, e) for what, e in exprs if e.free_symbols <= {X, Y, *map(real_symbol, names)}]
            fns = [(what, e, lambdify_numeric([X, Y, *[real_symbol(k) for k in names]], e))
                   for what, e in checked]
            cached = self.__dict__["_hf_of_parameters"] = (names, fns)
        names, fns = cached
        left, right = self.barriers
        lo, hi = max(left, -reach), min(right, reach)
        xs = np.unique(np.concatenate([np.linspace(lo, hi, samples), [0.0]]))
        ys = np.unique(np.concatenate([np.linspace(-speed, speed, samples), [0.0]]))
        XX, YY = np.meshgrid(xs, ys)
        values = [self.params[k] for k in names]
        for what, expr, fn in fns:
            try:
                with np.errstate(all="ignore"):
                    out = np.broadcast_to(np.asarray(fn(XX, YY, *values), dtype=float), XX.shape)
            except Exception as exc:  # the user's expression cannot be evaluated: say where, in one line
                raise ModelError(f"the {what} = {expr} cannot be evaluated for x in [{lo:g}, {hi:g}], |y| <= "
                                 f"{speed:g} ({type(exc).__name__}: {exc})") from exc
            bad = ~np.isfinite(out)
            if bad.any():
                i = np.argwhere(bad)[0]
                raise ModelError(f"the {what} = {expr} is not a finite real number at (x, y) = ({XX[tuple(i)]:.6g}, "
                                 f"{YY[tuple(i)]:.6g}), an admissible state; declare one defined on every state "
                                 "(e.g. Abs(y) inside a square root, no division by x)")

    def _restoring_of_parameters(self):
        """(parameter names, g as a numpy function of x and those parameters), built once and shared by the copies
        that :meth:`with_params` makes (each check would otherwise lambdify g again)."""
        cached = self.__dict__.get("_g_of_parameters")
        if cached is None:
            names = sorted(self.params)
            fn = lambdify_numeric([X, *[real_symbol(k) for k in names]], self.g)
            cached = self.__dict__["_g_of_parameters"] = (names, fn)
        return cached

    def _check_restoring(self, samples: int = 401, reach: float = 50.0) -> None:
        """g must be a finite real number at every admissible x (sampled between the walls, or up to |x| = ``reach``
        on a side without one), and G must grow outwards on a side without a wall, or the motion escapes."""
        left, right = self.barriers
        lo, hi = max(left, -reach), min(right, reach)
        xs = np.unique(np.concatenate([np.linspace(lo, hi, samples), [0.0]]))
        where = "between the walls" if self.has_barriers else "near the equilibrium"
        names, g_of = self._restoring_of_parameters()
        try:
            with np.errstate(all="ignore"):
                gx = np.broadcast_to(np.asarray(g_of(xs, *[self.params[k] for k in names]), dtype=float), xs.shape)
        except Exception as exc:  # the user's expression cannot be evaluated: say where, in one line
            raise ModelError(f"the restoring force g(x) = {self.g} cannot be evaluated on [{lo:g}, {hi:g}] "
                             f"({type(exc).__name__}: {exc})") from exc
        bad = ~np.isfinite(gx)
        if bad.any():
            raise ModelError(
                f"the restoring force g(x) = {self.g} is not a finite real number at x = {xs[bad][0]:.6g}, "
                f"inside the admissible range [{lo:g}, {hi:g}] {where}; declare a force defined on the whole range "
                "(e.g. sign(x)*sqrt(Abs(x)) instead of sqrt(x)) or put the walls where it is defined"
            )
        for side, open_side in ((-1.0, not np.isfinite(left)), (1.0, not np.isfinite(right))):
            if not open_side:
                continue
            with np.errstate(all="ignore"):
                near, far = (float(v) for v in self.potential(np.array([side * reach / 2, side * reach])))
            if not far > near:  # also NaN
                raise ModelError(
                    f"the restoring force g(x) = {self.g} does not confine the motion on the "
                    f"{'left' if side < 0 else 'right'}: there is no wall on that side and the potential G does not "
                    f"grow outwards (G({side * reach / 2:g}) = {near:.4g}, G({side * reach:g}) = {far:.4g}), so "
                    "orbits escape to infinity; add a wall on that side (barriers=...) or a force that pulls back"
                )

    def _check_intensity(self) -> None:
        """A state-independent intensity matrix D_kl must be real, finite and positive semi-definite."""
        D = self.substitute(self.intensity)
        if D.free_symbols & {X, Y}:
            return  # state-dependent: only the generated diffusion sigma**2 >= 0 can tell
        try:
            M = np.array(D.tolist(), dtype=float)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"the noise intensity D_kl = {D.tolist()} is not real; use real values") from exc
        if not np.all(np.isfinite(M)):
            raise ParameterError(f"the noise intensity D_kl = {M.tolist()} is not finite")
        low = float(np.linalg.eigvalsh(M).min())
        if low < -1e-12 * float(np.abs(M).max()):  # relative to the matrix itself: D = -1e-308 is negative too
            raise ParameterError(
                f"the noise intensity D_kl = {M.tolist()} is not positive semi-definite (eigenvalue {low:.3g}): "
                "E[xi_k xi_l] = 2 D_kl delta needs a covariance matrix; fix its entries"
            )

    def with_params(self, **values: float) -> ImpactOscillator:
        """A copy with some parameters changed (the model itself is never mutated).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> DuffingImpact().with_params(delta=1.2).params["delta"]
        1.2
        """
        unknown = set(values) - set(self.params)
        if unknown:
            raise ParameterError(
                f"unknown parameters {sorted(unknown)} for model {self.name!r}; known: {sorted(self.params)}"
            )
        new = object.__new__(type(self))
        new.__dict__.update({k: v for k, v in self.__dict__.items() if k not in _CACHED})
        new.params = MappingProxyType(self._check_params({**self.params, **values}))
        new._check_symbols()
        return new

    def with_restitution(self, law: RestitutionLaw) -> ImpactOscillator:
        """A copy with another restitution law.

        Examples
        --------
        >>> from models import DuffingImpact, Elastic
        >>> DuffingImpact().with_restitution(Elastic()).restitution
        Elastic()
        """
        if not isinstance(law, RestitutionLaw):
            raise ModelError(f"expected a RestitutionLaw, got {law!r}")
        new = object.__new__(type(self))
        new.__dict__.update({k: v for k, v in self.__dict__.items() if k not in _CACHED})
        new.restitution = law
        return new

    @property
    def parameter_symbols(self) -> dict[str, sp.Symbol]:
        """Parameter name -> sympy symbol."""
        return {k: real_symbol(k) for k in self.params}

    def substitute(self, expr: sp.Expr) -> sp.Expr:
        """``expr`` with the current parameter values substituted (leaves x, y and the speed v)."""
        return sp.sympify(expr).xreplace({real_symbol(k): sp.Float(v) for k, v in self.params.items()})

    # ------------------------------------------------------------------ barriers
    @property
    def barriers(self) -> tuple[float, float]:
        """(left, right) barrier positions as floats; (-inf, inf) without barriers."""
        if self.barrier_exprs is None:
            return (-np.inf, np.inf)
        left, right = (float(self.substitute(b)) for b in self.barrier_exprs)
        return left, right

    @property
    def has_barriers(self) -> bool:
        """True when at least one barrier is finite."""
        left, right = self.barriers
        return bool(np.isfinite(left) or np.isfinite(right))

    @property
    def is_symmetric(self) -> bool:
        """True when G(left) = G(right), so that impacts start at one energy level (the paper's assumption)."""
        left, right = self.barriers
        if not self.has_barriers:
            return True
        if not (np.isfinite(left) and np.isfinite(right)):
            return False
        gl, gr = self.potential(np.array([left, right]))
        return bool(abs(gl - gr) <= 1e-12 * max(1.0, abs(gl)))

    @property
    def barrier_energy(self) -> float:
        """G at the barriers: the energy above which the oscillator hits them (inf without barriers).

        For a one-sided stop it is G at that stop (0 for a stop at the equilibrium).

        Raises
        ------
        ModelError
            When G(left) != G(right): there is no single impact level (``averaging.quadrature.geometry(model)``
            gives each wall's level).

        Examples
        --------
        >>> m = ImpactOscillator("x", parameters={"D": 0.1, "delta": 2.0}, barriers=(None, "delta"))
        >>> m.barrier_energy
        2.0
        """
        if not self.has_barriers:
            return float("inf")
        left, right = self.barriers
        finite = [b for b in (left, right) if np.isfinite(b)]
        levels = [float(v) for v in self.potential(np.array(finite))]
        if len(levels) == 2 and abs(levels[0] - levels[1]) > 1e-12 * max(1.0, abs(levels[0])):
            raise ModelError(
                f"G(left)={levels[0]:.6g} differs from G(right)={levels[1]:.6g}: asymmetric walls have no single "
                "impact level G(delta) (each wall is hit above its own level; the averaging and Monte Carlo handle "
                "them, eqs. 11-14 of the free orbit assume one level)"
            )
        return max(levels)

    # ------------------------------------------------------------------ energy
    @cached_property
    def potential_expr(self) -> sp.Expr | None:
        """G(x) = int_0^x g, symbolic with parameter symbols; None when sympy cannot integrate g."""
        if self.g.is_polynomial(X):  # the usual case; sp.integrate's general machinery costs 0.05-0.1 s
            return sp.expand(sp.Poly(self.g, X).integrate().as_expr())
        s = sp.Dummy("s", real=True)
        G = sp.integrate(self.g.xreplace({X: s}), (s, 0, X))
        if G.has(sp.Integral):
            return None
        return sp.expand(G)

    @cached_property
    def energy_expr(self) -> sp.Expr | None:
        """H = y**2/2 + G(x), symbolic; None when G has no closed form."""
        G = self.potential_expr
        return None if G is None else Y**2 / 2 + G

    @cached_property
    def _g_numeric(self):
        return lambdify_numeric(X, self.substitute(self.g))

    @cached_property
    def _damping_numeric(self):
        """epsilon h(x, y) at the current parameters, a numpy function of (x, y) (lambdified once per model)."""
        return lambdify_numeric((X, Y), self.substitute(self.epsilon * self.h))

    @cached_property
    def _G_numeric(self):
        G = self.potential_expr
        if G is not None:
            fn = lambdify_numeric(X, self.substitute(G))  # erf, gamma, ... on arrays
            return lambda x: np.broadcast_to(np.asarray(fn(x), dtype=float), np.shape(x)) + 0.0
        g = self._g_numeric

        def by_quadrature(x):
            from scipy import integrate  # here only: scipy.integrate costs 0.2-0.4 s of start-up

            x = np.asarray(x, dtype=float)
            flat = [integrate.quad(lambda s: float(g(s)), 0.0, xi, epsabs=1e-14, epsrel=1e-13)[0] for xi in x.ravel()]
            return np.array(flat).reshape(x.shape)

        return by_quadrature

    def restoring(self, x):
        """g(x), numerically, at the current parameters."""
        x = np.asarray(x, dtype=float)
        return np.broadcast_to(np.asarray(self._g_numeric(x), dtype=float), x.shape) + 0.0

    def potential(self, x):
        """G(x), numerically (closed form when sympy finds one, quadrature otherwise).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> float(DuffingImpact().potential(1.0))
        0.55
        """
        x = np.asarray(x, dtype=float)
        return self._G_numeric(x)

    def energy(self, x, y):
        """H = y**2/2 + G(x)."""
        y = np.asarray(y, dtype=float)
        return 0.5 * y * y + self.potential(x)

    def check_single_well(self, samples: int = 2001) -> None:
        """Require x * g(x) > 0 between the barriers (and G -> inf without them): one well, one orbit per level.

        Raises
        ------
        ModelError
            When the potential does not confine, or has several wells inside the barriers, or the model is forced
            (the averaging needs an autonomous model).
        """
        self.require_autonomous()
        left, right = self.barriers
        span_l = left if np.isfinite(left) else -50.0
        span_r = right if np.isfinite(right) else 50.0
        # a wall at the equilibrium leaves one side empty (no samples there)
        xs = np.concatenate([np.linspace(span_l, 0, samples)[:-1] if span_l < 0 else [],
                             np.linspace(0, span_r, samples)[1:] if span_r > 0 else []])
        gx = self.restoring(xs)
        bad = ~(xs * gx > 0)
        if bad.any():
            raise ModelError(
                f"x*g(x) <= 0 at x={xs[bad][0]:.4g}: the potential G is not a single well between the barriers, "
                "so energy levels are not single closed orbits. The averaging needs a confining single-well potential "
                "(for example a > 0 and b >= 0 in a Duffing restoring force)"
            )
        if not (np.isfinite(left) and np.isfinite(right)):
            open_sides = [v for v, b in ((span_l, left), (span_r, right)) if not np.isfinite(b)]
            far = self.potential(np.array(open_sides))
            near = self.potential(np.array(open_sides) / 2)
            if not np.all(far > 2 * near):
                raise ModelError(
                    "without barriers the potential must grow without bound (confine the motion); "
                    "G does not grow enough at |x| = 50"
                )

    def turning_points(self, H):
        """(A_minus, A_plus): where G(x) = H on each side of 0, vectorised; clipped to the barriers.

        Examples
        --------
        >>> from models import ImpactOscillator
        >>> m = ImpactOscillator("x", parameters={"D": 0.0}, barriers=None)
        >>> [round(float(v), 9) for v in m.turning_points(0.5)]
        [-1.0, 1.0]
        """
        H = np.asarray(H, dtype=float)
        left, right = self.barriers
        lo = self._solve_level(H, -1.0, left).reshape(H.shape)
        hi = self._solve_level(H, +1.0, right).reshape(H.shape)
        return lo, hi

    def _solve_level(self, H, sign, bound):
        """Root of G(sign * s) = H for s > 0, clipped to the barrier at ``bound`` (G is monotone there)."""
        H = np.atleast_1d(H).astype(float)
        z, missing = solve_level(self.potential, self.restoring, H, sign)
        limit = abs(bound) if np.isfinite(bound) else np.inf
        if missing.any() and not np.isfinite(limit):
            raise ModelError(f"no turning point at H={H[missing][0]:.6g}: the potential does not confine")
        return sign * np.where(missing, limit, np.minimum(z, limit))

    def amplitude(self, H):
        """Turning amplitude A(H) with G(A) = H on the positive side (root finding; subclasses may override)."""
        H = np.asarray(H, dtype=float)
        out = self._solve_level(H, +1.0, self.barriers[1])
        return out.reshape(H.shape)

    # ------------------------------------------------------------------ stochastic structure
    @cached_property
    def ito_drift(self) -> sp.Expr:
        """m(x, y) = -g - eps*h + eps * D_jk f_j df_k/dy (eq. 16: Itô form with the Wong-Zakai term)."""
        m = len(self.f)
        wz = sum(self.intensity[j, k] * self.f[j] * sp.diff(self.f[k], Y) for j in range(m) for k in range(m))
        return sp.expand(-self.g - self.epsilon * self.h + self.forcing + self.epsilon * wz)

    @cached_property
    def diffusion_squared(self) -> sp.Expr:
        """sigma**2(x, y) = 2 eps D_jk f_j f_k (eq. 17)."""
        m = len(self.f)
        pairs = sum(self.intensity[j, k] * self.f[j] * self.f[k] for j in range(m) for k in range(m))
        return sp.expand(2 * self.epsilon * pairs)

    def linear_damping_constant(self) -> float | None:
        """c when the damping force is eps*h = c*y with a constant c (parameters substituted), else None.

        The one test of "linear damping" in the project: the exact elastic density, the method chooser, the Monte
        Carlo speed scale and the oracles all ask the model.

        Examples
        --------
        >>> ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.0}, barriers=None).linear_damping_constant()
        0.1
        >>> ImpactOscillator("x", "c*y**3", parameters={"c": 0.1, "D": 0.0}, barriers=None).linear_damping_constant()
        """
        h = sp.expand(self.substitute(self.epsilon * self.h))
        c = sp.diff(h, Y)
        if c.free_symbols & {X, Y} or sp.simplify(h - c * Y) != 0:
            return None
        return float(c)

    def constant_noise_intensity(self) -> float | None:
        """sigma**2 (parameters substituted) when it does not depend on the state, else None.

        Examples
        --------
        >>> ImpactOscillator("x", "c*y", parameters={"c": 0.1, "D": 0.05}, barriers=None).constant_noise_intensity()
        0.1
        """
        s2 = self.substitute(self.diffusion_squared)
        if s2.free_symbols & {X, Y}:
            return None
        return float(s2)

    @property
    def additive_noise(self) -> bool:
        """True when sigma does not depend on the state (Milstein then reduces to Euler-Maruyama)."""
        return not (self.diffusion_squared.free_symbols & {X, Y})

    # ------------------------------------------------------------------ forcing
    @property
    def is_forced(self) -> bool:
        """True when the model has a deterministic forcing F (its equations depend on time).

        Examples
        --------
        >>> m = ImpactOscillator("x", forcing="A*cos(W*t)", parameters={"A": 0.1, "W": 1.0, "D": 0.0}, barriers=None)
        >>> m.is_forced, ImpactOscillator("x", parameters={"D": 0.0}, barriers=None).is_forced
        (True, False)
        """
        return self.forcing != 0

    def _forcing_frequencies(self) -> list[float]:
        """The angular frequencies |w| of the sin/cos(w t + ...) terms of F, checked finite and non-zero."""
        out = []
        for fn in self.forcing.atoms(sp.sin, sp.cos):  # symbolic: Omega = 0 must not make the term vanish first
            arg = fn.args[0]
            if T not in arg.free_symbols:
                continue
            rate = sp.diff(arg, T)
            if rate.free_symbols & {T, X, Y}:
                continue  # not harmonic in t (a chirp, or a phase that depends on the state): no period
            w = float(self.substitute(rate))
            if not (np.isfinite(w) and w != 0.0):
                raise ParameterError(f"forcing frequency {rate} = {w!r} in F = {self.forcing}: a harmonic forcing "
                                     "needs a finite, non-zero frequency (a constant load belongs in the restoring "
                                     "force)")
            out.append(abs(w))
        return sorted(set(out))

    @property
    def forcing_period(self) -> float | None:
        """The period of the forcing, 2 pi / w for harmonic terms whose frequencies are integer multiples of the
        lowest w; None when the model is unforced or F is not periodic in that way.

        Examples
        --------
        >>> m = ImpactOscillator("x", forcing="A*cos(W*t) + B*sin(3*W*t)",
        ...                      parameters={"A": 0.1, "B": 0.0, "W": 2.0, "D": 0.0}, barriers=None)
        >>> round(m.forcing_period, 12)
        3.14159265359
        """
        if not self.is_forced:
            return None
        F = self.substitute(self.forcing)
        w = self._forcing_frequencies()
        if not w:
            return None
        # F may only depend on t through those harmonic terms
        trig = {fn: sp.Dummy() for fn in F.atoms(sp.sin, sp.cos) if T in fn.free_symbols}
        if T in F.xreplace(trig).free_symbols:
            return None
        ratios = [v / w[0] for v in w]
        if any(abs(r - round(r)) > 1e-9 * r for r in ratios):
            return None
        return 2.0 * np.pi / w[0]

    def require_autonomous(self, what: str = "the averaging methods") -> None:
        """Raise :class:`ModelError` when the model is forced (``what`` needs a time-independent model).

        Examples
        --------
        >>> m = ImpactOscillator("x", forcing="A*cos(W*t)", parameters={"A": 0.1, "W": 1.0, "D": 0.1}, barriers=None)
        >>> m.require_autonomous()  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        hybrid.errors.ModelError: the averaging methods need a model without time dependence, ... or orbits (...)
        """
        if self.is_forced:
            raise ModelError(f"{what} need a model without time dependence, but this one is forced by F = "
                             f"{self.forcing}; for its periodic density use vibro pdf --method fpk --phases N "
                             "(averaging.phase_plane.periodic_density_xy), Monte Carlo (vibro mc, "
                             "hybrid.stochastic.simulate_automaton(model.to_automaton(), ...)) or orbits (vibro orbit, "
                             "simulate_orbit)")

    # ------------------------------------------------------------------ automaton
    def to_automaton(self) -> HybridAutomaton:
        """The hybrid automaton: one mode ``free`` and one transition per finite barrier.

        The reset is y -> -e(|y|) y with the model's restitution law (symbolic when the law has an expression).

        Examples
        --------
        >>> from models import DuffingImpact
        >>> [t.name for t in DuffingImpact().to_automaton().transitions]
        ['right', 'left']
        """
        flow = (Y, -self.g - self.epsilon * self.h + self.forcing)
        noise = (sp.Integer(0), sp.sqrt(self.diffusion_squared))
        mode = Mode("free", flow, noise)
        transitions = []
        if self.barrier_exprs is not None:
            check = None
            try:
                e_expr = self.restitution.expression(sp.Abs(Y))
                reset = (X, -e_expr * Y)
                # e must lie in (0, 1] at every impact: Monte Carlo counts the firings where it does not
                check = sp.And(e_expr > 0, e_expr <= 1) if not e_expr.is_number else None
            except Exception:  # a callable law has no expression: reset numerically
                law = self.restitution

                def reset(state, params, _law=law):
                    out = np.array(state, dtype=float)
                    out[1] = -_law.coefficient(abs(out[1])) * out[1]
                    return out

            left, right = self.barrier_exprs
            if np.isfinite(self.barriers[1]):
                transitions.append(Transition("right", "free", "free", X - right, +1, reset, priority=0, check=check))
            if np.isfinite(self.barriers[0]):
                transitions.append(Transition("left", "free", "free", X - left, -1, reset, priority=1, check=check))
        observables = {"H": self.energy_expr} if self.energy_expr is not None else {}
        return HybridAutomaton(
            states=(X, Y), parameters=dict(self.params), modes=[mode], transitions=transitions,
            observables=observables,
        )

    # ------------------------------------------------------------------ identity
    def fingerprint(self) -> str:
        """A hash of the symbolic declaration (not the parameter values): the key for cached compiled kernels."""
        text = "|".join(
            [str(self.g), str(self.h), ";".join(map(str, self.f)), str(self.intensity), str(self.epsilon),
             str(self.barrier_exprs), ",".join(self.params)] + ([f"F={self.forcing}"] if self.is_forced else [])
        )
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def describe(self) -> dict:
        """A JSON-friendly description: expressions, parameters, restitution."""
        return {
            "model": self.name,
            "g": str(self.g), "h": str(self.h), "f": [str(f) for f in self.f],
            "D": str(self.intensity.tolist()), "epsilon": str(self.epsilon),
            "barriers": list(self.barriers), "parameters": dict(self.params),
            "restitution": self.restitution.spec(),
            **({"forcing": str(self.forcing), "forcing_period": self.forcing_period} if self.is_forced else {}),
        }

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v:g}" for k, v in self.params.items())
        return f"{type(self).__name__}({params}, restitution={self.restitution!r})"


_CACHED = {"potential_expr", "energy_expr", "_g_numeric", "_G_numeric", "_damping_numeric", "ito_drift",
           "diffusion_squared"}
