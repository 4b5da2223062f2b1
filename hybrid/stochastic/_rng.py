"""In-kernel random numbers: xoshiro256** (uint64) and ziggurat normals, one stream per chunk.

Each chunk of paths owns one xoshiro256** stream whose 256-bit state comes from
``numpy.random.SeedSequence(seed).spawn(n_chunks)[k].generate_state(4, numpy.uint64)``. The generator state is kept
in four local integers (functions take and return it) so that numba keeps it in registers.

Normals use a 256-layer ziggurat (Marsaglia & Tsang 2000): one 64-bit draw gives the layer (bits 0-7), the sign
(bit 8) and a 53-bit uniform (bits 11-63); about 99 % of draws are accepted by a single compare and multiply.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy import optimize, special

from hybrid.errors import ParameterError

_U53 = 1.0 / 9007199254740992.0  # 2**-53
_LAYERS = 256
# the shift amounts and masks as uint64 constants of the module: numba freezes them, where each ``np.uint64(k)``
# inside the inlined generator was a call to type in every kernel (76 of them, about 0.3 s of each cold compile)
_U1, _U5, _U7, _U8, _U9, _U11, _U17, _U19, _U45, _U57, _U255 = (
    np.uint64(k) for k in (1, 5, 7, 8, 9, 11, 17, 19, 45, 57, 255))


@nb.njit(inline="always")
def _rotl(v, left, right):
    # rotate left by ``left`` bits (``right`` = 64 - left)
    return (v << left) | (v >> right)


@nb.njit(inline="always")
def next_u64(s0, s1, s2, s3):
    """One xoshiro256** output and the new state: ``(out, s0, s1, s2, s3)``.

    Examples
    --------
    >>> import numpy as np
    >>> s = [np.uint64(v) for v in (1, 2, 3, 4)]
    >>> int(next_u64(*s)[0])
    11520
    """
    out = _rotl(s1 * _U5, _U7, _U57) * _U9
    t = s1 << _U17
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, _U45, _U19)
    return out, s0, s1, s2, s3


@nb.njit(inline="always")
def next_uniform(s0, s1, s2, s3):
    """A uniform double in (0, 1] (never 0, so that ``log`` is safe) and the new state.

    Examples
    --------
    >>> import numpy as np
    >>> u = next_uniform(*[np.uint64(v) for v in (1, 2, 3, 4)])[0]
    >>> 0.0 < u <= 1.0
    True
    """
    b, s0, s1, s2, s3 = next_u64(s0, s1, s2, s3)
    return ((b >> _U11) + _U1) * _U53, s0, s1, s2, s3


@nb.njit(inline="always")
def next_normal(s0, s1, s2, s3, zx, zk, zf):
    """A standard normal by the ziggurat method and the new state: ``(z, s0, s1, s2, s3)``.

    ``zx, zk, zf`` are the tables from :func:`ziggurat_tables` (layer edges, accept ratios, densities).

    Examples
    --------
    >>> import numpy as np
    >>> zx, zk, zf = ziggurat_tables()
    >>> z = next_normal(*[np.uint64(v) for v in (1, 2, 3, 4)], zx, zk, zf)[0]
    >>> bool(abs(z) < 10)
    True
    """
    while True:
        b, s0, s1, s2, s3 = next_u64(s0, s1, s2, s3)
        i = np.int64(b & _U255)
        neg = (b >> _U8) & _U1
        u = (b >> _U11) * _U53
        z = u * zx[i]
        if u < zk[i]:  # inside the rectangle: about 99 % of draws
            return (-z if neg else z), s0, s1, s2, s3
        if i == 0:  # base layer beyond r: sample the tail (Marsaglia 1964)
            r = zx[1]
            while True:
                u1, s0, s1, s2, s3 = next_uniform(s0, s1, s2, s3)
                u2, s0, s1, s2, s3 = next_uniform(s0, s1, s2, s3)
                a = -math.log(u1) / r
                c = -math.log(u2)
                if c + c > a * a:
                    z = r + a
                    return (-z if neg else z), s0, s1, s2, s3
        u2, s0, s1, s2, s3 = next_uniform(s0, s1, s2, s3)
        if zf[i] + u2 * (zf[i + 1] - zf[i]) < math.exp(-0.5 * z * z):  # wedge
            return (-z if neg else z), s0, s1, s2, s3


def _layers(r: float) -> tuple[np.ndarray, float]:
    f = lambda t: math.exp(-0.5 * t * t)  # noqa: E731
    v = r * f(r) + math.sqrt(math.pi / 2) * special.erfc(r / math.sqrt(2))
    x = np.empty(_LAYERS + 1)
    x[0] = v / f(r)
    x[1] = r
    for i in range(1, _LAYERS - 1):
        arg = v / x[i] + f(x[i]) if x[i] > 0.0 else 1.0  # a trial r too small ends the chain early
        x[i + 1] = math.sqrt(-2.0 * math.log(arg)) if arg < 1.0 else 0.0
    x[_LAYERS] = 0.0
    return x, v


def ziggurat_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tables of the 256-layer ziggurat: edges ``x`` (257), accept ratios ``x[i+1]/x[i]``, densities ``f(x)``.

    The base-layer abscissa r is solved so that the top layer has exactly the common area v (no bias from a
    rounded r).

    Examples
    --------
    >>> zx, zk, zf = ziggurat_tables()
    >>> round(float(zx[1]), 6), zx.shape
    (3.654153, (257,))
    """
    if _TABLES:
        return _TABLES[0]

    def top_mismatch(r):
        x, v = _layers(r)
        return x[_LAYERS - 1] * (1.0 - math.exp(-0.5 * x[_LAYERS - 1] ** 2)) - v

    r = optimize.brentq(top_mismatch, 3.6, 3.7, xtol=1e-15, rtol=1e-15)
    x, _ = _layers(r)
    k = np.empty(_LAYERS)
    k[:] = x[1:] / x[:-1]
    f = np.exp(-0.5 * x * x)
    tables = (x, k, f)
    for t in tables:
        t.setflags(write=False)
    _TABLES.append(tables)
    return tables


