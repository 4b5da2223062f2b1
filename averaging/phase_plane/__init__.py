r"""Stationary density of the full (x, y) Fokker-Planck equation with impact boundary conditions (method ``fpk``).

The model x'' + g(x) + eps h(x, x') = eps**(1/2) f_k xi_k (Itô drift m(x, y) of y with the Wong-Zakai term,
sigma**2 = 2 eps D_jk f_j f_k, as in :mod:`models.oscillator`) has the stationary Fokker-Planck equation

    0 = -d_x(y p) - d_y(m p) + (1/2) d_yy(sigma**2 p),     w_l < x < w_r,

and at a wall the probability flux y p dy arriving at speed v leaves at speed e(v) v (no other flux crosses it).

Discretisation, and why
-----------------------
The equation is convection-dominated along the free orbits (speed ~1) with a weak cross-orbit part (damping
~c, noise ~D = 0.005-0.5). A finite-volume scheme on an (x, y) grid makes the orbit cross cells, and the
upwind numerical diffusion (~|g| h_y / 2) is comparable with D; even second-order fluxes leave a cross-orbit
error that is large relative to D at affordable grids. We therefore use coordinates in which the free flow is
tangent to one family of cell faces:

* u = sign(x) sqrt(2 G(x)), r = sqrt(u**2 + y**2) = sqrt(2H), psi = atan2(y, u). The map (x, y) -> (H, psi)
  has unit Jacobian from (u, y), so the free flow is a rotation psi' = -w(x), w = g(x)/u, along the circles
  H = const, and the conservative flux in psi of the physical density p is exactly -p.
* Cells are rings H_i < H < H_{i+1} split in psi. Faces between rings are orbits: the convection never
  crosses them, so its numerical diffusion acts along the orbit only, where it does not move probability
  between energies. Along the orbit the convection is upwind-biased third order (kappa = 1/3, linear, so no
  nonlinear iteration; first order next to arc ends), which keeps the jump of p at the wall sharp. Rings are
  stretched, H = h_max (theta t + (1 - theta) t**2), theta = 0.4, finer where the density lives. Energy exchange
  between rings (the damping drift and the noise) is a drift-diffusion in H, discretised by Scharfetter-Gummel
  exponential fitting: positive, second order, and exact for the Gibbs density exp(-cH/D) of linear damping with
  additive noise (the drift/diffusion ratio
  -c/D is constant in H). The mixed derivatives of the rank-one noise tensor are central differences.
* A wall x = w is the vertical line u = U, |U| = sqrt(2 G(w)), in the (u, y) plane; it cuts the rings above
  G(w) at psi = +-arccos(|U|/r). Ring faces are put at the wall energies, and the arcs end at the cut. The
  flux reaching the wall from a ring is exactly p dH (the flux y p dy of the wall, since y dy = dH at fixed
  x); it is removed from the incoming cell and re-injected into the outgoing cells of the rings that contain
  H' = G(w) + e(v)**2 (H - G(w)), v = sqrt(2 (H - G(w))), slice by slice (any e(v), even non-monotone e v),
  with the wall flux reconstructed linearly across rings (second order; the linear part has zero sum).
  Every flux leaves one cell and enters another, so the discrete probability is conserved to round-off.
* The stationary vector is the null vector of the sparse operator, computed by one sparse LU solve (minimum
  degree ordering of A + A^T) with one equation replaced by the normalisation (implied by conservation).

A periodically forced model has a periodic density instead: :func:`periodic_density_xy` (module
:mod:`averaging.phase_plane.forced`) finds it as the fixed point of the period map of this operator.

Several wells
-------------
With several wells (x g(x) <= 0 somewhere between the walls, e.g. the bistable Duffing g = -x + x**3/4) an energy
level holds several orbits and the rings above do not exist. ``scheme="auto"`` then solves on Cartesian cells
(:mod:`.cartesian`, :mod:`._cartesian`): finite volumes on the (x, y) cells of H < h_max with a fifth-order
upwind-biased convection, face averages corrected to fourth order, a wall as a cell face with the same impact map,
and p(H) on [min G, h_max] from the level sets integrated exactly. Orbits cross the cells, so the scheme suits
moderate noise (D/c of 0.1-1: L1 1.2e-5 of the joint density of the bistable Duffing at 120 x 120 cells, 0.8 s;
``benchmarks/fpk_multiwell.py``, ``docs/results/fpk-multiwell.md``); ``scheme="cartesian"`` uses it for a single
well too.

Errors (``benchmarks/fpk_convergence.py``, both grid directions refined together): fitted order 2.15 for p(H)
on the exact elastic density, 1.75 on Fig. 2 (Ma, delta = 1); 1.3 for E[H] with a wall at the equilibrium
(the wall meets the equilibrium at a corner of the domain). The outer ring at ``h_max`` is reflecting: choose
h_max in the tail (a warning says when it is not).

Coloured noise
--------------
A model driven by Ornstein-Uhlenbeck noise (``models.excitation.ou_filter``) has a stationary density of
(x, y, eta): :func:`stationary_density_coloured` (module :mod:`averaging.phase_plane.coloured`) solves it on
Cartesian (x, y) levels of eta coupled by the filter's drift and diffusion, with the same impact map, and returns
the (x, y)-marginal with this interface (p(H), p(x, y)) and the eta-marginal.

First passage and spectra
-------------------------
The assembled operator is kept on the result (``PhaseDensity.discretisation``): its adjoint is the backward
generator, so first passage, survival and decay rates (:mod:`.passage`) and power spectra through the resolvent
(:mod:`.spectrum`) reuse this discretisation, impact boundary included.

Examples
--------
>>> from models import DuffingImpact, Ma
>>> from averaging.phase_plane import stationary_density_xy
>>> sd = stationary_density_xy(DuffingImpact(restitution=Ma(0.4)), grid=(60, 64), h_max=4.0, check=False)
>>> round(sd.mean_energy, 2), sd.method
(0.5, 'fpk')
"""

from __future__ import annotations

from .coloured import ColouredDensity, stationary_density_coloured
from .forced import PeriodicDensity, periodic_density_xy
from .passage import Domain, FirstPassage, PassageWarning, crossing_rate, first_passage_fpk
from .solver import DEFAULT_GRID, SCHEMES, GridWarning, PhaseDensity, solve_phase_plane, stationary_density_xy
from .spectrum import Spectrum, spectrum_fpk

METHOD = "fpk"
"""Name of this method family (beside the averaging methods ``paper``, ``exact-two-impact``, ``jump``)."""

__all__ = ["ColouredDensity", "DEFAULT_GRID", "METHOD", "SCHEMES", "Domain", "FirstPassage", "GridWarning",
           "PassageWarning", "PeriodicDensity", "PhaseDensity", "Spectrum", "crossing_rate", "first_passage_fpk",
           "periodic_density_xy", "solve_phase_plane", "spectrum_fpk", "stationary_density_coloured",
           "stationary_density_xy"]
