"""The fused merge kernel: one pass over every bracket's code values, multi-threaded.

For each pixel and channel the kernel sums ``sum_j w(Z_j) x_j`` and ``sum_j w(Z_j)``,
where ``x_j`` is the bracket's estimate from a per-exposure lookup table (``g(z) - ln
dt_j`` in the log domain, ``f^-1(z) / dt_j`` in the linear domain). It works a row at a
time: it streams each bracket's row of codes once through lookup tables into a row of
sums that stays in the core's cache, then writes the row's result (exponentiated there
in the log domain). Nothing but the output is written to memory. Why it is shaped so,
and what each choice measured against the others, is in docs/speed.md ("How the merge
is fast").

The two sums of a value travel together as one complex64, ``numerator + i
denominator``, and so do the tables' terms ``w(z) x_j(z) + i w(z)``.

Saturation (a code at or above its channel's *limit*: ``Z_max``, or lower where
:mod:`hdrio.merge.saturation` found the white level, less the noise margin, below it) drops the
observation from its bracket and from every longer one. The kernel walks the brackets
longest first and *resets* a channel's sums where it meets a dropped code: ``sum = (sum
+ term[z]) * (z < limit)``. What survives is exactly the sum over the brackets shorter
than the first dropped one, with no per-channel state and no data-dependent branch. With
the terms 0 from the limit up that is ``sum * (z < limit) + term[z]``, a fused
multiply-add.

**Whole observations** (the pixel rule: any dropped channel drops the whole observation,
the tutorial's ``pixel`` and the ``safe`` policy; the clip test of ``auto``, which drops
a partly clipped observation whole where its other channels disagree with the next
shorter bracket's, :mod:`hdrio.radiometry.cliptest`) are dropped by remapping each bracket's
row before it is summed, into a per-task buffer: every code of such an observation
becomes ``Z_max``. The per-channel resets then apply it, through the same pair tables
(the tutorial's per-pixel policy used to take one look-up per code instead).

**Pair tables** (8-bit codes, three channels: the common case; :mod:`hdrio.merge.row_sums`).
Two brackets ``j`` (longer) and ``j - 1`` are looked up together: one table per pair and
channel indexed by both codes, ``z_j * 256 + z_{j-1}``, holds the pair's summed terms
already (``T = t_j(z_j) s(z_{j-1}) + t_{j-1}(z_{j-1})``, with ``s`` the shorter bracket's
reset), so a pair costs one look-up and one fused multiply-add: ``sum = sum * r_j r_{j-1}
+ T``. An odd bracket out (the shortest) pairs with a row of zero codes. Two pairs are
added per pass over the row, and the row's first pass writes the sums rather than adding
to them. Deeper codes take the general path: one look-up per code, two brackets per pass.

Sums are float32: each term and each fused multiply-add rounds once, so ``ln E`` is
within a few float32 ulps of the float64 result (``tests/test_merge_kernel.py`` states
the bound).

A channel with no weight left takes the estimate of the longest bracket it was not
dropped from, or the shortest bracket's if it is saturated even there (a rare path that
rescans that channel's codes).

**Early stop.** Before a row is merged, the kernel finds the first bracket in which the
whole row is saturated; that bracket and every longer one would be reset away, so they
are never read. With pair tables, a stop after an odd number of brackets pairs the rest
differently from the full row, which changes the float32 rounding of the sums (within the
few ulps above), not the result.

**Exp in the kernel.** In the log domain each row's ``ln E`` (clamped to float32's range)
is exponentiated while the row is still in cache, by a polynomial ``exp`` (Cephes'
``expf``: ``2^k e^r``, ``|r| <= ln 2 / 2``, 1.3 ulp at most) that the compiler
vectorises.

The kernel merges a band of rows per call, so that brackets staged in a temporary file
(:mod:`hdrio.io.staging`) are read, and released, a band at a time. Compiled by numba on
first use and cached on disk (:mod:`hdrio.jit`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from hdrio.merge.row_sums import (
    INLINED,
    KERNEL,
    accumulate_by_brackets,
    accumulate_by_pairs,
)
from hdrio.parallel import on_threads
from hdrio.radiometry.cliptest import dropped_channels, dropped_channels_call

MAX_BRACKETS = 64
"""Brackets one merge takes (more is never a real bracket set)."""

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
FLOAT32_MAX = float(np.finfo(np.float32).max)
# ln of float32's extremes, pulled in by a little so float32 exp never rounds to 0 or inf.
LOG_FLOAT32_TINY = math.log(FLOAT32_TINY) + 1e-3
LOG_FLOAT32_MAX = math.log(FLOAT32_MAX) - 1e-3

# float32 constants, so that numba keeps the row loops in float32 (twice the SIMD lanes).
_TINY = np.float32(FLOAT32_TINY)
_MAX = np.float32(FLOAT32_MAX)
_LOG_TINY = np.float32(LOG_FLOAT32_TINY)
_LOG_MAX = np.float32(LOG_FLOAT32_MAX)
# Cephes expf: ln 2 split in two so that k ln 2 is exact, and e^r's minimax polynomial.
_LOG2E = np.float32(1.44269504088896341)
_LN2_HIGH = np.float32(0.693359375)
_LN2_LOW = np.float32(-2.12194440e-4)
_EXP_POLYNOMIAL = tuple(np.float32(c) for c in (
    1.9875691500e-4, 1.3981999507e-3, 8.3334519073e-3, 4.1665795894e-2, 1.6666665459e-1,
    5.0000001201e-1))


@njit(**INLINED)
def _saturated_everywhere(row, code_max):  # pragma: no cover - compiled
    for i in range(row.size):
        if row[i] != code_max:
            return False
    return True


@njit(**KERNEL)
def _exp_row(values, scale):  # pragma: no cover - compiled
    """``values = exp(values)`` for ``values`` within ``[LOG_FLOAT32_TINY,
    LOG_FLOAT32_MAX]``: ``e^v = 2^k e^r`` with ``k = round(v / ln 2)``. ``2^k`` is built
    from its bits in the int32 ``scale`` (as ``2^min(k, 127)``, times 2 for k = 128), so
    both loops vectorise."""
    powers = scale.view(np.float32)
    p0, p1, p2, p3, p4, p5 = _EXP_POLYNOMIAL
    for i in range(values.size):
        v = values[i]
        k = np.floor(v * _LOG2E + np.float32(0.5))
        r = v - k * _LN2_HIGH - k * _LN2_LOW
        p = ((((p0 * r + p1) * r + p2) * r + p3) * r + p4) * r + p5
        e = p * r * r + r + np.float32(1.0)
        whole = np.int32(k)
        capped = min(whole, np.int32(127))
        values[i] = e * np.float32(1 + whole - capped)
        scale[i] = (capped + np.int32(127)) << np.int32(23)
    for i in range(values.size):
        values[i] *= powers[i]


@njit(**INLINED)
def _finish(sums, row, log_domain, scale):  # pragma: no cover - compiled
    """``row = numerator / denominator`` (the sums' two parts), clamped to float32's
    range (the range of ``ln E``, then exponentiated, in the log domain). True if a
    denominator is 0."""
    empty = False
    if log_domain:
        for i in range(row.size):
            d = sums[i].imag
            empty |= d <= 0
            row[i] = min(max(sums[i].real / d, _LOG_TINY), _LOG_MAX)
        _exp_row(row, scale)
        return empty
    for i in range(row.size):
        d = sums[i].imag
        empty |= d <= 0
        row[i] = min(max(sums[i].real / d, _TINY), _MAX)
    return empty


@njit(**INLINED)
def _fallback(codes, source, row, y, stop, x, c, limits,
              estimates):  # pragma: no cover - compiled
    """The estimate of the longest bracket channel ``c`` of pixel ``x`` was not dropped
    from (``source[:stop, row]``: row ``y``'s codes as :func:`_policy_rows` gave them
    to the sums, every channel the policy dropped at ``Z_max``; bracket ``stop``, where
    there is one, is saturated across the row). Dropped even from the shortest bracket
    (clipped everywhere): a neutral lower bound, the largest of the shortest bracket's
    estimates over the pixel's channels (every channel the same, so no colour cast),
    when the policy dropped the whole observation or every channel is clipped; else the
    channel's own estimate there.

    The policy's drops are read from ``source``, not tested again, and the policy itself
    is not passed: a tuple of arrays handed to a function called for every channel
    left without weight (16 % of a dark stack's) costs an atomic reference count per
    array and call, which the threads then contend for (6 s of a 24 MP merge)."""
    channels = limits.size
    base = x * channels
    kept = 0
    while kept < stop and source[kept, row][base + c] < limits[c]:
        kept += 1
    if kept > 0:
        return estimates[kept - 1, c, codes[kept - 1, y][base + c]]
    shortest = codes[0, y]
    every = True
    for k in range(channels):
        every &= source[0, row][base + k] >= limits[k]
    if not every:
        return estimates[0, c, shortest[base + c]]
    value = estimates[0, 0, shortest[base]]
    for k in range(1, channels):
        value = max(value, estimates[0, k, shortest[base + k]])
    return value


@njit(**INLINED)
def _remap_row(codes, j, y, out, policy, code_max):  # pragma: no cover - compiled
    """``out``: bracket ``j``'s row ``y`` with every channel the policy drops besides its
    limit's (:func:`hdrio.radiometry.cliptest.dropped_channels`: every channel of an
    observation dropped whole) set to ``Z_max``, so that the per-channel resets apply
    the policy (a channel at or above its limit they drop themselves). The pixel rule
    in one pass written so that it vectorises; the clip test copies the row and tests
    only the observations with a channel at or above its gate, or below its limit where
    the shorter bracket is at it. With three channels that look reads the limits and
    gates from variables, not from their arrays at every pixel: the kernel's CPU on the
    7 x 24 MP speed set, one thread, went from 2.92-3.14 s to 2.15-2.32 s; the merge
    stage's first compile from 15.0 to 17.4 s. (Marking the observations to test in a
    first pass and testing them in a second took 10.4 s; one loop for every channel
    count, the limits read from variables where there are three, 2.9-3.2 s.)"""
    limits, gates, rule, neutral, estimates, variances, threshold = policy
    channels = limits.size
    row = codes[j, y]
    top = row.dtype.type(code_max)
    if channels == 3 and rule == 1:
        l0, l1, l2 = limits[0], limits[1], limits[2]
        for x in range(row.size // 3):
            i = 3 * x
            z0, z1, z2 = row[i], row[i + 1], row[i + 2]
            u = (z0 >= l0) | (z1 >= l1) | (z2 >= l2)
            out[i] = top if u else z0
            out[i + 1] = top if u else z1
            out[i + 2] = top if u else z2
        return
    for i in range(row.size):  # element by element: hdrio.jit, "Slice copies"
        out[i] = row[i]
    if rule == 0:
        return
    shorter = codes[max(j - 1, 0), y]
    if channels == 3:
        l0, l1, l2 = limits[0], limits[1], limits[2]
        g0, g1, g2 = gates[0], gates[1], gates[2]
        for x in range(row.size // 3):
            i = 3 * x
            z0, z1, z2 = row[i], row[i + 1], row[i + 2]
            s0, s1, s2 = shorter[i], shorter[i + 1], shorter[i + 2]
            if not ((z0 >= g0) | (z1 >= g1) | (z2 >= g2) | ((z0 < l0) & (s0 >= l0))
                    | ((z1 < l1) & (s1 >= l1)) | ((z2 < l2) & (s2 >= l2))):
                continue
            dropped = dropped_channels(row, shorter, i, j, max(j - 1, 0), limits, gates,
                                        rule, neutral, estimates, variances, threshold, 1.0)
            if dropped & 1:
                out[i] = top
            if dropped & 2:
                out[i + 1] = top
            if dropped & 4:
                out[i + 2] = top
        return
    for x in range(row.size // channels):
        base = x * channels
        near = False
        for k in range(channels):
            near |= (row[base + k] >= gates[k]) | (
                (row[base + k] < limits[k]) & (shorter[base + k] >= limits[k]))
        if not near:
            continue
        # Called, not inlined: a second inlined copy of the test cost a first run 3.9 s
        # of compiling, for the images that are not RGB.
        dropped = dropped_channels_call(row, shorter, base, j, max(j - 1, 0), limits,
                                        gates, rule, neutral, estimates, variances,
                                        threshold)
        for c in range(channels):
            if (dropped >> c) & 1:
                out[base + c] = top


@njit(**INLINED)
def _clipped_and_black(shortest, longest, limits, channels):  # pragma: no cover - compiled
    """Pixels with a channel at or above its limit in ``shortest``; pixels at 0 in all of
    ``longest``."""
    clipped = 0
    black = 0
    if channels == 3:
        l0, l1, l2 = limits[0], limits[1], limits[2]
        # Written so that it vectorises (8x faster than a stepped range of booleans).
        for x in range(shortest.size // 3):
            i = 3 * x
            clipped += np.int32((shortest[i] >= l0) | (shortest[i + 1] >= l1)
                                | (shortest[i + 2] >= l2))
            black += np.int32((longest[i] | longest[i + 1] | longest[i + 2]) == 0)
        return clipped, black
    for x in range(shortest.size // channels):
        any_saturated = False
        all_black = True
        for c in range(channels):
            any_saturated |= shortest[x * channels + c] >= limits[c]
            all_black &= longest[x * channels + c] == 0
        clipped += any_saturated
        black += all_black
    return clipped, black


@njit(**INLINED)
def _early_stop(codes, y, code_max, early_stop):  # pragma: no cover - compiled
    """The first bracket saturated across the whole row ``y`` (the bracket count when
    none is, or when ``early_stop`` is false): it and every longer one would be reset
    away, so the row is merged from the brackets below it."""
    count = codes.shape[0]
    for j in range(1, count if early_stop else 1):
        if _saturated_everywhere(codes[j, y], code_max):
            return j
    return count


@njit(**INLINED)
def _policy_rows(codes, y, stop, remapped, policy, code_max):  # pragma: no cover - compiled
    """The rows to sum for row ``y``: ``codes`` itself and ``y``, or (when ``remapped``
    has room) its brackets below ``stop`` remapped by the saturation policy
    (:func:`_remap_row`) and row 0 of ``remapped``."""
    if remapped.shape[0] == 0:
        return codes, y
    for j in range(stop):
        _remap_row(codes, j, y, remapped[j, 0], policy, code_max)
    return remapped, 0


@njit(**INLINED)
def _finish_row(codes, source, row, y, stop, sums, scale, estimates, limits, log_domain,
                out, clipped_rows, black_rows, skipped_rows):  # pragma: no cover - compiled
    """Row ``y``'s result from its sums (the fallback where no weight is left, from the
    rows summed, ``source[:stop, row]``) and its statistics."""
    count = codes.shape[0]
    channels = estimates.shape[1]
    n = out.shape[1]
    result = out[y]
    if _finish(sums, result, log_domain, scale):
        for i in range(n):
            if sums[i].imag <= 0.0:
                value = _fallback(codes, source, row, y, stop, i // channels, i % channels,
                                  limits, estimates)
                if log_domain:
                    value = math.exp(min(max(value, LOG_FLOAT32_TINY), LOG_FLOAT32_MAX))
                result[i] = min(max(value, FLOAT32_TINY), FLOAT32_MAX)
    skipped_rows[y] = (count - stop) * (n // channels)
    clipped_rows[y], black_rows[y] = _clipped_and_black(codes[0, y], codes[count - 1, y],
                                                        limits, channels)


@njit(**KERNEL)
def merge_rows_by_pairs(first, last, codes, top, pairs, estimates, code_max, policy, remap,
                        log_domain, early_stop, out, clipped_rows, black_rows,
                        skipped_rows):  # pragma: no cover - compiled
    """Rows ``top + first .. top + last - 1`` by :func:`merge_kernel`'s pair-table path."""
    n = out.shape[1]
    sums = np.empty(n, np.complex64)  # numerator + i denominator
    scale = np.empty(n, np.int32)
    zeros = np.zeros(n, codes.dtype)
    remapped = np.empty((codes.shape[0] if remap else 0, 1, n), codes.dtype)
    for y in range(top + first, top + last):
        stop = _early_stop(codes, y, code_max, early_stop)
        source, row = _policy_rows(codes, y, stop, remapped, policy, code_max)
        accumulate_by_pairs(source, row, stop, pairs, zeros, policy[0], sums)
        _finish_row(codes, source, row, y, stop, sums, scale, estimates, policy[0],
                    log_domain, out, clipped_rows, black_rows, skipped_rows)


