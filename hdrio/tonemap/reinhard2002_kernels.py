"""Fused, multi-threaded numba kernels behind the Reinhard (2002) paper operators.

The formulas are those of :mod:`hdrio.tonemap.reinhard2002` (which documents them and is
the public entry point); this module only evaluates them fast on large images:

* one pass over the pixels for the log-average key, one for everything per-pixel after it
  (luminance, scaling, compression, colour, clamp), with no full-size temporaries;
* the local operator's nine Gaussian blurs are separable FIR filters with the same
  kernels and mirrored borders as ``scipy.ndimage.gaussian_filter(..., truncate=4)``,
  evaluated tile by tile (a band of rows) together with the scale selection (eq. 8) and
  the colour step, so each blur lives only in a small per-tile buffer; a tile stops
  blurring as soon as every pixel in it has settled (the largest scale it needs);
* ``ln`` and ``x^s`` are branch-free polynomial evaluations (below) that the compiler
  vectorises; numba has no vectorised ``powf``/``logf`` without Intel's SVML.

Everything is float32 except the log sum and the exponent arithmetic of ``x^s`` (float64).
Kernels compile on first use and are cached on disk (``cache=True``). They are serial and
release the GIL; the entry points at the end share blocks of pixels (or bands of rows)
between threads (``HDRIO_THREADS``, default: the CPUs available). Plain threads rather
than ``parallel=True``: the same speed here, less to compile, and results that do not
depend on the thread count.

One file on purpose, although it is long: numba's disk cache is invalidated only by a
change to the file that defines the cached function, not to functions it calls from
other files (numba's "Notes on Caching", limitations), so a kernel and everything it
inlines live together.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from hdrio.float_bits import bits_float as _bits_float
from hdrio.float_bits import float_bits as _float_bits
from hdrio.jit import INNER
from hdrio.parallel import on_threads

TILE_ROWS = 16  # rows per tile of the local operator: 16 x 6000 float32 = 384 KB a buffer
COLUMN_BLOCK = 1024  # columns per block of the vertical blur: (2 r + 1) x 4 KB stays in L2
PIXEL_BLOCK = 1 << 16  # pixels per task of the per-pixel kernels
_COLOUR_BLOCK = 4096  # pixels per block of the colour step (48 KB of RGB in, 48 KB out)
_SQRT_HALF_BITS = 0x3F3504F3  # float32 bits of sqrt(1/2)
_LN2 = math.log(2.0)
_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}  # no zero-division branch
_INNER = dict(_JIT, cache=False, **INNER)  # helpers only other kernels call
# A helper called from one place is inlined by numba (``inline="always"``): no library of
# its own to compile (the global operator's first compile 2.65 -> 2.2 s of CPU). Not one
# compiled with other flags (``_log_sum_block``'s reassociation).

@numba.njit(inline="always", **_JIT)
def _log_parts(x: np.float32) -> tuple[int, np.float32]:
    """``(e, ln m)`` with ``x = 2^e m``, ``m`` in [sqrt(1/2), sqrt(2)), for finite ``x > 0``.

    ``ln m = 2 atanh(f)``, ``f = (m - 1) / (m + 1)``, to ``f^9`` (error < 1e-9).
    """
    shifted = _float_bits(x) - np.int32(_SQRT_HALF_BITS)
    m = _bits_float((shifted & np.int32(0x7FFFFF)) + np.int32(_SQRT_HALF_BITS))
    f = (m - np.float32(1.0)) / (m + np.float32(1.0))
    f2 = f * f
    p = np.float32(2.0 / 9.0) * f2 + np.float32(2.0 / 7.0)
    p = p * f2 + np.float32(2.0 / 5.0)
    p = p * f2 + np.float32(2.0 / 3.0)
    p = p * f2 + np.float32(2.0)
    return shifted >> 23, f * p


@numba.njit(inline="always", **_JIT)
def _ln(x: np.float32) -> float:
    """Natural log of a finite float32 ``x > 0``, as float64 (about 1e-7 absolute)."""
    e, ln_m = _log_parts(x)
    return e * _LN2 + np.float64(ln_m)


@numba.njit(inline="always", **_JIT)
def _exp(y: float) -> np.float32:
    """``e^y`` for float64 ``y``, float32 result (relative error about 2e-7), ``y``
    clamped to the normal float32 range (results in about [2^-126, 2^128))."""
    y = min(max(y, -126.0 * _LN2), 127.0 * _LN2)
    n = math.floor(y * (1.0 / _LN2) + 0.5)
    r = np.float32(y - n * _LN2)  # |r| <= ln(2) / 2
    p = np.float32(1.0 / 5040.0) * r + np.float32(1.0 / 720.0)
    p = p * r + np.float32(1.0 / 120.0)
    p = p * r + np.float32(1.0 / 24.0)
    p = p * r + np.float32(1.0 / 6.0)
    p = p * r + np.float32(0.5)
    p = p * r + np.float32(1.0)
    p = p * r + np.float32(1.0)
    return p * _bits_float((np.int64(n) + 127) << 23)


@numba.njit(inline="always", **_JIT)
def _power(x: np.float32, s: float) -> np.float32:
    """``x^s`` for float32 ``x >= 0`` (``0^0 = 1``, NaN stays NaN)."""
    if x != x:
        return x
    if x > 0:
        return _exp(s * _ln(x))
    return np.float32(1.0) if s == 0 else np.float32(0.0)


@numba.njit(inline="always", **_JIT)
def _channel(C: np.float32, L: np.float32, L_d: np.float32, saturation: float) -> np.float32:
    """``clip((C / L)^saturation L_d, 0, 1)``, the ratio taken as 0 where ``L <= 0``."""
    ratio = C / L if L > 0 else np.float32(0.0)
    if ratio < 0:
        ratio = np.float32(0.0)
    value = _power(ratio, saturation) * L_d
    if value < 0:
        return np.float32(0.0)
    return np.float32(1.0) if value > 1 else value


@numba.njit(inline="always", **_JIT)
def _luminance(rgb: np.ndarray, p: int, w: np.ndarray) -> np.float32:
    return w[0] * rgb[3 * p] + w[1] * rgb[3 * p + 1] + w[2] * rgb[3 * p + 2]


@numba.njit(**_INNER)
def _colour_channel(C: np.ndarray, L: np.ndarray, L_d: np.ndarray, saturation: float) -> None:
    for p in range(C.shape[0]):
        C[p] = _channel(C[p], L[p], L_d[p], saturation)


@numba.njit(inline="always", **_INNER)
def _colour(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray, L_d: np.ndarray,
            saturation: float) -> None:
    """The colour step for flat RGB ``rgb`` into ``out``, given ``L_d`` per pixel.

    A block at a time (it stays in cache): split the channels into contiguous buffers
    (with the luminance), one loop per channel, then interleave them again. These are the
    shapes the compiler vectorises; one loop over interleaved RGB is not vectorised, and
    a strided store per channel becomes a slow scatter.
    """
    n = L_d.shape[0]
    buffers = np.empty((4, min(n, _COLOUR_BLOCK)), dtype=np.float32)
    for p0 in range(0, n, _COLOUR_BLOCK):
        p1 = min(n, p0 + _COLOUR_BLOCK)
        src, dst, block = rgb[3 * p0: 3 * p1], out[3 * p0: 3 * p1], L_d[p0:p1]
        r, g, b, L = (buffers[0, : p1 - p0], buffers[1, : p1 - p0], buffers[2, : p1 - p0],
                      buffers[3, : p1 - p0])
        for p in range(p1 - p0):
            r[p], g[p], b[p] = src[3 * p], src[3 * p + 1], src[3 * p + 2]
            L[p] = _luminance(src, p, weights)
        _colour_channel(r, L, block, saturation)
        _colour_channel(g, L, block, saturation)
        _colour_channel(b, L, block, saturation)
        for p in range(p1 - p0):
            dst[3 * p], dst[3 * p + 1], dst[3 * p + 2] = r[p], g[p], b[p]


@numba.njit(**_INNER, fastmath={"reassoc"})
def _log_sum_block(rgb: np.ndarray, weights: np.ndarray, delta: float) -> float:
    total = 0.0
    for p in range(rgb.shape[0] // 3):
        L = max(np.float64(_luminance(rgb, p, weights)), 0.0)
        total += _ln(np.float32(delta + L))
    return total


@numba.njit(**_JIT)
def _log_sum_blocks(start: int, stop: int, rgb: np.ndarray, weights: np.ndarray,
                    delta: float, partial: np.ndarray) -> None:
    n = rgb.shape[0] // 3
    for b in range(start, stop):
        end = min(n, (b + 1) * PIXEL_BLOCK)
        partial[b] = _log_sum_block(rgb[3 * b * PIXEL_BLOCK: 3 * end], weights, delta)


@numba.njit(inline="always", **_INNER)
def _global_block(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray, scale: np.float32,
                  use_white: bool, white_squared: np.float32, saturation: float) -> None:
    one = np.float32(1.0)
    n = rgb.shape[0] // 3
    L_d = np.empty(_COLOUR_BLOCK, dtype=np.float32)  # small: from the heap, no page faults
    for p0 in range(0, n, _COLOUR_BLOCK):
        p1 = min(n, p0 + _COLOUR_BLOCK)
        src = rgb[3 * p0: 3 * p1]
        for p in range(p1 - p0):
            L_m = scale * _luminance(src, p, weights)
            if use_white:
                L_d[p] = L_m * (one + L_m / white_squared) / (one + L_m)
            else:
                L_d[p] = L_m / (one + L_m)
        _colour(src, out[3 * p0: 3 * p1], weights, L_d[: p1 - p0], saturation)


@numba.njit(**_JIT)
def _global_blocks(start: int, stop: int, rgb: np.ndarray, out: np.ndarray,
                   weights: np.ndarray, scale: np.float32, use_white: bool,
                   white_squared: np.float32, saturation: float) -> None:
    n = rgb.shape[0] // 3
    for b in range(start, stop):
        begin, end = 3 * b * PIXEL_BLOCK, 3 * min(n, (b + 1) * PIXEL_BLOCK)
        _global_block(rgb[begin:end], out[begin:end], weights, scale, use_white,
                      white_squared, saturation)


@numba.njit(inline="always", **_INNER)
def _scale_block(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray,
                 scale: np.float32) -> None:
    for p in range(rgb.shape[0] // 3):
        out[p] = scale * _luminance(rgb, p, weights)


@numba.njit(**_JIT)
def _scale_blocks(start: int, stop: int, rgb: np.ndarray, out: np.ndarray,
                  weights: np.ndarray, scale: np.float32) -> None:
    n = rgb.shape[0] // 3
    for b in range(start, stop):
        end = min(n, (b + 1) * PIXEL_BLOCK)
        _scale_block(rgb[3 * b * PIXEL_BLOCK: 3 * end], out[b * PIXEL_BLOCK: end], weights,
                     scale)


@numba.njit(inline="always", **_JIT)
def _mirror(i: int, n: int) -> int:
    """Index ``i`` reflected about the first and last samples' centres (scipy ``mirror``)."""
    if n == 1:
        return 0
    period = 2 * (n - 1)
    i = abs(i) % period
    return i if i < n else period - i


