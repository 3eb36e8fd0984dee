"""How far a warped bracket's observations can be trusted: its resampling error.

A warp resamples a bracket between its pixels, and an image sampled without a
band-limiting filter (a sensor's pixel integrates a box; most real scenes have edges
sharper than a pixel) is not recovered exactly between its samples by any interpolator:
at a sharp edge a warped bracket is off by a fraction of the edge's step, which the noise
model knows nothing about. On the GoldenGate truth stack a bracket's ideal radiance,
warped and warped back by a cubic spline in floating point, is off by 41-57 % at its 99th
percentile (1 % at the median).

Each warped bracket ``j``'s observation at ``x`` is given an extra variance
``var_resample_j(x)``, and its weight is multiplied by
``var_noise / (var_noise + var_resample)``: the inverse-variance weight becomes
``1 / (var_noise + var_resample)``. The extra variance is measured against the reference
bracket, which is never warped: ``E[(x_j - x_r)^2] = var_j + var_r + var_resample_j``
(``x = f^-1(z) / dt``, relative radiance; ``var``: the deghosting test's allowance, noise
plus the response's error, :func:`hdrio.align.deghost.consistency_variance`), so

``var_resample_j = max(0, mean over 5x5 of ((x_j - x_r)^2 - var_j - var_r) - its sd)``

(the variances scaled by :func:`disagreement_scale` when a real camera disagrees more
than the model says) where both are usable in most of the window; elsewhere (the
reference clipped or black) from the bracket's own discrete Laplacian
``h_j = x_j - (mean of its 4 neighbours)``: ``var_resample_j = h_j^2`` (the energy above
the sampling rate that the warp could not interpolate). At edges the reference so takes
over where it is well exposed.

On the truth stack (seeds 0-2) the merge's p99 error went from 5.2x / 4.9x / 4.8x the
still stack's to 2.30x / 2.06x / 1.97x (the Laplacian alone everywhere: 2.4x / 2.3x /
2.2x; weights from the true per-pixel error: 1.8x / 1.7x for seeds 0-1). The factor is
a per-pixel keep weight for :func:`hdrio.merge.masked.remerge_masked` (the fused
kernel's tables are untouched; a still stack is not re-merged at all), applied in bands
of rows so that memory stays bounded.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hdrio.io.staging import release
from hdrio.parallel import on_threads

WINDOW = 5
"""Pixels: the side of the window the disagreement with the reference is averaged over
(without the significance margin, 3: p99 2.2x / 2.1x / 1.9x on the truth stack, 5: 2.2x
/ 2.0x / 1.9x, 7: the same)."""
SIGNIFICANCE = 1.0
"""Standard deviations of its own estimate the window's excess disagreement must exceed
to count (the reference's noise alone makes it positive half the time: on the hand-held
JPEG stack a longer warped bracket, whose noise is a sixteenth of the reference's, lost
most of its weight in flat shadows; 2 moved the truth stack's p99 from 2.30x / 2.06x /
1.97x to 2.36x / 2.10x / 2.02x)."""
COVERED = 0.3
"""The fraction of the window where both brackets must be usable for the disagreement to
be used (else the Laplacian)."""
SAMPLES = 100_000
"""About this many pixels a bracket measure :func:`disagreement_scale`."""
FULL = 0.999
"""Factors above this are taken as 1 (the pixel is not re-merged for them)."""
BAND_PIXELS = 1 << 20
"""About this many pixels of each bracket a band (9 brackets of 24 MP: a few tens of MB
of weights and estimates at a time)."""


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
    out = np.ones((cells.shape[0], bottom - top, width), np.float32)
    for j in range(cells.shape[0]):
        if cells[j, y0].min() < 1.0 or cells[j, y1].min() < 1.0:  # else 1 throughout
            rows = (1.0 - wy)[:, None] * cells[j, y0] + wy[:, None] * cells[j, y1]
            out[j] = (1.0 - wx) * rows[:, x0] + wx * rows[:, x1]
    return out


def resampling_confidence(codes: np.ndarray, reference: np.ndarray, estimates: np.ndarray,
                          noise: np.ndarray, allowed: np.ndarray, limits, scale: float = 1.0
                          ) -> np.ndarray:
    """``var_noise / (var_noise + var_resample)`` of one warped bracket ``j`` (module
    docstring), ``(H, W)`` float32: the smallest over the channels the merge uses (a
    channel at or above its saturation limit, or of infinite noise variance, does not
    count).

    A pixel with one channel clipped keeps this factor for the others: with the
    per-channel saturation rule their codes are merged, and next to a clip they are the
    warp's nearest codes (:mod:`hdrio.align.warp`), up to half a pixel off (kept at
    weight 1 there, the truth stack's p99 was 3.3-3.8x the still stack's, not
    2.2-2.4x, with the Laplacian alone). The factor also scales a saturated code's reset
    of the longer brackets' sums (:func:`hdrio.merge.masked.remerge_masked`), which
    matters only where a warp broke the order of saturation (an edge).

    Parameters
    ----------
    codes, reference
        ``(H, W, C)`` codes of bracket ``j`` (warped) and of the reference bracket, a
        band of rows (the first and last rows' neighbours are taken from edge copies).
    estimates, noise, allowed
        ``(2, C, levels)``, bracket ``j``'s then the reference's: ``x(z)``, relative
        radiance; ``var(x | z)`` of the noise model; the variance the deghosting test
        allows (``inf`` where a code says nothing), relative radiance squared.
    limits
        ``(C,)`` the first code the merge's saturation policy drops per channel.
    scale
        How far the variances under-state the brackets' disagreement on the whole
        (:func:`disagreement_scale`): both are multiplied by it.
    """
    rows, width, channels = codes.shape
    codes, reference = np.ascontiguousarray(codes), np.ascontiguousarray(reference)
    estimates, noise, allowed = (np.ascontiguousarray(table, np.float64)
                                 for table in (estimates, noise, allowed))
    limits = np.ascontiguousarray(limits, np.int64)
    factor = np.ones((rows, width), np.float32)
    laplacian = np.empty((rows, width))
    sums = np.empty((3, rows, width))
    buffer = np.empty((rows, 3, width + WINDOW - 1))
    for c in range(channels):  # rows of sums first, then columns of them (all rows done)
        on_threads(_along_rows, rows, codes, reference, estimates, allowed, limits,
                   float(scale), c, laplacian, buffer, sums)
        on_threads(_along_columns, rows, codes, noise, limits, float(scale), c, laplacian,
                   sums, factor)
    factor[factor > FULL] = 1.0
    return factor


@njit(cache=True, nogil=True)
def _along_rows(start, stop, codes, reference, estimates, allowed, limits, scale, c,
                laplacian, buffer, sums):  # pragma: no cover - compiled
    """Rows ``start .. stop - 1`` of channel ``c``: the Laplacian's square, and the
    :data:`WINDOW`-wide sums along the row of the excess disagreement, its allowance and
    whether both brackets are usable (edges repeated, as ``scipy.ndimage``'s
    ``nearest``)."""
    rows, width, _ = codes.shape
    half = WINDOW // 2
    limit = limits[c]
    for y in range(start, stop):
        up, down = max(y - 1, 0), min(y + 1, rows - 1)
        row = buffer[y]  # excess, allowance, both, with the edges repeated
        row[:] = 0.0
        for x in range(width):
            z = codes[y, x, c]
            zr = reference[y, x, c]
            value = estimates[0, c, z]
            h = value - 0.25 * (estimates[0, c, codes[up, x, c]]
                                + estimates[0, c, codes[down, x, c]]
                                + estimates[0, c, codes[y, max(x - 1, 0), c]]
                                + estimates[0, c, codes[y, min(x + 1, width - 1), c]])
            laplacian[y, x] = h * h
            a = allowed[0, c, z] + allowed[1, c, zr]
            if np.isfinite(a) and z < limit and zr < limit:
                a *= scale
                d = value - estimates[1, c, zr]
                row[0, x + half] = d * d - a
                row[1, x + half] = a
                row[2, x + half] = 1.0
        for k in range(3):
            for x in range(half):
                row[k, x] = row[k, half]
                row[k, width + half + x] = row[k, width + half - 1]
            total = 0.0
            for x in range(WINDOW - 1):
                total += row[k, x]
            for x in range(width):  # a running sum along the row
                total += row[k, x + WINDOW - 1]
                sums[k, y, x] = total
                total -= row[k, x]


@njit(cache=True, nogil=True)
def _along_columns(start, stop, codes, noise, limits, scale, c, laplacian, sums,
                   factor):  # pragma: no cover - compiled
    """Rows ``start .. stop - 1`` of channel ``c``: the window's sums down the columns of
    :func:`_along_rows`' sums, the resampling variance and the factor (the smallest so
    far over the channels kept in ``factor``)."""
    rows, width, _ = codes.shape
    half = WINDOW // 2
    area = float(WINDOW * WINDOW)
    limit = limits[c]
    for y in range(start, stop):
        for x in range(width):
            z = codes[y, x, c]
            if z >= limit:
                continue
            e = 0.0
            a = 0.0
            b = 0.0
            for k in range(y - half, y + half + 1):
                i = min(max(k, 0), rows - 1)
                e += sums[0, i, x]
                a += sums[1, i, x]
                b += sums[2, i, x]
            covered = b / area
            if covered > COVERED:
                # The window's mean of a chi-square of one degree has a standard
                # deviation of sqrt(2 / n) of its allowance: only what is above
                # SIGNIFICANCE of them counts.
                resample = max(0.0, (e / area - SIGNIFICANCE * math.sqrt(2.0 / b)
                                     * a / area) / covered)
            else:
                resample = laplacian[y, x]
            variance = scale * noise[0, c, z]
            f = variance / (variance + resample)
            if np.isfinite(f) and f < factor[y, x]:
                factor[y, x] = f


def disagreement_scale(codes: np.ndarray, reference: np.ndarray, estimates: np.ndarray,
                       allowed: np.ndarray, limits) -> float:
    """``max(1, median((x_j - x_r)^2 / (var_j + var_r)))`` over the samples ``(n, C)`` of a
    warped bracket and the reference where both are usable: about 1 when the variances
    are right (0.5 for a chi-square of one degree; the truth stacks), above where a real
    camera's noise or its response's error is more than the model says (JPEG: the
    deghosting test's quick look scales its threshold the same way). Without it the
    resampling variance came out positive everywhere on the hand-held JPEG stack,
    moving its merge by 2.5 % at the median."""
    ratios = []
    for c in range(codes.shape[-1]):
        z, zr = codes[:, c], reference[:, c]
        total = allowed[0, c][z] + allowed[1, c][zr]
        both = np.isfinite(total) & (z < limits[c]) & (zr < limits[c])
        ratios.append((estimates[0, c][z[both]] - estimates[1, c][zr[both]]) ** 2
                      / total[both])
    ratios = np.concatenate(ratios)
    return max(1.0, float(np.median(ratios))) if ratios.size else 1.0


def remerge_resampled(codes: np.ndarray, limits, cells: np.ndarray | None, cell: int,
                      reference: int, estimates: np.ndarray, noise: np.ndarray,
                      allowed: np.ndarray, remerge, radiance: np.ndarray) -> None:
    """Re-merge ``radiance`` ``(H, W, C)`` in bands of rows with every bracket's keep
    weight on ``cells`` (or 1) times, but for the ``reference`` (never warped), its
    :func:`resampling_confidence`.

    ``limits``: the merge's saturation limits, ``(C,)`` codes; ``estimates``, ``noise``,
    ``allowed``: ``(P, C, levels)`` tables (see :func:`resampling_confidence`).
    ``remerge`` (``codes_band, keep_band, radiance_band``) re-merges one band with
    per-pixel weights (:func:`hdrio.merge.masked.remerge_masked` with the merge's tables,
    ``cell`` 1). Staged brackets' pages are given back after each band.
    """
    count, height, width, _ = codes.shape
    limits = np.asarray(limits)
    halo = WINDOW // 2 + 1  # the window's reach, and the Laplacian's
    band = max(8, BAND_PIXELS // max(1, width))
    step = max(1, int(np.sqrt(height * width / SAMPLES)))
    grid = np.ascontiguousarray(codes[:, step // 2::step, step // 2::step]).reshape(
        count, -1, codes.shape[-1])
    scales = [disagreement_scale(grid[j], grid[reference], estimates[[j, reference]],
                                 allowed[[j, reference]], limits) for j in range(count)]
    for top in range(0, height, band):
        bottom = min(height, top + band)
        keep = (cell_weights(cells, cell, top, bottom, width) if cells is not None
                else np.ones((count, bottom - top, width), np.float32))
        above, below = max(0, top - halo), min(height, bottom + halo)
        rows = slice(top - above, top - above + bottom - top)
        for j in range(count):
            if j != reference:
                pair = [j, reference]
                keep[j] *= resampling_confidence(
                    codes[j, above:below], codes[reference, above:below], estimates[pair],
                    noise[pair], allowed[pair], limits, scales[j])[rows]
        remerge(np.ascontiguousarray(codes[:, top:bottom]), keep, radiance[top:bottom])
        release(codes, None, 0, bottom)
