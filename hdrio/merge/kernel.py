"""The fused merge kernel: one pass over every bracket's code values, multi-threaded.

For each pixel and channel the kernel sums ``sum_j w(Z_j) x_j`` and ``sum_j w(Z_j)``,
where ``x_j`` is the bracket's estimate from a per-exposure lookup table (``g(z) - ln
dt_j`` in the log domain, ``f^-1(z) / dt_j`` in the linear domain). It works a row at a
time: it streams each bracket's row of codes once through lookup tables into a row of
sums that stays in the core's cache, then writes the row's result (exponentiated there
in the log domain). Nothing but the output is written to memory.

The two sums of a value travel together as one complex64, ``numerator + i
denominator``, and so do the tables' terms ``w(z) x_j(z) + i w(z)``: one 8-byte load and
store for both (1.13x faster than two float32 arrays, which also left the compiler
short of registers).

Saturation (a code at or above its channel's *limit*: ``Z_max``, or lower where
:mod:`hdrio.merge.saturation` found the white level, less the noise margin, below it) drops the
observation from its bracket and from every longer one. The kernel walks the brackets
longest first and *resets* a channel's sums where it meets a dropped code: ``sum = (sum
+ term[z]) * (z < limit)``. What survives is exactly the sum over the brackets shorter
than the first dropped one, with no per-channel state to load and store and no
data-dependent branch (on this machine 1.3x faster than carrying an "alive" flag). With
the terms 0 from the limit up that is ``sum * (z < limit) + term[z]``, a fused
multiply-add; a limit below ``Z_max`` costs nothing more than ``Z_max`` itself.

**Whole observations** (the pixel rule: any dropped channel drops the whole observation,
the tutorial's ``pixel`` and the ``safe`` policy; the clip test of ``auto``, which drops
a partly clipped observation whole where its other channels disagree with the next
shorter bracket's, :mod:`hdrio.merge.cliptest`) are dropped by remapping each bracket's
row before it is summed, into a per-task buffer: every code of such an observation
becomes ``Z_max``. The per-channel resets then apply it, through the same pair tables
(the tutorial's per-pixel policy used to take one look-up per code instead).
``benchmarks/speed`` times the remap.

**Pair tables (8-bit codes, three channels: the common case).** The
kernel is bound by its scalar table look-ups, about ten instructions per code value
(this machine's AVX-512 gathers are slower still: 0.40 s against 0.34 s for a plain C
loop over the benchmark's codes). Two brackets ``j`` (longer) and ``j - 1`` are
therefore looked up together: one table per pair and channel indexed by both codes,
``z_j * 256 + z_{j-1}``, holds the pair's summed terms already (``T = t_j(z_j)
s(z_{j-1}) + t_{j-1}(z_{j-1})``, with ``s`` the shorter bracket's reset), so a pair costs
one look-up where two brackets cost two, and one fused multiply-add: ``sum = sum *
r_j r_{j-1} + T``. An odd bracket out (the shortest) pairs with a row of zero codes.
The tables hold 65536 entries per pair and channel (1.5 MB a pair), but a pair of
brackets only ever shows the codes near its response curves, so the entries in use stay
in cache (with every code the same the kernel is only 1.1x faster). Two pairs are
added per pass over the row (half the loads and stores of the sums; 1.1x), and the
row's first pass writes the sums rather than adding to them (no zeroing, no load).

Measured at 7 x 24 MP on one thread (``process_time``): 0.24 s of CPU for the whole
kernel, ``exp`` and statistics included, against 0.38 s plus a 0.03 s NumPy ``exp``
pass for one bracket per look-up with float64 sums (commit 2756785). Deeper codes would
need ``levels**2`` entries a table and take the general path (one look-up per code,
two brackets per pass over the row), which the complex sums speed up too.

Sums are float32: each term and each fused multiply-add rounds once, so ``ln E`` is
within a few float32 ulps of the float64 result (the output is float32 anyway;
``tests/test_merge_kernel.py`` states the bound).

A channel with no weight left takes the estimate of the longest bracket it was not
dropped from, or the shortest bracket's if it is saturated even there (a rare path that
rescans that channel's codes).

**Early stop.** Before a row is merged, the kernel finds the first bracket in which the
whole row is saturated; that bracket and every longer one would be reset away, so they
are never read (the sky rows of an outdoor scene in the long exposures, say;
``benchmarks/speed`` measures it). Stopping per 32-pixel segment instead would skip
more on the benchmark's scene (5.9 of 7 brackets read) but the short loops cost more
than they save (1.45x slower in all). With pair tables, a stop after an odd number of
brackets pairs the rest differently from the full row, which changes the float32
rounding of the sums (within the few ulps above), not the result; keeping the full row's
pairs would read a saturated bracket more and halve what the stop saves on the
benchmark's sky scene.

**Exp in the kernel.** In the log domain each row's ``ln E`` (clamped to float32's range)
is exponentiated while the row is still in cache, by a polynomial ``exp`` (Cephes'
``expf``: ``2^k e^r``, ``|r| <= ln 2 / 2``, 1.3 ulp at most) that the compiler
vectorises, where ``math.exp`` would be a scalar library call per value. It replaces a
separate NumPy ``exp`` pass over the whole image.

The kernel merges a band of rows per call, so that brackets staged in a temporary file
(:mod:`hdrio.io.staging`) are read, and released, a band at a time.

Compiled by numba on first use and cached on disk beside this module (or in
``NUMBA_CACHE_DIR``); the first call in a new environment pays the compile, which
``benchmarks/speed`` reports, and later processes load the cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hdrio.jit import INNER
from hdrio.merge.cliptest import dropped_channels, dropped_whole
from hdrio.parallel import on_threads

MAX_BRACKETS = 64
"""Brackets one merge takes (more is never a real bracket set)."""

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
FLOAT32_MAX = float(np.finfo(np.float32).max)
# ln of float32's extremes, pulled in by a little so float32 exp never rounds to 0 or inf.
LOG_FLOAT32_TINY = math.log(FLOAT32_TINY) + 1e-3
LOG_FLOAT32_MAX = math.log(FLOAT32_MAX) - 1e-3

PAIR_LEVELS = 256
"""Pair tables are built for codes of at most this many levels (8-bit)."""

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

_KERNEL = dict(cache=True, nogil=True, fastmath={"contract"}, error_model="numpy")
"""Fused multiply-adds allowed (they round once, not twice); division by 0 gives inf or
NaN instead of raising (the fallback replaces those values)."""
_INNER = dict(_KERNEL, cache=False, **INNER)
"""The helpers only other kernels call (:data:`hdrio.jit.INNER`)."""
_INLINED = dict(_INNER, inline="always")
"""Helpers numba inlines into their caller's IR: typed and lowered as part of it, with no
library of their own to optimise, link and turn into machine code (about 0.2 s each of a
first run). Not ``_exp_row``: inlined, the log domain's merge was 3 % slower."""