@numba.njit(**_INNER)
def _axpy_pair(acc: np.ndarray, k: np.float32, a: np.ndarray, b: np.ndarray) -> None:
    for x in range(acc.shape[0]):
        acc[x] += k * (a[x] + b[x])


@numba.njit(**_INNER)
def _axpy_pairs4(acc: np.ndarray, k: np.ndarray, a0: np.ndarray, b0: np.ndarray,
                 a1: np.ndarray, b1: np.ndarray, a2: np.ndarray, b2: np.ndarray,
                 a3: np.ndarray, b3: np.ndarray) -> None:
    """Four symmetric taps at once (one pass over ``acc`` instead of four)."""
    k0, k1, k2, k3 = k[0], k[1], k[2], k[3]
    for x in range(acc.shape[0]):
        acc[x] += (k0 * (a0[x] + b0[x]) + k1 * (a1[x] + b1[x])
                   + (k2 * (a2[x] + b2[x]) + k3 * (a3[x] + b3[x])))


@numba.njit(**_INNER)
def _scaled_copy(acc: np.ndarray, k: np.float32, a: np.ndarray) -> None:
    for x in range(acc.shape[0]):
        acc[x] = k * a[x]


@numba.njit(**_JIT)
def _blur_rows(L_m: np.ndarray, y0: int, kernel: np.ndarray, vertical: np.ndarray,
               padded: np.ndarray, out: np.ndarray) -> None:
    """Rows ``y0 .. y0 + len(out)`` of ``L_m`` blurred with the symmetric odd ``kernel``
    along axis 0, then axis 1 (as scipy), mirrored at the borders, into ``out``.

    Taps are applied four at a time, folded (``k_t (x_{-t} + x_t)``), as scipy does."""
    height, width = L_m.shape
    rows = out.shape[0]
    r = kernel.shape[0] // 2
    k = kernel[r:]  # k[t] for t = 0 .. r
    for x0 in range(0, width, COLUMN_BLOCK):  # vertical pass, a block of columns at a time
        x1 = min(x0 + COLUMN_BLOCK, width)
        for j in range(rows):
            y = y0 + j
            acc = vertical[j, x0:x1]
            _scaled_copy(acc, k[0], L_m[_mirror(y, height), x0:x1])
            t = 1
            while t + 3 <= r:
                _axpy_pairs4(acc, k[t: t + 4],
                             L_m[_mirror(y - t, height), x0:x1],
                             L_m[_mirror(y + t, height), x0:x1],
                             L_m[_mirror(y - t - 1, height), x0:x1],
                             L_m[_mirror(y + t + 1, height), x0:x1],
                             L_m[_mirror(y - t - 2, height), x0:x1],
                             L_m[_mirror(y + t + 2, height), x0:x1],
                             L_m[_mirror(y - t - 3, height), x0:x1],
                             L_m[_mirror(y + t + 3, height), x0:x1])
                t += 4
            for u in range(t, r + 1):
                _axpy_pair(acc, k[u], L_m[_mirror(y - u, height), x0:x1],
                           L_m[_mirror(y + u, height), x0:x1])
    line = padded[: width + 2 * r]
    for j in range(rows):  # horizontal pass, through a row padded with its mirror image
        row = vertical[j]
        for x in range(width):  # element by element: hdrio.jit, "Slice copies"
            line[r + x] = row[x]
        for x in range(r):
            line[x] = row[_mirror(x - r, width)]
            line[r + width + x] = row[_mirror(width + x, width)]
        dst = out[j]
        _scaled_copy(dst, k[0], line[r: r + width])
        t = 1
        while t + 3 <= r:
            _axpy_pairs4(dst, k[t: t + 4],
                         line[r - t: r - t + width], line[r + t: r + t + width],
                         line[r - t - 1: r - t - 1 + width], line[r + t + 1: r + t + 1 + width],
                         line[r - t - 2: r - t - 2 + width], line[r + t + 2: r + t + 2 + width],
                         line[r - t - 3: r - t - 3 + width], line[r + t + 3: r + t + 3 + width])
            t += 4
        for u in range(t, r + 1):
            _axpy_pair(dst, k[u], line[r - u: r - u + width], line[r + u: r + u + width])


