"""How the merge kernel (:mod:`hdrio.merge.kernel`) sums a row: bracket by bracket (the
general path, one look-up per code) or pair by pair (8-bit RGB codes: one look-up in a
pair table per two brackets), longest bracket first, with the saturation resets.

The numba settings the merge's kernels share are here too, so that the kernel and its
helpers compile alike.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hdrio.jit import INNER

KERNEL = dict(cache=True, nogil=True, fastmath={"contract"}, error_model="numpy")
"""Fused multiply-adds allowed (they round once, not twice); division by 0 gives inf or
NaN instead of raising (the fallback replaces those values)."""
INNER_KERNEL = dict(KERNEL, cache=False, **INNER)
"""The helpers only other kernels call (:data:`hdrio.jit.INNER`)."""
INLINED = dict(INNER_KERNEL, inline="always")
"""Helpers numba inlines into their caller's IR: typed and lowered as part of it, with no
library of their own to optimise, link and turn into machine code (about 0.2 s each of a
first run). Not ``_exp_row``: inlined, the log domain's merge was 3 % slower."""

PAIR_LEVELS = 256
"""Pair tables are built for codes of at most this many levels (8-bit)."""


@njit(**INLINED)
def _reset_add(total, keep, term):  # pragma: no cover - compiled
    """``total * keep + term`` on both parts (``keep`` 0 or 1), as fused multiply-adds."""
    return complex(total.real * keep + term.real, total.imag * keep + term.imag)


@njit(**INNER_KERNEL)
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


@njit(**INNER_KERNEL)
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

    ``terms`` are :func:`hdrio.merge.kernel.merge_kernel`'s (0 from each channel's entry
    of ``limits`` up), complex128 here: the sums are formed in float64, then rounded once.
    (NumPy, not a kernel: a few milliseconds, and nothing to compile.)
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


@njit(**INNER_KERNEL)
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


@njit(**INLINED)
def _add_pair(longer, shorter, table, limits, sums, fresh):  # pragma: no cover
    """One pair of brackets over a row (three channels)."""
    t0, t1, t2 = table[0], table[1], table[2]
    l0, l1, l2 = np.int32(limits[0]), np.int32(limits[1]), np.int32(limits[2])
    for x in range(longer.size // 3):
        i = 3 * x
        sums[i] = _pair_term(sums[i], i, longer, shorter, t0, l0, fresh)
        sums[i + 1] = _pair_term(sums[i + 1], i + 1, longer, shorter, t1, l1, fresh)
        sums[i + 2] = _pair_term(sums[i + 2], i + 2, longer, shorter, t2, l2, fresh)


@njit(**INLINED)
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


@njit(**INLINED)
def accumulate_by_pairs(codes, y, stop, pairs, zeros, limits,
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


@njit(**INNER_KERNEL)
def accumulate_by_brackets(codes, y, stop, terms, limits,
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
