"""Counter-based normals for the CUDA kernels: Philox-4x32-10 (Salmon et al. 2011) and Box-Muller.

A step's normal is a pure function of (key, path index, step index): the key is two 32-bit words from
``numpy.random.SeedSequence(seed)``, the counter is (step // 2 as 64 bits, global path index as 64 bits), and one
Philox call gives 128 bits, i.e. two uniforms and by Box-Muller the normals of steps 2j and 2j + 1. Nothing depends
on the block size, the grid or where a launch starts, which is what makes CUDA runs reproducible across launch
configurations and across a checkpoint and resume.

Words are held in uint64 variables (values below 2**32) so that the 32 x 32 -> 64 bit products of Philox are plain
uint64 multiplications, identical under numba-cuda and under its simulator (numpy scalars); on a GPU the high
words come from the 32-bit multiply-high instead (:func:`_make_round_hi32`), the same words in fewer instructions.
The host functions here are plain Python (the tests check them against known-answer vectors);
:func:`device_normal_pair` compiles the very same code for the device.
"""

from __future__ import annotations

import math

import numpy as np

_M0 = np.uint64(0xD2511F53)
_M1 = np.uint64(0xCD9E8D57)
_W0 = np.uint64(0x9E3779B9)
_W1 = np.uint64(0xBB67AE85)
_MASK = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_S5 = np.uint64(5)
_S6 = np.uint64(6)
_S1 = np.uint64(1)
_T26 = np.uint64(67108864)  # 2**26
_U53 = 1.0 / 9007199254740992.0  # 2**-53
_U32F = np.float32(2.3283064365386963e-10)  # 2**-32
_TWO_PI = 6.283185307179586
_TWO_PI_F = np.float32(6.283185307179586)
_M2_F = np.float32(-2.0)


def _philox_round(c0, c1, c2, c3, k0, k1):
    # words < 2**32 in uint64: the product is exact (NVVM emits mul.lo.u64; libdevice's umulhi has no simulator)
    p0 = _M0 * c0
    p1 = _M1 * c2
    return (p1 >> _S32) ^ c1 ^ k0, p1 & _MASK, (p0 >> _S32) ^ c3 ^ k1, p0 & _MASK


def _make_philox(rnd):
    def philox4x32_10(c0, c1, c2, c3, k0, k1):
        # ten rounds written out (a loop was not unrolled by NVVM), the key bumped between rounds
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, k0, k1)
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
        return rnd(c0, c1, c2, c3, k0, k1)

    return philox4x32_10


philox4x32_10 = _make_philox(_philox_round)
philox4x32_10.__doc__ = """Philox-4x32-10 of the counter (c0, c1, c2, c3) under the key (k0, k1), words below 2**32.

Examples
--------
>>> z = np.uint64(0)
>>> [hex(int(w)) for w in philox4x32_10(z, z, z, z, z, z)]  # Random123 known-answer vector
['0x6627e8d5', '0xe169c58d', '0xbc57ac4c', '0x9b00dbd8']
"""


def _make_normal_pair(philox, single: bool):
    """Box-Muller on one Philox call, written once for the host (tests) and the device (``philox`` jitted)."""
    if single:
        def normal_pair(k0, k1, path, pair):
            pr = np.uint64(pair)
            pa = np.uint64(path)
            a, b, c, d = philox(pr & _MASK, pr >> _S32, pa & _MASK, pa >> _S32, k0, k1)
            u1 = np.float32(a + _S1) * _U32F
            u2 = np.float32(c) * _U32F
            r = math.sqrt(_M2_F * math.log(u1))
            t = _TWO_PI_F * u2
            return r * math.cos(t), r * math.sin(t)
    else:
        def normal_pair(k0, k1, path, pair):
            pr = np.uint64(pair)
            pa = np.uint64(path)
            a, b, c, d = philox(pr & _MASK, pr >> _S32, pa & _MASK, pa >> _S32, k0, k1)
            u1 = np.float64((a >> _S5) * _T26 + (b >> _S6) + _S1) * _U53
            u2 = np.float64((c >> _S5) * _T26 + (d >> _S6)) * _U53
            r = math.sqrt(-2.0 * math.log(u1))
            t = _TWO_PI * u2
            return r * math.cos(t), r * math.sin(t)
    return normal_pair