_TABLES: list = []


def chunk_states(seed: int, n_chunks: int) -> np.ndarray:
    """The (n_chunks, 4) uint64 xoshiro states of every chunk, from ``SeedSequence(seed).spawn(n_chunks)``.

    Examples
    --------
    >>> chunk_states(1, 3).shape
    (3, 4)
    """
    # SeedSequence(None) would draw OS entropy: refuse it, randomness comes only from explicit seeds
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"seed={seed!r} must be a non-negative integer (randomness only from explicit seeds)")
    children = np.random.SeedSequence(seed).spawn(n_chunks)
    out = np.empty((n_chunks, 4), dtype=np.uint64)
    for k, child in enumerate(children):
        st = child.generate_state(4, np.uint64)
        if not st.any():  # the all-zero state is the one fixed point of xoshiro
            st[0] = np.uint64(0x9E3779B97F4A7C15)
        out[k] = st
    return out


@nb.njit(cache=True)
def normals(state, n, zx, zk, zf):
    """``n`` standard normals from a 4-word state (updated in place); for tests and diagnostics.

    Examples
    --------
    >>> zx, zk, zf = ziggurat_tables()
    >>> z = normals(chunk_states(1, 1)[0], 1000, zx, zk, zf)
    >>> bool(abs(z.mean()) < 0.2)
    True
    """
    s0, s1, s2, s3 = state[0], state[1], state[2], state[3]
    out = np.empty(n)
    for j in range(n):
        z, s0, s1, s2, s3 = next_normal(s0, s1, s2, s3, zx, zk, zf)
        out[j] = z
    state[0], state[1], state[2], state[3] = s0, s1, s2, s3
    return out