@njit(**_INLINED)
def _saturated_everywhere(row, code_max):  # pragma: no cover - compiled
    for i in range(row.size):
        if row[i] != code_max:
            return False
    return True


@njit(**_INLINED)
def _reset_add(total, keep, term):  # pragma: no cover - compiled
    """``total * keep + term`` on both parts (``keep`` 0 or 1), as fused multiply-adds."""
    return complex(total.real * keep + term.real, total.imag * keep + term.imag)


@njit(**_INNER)
def _accumulate(row, terms, limits, channels, sums):  # pragma: no cover - compiled
    """``sum = sum * (z < limit) + term[z]`` over one bracket's row (the terms are 0 from
    the channel's limit up, so this is ``(sum + term) * (z < limit)``: one fused
    multiply-add, 1.25x faster than the product form)."""
    if channels == 3:
        t0, t1, t2 = terms[0], terms[1], terms[2]
        l0, l1, l2 = limits[0], limits[1], limits[2]
        for x in range(row.size // 3):  # not range(0, row.size, 3): 1.4x slower
            i = 3 * x
            z0, z1, z2 = row[i], row[i + 1], row[i + 2]
            sums[i] = _reset_add(sums[i], np.float32(z0 < l0), t0[z0])
            sums[i + 1] = _reset_add(sums[i + 1], np.float32(z1 < l1), t1[z1])
            sums[i + 2] = _reset_add(sums[i + 2], np.float32(z2 < l2), t2[z2])
        return
    for i in range(row.size):
        z = row[i]
        sums[i] = _reset_add(sums[i], np.float32(z < limits[i % channels]),
                             terms[i % channels, z])


@njit(**_INNER)
def _accumulate_two(longer, shorter, terms_longer, terms_shorter, limits,
                    sums):  # pragma: no cover - compiled
    """Two brackets at once, per-channel policy, three channels: half the loads and
    stores of the sums that two :func:`_accumulate` calls make (1.13x faster)."""
    a0, a1, a2 = terms_longer[0], terms_longer[1], terms_longer[2]
    b0, b1, b2 = terms_shorter[0], terms_shorter[1], terms_shorter[2]
    l0, l1, l2 = limits[0], limits[1], limits[2]
    for x in range(longer.size // 3):
        i = 3 * x
        z0, z1, z2 = longer[i], longer[i + 1], longer[i + 2]
        y0, y1, y2 = shorter[i], shorter[i + 1], shorter[i + 2]
        sums[i] = _reset_add(_reset_add(sums[i], np.float32(z0 < l0), a0[z0]),
                             np.float32(y0 < l0), b0[y0])
        sums[i + 1] = _reset_add(
            _reset_add(sums[i + 1], np.float32(z1 < l1), a1[z1]),
            np.float32(y1 < l1), b1[y1])
        sums[i + 2] = _reset_add(
            _reset_add(sums[i + 2], np.float32(z2 < l2), a2[z2]),
            np.float32(y2 < l2), b2[y2])


def pair_tables(terms: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """The pair tables of three-channel codes below :data:`PAIR_LEVELS` levels, complex64
    ``(P, 3, 256 * 256)``: entry ``z * 256 + y`` of table ``j`` holds the terms of bracket
    ``j`` at code ``z`` and bracket ``j - 1`` at code ``y``, ``t_j(z) (y < limit) +
    t_{j-1}(y)``. Table 0 pairs the shortest bracket with a row of code 0 (no term of
    its own).

    ``terms`` are :func:`merge_kernel`'s (0 from each channel's entry of ``limits`` up),
    complex128 here: the sums are formed in float64, then rounded once. (NumPy, not a
    kernel: a few milliseconds, and nothing to compile.)
    """
    terms = np.asarray(terms, dtype=np.complex128)
    count, channels, levels = terms.shape
    tables = np.zeros((count, channels, PAIR_LEVELS, PAIR_LEVELS), np.complex64)
    tables[0, :, :levels, 0] = terms[0]  # the zero row's code is never dropped (limit >= 1)
    if count > 1:
        # Bracket j's term counts unless the shorter bracket's code y is dropped.
        keep = np.arange(levels)[None, :] < np.asarray(limits)[:, None]  # (C, levels)
        tables[1:, :, :levels, :levels] = (terms[1:, :, :, None] * keep[None, :, None, :]
                                           + terms[:-1, :, None, :])
    return tables.reshape(count, channels, PAIR_LEVELS * PAIR_LEVELS)


@njit(**_INNER)
def _pair_term(total, i, longer, shorter, table, limit, fresh):  # pragma: no cover
    """``total`` after the pair's codes at ``i``: ``T[z, y]`` added to it (reset where
    ``z`` or ``y`` is at or above the channel's ``limit``), or ``T[z, y]`` alone for the
    row's first pair (``fresh``)."""
    z = np.int32(longer[i])
    y = np.int32(shorter[i])
    term = table[z * PAIR_LEVELS + y]
    if fresh:
        return term
    return _reset_add(total, np.float32((z < limit) & (y < limit)), term)


@njit(**_INLINED)
def _add_pair(longer, shorter, table, limits, sums, fresh):  # pragma: no cover
    """One pair of brackets over a row (three channels)."""
    t0, t1, t2 = table[0], table[1], table[2]
    l0, l1, l2 = np.int32(limits[0]), np.int32(limits[1]), np.int32(limits[2])
    for x in range(longer.size // 3):
        i = 3 * x
        sums[i] = _pair_term(sums[i], i, longer, shorter, t0, l0, fresh)
        sums[i + 1] = _pair_term(sums[i + 1], i + 1, longer, shorter, t1, l1, fresh)
        sums[i + 2] = _pair_term(sums[i + 2], i + 2, longer, shorter, t2, l2, fresh)


@njit(**_INLINED)
def _add_two_pairs(longer, shorter, longer2, shorter2, table, table2, limits, sums,
                   fresh):  # pragma: no cover - compiled
    """Two pairs of brackets over a row, the longer pair first: half the loads and
    stores of the sums that two :func:`_add_pair` calls make (1.1x faster)."""
    a0, a1, a2 = table[0], table[1], table[2]
    b0, b1, b2 = table2[0], table2[1], table2[2]
    l0, l1, l2 = np.int32(limits[0]), np.int32(limits[1]), np.int32(limits[2])
    for x in range(longer.size // 3):
        i = 3 * x
        sums[i] = _pair_term(
            _pair_term(sums[i], i, longer, shorter, a0, l0, fresh),
            i, longer2, shorter2, b0, l0, False)
        sums[i + 1] = _pair_term(
            _pair_term(sums[i + 1], i + 1, longer, shorter, a1, l1, fresh),
            i + 1, longer2, shorter2, b1, l1, False)
        sums[i + 2] = _pair_term(
            _pair_term(sums[i + 2], i + 2, longer, shorter, a2, l2, fresh),
            i + 2, longer2, shorter2, b2, l2, False)


@njit(**_INLINED)
def _accumulate_by_pairs(codes, y, stop, pairs, zeros, limits,
                         sums):  # pragma: no cover - compiled
    """Brackets ``stop - 1 .. 0`` of row ``y``, in pairs (four brackets per pass while
    there are three or more left), longest first; a last odd bracket pairs with
    ``zeros``."""
    j = stop - 1
    fresh = True
    while j >= 2:
        _add_two_pairs(codes[j, y], codes[j - 1, y], codes[j - 2, y],
                       codes[j - 3, y] if j >= 3 else zeros, pairs[j], pairs[j - 2],
                       limits, sums, fresh)
        fresh = False
        j -= 4
    if j >= 0:
        _add_pair(codes[j, y], codes[j - 1, y] if j >= 1 else zeros, pairs[j], limits,
                  sums, fresh)


@njit(**_INNER)
def _accumulate_by_brackets(codes, y, stop, terms, limits,
                            sums):  # pragma: no cover - compiled
    """Brackets ``stop - 1 .. 0`` of row ``y``, one look-up per code, longest first."""
    channels = terms.shape[1]
    sums[:] = 0.0
    j = stop - 1
    if channels == 3:
        while j >= 1:
            _accumulate_two(codes[j, y], codes[j - 1, y], terms[j], terms[j - 1], limits,
                            sums)
            j -= 2
    while j >= 0:
        _accumulate(codes[j, y], terms[j], limits, channels, sums)
        j -= 1


@njit(**_KERNEL)
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


@njit(**_INLINED)
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


@njit(**_INLINED)
def _unsafe(codes, j, y, x, c, policy):  # pragma: no cover - compiled
    """Whether channel ``c`` of pixel ``x`` of row ``y`` in bracket ``j`` is dropped: its
    code at or above its limit, or the policy drops it
    (:func:`hdrio.merge.cliptest.dropped_channels`)."""
    limits = policy[0]
    channels = limits.size
    row = codes[j, y]
    if row[x * channels + c] >= limits[c]:
        return True
    dropped = dropped_channels(row, codes[max(j - 1, 0), y], x * channels, j, policy)
    return (dropped >> c) & 1 == 1


@njit(**_INLINED)
def _fallback(codes, y, x, c, policy, estimates):  # pragma: no cover - compiled
    """The estimate of the longest bracket channel ``c`` of pixel ``x`` was not dropped
    from. Dropped even from the shortest bracket (clipped everywhere): a neutral lower
    bound, the largest of the shortest bracket's estimates over the pixel's channels
    (every channel the same, so no colour cast), when the policy dropped the whole
    observation or every channel is clipped; else the channel's own estimate there."""
    limits = policy[0]
    channels = limits.size
    kept = 0
    while kept < codes.shape[0] and not _unsafe(codes, kept, y, x, c, policy):
        kept += 1
    if kept > 0:
        return estimates[kept - 1, c, codes[kept - 1, y][x * channels + c]]
    row = codes[0, y]
    every = True
    for k in range(channels):
        every &= row[x * channels + k] >= limits[k]
    if not (every or dropped_whole(row, row, x * channels, 0, policy)):
        return estimates[0, c, row[x * channels + c]]
    value = estimates[0, 0, row[x * channels]]
    for k in range(1, channels):
        value = max(value, estimates[0, k, row[x * channels + k]])
    return value


@njit(**_INLINED)
def _remap_row(codes, j, y, out, policy, code_max):  # pragma: no cover - compiled
    """``out``: bracket ``j``'s row ``y`` with every channel the policy drops besides its
    limit's (:func:`hdrio.merge.cliptest.dropped_channels`: every channel of an
    observation dropped whole) set to ``Z_max``, so that the per-channel resets apply
    the policy (a channel at or above its limit they drop themselves)."""
    limits = policy[0]
    pixel_rule = policy[2] == 1
    channels = limits.size
    row = codes[j, y]
    top = row.dtype.type(code_max)
    if channels == 3 and pixel_rule:
        l0, l1, l2 = limits[0], limits[1], limits[2]
        for x in range(row.size // 3):  # written so that it vectorises
            i = 3 * x
            z0, z1, z2 = row[i], row[i + 1], row[i + 2]
            u = (z0 >= l0) | (z1 >= l1) | (z2 >= l2)
            out[i] = top if u else z0
            out[i + 1] = top if u else z1
            out[i + 2] = top if u else z2
        return
    shorter = codes[max(j - 1, 0), y]
    for x in range(row.size // channels):
        base = x * channels
        dropped = dropped_channels(row, shorter, base, j, policy)
        for c in range(channels):
            out[base + c] = top if (dropped >> c) & 1 else row[base + c]


@njit(**_INLINED)
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


@njit(**_INLINED)
def _early_stop(codes, y, code_max, early_stop):  # pragma: no cover - compiled
    """The first bracket saturated across the whole row ``y`` (the bracket count when
    none is, or when ``early_stop`` is false): it and every longer one would be reset
    away, so the row is merged from the brackets below it."""
    count = codes.shape[0]
    for j in range(1, count if early_stop else 1):
        if _saturated_everywhere(codes[j, y], code_max):
            return j
    return count


@njit(**_INLINED)
def _policy_rows(codes, y, stop, remapped, policy, code_max):  # pragma: no cover - compiled
    """The rows to sum for row ``y``: ``codes`` itself and ``y``, or (when ``remapped``
    has room) its brackets below ``stop`` remapped by the saturation policy
    (:func:`_remap_row`) and row 0 of ``remapped``."""
    if remapped.shape[0] == 0:
        return codes, y
    for j in range(stop):
        _remap_row(codes, j, y, remapped[j, 0], policy, code_max)
    return remapped, 0


@njit(**_INLINED)
def _finish_row(codes, y, stop, sums, scale, estimates, policy, log_domain, out,
                clipped_rows, black_rows, skipped_rows):  # pragma: no cover - compiled
    """Row ``y``'s result from its sums (the fallback where no weight is left) and its
    statistics."""
    count = codes.shape[0]
    channels = estimates.shape[1]
    n = out.shape[1]
    row = out[y]
    if _finish(sums, row, log_domain, scale):
        for i in range(n):
            if sums[i].imag <= 0.0:
                value = _fallback(codes, y, i // channels, i % channels, policy, estimates)
                if log_domain:
                    value = math.exp(min(max(value, LOG_FLOAT32_TINY), LOG_FLOAT32_MAX))
                row[i] = min(max(value, FLOAT32_TINY), FLOAT32_MAX)
    skipped_rows[y] = (count - stop) * (n // channels)
    clipped_rows[y], black_rows[y] = _clipped_and_black(codes[0, y], codes[count - 1, y],
                                                        policy[0], channels)


@njit(**_KERNEL)
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
        _accumulate_by_pairs(source, row, stop, pairs, zeros, policy[0], sums)
        _finish_row(codes, y, stop, sums, scale, estimates, policy, log_domain, out,
                    clipped_rows, black_rows, skipped_rows)


@njit(**_KERNEL)
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
        _accumulate_by_brackets(source, row, stop, terms, policy[0], sums)
        _finish_row(codes, y, stop, sums, scale, estimates, policy, log_domain, out,
                    clipped_rows, black_rows, skipped_rows)


def merge_kernel(codes, top, bottom, tables, code_max, policy, log_domain, early_stop, out,
                 statistics):
    """Merge rows ``top .. bottom`` of the brackets into ``out`` ``(H, W * C)`` float32.

    ``codes`` is ``(P, H, W * C)``, shortest exposure first. ``tables`` is ``(terms,
    estimates, pairs)``: ``terms[j, c, z]`` (complex64) is ``w(z) x_j(z) + i w(z)``, the
    numerator's and the denominator's term, both 0 for ``z >= limits[c]`` (a dropped
    observation never counts); ``estimates[j, c, z]`` (float64) is ``x_j(z)`` for the
    fallback; ``pairs`` is :func:`pair_tables` of the terms (three channels of 8-bit
    codes), or empty for the general path.

    The saturation policy, ``policy``, is
    :meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`: ``limits`` ``(C,)`` int64, the
    first code of each channel that is dropped (``code_max`` drops the top code only),
    applied by the resets, and the observations it drops whole
    (:func:`hdrio.merge.cliptest.dropped_channels`: the pixel rule, or the clip test), for
    which each bracket's row is first remapped (:func:`_remap_row`, into a per-task
    buffer). Writes ``E``, clamped to float32's normal range. ``early_stop`` false reads
    every bracket of every row (the same result, to float32 rounding). ``statistics``
    ``(clipped_rows, black_rows, skipped_rows)``, per row: pixels with a channel at or
    above its limit in the shortest bracket, pixels at code 0 in every channel of the
    longest, and pixel-brackets the early stop never read.

    The two paths are two serial kernels (each compiles only what it runs, on first
    use) whose rows the threads share in chunks (:func:`hdrio.parallel.on_threads`):
    less to compile than numba's ``parallel=True``, for the same speed.
    """
    terms, estimates, pairs = tables
    remap = int(policy[2]) != 0
    if pairs.shape[0] == codes.shape[0]:
        on_threads(merge_rows_by_pairs, bottom - top, codes, top, pairs, estimates,
                   code_max, policy, remap, log_domain, early_stop, out, *statistics)
    else:
        on_threads(merge_rows_by_brackets, bottom - top, codes, top, terms, estimates,
                   code_max, policy, remap, log_domain, early_stop, out, *statistics)
