"""Counter-based normals for the CUDA kernels: Philox-4x32-10 (Salmon et al. 2011) and Box-Muller.

A step's normal is a pure function of (key, path index, step index): the key is two 32-bit words from
``numpy.random.SeedSequence(seed)``, the counter is (step // 2 as 64 bits, global path index as 64 bits), and one
Philox call gives 128 bits, i.e. two uniforms and by Box-Muller the normals of steps 2j and 2j + 1. Nothing depends
on the block size, the grid or where a launch starts, which is what makes CUDA runs reproducible across launch
configurations and across a checkpoint and resume.

Words are held in uint64 variables (values below 2**32) so that the 32 x 32 -> 64 bit products of Philox are plain
uint64 multiplications, identical under numba-cuda and under its simulator (numpy scalars). The host functions
here are plain Python (the tests check them against known-answer vectors); :func:`device_normal_pair` compiles the
same Philox and Box-Muller code for the device, except Box-Muller's angle: libdevice's ``sincospi(2u)`` on the
device, sin and cos of 2 pi u on the host and the simulator, which agree to rounding.
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


def round_keys(k0, k1) -> tuple:
    """The ten round keys of Philox-4x32-10 under the key (k0, k1), flat: (k0, k1, k0 + W0, k1 + W1, ...) mod 2**32.

    The device kernel takes them as launch arguments, which the GPU reads from its constant bank: computed in the
    kernel, they were hoisted out of the step loop and held 20 registers (or spilled, under a register cap).
    """
    out = []
    for _ in range(10):  # uint32, so that the device knows their upper words are zero
        out += [np.uint32(k0), np.uint32(k1)]
        k0, k1 = (k0 + _W0) & _MASK, (k1 + _W1) & _MASK
    return tuple(out)


def _make_philox(rnd, rounds: int = 10):
    """Philox-4x32 of ``rounds`` rounds (10, the generator's; 7 for benchmarks/gpu_ceiling.py's price of fewer)."""
    if rounds not in (7, 10):
        raise ValueError(f"Philox-4x32 with {rounds} rounds: 7 or 10")

    def philox4x32(c0, c1, c2, c3, rk):
        # the rounds written out (a loop was not unrolled by NVVM); rk: round_keys(k0, k1). ``rounds`` is a constant
        # of the closure, so numba drops the branch it does not take
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[0], rk[1])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[2], rk[3])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[4], rk[5])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[6], rk[7])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[8], rk[9])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[10], rk[11])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[12], rk[13])
        if rounds == 7:
            return c0, c1, c2, c3
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[14], rk[15])
        c0, c1, c2, c3 = rnd(c0, c1, c2, c3, rk[16], rk[17])
        return rnd(c0, c1, c2, c3, rk[18], rk[19])

    return philox4x32


_philox_keyed = _make_philox(_philox_round)


def philox4x32_10(c0, c1, c2, c3, k0, k1):
    """Philox-4x32-10 of the counter (c0, c1, c2, c3) under the key (k0, k1), words below 2**32.

    Examples
    --------
    >>> z = np.uint64(0)
    >>> [hex(int(w)) for w in philox4x32_10(z, z, z, z, z, z)]  # Random123 known-answer vector
    ['0x6627e8d5', '0xe169c58d', '0xbc57ac4c', '0x9b00dbd8']
    """
    return _philox_keyed(c0, c1, c2, c3, round_keys(k0, k1))


def _sincos_2pi(u):
    # sin and cos of 2 pi u on the host (and on the simulator, which has no libdevice)
    t = _TWO_PI * u
    return math.sin(t), math.cos(t)


def _sincos_2pi_f32(u):
    t = _TWO_PI_F * u
    return math.sin(t), math.cos(t)


def _make_normal_pair(philox, single: bool, sincos, f32_transform: bool = False):
    """Box-Muller on one Philox call, written once for the host (tests) and the device (``philox`` jitted);
    ``sincos(u)``: sin and cos of 2 pi u.

    ``f32_transform`` (double precision only, for benchmarks/gpu_ceiling.py's price of it): the same 53-bit
    uniforms, the logarithm, square root and ``sincos`` (a float32 one) in single precision, the normals returned
    as doubles. A constant of the closure: numba drops the branch not taken.
    """
    if single:
        def normal_pair(rk, path, pair):
            pr = np.uint64(pair)
            pa = np.uint64(path)
            a, b, c, d = philox(pr & _MASK, pr >> _S32, pa & _MASK, pa >> _S32, rk)
            u1 = np.float32(a + _S1) * _U32F
            u2 = np.float32(c) * _U32F
            r = math.sqrt(_M2_F * math.log(u1))
            s, co = sincos(u2)
            return r * co, r * s
    else:
        def normal_pair(rk, path, pair):
            pr = np.uint64(pair)
            pa = np.uint64(path)
            a, b, c, d = philox(pr & _MASK, pr >> _S32, pa & _MASK, pa >> _S32, rk)
            u1 = np.float64((a >> _S5) * _T26 + (b >> _S6) + _S1) * _U53
            u2 = np.float64((c >> _S5) * _T26 + (d >> _S6)) * _U53
            if f32_transform:
                r32 = math.sqrt(_M2_F * math.log(np.float32(u1)))
                s32, co32 = sincos(np.float32(u2))
                return np.float64(r32 * co32), np.float64(r32 * s32)
            r = math.sqrt(-2.0 * math.log(u1))
            s, co = sincos(u2)
            return r * co, r * s
    return normal_pair


_normal_pair_f64 = _make_normal_pair(_philox_keyed, False, _sincos_2pi)
_normal_pair_f32 = _make_normal_pair(_philox_keyed, True, _sincos_2pi_f32)


def normal_pair_f64(k0, k1, path, pair):
    """The two standard normals (double) of steps ``2 * pair`` and ``2 * pair + 1`` of a path.

    Uniforms have 53 bits; the first lies in (0, 1] so that the logarithm is finite (largest |z| about 8.6).

    Examples
    --------
    >>> z0, z1 = normal_pair_f64(np.uint64(1), np.uint64(2), 0, 0)
    >>> bool(abs(z0) < 9 and abs(z1) < 9)
    True
    """
    return _normal_pair_f64(round_keys(k0, k1), path, pair)


def normal_pair_f32(k0, k1, path, pair):
    """As :func:`normal_pair_f64` in single precision: 32-bit uniforms (largest |z| about 6.7).

    Examples
    --------
    >>> z0, z1 = normal_pair_f32(np.uint64(1), np.uint64(2), 0, 0)
    >>> bool(abs(z0) < 7 and abs(z1) < 7)
    True
    """
    return _normal_pair_f32(round_keys(k0, k1), path, pair)


def seed_key(seed: int) -> tuple[np.uint64, np.uint64]:
    """The Philox key of a seed: two 32-bit words of ``SeedSequence(seed)`` (as uint64).

    Examples
    --------
    >>> [int(w) < 2**32 for w in seed_key(1)]
    [True, True]
    """
    words = np.random.SeedSequence(int(seed)).generate_state(2, np.uint32)
    return np.uint64(words[0]), np.uint64(words[1])


_DEVICE: dict = {}


def device_normal_pair(precision: str):
    """The CUDA device function ``normal_pair(rk, path, pair)`` (``rk``: :func:`round_keys`) for ``precision``
    ('f64' or 'f32'); on numba's simulator the plain Python function, the host's.

    Built on first use, so that importing this module (doctests, CI without numba-cuda) needs no ``numba.cuda``.
    """
    if precision not in _DEVICE:
        from numba.core import config

        single = precision == "f32"
        if config.ENABLE_CUDASIM:
            # no libdevice there: the host's own functions. Plain Python, not device functions: the simulator
            # takes two locks at every device function's call, and 32 threads contending for them at each Philox
            # round sometimes crawled (a run of 1 s took up to 150 s)
            _DEVICE[precision] = _normal_pair_f32 if single else _normal_pair_f64
            return _DEVICE[precision]
        from numba import cuda
        from numba.cuda import libdevice

        device = cuda.jit(device=True, inline=True)
        rnd = device(_philox_round)
        philox = device(_make_philox(rnd))
        # sincospi: no range reduction of 2 pi u, both values at once (the same to rounding as the host's)
        sincospi = libdevice.sincospif if single else libdevice.sincospi
        two = np.float32(2.0) if single else 2.0

        def sincos_2pi(u):
            return sincospi(two * u)

        sincos = device(sincos_2pi)
        _DEVICE[precision] = device(_make_normal_pair(philox, single, sincos))
    return _DEVICE[precision]
