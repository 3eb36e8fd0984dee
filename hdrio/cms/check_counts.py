"""The counting kernel of :class:`hdrio.cms.checks.StreamingCheck` (``compiled=True``):
one pass over pixels as stored (float32, or half bits), no temporaries, no GIL.

The check after a merge counts each piece of the EXR on the thread that converted it to
half. With NumPy that is eight passes and as many temporaries a piece, each taking and
giving back the GIL: on the 16-core device the pieces queued for it, and the write of a
7 x 24 MP merge took 1.4-1.8 s (docs/speed.md, "Many cores"). The numbers are NumPy's
check's, bit for bit: float32 arithmetic in the same order (tests/test_check_counts.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import overload

from hdrio.float_bits import float_bits
from hdrio.io.half import half_value
from hdrio.jit import INNER


def _as_float32(value):
    """A stored value as float32: a half's bits (``uint16``) or a float32 itself."""
    raise NotImplementedError("numba only")


@overload(_as_float32)
def _as_float32_typed(value):
    if value == types.uint16:
        return lambda value: half_value(value)
    if value == types.float32:
        return lambda value: value
    return None


@njit(**INNER)
def _luminance(r, g, b, weights):
    y = r * weights[0]
    y = y + g * weights[1]
    return y + b * weights[2]


@njit(cache=True, nogil=True)
def count_pixels(red, green, blue, weights, to_gamut, use_gamut, shift):
    """Counts of pixels given as three planes of one length (1-D, float32 or half bits):
    ``(non_finite, negative, outside, low, high, first, histogram)``.

    ``Y`` is ``red * w0 + green * w1 + blue * w2`` in float32 (``weights``); non-finite
    where ``Y`` is; negative where the least channel is below 0 (NaN is not); outside
    where a finite pixel's least channel in the target gamut (``to_gamut @ rgb`` in
    float32 when ``use_gamut``, else its own) is below -1e-6 of ``|Y|``; ``low`` and
    ``high`` the least and greatest positive finite ``Y`` (inf and 0 when there is
    none); ``histogram[k]`` the positive finite ``Y`` whose bits >> ``shift`` are
    ``first + k`` (empty when there is none)."""
    threshold = np.float32(-1e-6)
    non_finite = negative = outside = 0
    low, high = np.float32(np.inf), np.float32(0.0)
    first, last = 0x7FFFFFFF, -1
    codes = np.empty(red.size, np.int32)  # each pixel's bin, -1 where none
    for i in range(red.size):
        r, g, b = _as_float32(red[i]), _as_float32(green[i]), _as_float32(blue[i])
        y = _luminance(r, g, b, weights)
        finite = np.isfinite(y)
        if not finite:
            non_finite += 1
        has_nan = r != r or g != g or b != b
        lowest = min(r, g, b)
        below = not has_nan and lowest < 0
        if below:
            negative += 1
        if use_gamut:
            t0 = to_gamut[0, 0] * r + to_gamut[0, 1] * g + to_gamut[0, 2] * b
            t1 = to_gamut[1, 0] * r + to_gamut[1, 1] * g + to_gamut[1, 2] * b
            t2 = to_gamut[2, 0] * r + to_gamut[2, 1] * g + to_gamut[2, 2] * b
            if finite and not (t0 != t0 or t1 != t1 or t2 != t2) and \
                    min(t0, t1, t2) < threshold * abs(y):
                outside += 1
        elif below and finite and lowest < threshold * abs(y):
            outside += 1
        codes[i] = -1
        if finite and y > 0:
            code = float_bits(y) >> shift
            codes[i] = code
            first, last = min(first, code), max(last, code)
            low, high = min(low, y), max(high, y)
    if last < 0:
        return non_finite, negative, outside, low, high, 0, np.zeros(0, np.int64)
    histogram = np.zeros(last - first + 1, np.int64)
    for code in codes:
        if code >= 0:
            histogram[code - first] += 1
    return non_finite, negative, outside, low, high, first, histogram
