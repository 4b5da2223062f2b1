"""Two plain CUDA kernels over a device run's per-path rows: their start values, and their sums per chunk.

A run of 2**20 paths keeps about 250 MB of per-path rows on the device (the state, counters, event statistics).
Filled on the host and copied there and back, they cost an H100 run of Example 1 0.22 s, as long as its 20,000
steps took (benchmarks/data/gpu_h100_fixed_cost.txt). Here the rows start on the device, and only their sums per
chunk come back: each thread adds the rows of one chunk in path order, so the sums do not depend on the launch.

Imported only by :mod:`hybrid.stochastic._auto_cuda` once numba-cuda is known to be there. Module-level kernels, so
that numba's simulator, which swaps the name ``cuda`` in a kernel's globals, runs them too.
"""

from __future__ import annotations

import math

from numba import cuda


@cuda.jit(cache=True)
def init_rows(x0, mode0, fw_gstat, n_trans, XS, MS, CNT, SM, PSM, IWS, FWS, elogs):
    """Rows of paths at t = 0, one thread per path: state ``x0``, mode ``mode0``, zero counters and sums, NaN event
    logs, and the guard statistics' extremes empty (+inf, -inf)."""
    ip = cuda.grid(1)
    if ip >= XS.shape[0]:
        return
    for i in range(XS.shape[1]):
        XS[ip, i] = x0[i]
    MS[ip] = mode0
    for i in range(CNT.shape[1]):
        CNT[ip, i] = 0
    for i in range(SM.shape[1]):
        SM[ip, i] = 0.0
    for k in range(PSM.shape[1]):
        for i in range(PSM.shape[2]):
            PSM[ip, k, i] = 0.0
    for i in range(IWS.shape[1]):
        IWS[ip, i] = 0
    for i in range(FWS.shape[1]):
        FWS[ip, i] = 0.0
    for j in range(n_trans):
        FWS[ip, fw_gstat + 4 * j + 2] = math.inf
        FWS[ip, fw_gstat + 4 * j + 3] = -math.inf
    for k in range(elogs.shape[1]):
        for i in range(3):
            elogs[ip, k, i] = math.nan


@cuda.jit(cache=True)
def reduce_chunks(cp, iw_events, fw_gstat, fw_fbad, n_trans, CNT, SM, PSM, IWS, FWS, counts, sums, psums, events,
                  vsum, gstat, fbad):
    """The runner's per-chunk rows from the per-path ones, one thread per chunk of ``cp`` paths, in path order.

    ``counts`` adds the event code's own counters (``IWS`` columns 1 and 5: steps over the event cap, failed
    checks); ``fbad`` is the speed at the first failed check of the chunk's first path that has one (0 if none).
    """
    c = cuda.grid(1)
    if c >= counts.shape[0]:
        return
    p0 = c * cp
    p1 = min(p0 + cp, CNT.shape[0])
    for k in range(CNT.shape[1]):
        n = 0
        for p in range(p0, p1):
            n += CNT[p, k]
            if k == 1 or k == 5:
                n += IWS[p, k]
        counts[c, k] = n
    for o in range(SM.shape[1]):
        s = 0.0
        for p in range(p0, p1):
            s += SM[p, o]
        sums[c, o] = s
    for kp in range(PSM.shape[1]):
        for o in range(PSM.shape[2]):
            s = 0.0
            for p in range(p0, p1):
                s += PSM[p, kp, o]
            psums[c, kp, o] = s
    for j in range(n_trans):
        g = fw_gstat + 4 * j
        n = 0
        v = 0.0
        s0 = 0.0
        s1 = 0.0
        lo = math.inf
        hi = -math.inf
        for p in range(p0, p1):
            n += IWS[p, iw_events + j]
            v += FWS[p, j]
            s0 += FWS[p, g]
            s1 += FWS[p, g + 1]
            lo = min(lo, FWS[p, g + 2])
            hi = max(hi, FWS[p, g + 3])
        events[c, j] = n
        vsum[c, j] = v
        gstat[c, j, 0] = s0
        gstat[c, j, 1] = s1
        gstat[c, j, 2] = lo
        gstat[c, j, 3] = hi
    first = 0.0
    for p in range(p0, p1):
        if IWS[p, 5] != 0:
            first = FWS[p, fw_fbad]
            break
    fbad[c, 0] = first
