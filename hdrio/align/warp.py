"""Resampling a bracket's code values through a warp without changing what codes mean.

Output pixel ``x`` takes the moving bracket at ``W x``. Where the four codes around
``W x`` are all strictly between 0 and ``Z_max`` in a channel, that channel is
interpolated bilinearly (in code values, then rounded: a sub-pixel shift is a blend of
neighbours of the same kind); where any of them is clipped or black it takes the
nearest code, so a saturated code is never blended with an unsaturated one (a blend
would be a well-exposed-looking code of no real radiance). Pixels whose ``W x`` falls
outside the bracket take the nearest edge code *and* are reported uncovered (the merge
drops them: :func:`coverage`), never invented from another bracket.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, nogil=True)
def _warp_kernel(codes, warp, code_max, out):  # pragma: no cover - compiled
    height, width, channels = codes.shape
    for y in prange(out.shape[0]):
        for x in range(out.shape[1]):
            w = warp[2, 0] * x + warp[2, 1] * y + warp[2, 2]
            sx = (warp[0, 0] * x + warp[0, 1] * y + warp[0, 2]) / w
            sy = (warp[1, 0] * x + warp[1, 1] * y + warp[1, 2]) / w
            sx = min(max(sx, 0.0), width - 1.0)
            sy = min(max(sy, 0.0), height - 1.0)
            x0 = min(int(sx), width - 2) if width > 1 else 0
            y0 = min(int(sy), height - 2) if height > 1 else 0
            x1 = min(x0 + 1, width - 1)
            y1 = min(y0 + 1, height - 1)
            fx = sx - x0
            fy = sy - y0
            nx = x1 if fx >= 0.5 else x0
            ny = y1 if fy >= 0.5 else y0
            for c in range(channels):
                a = codes[y0, x0, c]
                b = codes[y0, x1, c]
                d = codes[y1, x0, c]
                e = codes[y1, x1, c]
                inside = ((a > 0) & (a < code_max) & (b > 0) & (b < code_max) & (d > 0)
                          & (d < code_max) & (e > 0) & (e < code_max))
                if inside:
                    value = ((1.0 - fy) * ((1.0 - fx) * a + fx * b)
                             + fy * ((1.0 - fx) * d + fx * e))
                    out[y, x, c] = int(value + 0.5)
                else:
                    out[y, x, c] = codes[ny, nx, c]


def warp_codes(codes: np.ndarray, warp: np.ndarray, code_max: int,
               out: np.ndarray | None = None) -> np.ndarray:
    """``codes`` ``(H, W, C)`` resampled at ``warp @ (x, y, 1)`` (full-resolution pixels).

    ``out`` (same dtype, not ``codes`` itself; by default ``codes``' shape) receives the
    result, for ``x, y`` over its own rows and columns."""
    if out is None:
        out = np.empty_like(codes)
    _warp_kernel(codes, np.ascontiguousarray(warp, np.float64), code_max, out)
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
