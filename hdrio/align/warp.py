"""Resampling a bracket's code values through a warp without changing what codes mean.

Output pixel ``x`` takes the moving bracket at ``W x``. Where the 4x4 codes around
``W x`` are all strictly between 0 and ``Z_max`` in a channel, that channel is
interpolated by Keys' cubic convolution (in code values, clamped to the four nearest
codes so an edge does not overshoot, then rounded: a sub-pixel shift is a blend of
neighbours of the same kind; bilinear blurred the textured truth scenes enough to
double the merge's error there); where one of those is clipped or black but not the
four nearest, bilinearly; where any of the four is clipped or black it takes the
nearest code, so a saturated code is never blended with an unsaturated one (a blend
would be a well-exposed-looking code of no real radiance). Pixels whose ``W x`` falls
outside the bracket take the nearest edge code *and* are reported uncovered (the merge
drops them: :func:`coverage`), never invented from another bracket.

Speed: an affine warp close to a shift (what ``translation`` and ``euclidean`` find) is
resampled in runs of output pixels whose 4x4 neighbourhoods move one pixel at a time, by
a branch-free float32 loop over the run's samples that the compiler vectorises (all
three rules computed, one selected); rows are shared among hdrio's threads. At 24 MP
that is about 0.33 s of CPU a bracket, against 1.5-2.2 s for the float64 loop pixel by
pixel, which still does homographies and the borders; the two agree to the code except
where float32 rounds a value within about 1e-6 of a half the other way (1 code, a few
samples in a million at 8 bits).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hdrio.parallel import on_threads, row_bands
from hdrio.stack import every_channel, some_channel

RUN_SLOPE = 0.125
"""Affine warps whose neighbourhoods drift by less than this (pixels per output pixel,
each way) are resampled in runs (:func:`_warp_rows`): runs of 8 pixels or more; a
steeper warp (a scaled grid, a large rotation) pixel by pixel."""


@njit(cache=True, nogil=True)
def _keys(t, weights):  # pragma: no cover - compiled
    """Keys' cubic convolution weights (a = -0.5) for offsets ``-1, 0, 1, 2`` at ``t``,
    into ``weights`` (an array: numba indexes a tuple by a loop variable slowly)."""
    t2 = t * t
    t3 = t2 * t
    weights[0] = -0.5 * t3 + t2 - 0.5 * t
    weights[1] = 1.5 * t3 - 2.5 * t2 + 1.0
    weights[2] = -1.5 * t3 + 2.0 * t2 + 0.5 * t
    weights[3] = 0.5 * t3 - 0.5 * t2


@njit(cache=True, nogil=True)
def _source(warp, x, y, width, height):  # pragma: no cover - compiled
    """``W (x, y, 1)``, clamped to the bracket."""
    w = warp[2, 0] * x + warp[2, 1] * y + warp[2, 2]
    sx = (warp[0, 0] * x + warp[0, 1] * y + warp[0, 2]) / w
    sy = (warp[1, 0] * x + warp[1, 1] * y + warp[1, 2]) / w
    return min(max(sx, 0.0), width - 1.0), min(max(sy, 0.0), height - 1.0)


@njit(cache=True, nogil=True)
def _pixel(codes, sx, sy, code_max, interpolate, out, y, x, wx, wy):  # pragma: no cover
    """Output pixel ``(y, x)`` from the bracket at ``(sx, sy)``, one channel at a time:
    the rules of the module's docstring, in float64."""
    height, width, channels = codes.shape
    x0 = int(sx)
    y0 = int(sy)
    fx = sx - x0
    fy = sy - y0
    nx = min(x0 + 1, width - 1) if fx >= 0.5 else x0
    ny = min(y0 + 1, height - 1) if fy >= 0.5 else y0
    cubic = interpolate and 1 <= x0 < width - 2 and 1 <= y0 < height - 2
    _keys(fx, wx)
    _keys(fy, wy)
    for c in range(channels):
        if not cubic:
            out[y, x, c] = codes[ny, nx, c]
            continue
        inside = True  # all 16 usable
        near = True  # the 4 nearest usable
        low = code_max
        high = 0
        value = 0.0
        for i in range(4):
            row = 0.0
            for k in range(4):
                z = codes[y0 - 1 + i, x0 - 1 + k, c]
                usable = (z > 0) & (z < code_max)
                inside &= usable
                row += wx[k] * z
                if 1 <= i <= 2 and 1 <= k <= 2:
                    near &= usable
                    low = min(low, z)
                    high = max(high, z)
            value += wy[i] * row
        if inside:  # clamped to the four nearest: no overshoot at edges
            out[y, x, c] = int(min(max(value, low), high) + 0.5)
        elif near:
            a = codes[y0, x0, c]
            b = codes[y0, x0 + 1, c]
            d = codes[y0 + 1, x0, c]
            e = codes[y0 + 1, x0 + 1, c]
            value = ((1.0 - fy) * ((1.0 - fx) * a + fx * b)
                     + fy * ((1.0 - fx) * d + fx * e))
            out[y, x, c] = int(value + 0.5)
        else:
            out[y, x, c] = codes[ny, nx, c]