@numba.njit(**_INNER)
def _select(v1: np.ndarray, v1_next: np.ndarray, chosen: np.ndarray, open_: np.ndarray,
            surround: np.float32, epsilon: np.float32) -> int:
    """One step of eq. 8 on flat tile buffers; returns how many pixels are still open."""
    still_open = 0
    for p in range(v1.shape[0]):
        activity = abs(v1[p] - v1_next[p]) / (surround + v1[p])
        keep = open_[p] and not activity > epsilon
        open_[p] = keep
        if keep:
            chosen[p] = v1[p]
            still_open += 1
    return still_open


@numba.njit(**_INNER)
def _local_tile(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray, L_m: np.ndarray,
                y0: int, rows: int, kernels: np.ndarray, radii: np.ndarray,
                surround: np.ndarray, epsilon: np.float32, saturation: float,
                workspace: np.ndarray, padded: np.ndarray, open_: np.ndarray) -> None:
    """Rows ``y0 .. y0 + rows`` of the local operator; ``workspace`` holds four
    ``TILE_ROWS x width`` buffers (blurred columns, ``V1(s)``, ``V1(1.6 s)``, chosen)."""
    width = L_m.shape[1]
    size = rows * width
    vertical = workspace[0, :rows]
    v1 = workspace[1, :rows]
    v1_next = workspace[2, :rows]
    chosen = workspace[3, :rows].reshape(size)
    open_ = open_[:size]
    open_[:] = True
    _blur_rows(L_m, y0, kernels[0, : 2 * radii[0] + 1], vertical, padded, v1)
    first = v1.reshape(size)
    for p in range(size):  # element by element: hdrio.jit, "Slice copies"
        chosen[p] = first[p]
    for i in range(kernels.shape[0] - 1):
        _blur_rows(L_m, y0, kernels[i + 1, : 2 * radii[i + 1] + 1], vertical, padded, v1_next)
        if _select(v1.reshape(size), v1_next.reshape(size), chosen, open_, surround[i],
                   epsilon) == 0:
            break  # every pixel of the tile has its scale: no wider blur is needed
        v1, v1_next = v1_next, v1
    L_m_tile = L_m[y0: y0 + rows].reshape(size)
    for p in range(size):  # eq. 9, in place
        chosen[p] = L_m_tile[p] / (np.float32(1.0) + chosen[p])
    start = 3 * y0 * width
    _colour(rgb[start: start + 3 * size], out[start: start + 3 * size], weights, chosen,
            saturation)