normal_pair_f64 = _make_normal_pair(philox4x32_10, single=False)
normal_pair_f64.__doc__ = """The two standard normals (double) of steps ``2 * pair`` and ``2 * pair + 1`` of a path.

Uniforms have 53 bits; the first lies in (0, 1] so that the logarithm is finite (largest |z| about 8.6).

Examples
--------
>>> z0, z1 = normal_pair_f64(np.uint64(1), np.uint64(2), 0, 0)
>>> bool(abs(z0) < 9 and abs(z1) < 9)
True
"""

normal_pair_f32 = _make_normal_pair(philox4x32_10, single=True)
normal_pair_f32.__doc__ = """As :func:`normal_pair_f64` in single precision: 32-bit uniforms (largest |z| about 6.7).

Examples
--------
>>> z0, z1 = normal_pair_f32(np.uint64(1), np.uint64(2), 0, 0)
>>> bool(abs(z0) < 7 and abs(z1) < 7)
True
"""


def seed_key(seed: int) -> tuple[np.uint64, np.uint64]:
    """The Philox key of a seed: two 32-bit words of ``SeedSequence(seed)`` (as uint64).

    Examples
    --------
    >>> [int(w) < 2**32 for w in seed_key(1)]
    [True, True]
    """
    words = np.random.SeedSequence(int(seed)).generate_state(2, np.uint32)
    return np.uint64(words[0]), np.uint64(words[1])


def _signed32(word: int) -> np.int32:
    """The 32-bit word as numba-cuda's int32 (libdevice's ``umulhi`` is typed int32; the bits are what count)."""
    return np.array(word, dtype=np.uint32).view(np.int32)[()]


_M0_I32 = _signed32(0xD2511F53)
_M1_I32 = _signed32(0xCD9E8D57)


def _make_round_hi32(umulhi):
    """A Philox round whose high product words come from the device's 32 x 32 multiply-high (``umulhi``) instead
    of a 64-bit product: the same words, fewer instructions. The simulator has no ``umulhi``, so it keeps
    :func:`_philox_round`; a GPU run checks the two against each other through the host's normals (the tests feed
    the CPU kernel the host's Philox normals and find the GPU's paths)."""
    def philox_round_hi32(c0, c1, c2, c3, k0, k1):
        h0 = np.uint64(umulhi(_M0_I32, np.int32(c0))) & _MASK
        h1 = np.uint64(umulhi(_M1_I32, np.int32(c2))) & _MASK
        return h1 ^ c1 ^ k0, (_M1 * c2) & _MASK, h0 ^ c3 ^ k1, (_M0 * c0) & _MASK

    return philox_round_hi32


PHILOX_PRODUCTS = ("hi32", "u64")
"""How the device forms Philox's 32 x 32 -> 64 bit products: ``hi32`` (multiply-high, the default on a GPU) or
``u64`` (a 64-bit multiplication; the simulator's)."""

_DEVICE: dict = {}


def device_normal_pair(precision: str, products: str = "u64"):
    """The CUDA device function ``normal_pair(k0, k1, path, pair)`` for ``precision`` ('f64' or 'f32'), its Philox
    products formed as ``products`` says (:data:`PHILOX_PRODUCTS`; the same words either way).

    Built on first use, so that importing this module (doctests, CI without numba-cuda) needs no ``numba.cuda``.
    """
    if products not in PHILOX_PRODUCTS:
        raise ValueError(f"products={products!r}; choose one of {PHILOX_PRODUCTS}")
    if (precision, products) not in _DEVICE:
        from numba import cuda

        if products == "hi32":
            from numba.cuda import libdevice

            rnd = cuda.jit(device=True, inline=True)(_make_round_hi32(libdevice.umulhi))
        else:
            rnd = cuda.jit(device=True, inline=True)(_philox_round)
        philox = cuda.jit(device=True, inline=True)(_make_philox(rnd))
        _DEVICE[precision, products] = cuda.jit(device=True, inline=True)(_make_normal_pair(philox,
                                                                                           precision == "f32"))
    return _DEVICE[precision, products]
