"""The fused merge kernel: one pass over every bracket's code values, multi-threaded.

For each pixel and channel the kernel sums ``sum_j w(Z_j) x_j`` and ``sum_j w(Z_j)``,
where ``x_j`` is the bracket's estimate from a per-exposure lookup table (``g(z) - ln
dt_j`` in the log domain, ``f^-1(z) / dt_j`` in the linear domain). It works a row at a
time: for each bracket it streams that bracket's row of codes once through two tables
(``w(z) x_j(z)`` and ``w(z)``) into two row accumulators that stay in the core's cache,
then writes the row's result. Nothing but the output is written to memory.

Saturation (a code at ``Z_max``) drops the observation from its bracket and from every
longer one. The kernel walks the brackets longest first and *resets* a channel's sums
where it meets a saturated code: ``sum = (sum + table[z]) * (z != Z_max)``. What
survives is exactly the sum over the brackets shorter than the first saturated one, with
no per-channel state to load and store and no data-dependent branch (on this machine
1.3x faster than carrying an "alive" flag). With the tables 0 at ``Z_max`` that is
``sum * (z != Z_max) + table[z]``, a fused multiply-add, and the default policy takes
two brackets per pass over the row (half the loads and stores of the sums). The
tutorial's policy (``per_channel`` false) resets all of a pixel's channels when any one
saturates. Measured at 7 x 24 MP: 0.38 s of CPU, against 0.86 s for the previous
pixel-at-a-time kernel with its saturation flags (``hdrio`` 0.1, commit 52a476c).

A channel with no weight left takes the estimate of the longest bracket it was not
dropped from, or the shortest bracket's if it is saturated even there (a rare path that
rescans that channel's codes).

**Early stop.** Before a row is merged, the kernel finds the first bracket in which the
whole row is saturated; that bracket and every longer one would be reset away, so they
are never read (the sky rows of an outdoor scene in the long exposures, say;
``benchmarks/speed`` measures it). Stopping per 32-pixel segment instead would skip
more on the benchmark's scene (5.9 of 7 brackets read) but the short loops cost more
than they save (1.45x slower in all).

The log-domain result is left as ``ln E`` (float32, clamped to float32's range) for
:func:`exp_in_place`, NumPy's SIMD ``exp`` run on every core.

The kernel merges a band of rows per call, so that brackets staged in a temporary file
(:mod:`hdrio.io.staging`) are read, and released, a band at a time.

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
"""Brackets one merge takes (more is never a real bracket set)."""

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
FLOAT32_MAX = float(np.finfo(np.float32).max)
# ln of float32's extremes, pulled in by a little so float32 exp never rounds to 0 or inf.
LOG_FLOAT32_TINY = math.log(FLOAT32_TINY) + 1e-3
LOG_FLOAT32_MAX = math.log(FLOAT32_MAX) - 1e-3

ROWS_PER_TASK = 16
"""Rows per parallel task: small enough for the threads to share any band evenly."""



@njit(cache=True, nogil=True)
def _saturated_everywhere(row, code_max):  # pragma: no cover - compiled
    for i in range(row.size):
        if row[i] != code_max:
            return False
    return True


@njit(cache=True, nogil=True)
def _accumulate(row, weighted, weights, code_max, per_channel, channels, numerator,
                denominator):  # pragma: no cover - compiled
    """``sum = (sum + table[z]) * (z != Z_max)`` over one bracket's row."""
    if channels == 3:
        a0, a1, a2 = weighted[0], weighted[1], weighted[2]
        b0, b1, b2 = weights[0], weights[1], weights[2]
        if per_channel:
            # The tables are 0 at Z_max, so "(sum + t) * r" is "sum * r + t": one fused
            # multiply-add (1.25x faster than the product form).
            for x in range(row.size // 3):  # not range(0, row.size, 3): 1.4x slower
                i = 3 * x
                z0, z1, z2 = row[i], row[i + 1], row[i + 2]
                r0 = 1.0 * (z0 != code_max)
                r1 = 1.0 * (z1 != code_max)
                r2 = 1.0 * (z2 != code_max)
                numerator[i] = numerator[i] * r0 + a0[z0]
                denominator[i] = denominator[i] * r0 + b0[z0]
                numerator[i + 1] = numerator[i + 1] * r1 + a1[z1]
                denominator[i + 1] = denominator[i + 1] * r1 + b1[z1]
                numerator[i + 2] = numerator[i + 2] * r2 + a2[z2]
                denominator[i + 2] = denominator[i + 2] * r2 + b2[z2]
            return
        for x in range(row.size // 3):
            i = 3 * x
            z0, z1, z2 = row[i], row[i + 1], row[i + 2]
            r = 1.0 * ((z0 != code_max) & (z1 != code_max) & (z2 != code_max))
            numerator[i] = (numerator[i] + a0[z0]) * r
            denominator[i] = (denominator[i] + b0[z0]) * r
            numerator[i + 1] = (numerator[i + 1] + a1[z1]) * r
            denominator[i + 1] = (denominator[i + 1] + b1[z1]) * r
            numerator[i + 2] = (numerator[i + 2] + a2[z2]) * r
            denominator[i + 2] = (denominator[i + 2] + b2[z2]) * r
        return
    for x in range(row.size // channels):
        keep = 1.0
        if not per_channel:
            for c in range(channels):
                keep *= row[x * channels + c] != code_max
        for c in range(channels):
            i = x * channels + c
            z = row[i]
            r = keep * (z != code_max)
            numerator[i] = (numerator[i] + weighted[c, z]) * r
            denominator[i] = (denominator[i] + weights[c, z]) * r


@njit(cache=True, nogil=True)
def _accumulate_pair(longer, shorter, weighted_longer, weighted_shorter, weights, code_max,
                     numerator, denominator):  # pragma: no cover - compiled
    """Two brackets at once, per-channel policy, three channels: half the loads and
    stores of the sums that two :func:`_accumulate` calls make (1.13x faster)."""
    a0, a1, a2 = weighted_longer[0], weighted_longer[1], weighted_longer[2]
    c0, c1, c2 = weighted_shorter[0], weighted_shorter[1], weighted_shorter[2]
    b0, b1, b2 = weights[0], weights[1], weights[2]
    for x in range(longer.size // 3):
        i = 3 * x
        z0, z1, z2 = longer[i], longer[i + 1], longer[i + 2]
        y0, y1, y2 = shorter[i], shorter[i + 1], shorter[i + 2]
        r0 = 1.0 * (z0 != code_max)
        r1 = 1.0 * (z1 != code_max)
        r2 = 1.0 * (z2 != code_max)
        s0 = 1.0 * (y0 != code_max)
        s1 = 1.0 * (y1 != code_max)
        s2 = 1.0 * (y2 != code_max)
        numerator[i] = (numerator[i] * r0 + a0[z0]) * s0 + c0[y0]
        denominator[i] = (denominator[i] * r0 + b0[z0]) * s0 + b0[y0]
        numerator[i + 1] = (numerator[i + 1] * r1 + a1[z1]) * s1 + c1[y1]
        denominator[i + 1] = (denominator[i + 1] * r1 + b1[z1]) * s1 + b1[y1]
        numerator[i + 2] = (numerator[i + 2] * r2 + a2[z2]) * s2 + c2[y2]
        denominator[i + 2] = (denominator[i + 2] * r2 + b2[z2]) * s2 + b2[y2]


@njit(cache=True, nogil=True)
def _fallback(codes, y, x, c, channels, code_max, per_channel,
              estimates):  # pragma: no cover - compiled
    """The estimate of the longest bracket channel ``c`` of pixel ``x`` was not dropped
    from (the shortest bracket's if it is saturated even there)."""
    kept = 0
    while kept < codes.shape[0]:
        row = codes[kept, y]
        saturated = row[x * channels + c] == code_max
        if not per_channel:
            for k in range(channels):
                saturated |= row[x * channels + k] == code_max
        if saturated:
            break
        kept += 1
    j = kept - 1 if kept > 0 else 0
    return estimates[j, c, codes[j, y][x * channels + c]]


@njit(cache=True, nogil=True)
def _clipped_and_black(shortest, longest, code_max, channels):  # pragma: no cover - compiled
    """Pixels with a channel saturated in ``shortest``; pixels at 0 in all of ``longest``."""
    clipped = 0
    black = 0
    if channels == 3:
        for i in range(0, shortest.size, 3):
            clipped += ((shortest[i] == code_max) | (shortest[i + 1] == code_max)
                        | (shortest[i + 2] == code_max))
            black += (longest[i] == 0) & (longest[i + 1] == 0) & (longest[i + 2] == 0)
        return clipped, black
    for x in range(shortest.size // channels):
        any_saturated = False
        all_black = True
        for c in range(channels):
            any_saturated |= shortest[x * channels + c] == code_max
            all_black &= longest[x * channels + c] == 0
        clipped += any_saturated
        black += all_black
    return clipped, black


@njit(parallel=True, cache=True, nogil=True)
def merge_kernel(codes, top, bottom, weighted, estimates, weights, code_max,
                 per_channel, log_domain, early_stop, out, clipped_rows, black_rows,
                 skipped_rows):  # pragma: no cover - compiled
    """Merge rows ``top .. bottom`` of the brackets into ``out`` ``(H, W * C)`` float32.

    ``codes`` is ``(P, H, W * C)``, shortest exposure first.
    Tables, float64: ``weights[c, z]``, ``estimates[j, c, z]`` and
    ``weighted[j, c, z] = weights[c, z] * estimates[j, c, z]``, both weight tables 0 at
    ``z = code_max`` (a saturated observation never counts). Writes ``ln E`` in the
    log domain (see :func:`exp_in_place`), ``E`` in the linear domain. ``early_stop``
    false reads every bracket of every row (the same result). Per row, for the
    statistics: ``clipped_rows`` (pixels with a channel saturated in the shortest
    bracket), ``black_rows`` (pixels at code 0 in every channel of the longest) and
    ``skipped_rows`` (pixel-brackets the early stop never read).
    """
    count = codes.shape[0]
    channels = weights.shape[0]
    n = out.shape[1]
    low = LOG_FLOAT32_TINY if log_domain else FLOAT32_TINY
    high = LOG_FLOAT32_MAX if log_domain else FLOAT32_MAX
    tasks = (bottom - top + ROWS_PER_TASK - 1) // ROWS_PER_TASK
    for task in prange(tasks):
        numerator = np.empty(n)
        denominator = np.empty(n)
        for y in range(top + task * ROWS_PER_TASK,
                       min(bottom, top + (task + 1) * ROWS_PER_TASK)):
            # Early stop: the first bracket saturated across the whole row, and every
            # longer one, would be reset away; start below it.
            stop = count
            for j in range(1, count if early_stop else 1):
                if _saturated_everywhere(codes[j, y], code_max):
                    stop = j
                    break
            numerator[:] = 0.0
            denominator[:] = 0.0
            j = stop - 1
            if per_channel and channels == 3:
                while j >= 1:
                    _accumulate_pair(codes[j, y], codes[j - 1, y], weighted[j],
                                     weighted[j - 1], weights, code_max, numerator,
                                     denominator)
                    j -= 2
            while j >= 0:
                _accumulate(codes[j, y], weighted[j], weights, code_max, per_channel,
                            channels, numerator, denominator)
                j -= 1
            row = out[y]
            empty = False
            for i in range(n):
                d = denominator[i]
                empty |= d <= 0.0
                value = numerator[i] / d if d > 0.0 else 0.0
                row[i] = min(max(value, low), high)
            if empty:
                for i in range(n):
                    if denominator[i] <= 0.0:
                        value = _fallback(codes, y, i // channels, i % channels,
                                          channels, code_max, per_channel,
                                          estimates)
                        row[i] = min(max(value, low), high)
            skipped_rows[y] = (count - stop) * (n // channels)
            clipped_rows[y], black_rows[y] = _clipped_and_black(
                codes[0, y],
                codes[count - 1, y], code_max, channels)


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
