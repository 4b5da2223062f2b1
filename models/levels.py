"""Level sets of the potential: where G(x) = H. The one root finder behind every turning point in the project."""

from __future__ import annotations

import numpy as np


def solve_level(potential, restoring, H, sign, start=0.0):
    """Solve G(sign*z) = H for z >= start (G increasing there): bracket by doubling, bisect, polish by Newton.

    Parameters
    ----------
    potential, restoring : callable
        G(x) and g(x) = G'(x), vectorised.
    H : array_like
    sign : float
        +1 for the right side, -1 for the left.
    start : float

    Returns
    -------
    z : ndarray
        The distance from 0 (converged to about 1e-15 relative).
    missing : ndarray of bool
        Levels where G does not reach H beyond ``start`` (z is then the last bracket end).

    Examples
    --------
    >>> z, missing = solve_level(lambda x: 0.5 * x * x, lambda x: x, [0.5, 2.0], +1.0)
    >>> z.round(12).tolist(), missing.tolist()
    ([1.0, 2.0], [False, False])
    """
    H = np.asarray(H, dtype=float)
    lo = np.full_like(H, start)
    hi = np.maximum(2.0 * lo, 1.0) + 0.0 * H
    G = potential
    for _ in range(80):
        short = G(sign * hi) < H
        if not short.any():
            break
        lo = np.where(short, hi, lo)
        hi = np.where(short, 2.0 * hi, hi)
    missing = G(sign * hi) < H
    # safeguarded Newton (G' = sign * g > 0 on the bracket): bisect whenever the Newton step leaves [lo, hi]
    # start from the harmonic guess sqrt(2H/k0) when it lies above the root (hardening), else from the bracket
    eps = 1e-6 * max(start, 1.0)
    k0 = float(sign * restoring(sign * eps) / eps)
    z = hi.copy()
    if k0 > 0:
        guess = np.clip(np.sqrt(2.0 * np.maximum(H, 0.0) / k0), lo, hi)
        z = np.where(G(sign * guess) >= H, guess, hi)
    for _ in range(100):
        Gz = G(sign * z)
        over = Gz > H
        lo = np.where(over, lo, z)
        hi = np.where(over, z, hi)
        gz = sign * restoring(sign * z)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = z - (Gz - H) / gz
        ok = (newton >= lo) & (newton <= hi) & np.isfinite(newton)
        znew = np.where(ok, newton, 0.5 * (lo + hi))
        done = ok & (np.abs(znew - z) <= 1e-15 * np.abs(z) + 1e-300)
        z = znew
        if done.all():
            break
    return z, missing