@njit(cache=True, nogil=True, inline="always")
def _keys32(t):  # pragma: no cover - compiled
    """:func:`_keys` in float32, as a tuple (for the vectorised loop)."""
    t2 = t * t
    t3 = t2 * t
    h = np.float32(0.5)
    return (-h * t3 + t2 - h * t, np.float32(1.5) * t3 - np.float32(2.5) * t2 + np.float32(1.0),
            np.float32(-1.5) * t3 + np.float32(2.0) * t2 + h * t, h * t3 - h * t2)


@njit(cache=True, nogil=True)
def _run3(r0, r1, r2, r3, o, count, fx0, dfx, fy0, dfy, code_max):  # pragma: no cover
    """``count`` pixels of three channels along an output row whose 4x4 neighbourhoods
    are at the same place in the rows ``r0 .. r3`` (flattened ``(W * 3,)``, starting at
    the first pixel's top-left neighbour) one pixel further each: the module's rules in
    float32, branch-free, so that the compiler vectorises the loop over samples.
    ``fx0 + dfx * k``, ``fy0 + dfy * k``: pixel ``k``'s offsets from its neighbourhood's
    second column and row (an affine warp)."""
    top = np.float32(code_max)
    fx0 = np.float32(fx0)
    dfx = np.float32(dfx)
    fy0 = np.float32(fy0)
    dfy = np.float32(dfy)
    half = np.float32(0.5)
    one = np.float32(1.0)
    zero = np.float32(0.0)
    for j in range(3 * count):  # from 0: no negative-index fix-ups, contiguous loads
        k = np.float32(j // 3)
        fx = fx0 + dfx * k
        fy = fy0 + dfy * k
        wx0, wx1, wx2, wx3 = _keys32(fx)
        wy0, wy1, wy2, wy3 = _keys32(fy)
        a0, a1, a2, a3 = (np.float32(r0[j]), np.float32(r0[j + 3]), np.float32(r0[j + 6]),
                          np.float32(r0[j + 9]))
        b0, b1, b2, b3 = (np.float32(r1[j]), np.float32(r1[j + 3]), np.float32(r1[j + 6]),
                          np.float32(r1[j + 9]))
        c0, c1, c2, c3 = (np.float32(r2[j]), np.float32(r2[j + 3]), np.float32(r2[j + 6]),
                          np.float32(r2[j + 9]))
        d0, d1, d2, d3 = (np.float32(r3[j]), np.float32(r3[j + 3]), np.float32(r3[j + 6]),
                          np.float32(r3[j + 9]))
        low4 = min(min(b1, b2), min(c1, c2))
        high4 = max(max(b1, b2), max(c1, c2))
        low = min(min(min(a0, a1), min(a2, a3)), min(min(d0, d1), min(d2, d3)))
        low = min(min(low, low4), min(min(b0, b3), min(c0, c3)))
        high = max(max(max(a0, a1), max(a2, a3)), max(max(d0, d1), max(d2, d3)))
        high = max(max(high, high4), max(max(b0, b3), max(c0, c3)))
        value = (wy0 * (wx0 * a0 + wx1 * a1 + wx2 * a2 + wx3 * a3)
                 + wy1 * (wx0 * b0 + wx1 * b1 + wx2 * b2 + wx3 * b3)
                 + wy2 * (wx0 * c0 + wx1 * c1 + wx2 * c2 + wx3 * c3)
                 + wy3 * (wx0 * d0 + wx1 * d1 + wx2 * d2 + wx3 * d3))
        cubic = min(max(value, low4), high4)
        gx = one - fx
        linear = (one - fy) * (gx * b1 + fx * b2) + fy * (gx * c1 + fx * c2)
        upper = b2 if fx >= half else b1
        lower = c2 if fx >= half else c1
        nearest = lower if fy >= half else upper
        inside = (low > zero) & (high < top)
        near = (low4 > zero) & (high4 < top)
        o[j] = np.int32((cubic if inside else (linear if near else nearest)) + half)


@njit(cache=True, nogil=True)
def _same_run(warp, e, y, width, height, off, y0):  # pragma: no cover - compiled
    """Whether output pixel ``(y, e)`` has its cubic neighbourhood inside the bracket at
    column ``e + off - 1`` and row ``y0 - 1``."""
    sx, sy = _source(warp, e, y, width, height)
    x0 = int(sx)
    return x0 - e == off and int(sy) == y0 and x0 < width - 2


@njit(cache=True, nogil=True)
def _run_end(warp, x, y, fx, fy, off, columns, width):  # pragma: no cover - compiled
    """Where the run starting at output pixel ``(y, x)`` should end, from the affine warp's
    slopes: ``fx``, ``fy`` (the start's offsets in its neighbourhood) leave ``[0, 1)``, or
    the neighbourhood the bracket's last columns (checked by the caller)."""
    end = min(columns, width - 2 - off)
    for offset, slope in ((fx, warp[0, 0] - 1.0), (fy, warp[1, 0])):
        if slope == 0.0:
            continue
        limit = x + 1.0 + ((1.0 - offset) / slope if slope > 0.0 else offset / -slope)
        if limit < end:  # compared as floats: a tiny slope's limit overflows an int
            end = int(limit)
    return max(end, x + 1)


@njit(cache=True, nogil=True)
def _warp_rows(start, stop, codes, flat, warp, code_max, interpolate, out,
               out_flat):  # pragma: no cover - compiled
    """Output rows ``start .. stop - 1``. An affine warp of three channels close to a
    shift (:data:`RUN_SLOPE`) is done in runs of pixels whose neighbourhoods step one
    pixel at a time (the whole row for a shift; about ``1 / sin(angle)`` pixels for a
    rotation; a run's end computed from the warp's slopes, then checked pixel by pixel
    around it), through :func:`_run3`; everything else (a homography, the borders) pixel
    by pixel."""
    height, width, channels = codes.shape
    columns = out.shape[1]
    fast = (interpolate and channels == 3 and warp[2, 0] == 0.0 and warp[2, 1] == 0.0
            and warp[2, 2] == 1.0 and abs(warp[0, 0] - 1.0) < RUN_SLOPE
            and abs(warp[1, 0]) < RUN_SLOPE)
    wx = np.empty(4)
    wy = np.empty(4)
    for y in range(start, stop):
        x = 0
        while x < columns:
            sx, sy = _source(warp, x, y, width, height)
            x0 = int(sx)
            y0 = int(sy)
            if not (fast and 1 <= x0 < width - 2 and 1 <= y0 < height - 2):
                _pixel(codes, sx, sy, code_max, interpolate, out, y, x, wx, wy)
                x += 1
                continue
            off = x0 - x
            end = _run_end(warp, x, y, sx - x0, sy - y0, off, columns, width)
            while end > x + 1 and not _same_run(warp, end - 1, y, width, height, off, y0):
                end -= 1  # the estimate checked: the run is x .. end - 1
            while end < columns and _same_run(warp, end, y, width, height, off, y0):
                end += 1
            base = 3 * (x0 - 1)
            _run3(flat[y0 - 1, base:], flat[y0, base:], flat[y0 + 1, base:],
                  flat[y0 + 2, base:], out_flat[y, 3 * x:], end - x, sx - x0,
                  warp[0, 0] - 1.0, sy - y0, warp[1, 0], code_max)
            x = end


def warp_codes(codes: np.ndarray, warp: np.ndarray, code_max: int,
               out: np.ndarray | None = None, interpolate: bool = True) -> np.ndarray:
    """``codes`` ``(H, W, C)`` resampled at ``warp @ (x, y, 1)`` (full-resolution pixels).

    ``out`` (same dtype, not ``codes`` itself; by default ``codes``' shape) receives the
    result, for ``x, y`` over its own rows and columns. ``interpolate`` false takes the
    nearest code everywhere. Rows are shared among hdrio's threads
    (:func:`hdrio.parallel.on_threads`)."""
    if out is None:
        out = np.empty_like(codes)
    codes = np.ascontiguousarray(codes)
    target = out if out.flags.c_contiguous else np.empty_like(out)
    flat = codes.reshape(codes.shape[0], -1)
    on_threads(_warp_rows, out.shape[0], codes, flat,
               np.ascontiguousarray(warp, np.float64), int(code_max), bool(interpolate),
               target, target.reshape(target.shape[0], -1))
    if target is not out:
        out[...] = target
    return out


def coverage(warp: np.ndarray, height: int, width: int, factor: int,
             source: tuple[int, int] | None = None) -> np.ndarray:
    """``(ceil(H / factor), ceil(W / factor))`` float32 cells: 1 where every pixel of the
    cell maps inside the bracket (``source``: its height and width, by default ``H, W``),
    else 0 (the cell's corners are tested: a warp close to the identity maps a cell to a
    convex quadrilateral)."""
    rows, cols = -(-height // factor), -(-width // factor)
    source_height, source_width = source or (height, width)
    ys = np.minimum(np.arange(rows + 1) * factor, height) - 0.5
    x = (np.minimum(np.arange(cols + 1) * factor, width) - 0.5)[None, :]
    inside = np.empty((rows + 1, cols + 1), bool)
    bands = row_bands(inside)
    for top in bands:  # band by band of rows: no full-size float64 grids (96 MB each)
        y = ys[top:top + bands.step, None]
        w = warp[2, 0] * x + warp[2, 1] * y + warp[2, 2]
        sx = (warp[0, 0] * x + warp[0, 1] * y + warp[0, 2]) / w
        sy = (warp[1, 0] * x + warp[1, 1] * y + warp[1, 2]) / w
        inside[top:top + bands.step] = ((sx >= -0.5) & (sx <= source_width - 0.5)
                                        & (sy >= -0.5) & (sy <= source_height - 0.5))
    cells = inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]
    return cells.astype(np.float32)


def clipped_elsewhere(codes: np.ndarray, code_max: int, others, j: int,
                      cell: int) -> np.ndarray:
    """``(rows, cols)`` cells of ``cell`` pixels holding a pixel that every bracket of
    ``others`` has clipped (some channel at ``code_max``) and bracket ``j`` sees with
    every channel below it: a highlight that only ``j`` shows (a sun that only the
    darkest frame through an ND filter reads). :func:`seen_elsewhere` is decided on half
    of a cell, and a sun's core is a few pixels of it."""
    count, height, width, channels = codes.shape
    rows, cols = -(-height // cell), -(-width // cell)
    top = (code_max,) * channels
    only = every_channel(codes[j], np.less, top)
    for k in others:
        only &= some_channel(codes[k], np.greater_equal, top)
    padded = np.zeros((rows * cell, cols * cell), bool)
    padded[:height, :width] = only
    return padded.reshape(rows, cell, cols, cell).any(axis=(1, 3))


def seen_elsewhere(codes: np.ndarray, code_max: int, others, cell: int) -> np.ndarray:
    """``(rows, cols)`` cells of ``cell`` pixels where some bracket of ``others`` has
    every channel strictly between 0 and ``code_max`` at half of the cell's pixels or
    more (every second pixel each way): a registered bracket sees the scene there, so an
    unregistered one, left unwarped, is not merged there (it would put the scene in the
    wrong place)."""
    count, height, width, channels = codes.shape
    rows, cols = -(-height // cell), -(-width // cell)
    seen = np.zeros((rows, cols), bool)
    for j in others:
        sample = codes[j, ::2, ::2]
        inside = (every_channel(sample, np.greater, (0,) * channels)
                  & every_channel(sample, np.less, (code_max,) * channels)).astype(np.float32)
        per = cell // 2
        padded = np.zeros((rows * per, cols * per), np.float32)
        padded[:inside.shape[0], :inside.shape[1]] = inside
        seen |= padded.reshape(rows, per, cols, per).mean(axis=(1, 3)) >= 0.5
    return seen