@njit(**KERNEL)
def merge_rows_by_brackets(first, last, codes, top, terms, estimates, code_max, policy,
                           remap, log_domain, early_stop, out, clipped_rows, black_rows,
                           skipped_rows):  # pragma: no cover - compiled
    """Rows ``top + first .. top + last - 1`` by :func:`merge_kernel`'s general path."""
    n = out.shape[1]
    sums = np.empty(n, np.complex64)
    scale = np.empty(n, np.int32)
    remapped = np.empty((codes.shape[0] if remap else 0, 1, n), codes.dtype)
    for y in range(top + first, top + last):
        stop = _early_stop(codes, y, code_max, early_stop)
        source, row = _policy_rows(codes, y, stop, remapped, policy, code_max)
        accumulate_by_brackets(source, row, stop, terms, policy[0], sums)
        _finish_row(codes, source, row, y, stop, sums, scale, estimates, policy[0],
                    log_domain, out, clipped_rows, black_rows, skipped_rows)


@dataclass(frozen=True)
class KernelTables:
    """What :func:`merge_kernel` reads besides the codes: the tables and the policy.

    Attributes
    ----------
    terms
        ``(P, C, levels)`` complex64: ``w(z) x_j(z) + i w(z)``, the numerator's and the
        denominator's term, both 0 for ``z >= limits[c]`` (a dropped observation never
        counts).
    estimates
        ``(P, C, levels)`` float64: ``x_j(z)``, for the fallback.
    pairs
        :func:`hdrio.merge.row_sums.pair_tables` of the terms (three channels of 8-bit
        codes), or empty for the general path.
    code_max
        The top code.
    policy
        The saturation policy as the compiled kernels take it
        (:meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`): ``limits`` ``(C,)``
        int64, the first code of each channel that is dropped (``code_max`` drops the top
        code only), applied by the resets, and the observations it drops whole
        (:func:`hdrio.radiometry.cliptest.dropped_channels`: the pixel rule, or the clip
        test), for which each bracket's row is first remapped (:func:`_remap_row`, into a
        per-task buffer).
    log_domain
        Average ``ln E`` (then exponentiate) rather than ``E``.
    early_stop
        Skip the brackets saturated across a whole row (false: read every bracket of
        every row; the same result, to float32 rounding).
    """

    terms: np.ndarray
    estimates: np.ndarray
    pairs: np.ndarray
    code_max: int
    policy: tuple
    log_domain: bool
    early_stop: bool


