"""Half floats (IEEE-754 binary16) inside numba kernels, bit for bit as NumPy makes them.

numba has no ``float16``; a half is kept as its 16 bits (``uint16``, viewed as
``numpy.float16`` outside the kernels). :func:`half_bits` rounds a float32 to the nearest
half, ties to even, as ``numpy.float32(...).astype(numpy.float16)`` does (NumPy's
``npy_floatbits_to_halfbits``): subnormal halves, overflow to infinity, NaN kept a NaN.
:func:`half_value` is the float32 equal to a half (exact: every half is a float32).
:func:`to_half` writes an EXR band's half bits on every core: what NumPy's ``astype``
did on one thread at 8 ns a value (0.6 s of a 24 MP RGB image's write, in a stage that
did not get faster with cores).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hdrio.float_bits import bits_float, float_bits
from hdrio.jit import INNER
from hdrio.parallel import on_threads


@njit(inline="always", **INNER)
def half_bits(value):
    """The bits of the half nearest ``value`` (float32), ties to even."""
    f = np.int64(float_bits(np.float32(value))) & 0xFFFFFFFF
    sign = (f & 0x80000000) >> 16
    exponent = f & 0x7F800000
    if exponent >= 0x47800000:  # overflow, infinity or NaN
        significand = f & 0x007FFFFF
        if exponent == 0x7F800000 and significand != 0:  # NaN stays a NaN
            bits = 0x7C00 + (significand >> 13)
            return np.uint16(sign + (bits + 1 if bits == 0x7C00 else bits))
        return np.uint16(sign + 0x7C00)
    if exponent <= 0x38000000:  # a subnormal half, or signed zero
        if exponent < 0x33000000:
            return np.uint16(sign)
        significand = (0x00800000 + (f & 0x007FFFFF)) >> (113 - (exponent >> 23))
        if (significand & 0x3FFF) != 0x1000 or (f & 0x7FF) != 0:
            significand += 0x1000
        return np.uint16(sign + (significand >> 13))
    significand = f & 0x007FFFFF
    if (significand & 0x3FFF) != 0x1000:
        significand += 0x1000
    # A carry out of the significand raises the exponent: that is the right rounding.
    return np.uint16(sign + ((exponent - 0x38000000) >> 13) + (significand >> 13))


@njit(inline="always", **INNER)
def half_value(bits):
    """The float32 equal to the half whose bits are ``bits``."""
    h = np.int64(bits) & 0xFFFF
    sign = (h & 0x8000) << 16
    exponent = (h >> 10) & 0x1F
    significand = h & 0x3FF
    if exponent == 0x1F:  # infinity or NaN
        return bits_float(sign | 0x7F800000 | (significand << 13))
    if exponent == 0:  # zero or subnormal: significand x 2**-24
        value = np.float32(significand) * np.float32(2.0 ** -24)
        return -value if sign else value
    return bits_float(sign | ((exponent + 112) << 23) | (significand << 13))


@njit(inline="always", **INNER)
def _scaled_half(value, scale, low, high, floor):
    """The half bits of ``value * scale`` clipped to ``[low, high]`` in float32, a value
    in ``[0, floor)`` raised to ``floor`` (NaN stays NaN, as ``numpy.clip`` leaves it)."""
    value = value * scale
    if value < low:
        value = low
    elif value > high:
        value = high
    if value >= 0 and value < floor:
        value = floor
    return half_bits(value)


@njit(cache=True, nogil=True)
def _to_half_values(source, scale, low, high, floor, out):
    """:func:`_to_half_rows` of flat values sharing one channel's numbers (a loop the
    compiler vectorises: 1.2 ns a value on one core, against 8 for NumPy's ``astype``)."""
    for i in range(source.size):
        out[i] = _scaled_half(source[i], scale, low, high, floor)


@njit(cache=True, nogil=True)
def _to_half_rows(source, scales, lows, highs, floors, out):
    """``out[y, x, c]`` the half bits of ``source[y, x, c] * scales[c]`` clipped to
    ``[lows[c], highs[c]]``, raised to ``floors[c]`` from 0."""
    for y in range(source.shape[0]):
        for x in range(source.shape[1]):
            for c in range(source.shape[2]):
                out[y, x, c] = _scaled_half(source[y, x, c], scales[c], lows[c], highs[c],
                                            floors[c])


def to_half(source: np.ndarray, scales: np.ndarray, lows: np.ndarray, highs: np.ndarray,
            observe=None, floors: np.ndarray | None = None) -> np.ndarray:
    """``(rows, W, C)`` float32 pixels as half (``float16``), each channel ``c`` scaled by
    ``scales[c]`` and clipped to ``[lows[c], highs[c]]`` in float32 first, on every core;
    where ``floors`` are given, a value from 0 up to ``floors[c]`` becomes ``floors[c]``
    (a merge's radiance: no pixel 0; negative values are left as they are).
    ``observe(rows)``, when given, sees each piece of the result (``float16``) on the
    thread that made it, while it is in the cache; it must be safe to call from several
    threads at once."""
    source = np.ascontiguousarray(source, dtype=np.float32)
    out = np.empty(source.shape, dtype=np.uint16)
    factors, low, high = (np.asarray(v, dtype=np.float32) for v in (scales, lows, highs))
    floor = np.zeros_like(low) if floors is None else np.asarray(floors, dtype=np.float32)
    shared = bool(np.all(factors == factors[0]) and np.all(low == low[0])
                  and np.all(high == high[0]) and np.all(floor == floor[0]))

    def piece(top: int, bottom: int) -> None:
        if shared:  # every channel alike (RGB without layers): one flat loop
            _to_half_values(source[top:bottom].reshape(-1), factors[0], low[0], high[0],
                            floor[0], out[top:bottom].reshape(-1))
        else:
            _to_half_rows(source[top:bottom], factors, low, high, floor, out[top:bottom])
        if observe is not None:
            observe(out[top:bottom].view(np.float16))

    on_threads(piece, source.shape[0])
    return out.view(np.float16)
