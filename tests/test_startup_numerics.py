"""The numpy replacements that keep scipy.interpolate, scipy.special and scipy.fft off the start-up of ``vibro solve``
(issue 23) give scipy's numbers: the shape-preserving cubic of the cumulative masses, Gauss-Jacobi rules and the
DCT-II of the Chebyshev fits, each against the scipy routine it replaces, on random data (seeded)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.fft import dct
from scipy.interpolate import PchipInterpolator
from scipy.special import roots_jacobi

from averaging.phase_plane._monotone import MonotoneCubic
from averaging.quadrature import gauss_jacobi
from averaging.table import dct2
from hybrid.automaton import lambdify_numeric, real_symbol


@pytest.mark.parametrize("monotone", [True, False])
def test_monotone_cubic_is_scipys_pchip_inside_the_range(monotone):
    rng = np.random.default_rng(7 + monotone)
    for _ in range(40):
        x = np.unique(rng.uniform(0.0, 5.0, rng.integers(2, 60)))
        if len(x) < 2:
            continue
        steps = rng.exponential(size=len(x)) * (rng.uniform(size=len(x)) > 0.2)  # flat stretches included
        y = np.cumsum(steps) if monotone else rng.normal(size=len(x))
        t = np.linspace(x[0], x[-1], 501)
        ours, theirs = MonotoneCubic(x, y), PchipInterpolator(x, y)
        scale = max(1.0, float(np.abs(y).max()))
        assert np.max(np.abs(ours(t) - theirs(t))) <= 1e-12 * scale
        slope = theirs.derivative()(t)
        assert np.max(np.abs(ours.derivative()(t) - slope)) <= 1e-10 * max(1.0, float(np.abs(slope).max()))
        if monotone:
            assert np.all(np.diff(ours(t)) >= -1e-12 * scale)  # cumulative masses stay monotone: no negative bin


@pytest.mark.parametrize("n", [5, 17, 33, 65])
@pytest.mark.parametrize("beta", [0.3, 1.0, 3.2])
def test_gauss_jacobi_is_scipys_rule(n, beta):
    t, w = gauss_jacobi(n, 0.0, beta)
    t_ref, w_ref = roots_jacobi(n, 0.0, beta)
    assert np.max(np.abs(t - t_ref)) < 1e-14
    assert np.max(np.abs(w - w_ref) / w_ref) < 1e-10
    f = np.cos(3.0 * t) + t**4
    assert abs(np.sum(w * f) - np.sum(w_ref * (np.cos(3.0 * t_ref) + t_ref**4))) < 1e-13


@pytest.mark.parametrize("n", [17, 33, 129, 513])
def test_dct2_is_scipys_dct_type_2(n):
    x = np.random.default_rng(n).normal(size=(3, n))
    ref = dct(x, type=2, axis=-1)
    assert np.max(np.abs(dct2(x) - ref)) <= 1e-14 * np.max(np.abs(ref)) * np.log2(n)


def test_lambdify_numeric_takes_scipy_only_for_special_functions():
    x = real_symbol("x")
    xs = np.linspace(-2.0, 2.0, 9)
    plain = sp.sin(x) * sp.Abs(x) + sp.Piecewise((x, x > 0), (0, True))
    assert np.array_equal(lambdify_numeric([x], plain)(xs), sp.lambdify([x], plain, "numpy")(xs))
    special = sp.erf(x) + x**2
    assert np.allclose(lambdify_numeric([x], special)(xs), sp.lambdify([x], special, ["scipy", "numpy"])(xs),
                       rtol=0, atol=1e-15)
