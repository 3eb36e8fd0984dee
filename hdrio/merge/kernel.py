"""The fused merge kernel: one pass over every bracket's code values, multi-threaded.

For each pixel and channel the kernel walks the brackets (shortest exposure first) and
accumulates ``sum_j w(Z_j) x_j`` and ``sum_j w(Z_j)`` in registers, where ``x_j`` is the
bracket's estimate from a per-exposure lookup table (``g(z) - ln dt_j`` in the log domain,
``f^-1(z) / dt_j`` in the linear domain). Nothing but the output is written, so the
memory traffic is one read of the codes and one write of the result (see
``benchmarks/speed``). The inner loop has no data-dependent branch: saturation is an
integer flag that zeroes the rest of a channel's terms.

Saturation (a code at ``Z_max``) drops the observation from its bracket and from every
longer one, either for the whole pixel when any channel saturates (``per_channel``
false, the tutorial's policy) or for that channel alone. A channel with no weight left
takes the estimate of the longest bracket it was not dropped from, or the shortest
bracket's if it is saturated even there.

The log-domain result is left as ``ln E`` (float32, clamped to float32's range) for
:func:`exp_in_place`, NumPy's SIMD ``exp`` run on every core.

Compiled by numba on first use and cached on disk beside this module (or in
``NUMBA_CACHE_DIR``); the first call in a new environment pays the compile, which
``benchmarks/speed`` reports, and later processes load the cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from hdrio.parallel import on_threads

MAX_BRACKETS = 64
"""The kernel records which brackets a pixel used as bits of one 64-bit word."""

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
FLOAT32_MAX = float(np.finfo(np.float32).max)
# ln of float32's extremes, pulled in by a little so float32 exp never rounds to 0 or inf.
LOG_FLOAT32_TINY = math.log(FLOAT32_TINY) + 1e-3
LOG_FLOAT32_MAX = math.log(FLOAT32_MAX) - 1e-3


@njit(parallel=True, cache=True, nogil=True)
def merge_kernel(codes, weighted, estimates, weights, code_max, per_channel, log_domain,
                 out, used_rows, clipped_rows, black_rows):  # pragma: no cover - compiled
    """Merge ``codes`` ``(P, H, W, C)`` into ``out`` ``(H, W, C)`` float32.

    Tables, channel first: ``weights[c, z]``, ``estimates[c, j, z]`` and
    ``weighted[c, j, z] = weights[c, z] * estimates[c, j, z]`` (float64). Writes ``ln E``
    in the log domain (see :func:`exp_in_place`), ``E`` in the linear domain. Per-row
    counts for the statistics go to ``used_rows (H, P)``, ``clipped_rows (H,)`` (a channel
    saturated in the shortest bracket) and ``black_rows (H,)`` (code 0 in every channel
    of the longest bracket).
    """
    count, height, width, channels = codes.shape
    low = LOG_FLOAT32_TINY if log_domain else FLOAT32_TINY
    high = LOG_FLOAT32_MAX if log_domain else FLOAT32_MAX
    for y in prange(height):
        for x in range(width):
            # Under the tutorial's policy, the first bracket any channel saturates in.
            limit = count
            if not per_channel:
                for c in range(channels):
                    for j in range(limit):
                        if codes[j, y, x, c] == code_max:
                            limit = j
                            break
            used = np.uint64(0)
            clipped = False
            black = True
            for c in range(channels):
                numerator = 0.0
                denominator = 0.0
                alive = 1
                kept = 0
                for j in range(limit):
                    z = codes[j, y, x, c]
                    alive *= z != code_max
                    numerator += alive * weighted[c, j, z]
                    w = alive * weights[c, z]
                    denominator += w
                    used |= np.uint64(w > 0.0) << np.uint64(j)
                    kept += alive
                clipped |= codes[0, y, x, c] == code_max
                black &= codes[count - 1, y, x, c] == 0
                if denominator > 0.0:
                    value = numerator / denominator
                else:
                    j = kept - 1 if kept > 0 else 0
                    value = estimates[c, j, codes[j, y, x, c]]
                out[y, x, c] = min(max(value, low), high)
            for j in range(count):
                used_rows[y, j] += (used >> np.uint64(j)) & np.uint64(1)
            clipped_rows[y] += clipped
            black_rows[y] += black


EXP_BLOCK = 1 << 20
"""Values per task of :func:`exp_in_place` (4 MB of float32)."""


def exp_in_place(values: np.ndarray) -> None:
    """``values = exp(values)`` for float32 ``values``, in blocks on every core.

    NumPy's float32 ``exp`` is vectorised (SIMD) and releases the GIL, so blocks run at
    once on :func:`hdrio.parallel.on_threads`; numba's would be a scalar libm call per
    value.
    """
    flat = values.reshape(-1)

    def blocks(first: int, last: int) -> None:
        part = flat[first * EXP_BLOCK: last * EXP_BLOCK]
        np.exp(part, out=part)

    on_threads(blocks, -(-flat.size // EXP_BLOCK))
