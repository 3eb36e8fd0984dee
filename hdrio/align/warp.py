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
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


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


@njit(parallel=True, cache=True, nogil=True)
def _warp_kernel(codes, warp, code_max, interpolate, out):  # pragma: no cover - compiled
    height, width, channels = codes.shape
    for y in prange(out.shape[0]):
        wx = np.empty(4)
        wy = np.empty(4)
        for x in range(out.shape[1]):
            w = warp[2, 0] * x + warp[2, 1] * y + warp[2, 2]
            sx = (warp[0, 0] * x + warp[0, 1] * y + warp[0, 2]) / w
            sy = (warp[1, 0] * x + warp[1, 1] * y + warp[1, 2]) / w
            sx = min(max(sx, 0.0), width - 1.0)
            sy = min(max(sy, 0.0), height - 1.0)
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


def warp_codes(codes: np.ndarray, warp: np.ndarray, code_max: int,
               out: np.ndarray | None = None, interpolate: bool = True) -> np.ndarray:
    """``codes`` ``(H, W, C)`` resampled at ``warp @ (x, y, 1)`` (full-resolution pixels).

    ``out`` (same dtype, not ``codes`` itself; by default ``codes``' shape) receives the
    result, for ``x, y`` over its own rows and columns. ``interpolate`` false takes the
    nearest code everywhere."""
    if out is None:
        out = np.empty_like(codes)
    _warp_kernel(codes, np.ascontiguousarray(warp, np.float64), code_max, interpolate, out)
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
    xs = np.minimum(np.arange(cols + 1) * factor, width) - 0.5
    x, y = np.meshgrid(xs, ys)
    w = warp[2, 0] * x + warp[2, 1] * y + warp[2, 2]
    sx = (warp[0, 0] * x + warp[0, 1] * y + warp[0, 2]) / w
    sy = (warp[1, 0] * x + warp[1, 1] * y + warp[1, 2]) / w
    inside = ((sx >= -0.5) & (sx <= source_width - 0.5) & (sy >= -0.5)
              & (sy <= source_height - 0.5))
    cells = inside[:-1, :-1] & inside[1:, :-1] & inside[:-1, 1:] & inside[1:, 1:]
    return cells.astype(np.float32)
