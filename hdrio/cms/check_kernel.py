"""The per-pixel pass of :class:`hdrio.cms.checks.StreamingCheck`, compiled.

One pass over a band of RGB pixels counts what ``hdrio check`` reports: non-finite and
negative pixels, pixels outside a gamut, the luminance extremes and a histogram of
luminance by its float32 bit pattern. Half-float bands are decoded through a table of
all 65,536 half values (exact; numba has no float16), so no float32 copy of the band is
made.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload

from hdrio.float_bits import float_bits

HALF_TABLE = np.arange(1 << 16, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(
    np.float32)
"""float32 value of every half bit pattern, indexed by the pattern."""

_KERNEL = dict(cache=True, nogil=True, error_model="numpy")


@njit(inline="always", **_KERNEL)
def _lowest(r, g, b):  # pragma: no cover - compiled
    """``numpy.minimum`` of three values: NaN when any is NaN."""
    if r != r or g != g or b != b:
        return np.float32(np.nan)
    return min(r, g, b)


@njit(inline="always", **_KERNEL)
def _count(r, g, b, weights, to_gamut, use_gamut, counts, bin_shift):  # pragma: no cover
    """Count one pixel into the histogram ``counts``: its luminance when positive and
    finite (else 0) and whether it is non-finite, negative, outside the gamut."""
    Y = r * weights[0] + g * weights[1] + b * weights[2]
    finite = np.isfinite(Y)  # finite exactly when every channel is (positive weights)
    lowest = _lowest(r, g, b)
    negative = lowest < 0
    if use_gamut:
        lowest = _lowest(
            to_gamut[0, 0] * r + to_gamut[0, 1] * g + to_gamut[0, 2] * b,
            to_gamut[1, 0] * r + to_gamut[1, 1] * g + to_gamut[1, 2] * b,
            to_gamut[2, 0] * r + to_gamut[2, 1] * g + to_gamut[2, 2] * b)
    # Outside: a channel below -1e-6 of the pixel's luminance (float rounding is not).
    outside = finite and lowest < np.float32(-1e-6) * abs(Y)
    if finite and Y > 0:
        counts[float_bits(Y) >> bin_shift] += 1
    else:
        Y = np.float32(0)
    return Y, not finite, negative, outside


@njit(**_KERNEL)
def count_rows(rows, table, weights, to_gamut, use_gamut, counts, bin_shift,
               extremes):  # pragma: no cover - compiled
    """Count ``rows`` ``(N, C)`` (first three channels RGB): half bit patterns (uint16)
    decoded through ``table``, or float32 pixels (``table`` is then ignored). Returns
    the non-finite, negative and outside counts; ``extremes`` holds the lowest and
    highest positive finite luminance so far."""
    bad = negative = outside = 0
    low, high = extremes[0], extremes[1]
    for p in range(rows.shape[0]):
        r, g, b = _pixel(rows, p, table)
        Y, is_bad, is_negative, is_outside = _count(r, g, b, weights, to_gamut, use_gamut,
                                                    counts, bin_shift)
        bad += is_bad
        negative += is_negative
        outside += is_outside
        if Y > 0:
            low = min(low, Y)
            high = max(high, Y)
    extremes[0], extremes[1] = low, high
    return bad, negative, outside


def _pixel(rows, p, table):  # pragma: no cover - compiled (overloaded below)
    """RGB of pixel ``p`` as float32."""


@overload(_pixel, inline="always")
def _pixel_overload(rows, p, table):
    if rows.dtype == types.uint16:  # half bit patterns
        return lambda rows, p, table: (table[rows[p, 0]], table[rows[p, 1]],
                                       table[rows[p, 2]])
    return lambda rows, p, table: (rows[p, 0], rows[p, 1], rows[p, 2])