def merge_kernel(codes: np.ndarray, top: int, bottom: int, tables: KernelTables,
                 out: np.ndarray, counts: np.ndarray) -> None:
    """Merge rows ``top .. bottom`` of the brackets into ``out`` ``(H, W * C)`` float32.

    ``codes`` is ``(P, H, W * C)``, shortest exposure first; ``tables`` say how
    (:class:`KernelTables`). Writes ``E``, clamped to float32's normal range, and per
    row, in ``counts`` ``(3, H)`` int64, the statistics: pixels with a channel at or above
    its limit in the shortest bracket, pixels at code 0 in every channel of the longest,
    and pixel-brackets the early stop never read.

    The two paths are two serial kernels (each compiles only what it runs, on first
    use) whose rows the threads share in chunks (:func:`hdrio.parallel.on_threads`):
    less to compile than numba's ``parallel=True``, for the same speed.
    """
    t = tables
    remap = int(t.policy[2]) != 0
    if t.pairs.shape[0] == codes.shape[0]:
        kernel, lookups = merge_rows_by_pairs, t.pairs
    else:
        kernel, lookups = merge_rows_by_brackets, t.terms
    on_threads(kernel, bottom - top, codes, top, lookups, t.estimates, t.code_max, t.policy,
               remap, t.log_domain, t.early_stop, out, *counts)