@numba.njit(**_JIT)
def _local_tiles(start: int, stop: int, rgb: np.ndarray, out: np.ndarray, weights: np.ndarray,
                 L_m: np.ndarray, kernels: np.ndarray, radii: np.ndarray,
                 surround: np.ndarray, epsilon: np.float32, saturation: float) -> None:
    height, width = L_m.shape
    workspace = np.empty((4, TILE_ROWS, width), dtype=np.float32)  # once per chunk
    padded = np.empty(width + 2 * radii.max(), dtype=np.float32)
    open_ = np.empty(TILE_ROWS * width, dtype=np.bool_)
    for tile in range(start, stop):
        y0 = tile * TILE_ROWS
        _local_tile(rgb, out, weights, L_m, y0, min(TILE_ROWS, height - y0), kernels, radii,
                    surround, epsilon, saturation, workspace, padded, open_)


@numba.njit(inline="always", **_JIT)
def _blocks(pixels: int) -> int:
    return (pixels + PIXEL_BLOCK - 1) // PIXEL_BLOCK


# --- the entry points: split the blocks (or bands of rows) between threads -----------------

def log_luminance_sum(rgb: np.ndarray, weights: np.ndarray, delta: float) -> float:
    """``sum(ln(delta + max(L, 0)))`` over the pixels of ``rgb`` (3N flat float32, ``L`` its
    luminance with ``weights``), float64. Negative luminance counts as 0. Partial sums
    are added in block order: the result does not depend on the thread count."""
    partial = np.zeros(_blocks(rgb.shape[0] // 3))
    on_threads(_log_sum_blocks, partial.shape[0], rgb, weights, float(delta), partial)
    return float(partial.sum())


def global_operator(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray, scale: np.float32,
                    use_white: bool, white_squared: np.float32, saturation: float) -> None:
    """Eqs. 2-4 and the colour step from ``rgb`` into ``out`` (both 3N flat float32;
    relative linear RGB in, display-linear [0, 1] out); ``scale = a / L_bar``; eq. 4 with
    ``L_white^2 = white_squared`` if ``use_white``, else eq. 3.

    Outputs are allocated by the caller with numpy, which asks Linux for huge pages: a
    fresh 288 MB array from numba's allocator cost as much in page faults as the work.
    """
    on_threads(_global_blocks, _blocks(rgb.shape[0] // 3), rgb, out, weights, scale,
                use_white, white_squared, saturation)


def scaled_luminance(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray,
                     scale: np.float32) -> None:
    """``L_m = scale L`` (eq. 2) from ``rgb`` (3N flat float32) into ``out`` (N float32)."""
    on_threads(_scale_blocks, _blocks(rgb.shape[0] // 3), rgb, out, weights, scale)


def local_operator(rgb: np.ndarray, out: np.ndarray, weights: np.ndarray, L_m: np.ndarray,
                   kernels: np.ndarray, radii: np.ndarray, surround: np.ndarray,
                   epsilon: np.float32, saturation: float) -> None:
    """Eqs. 5-9 and the colour step, a band of ``TILE_ROWS`` rows at a time.

    ``rgb`` and ``out`` are the H x W x 3 float32 images, flat (``out`` allocated by the
    caller, see :func:`global_operator`), ``L_m`` the H x W scaled luminance (eq. 2),
    ``kernels[i, :2 radii[i] + 1]`` the blur of scale ``i``, ``surround[i] = 2^phi a /
    s_i^2``.
    """
    bands = (L_m.shape[0] + TILE_ROWS - 1) // TILE_ROWS
    on_threads(_local_tiles, bands, rgb, out, weights, L_m, kernels, radii, surround,
                epsilon, saturation)


def gaussian_kernel_scipy(sigma: float, truncate: float = 4.0) -> np.ndarray:
    """The 1-D kernel of ``scipy.ndimage.gaussian_filter(sigma, truncate=truncate)``.

    Radius ``int(truncate sigma + 0.5)`` pixels, samples ``exp(-x^2 / (2 sigma^2))``
    normalised to sum 1, float64 (``scipy.ndimage._filters._gaussian_kernel1d``).
    """
    radius = int(truncate * float(sigma) + 0.5)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    phi = np.exp(-0.5 / (sigma * sigma) * x**2)
    return phi / phi.sum()

