"""How far a warped bracket's observations can be trusted: its resampling error.

A warp resamples a bracket between its pixels, and an image sampled without a
band-limiting filter (a sensor's pixel integrates a box; most real scenes have edges
sharper than a pixel) is not recovered exactly between its samples by any interpolator:
at a sharp edge a warped bracket is off by a fraction of the edge's step, which the noise
model knows nothing about. On the GoldenGate truth stack a bracket's ideal radiance,
warped and warped back by a cubic spline in floating point, is off by 41-57 % at its 99th
percentile (1 % at the median).

Each warped bracket's observation at ``x`` is given the extra variance

``var_resample_j(x) = RESAMPLING * h_j(x)^2``, ``h_j = x_j - (x_j(up) + x_j(down) +
x_j(left) + x_j(right)) / 4``

(``x_j = f^-1(z) / dt_j``, relative radiance: the bracket's discrete Laplacian, a
measure of the energy above the sampling rate that the warp could not interpolate), and
its weight is multiplied by ``var_noise / (var_noise + var_resample)``: the
inverse-variance weight becomes ``1 / (var_noise + var_resample)``. The reference bracket
is never warped and keeps its weight, so at edges it takes over where it is well
exposed. The factor is a per-pixel keep weight for :func:`hdrio.merge.masked.remerge_masked`
(the fused kernel's tables are untouched; a still stack is not re-merged at all), applied
in bands of rows so that memory stays bounded.
"""

from __future__ import annotations

import numpy as np

from hdrio.io.staging import release

RESAMPLING = 1.0
"""``var_resample / h^2``: on the truth stacks, the warped brackets' squared error beyond
their noise is 0.7-2.3 times ``h^2`` where ``h^2`` is 100-4000 times the noise variance
(the only place the factor matters)."""
FULL = 0.999
"""Factors above this are taken as 1 (the pixel is not re-merged for them)."""
BAND_PIXELS = 1 << 20
"""About this many pixels of each bracket a band (9 brackets of 24 MP: rows of ~40 MB of
weights and estimates at a time)."""


def cell_weights(cells: np.ndarray, cell: int, top: int, bottom: int, width: int
                 ) -> np.ndarray:
    """Per-bracket keep weights on cells ``(P, rows, cols)`` interpolated to pixels of rows
    ``top .. bottom - 1``, ``(P, bottom - top, width)`` float32: bilinear between cell
    centres ``(i + 0.5) * cell``, clamped at the borders (as
    :func:`hdrio.merge.masked.remerge_masked` reads them)."""

    def corners(positions: np.ndarray, size: int):
        f = (positions + 0.5) / cell - 0.5
        i0 = np.clip(np.floor(f).astype(np.int64), 0, size - 1)
        i1 = np.minimum(i0 + 1, size - 1)
        return i0, i1, np.clip(f - i0, 0.0, 1.0).astype(np.float32)

    y0, y1, wy = corners(np.arange(top, bottom), cells.shape[1])
    x0, x1, wx = corners(np.arange(width), cells.shape[2])
    rows = (1.0 - wy)[:, None] * cells[:, y0] + wy[:, None] * cells[:, y1]
    return ((1.0 - wx) * rows[:, :, x0] + wx * rows[:, :, x1]).astype(np.float32)


def resampling_confidence(codes: np.ndarray, estimates: np.ndarray, variance: np.ndarray,
                          limits) -> np.ndarray:
    """``var_noise / (var_noise + var_resample)`` of one warped bracket, ``(H, W)`` float32
    (the smallest over the channels the merge uses: a channel at or above its saturation
    limit, or whose noise variance is infinite, does not count).

    A pixel with one channel clipped keeps this factor for the others: with the
    per-channel saturation rule their codes are merged, and next to a clip they are the
    warp's nearest codes (:mod:`hdrio.align.warp`), up to half a pixel off (kept at
    weight 1 there, the p99 of the GoldenGate truth stack was 3.3-3.8x the still
    stack's instead of 2.2-2.4x). The factor also scales a saturated code's reset of the
    longer brackets' sums (:func:`hdrio.merge.masked.remerge_masked`), which matters only
    where a warp broke the order of saturation (an edge).

    Parameters
    ----------
    codes
        ``(H, W, C)`` the warped bracket's codes (a band of rows with one row of context
        above and below: the first and last rows' Laplacian is taken from edge copies).
    estimates, variance
        ``(C, levels)`` its ``x_j(z)`` and ``var(x_j | z)`` (relative radiance, squared).
    limits
        ``(C,)`` the first code the merge's saturation policy drops per channel.
    """
    channels = codes.shape[2]
    limits = np.asarray(limits)
    factor = np.ones(codes.shape[:2], np.float32)
    for c in range(channels):
        z = codes[..., c]
        x = estimates[c][z]
        padded = np.pad(x, 1, mode="edge")
        h = x - 0.25 * (padded[:-2, 1:-1] + padded[2:, 1:-1] + padded[1:-1, :-2]
                        + padded[1:-1, 2:])
        noise = variance[c][z]
        with np.errstate(invalid="ignore"):
            f = noise / (noise + RESAMPLING * h * h)
        f[~np.isfinite(f) | (z >= limits[c])] = 1.0
        np.minimum(factor, f, out=factor)
    factor[factor > FULL] = 1.0
    return factor


def remerge_resampled(codes: np.ndarray, limits, cells: np.ndarray | None, cell: int,
                      warped: list[bool], estimates: np.ndarray, variance: np.ndarray,
                      remerge, radiance: np.ndarray) -> None:
    """Re-merge ``radiance`` ``(H, W, C)`` in bands of rows with every warped bracket's
    :func:`resampling_confidence` times its keep weight on ``cells`` (or 1); ``limits``:
    the merge's saturation limits, ``(C,)`` codes.

    ``warped[j]``: whether bracket ``j`` was resampled (not the reference). ``remerge``
    (``codes_band, keep_band, radiance_band``) re-merges one band with per-pixel weights
    (:func:`hdrio.merge.masked.remerge_masked` with the merge's tables, ``cell`` 1).
    Staged brackets' pages are given back after each band.
    """
    count, height, width, _ = codes.shape
    band = max(8, BAND_PIXELS // max(1, width))
    for top in range(0, height, band):
        bottom = min(height, top + band)
        keep = (cell_weights(cells, cell, top, bottom, width) if cells is not None
                else np.ones((count, bottom - top, width), np.float32))
        above, below = max(0, top - 1), min(height, bottom + 1)
        for j in range(count):
            if warped[j]:
                factor = resampling_confidence(codes[j, above:below], estimates[j],
                                               variance[j], limits)
                keep[j] *= factor[top - above:top - above + bottom - top]
        remerge(np.ascontiguousarray(codes[:, top:bottom]), keep, radiance[top:bottom])
        release(codes, None, 0, bottom)
