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
import scipy.ndimage
from numba import njit

from hdrio.align import shares
from hdrio.align.shares import range_tables, weighty_cells
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
BAND_PIXELS = 1 << 21
"""About this many pixels of each bracket a band (9 brackets of 24 MP: a few tens of MB
of weights and estimates at a time)."""


EDGE = 8.0 / 255.0
"""The fraction of the code range a warped bracket's discrete Laplacian (a code minus the
mean of its 4 neighbours, in any channel) must exceed somewhere within :data:`HALO` pixels
of a cell for the cell's resampling weights to be computed: elsewhere the bracket is
smooth, a warp interpolates it well and the factor is 1 (the cell is not re-merged for
it). On the truth stacks (``python -m tests.align_truth``) the merge's p99 error is the
same to 0.01x the still stack's with 8 codes of 255 as with every cell computed, 0.15x
worse with 16; 24 MP of the speed benchmark's scene: about a third of the cells of a
warped bracket pass at 8.)"""
HALO = WINDOW // 2 + 1
"""Pixels: the reach of a pixel's factor (its window, and the Laplacian's neighbours)."""


def edge_cells(codes: np.ndarray, code_max: int, cell: int, edge: float = EDGE,
               offset: int = 0, rows: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cells of a bracket's codes ``(H, W, C)`` within :data:`HALO` pixels of which
    its discrete Laplacian exceeds ``edge`` of the code range in some channel (4 times
    it: ``|4 z - sum of the 4 neighbours|``; edges repeated), ``(ceil(rows / cell),
    ceil(W / cell))`` bool, and the smallest and largest code of each channel there,
    ``(ceil(rows / cell), ceil(W / cell), C)``. The cells tile rows ``offset .. offset +
    rows - 1`` (all by default); the rows around them are read."""
    codes = np.ascontiguousarray(codes)
    height, width, channels = codes.shape
    rows = height - offset if rows is None else rows
    flags = np.zeros((-(-rows // cell), -(-width // cell)), np.bool_)
    low = np.empty(flags.shape + (channels,), codes.dtype)
    high = np.empty_like(low)
    on_threads(_edge_cells, flags.shape[0], codes, code_max, float(4.0 * edge * code_max), cell,
               offset, rows, flags, low, high)
    return flags, low, high


@njit(cache=True, nogil=True)
def _edge_cells(start, stop, codes, code_max, threshold, cell, offset, rows, flags, low,
                high):  # pragma: no cover - compiled
    """Cell rows ``start .. stop - 1`` of :func:`edge_cells`: each pixel row once (its
    channels interleaved, a pixel's neighbours along the row ``channels`` apart), its
    Laplacian and codes kept, largest (and smallest) first, for the (at most two) cell
    rows it reaches; loops over contiguous slices, which the compiler vectorises."""
    height, width, channels = codes.shape
    n = width * channels
    inner = n - 2 * channels
    peak = np.zeros((stop - start, n), np.int32)
    least = np.full((stop - start, n), code_max, np.int32)
    most = np.zeros((stop - start, n), np.int32)
    row = np.empty(n, np.int32)
    for y in range(max(0, offset + start * cell - HALO),
                   min(height, offset + min(stop * cell, rows) + HALO)):
        here = codes[y].reshape(n)
        up = codes[max(y - 1, 0)].reshape(n)
        down = codes[min(y + 1, height - 1)].reshape(n)
        centre, left, right = here[channels:n - channels], here[:inner], here[2 * channels:]
        above, below, out = up[channels:n - channels], down[channels:n - channels], \
            row[channels:n - channels]
        for k in range(inner):
            out[k] = abs(4 * np.int32(centre[k]) - np.int32(above[k]) - np.int32(below[k])
                         - np.int32(left[k]) - np.int32(right[k]))
        for k in range(channels):  # the first and last pixels: edges repeated
            for i, j in ((k, k + channels), (n - channels + k, n - 2 * channels + k)):
                row[i] = abs(3 * np.int32(here[i]) - np.int32(up[i]) - np.int32(down[i])
                             - np.int32(here[j]))
        for cy in range(max(start, (y - offset - HALO) // cell),
                        min(stop, (y - offset + HALO) // cell + 1)):
            p, lo, hi = peak[cy - start], least[cy - start], most[cy - start]
            for k in range(n):
                p[k] = max(p[k], row[k])
            for k in range(n):
                lo[k] = min(lo[k], np.int32(here[k]))
            for k in range(n):
                hi[k] = max(hi[k], np.int32(here[k]))
    for cy in range(start, stop):
        p, lo, hi = peak[cy - start], least[cy - start], most[cy - start]
        for cx in range(flags.shape[1]):
            first = max(0, cx * cell - HALO)
            last = min(width, (cx + 1) * cell + HALO)
            top = 0
            for k in range(first * channels, last * channels):
                top = max(top, p[k])
            flags[cy, cx] = top > threshold
            for c in range(channels):
                a, b = lo[first * channels + c], hi[first * channels + c]
                for x in range(first + 1, last):
                    a = min(a, lo[x * channels + c])
                    b = max(b, hi[x * channels + c])
                low[cy, cx, c], high[cy, cx, c] = a, b


def resampling_confidence(codes: np.ndarray, reference: np.ndarray, estimates: np.ndarray,
                          noise: np.ndarray, allowed: np.ndarray, limits, scale: float = 1.0,
                          cells: np.ndarray | None = None, cell: int = 8, offset: int = 0,
                          rows: int | None = None, out: np.ndarray | None = None
                          ) -> np.ndarray:
    """``var_noise / (var_noise + var_resample)`` of one warped bracket ``j`` (module
    docstring), ``(rows, W)`` float32: the smallest over the channels the merge uses (a
    channel at or above its saturation limit, or of infinite noise variance, does not
    count); 1 where it is above :data:`FULL`, and outside ``cells``.

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
        ``(H, W, C)`` codes of bracket ``j`` (warped) and of the reference bracket
        (beyond the first and last rows, edge copies).
    estimates, noise, allowed
        ``(2, C, levels)``, bracket ``j``'s then the reference's: ``x(z)``, relative
        radiance; ``var(x | z)`` of the noise model; the variance the deghosting test
        allows (``inf`` where a code says nothing), relative radiance squared.
    limits
        ``(C,)`` the first code the merge's saturation policy drops per channel.
    scale
        How far the variances under-state the brackets' disagreement on the whole
        (:func:`disagreement_scale`): both are multiplied by it.
    cells, cell
        ``(ceil(rows / cell), ceil(W / cell))`` bool: the cells computed (``None``:
        every one; :func:`edge_cells` gives the ones that can matter).
    offset, rows
        The rows computed: ``offset .. offset + rows - 1`` of ``codes`` (the rows around
        them are read: a band of rows with its halo); all of them by default.
    out
        ``(rows, W)`` float32 to write the factors to (else a new array).
    """
    height, width, _ = codes.shape
    rows = height - offset if rows is None else rows
    if cells is None:
        cells = np.ones((-(-rows // cell), -(-width // cell)), np.bool_)
    factor = np.empty((rows, width), np.float32) if out is None else out
    factor[...] = 1.0
    on_threads(_confidence, cells.shape[0], np.ascontiguousarray(codes),
               np.ascontiguousarray(reference), *(np.ascontiguousarray(t, np.float64)
                                                  for t in (estimates, noise, allowed)),
               np.ascontiguousarray(limits, np.int64), float(scale),
               np.ascontiguousarray(cells, np.bool_), cell, offset, factor)
    return factor


@njit(cache=True, nogil=True)
def _confidence(start, stop, codes, reference, estimates, noise, allowed, limits, scale,
                cells, cell, offset, factor):  # pragma: no cover - compiled
    """Cell rows ``start .. stop - 1`` of :func:`resampling_confidence`: each run of
    computed cells along a cell row at once, its excess disagreement, allowance and
    coverage on the run's pixels and :data:`WINDOW` // 2 around them (edges repeated, as
    ``scipy.ndimage``'s ``nearest``), summed down the window's columns, then along the
    row as a running sum."""
    height, width, channels = codes.shape
    rows = factor.shape[0]
    half = WINDOW // 2
    area = float(WINDOW * WINDOW)
    tile = np.empty((3, cell + 2 * half, width + 2 * half))
    column = np.empty((3, width + 2 * half))
    for cy in range(start, stop):
        y0, y1 = cy * cell, min((cy + 1) * cell, rows)
        cx = 0
        while cx < cells.shape[1]:
            if not cells[cy, cx]:
                cx += 1
                continue
            end = cx
            while end < cells.shape[1] and cells[cy, end]:
                end += 1
            x0, x1 = cx * cell, min(end * cell, width)
            cx = end
            th, tw = y1 - y0 + 2 * half, x1 - x0 + 2 * half
            for c in range(channels):
                limit = limits[c]
                for ty in range(th):
                    yy = min(max(offset + y0 - half + ty, 0), height - 1)
                    for tx in range(tw):
                        xx = min(max(x0 - half + tx, 0), width - 1)
                        z = codes[yy, xx, c]
                        zr = reference[yy, xx, c]
                        a = allowed[0, c, z] + allowed[1, c, zr]
                        if np.isfinite(a) and z < limit and zr < limit:
                            a *= scale
                            d = estimates[0, c, z] - estimates[1, c, zr]
                            tile[0, ty, tx] = d * d - a
                            tile[1, ty, tx] = a
                            tile[2, ty, tx] = 1.0
                        else:
                            tile[0, ty, tx] = 0.0
                            tile[1, ty, tx] = 0.0
                            tile[2, ty, tx] = 0.0
                for k in range(3):  # the window's sums down each column, running
                    for tx in range(tw):
                        total = 0.0
                        for ty in range(WINDOW - 1):
                            total += tile[k, ty, tx]
                        column[k, tx] = total
                for oy in range(y1 - y0):
                    for k in range(3):
                        for tx in range(tw):
                            column[k, tx] += tile[k, oy + WINDOW - 1, tx]
                            if oy > 0:
                                column[k, tx] -= tile[k, oy - 1, tx]
                    e = column[0, 0] + column[0, 1] + column[0, 2] + column[0, 3]
                    a = column[1, 0] + column[1, 1] + column[1, 2] + column[1, 3]
                    b = column[2, 0] + column[2, 1] + column[2, 2] + column[2, 3]
                    y = offset + y0 + oy
                    for ox in range(x1 - x0):  # running sums along the row
                        e += column[0, ox + WINDOW - 1]
                        a += column[1, ox + WINDOW - 1]
                        b += column[2, ox + WINDOW - 1]
                        x = x0 + ox
                        z = codes[y, x, c]
                        if z < limit:
                            if b > COVERED * area:
                                # The window's mean of a chi-square of one degree has a
                                # standard deviation of sqrt(2 / n) of its allowance: only
                                # what is above SIGNIFICANCE of them counts (most windows:
                                # none, tested without the square root).
                                margin = SIGNIFICANCE * SIGNIFICANCE * 2.0 * a * a
                                if e > 0.0 and e * e * b > margin:
                                    resample = (e - SIGNIFICANCE * math.sqrt(2.0 / b) * a) / b
                                else:
                                    resample = 0.0
                            else:
                                h = estimates[0, c, z] - 0.25 * (
                                    estimates[0, c, codes[max(y - 1, 0), x, c]]
                                    + estimates[0, c, codes[min(y + 1, height - 1), x, c]]
                                    + estimates[0, c, codes[y, max(x - 1, 0), c]]
                                    + estimates[0, c, codes[y, min(x + 1, width - 1), c]])
                                resample = h * h
                            if resample > 0.0:
                                variance = scale * noise[0, c, z]
                                f = variance / (variance + resample)
                                if np.isfinite(f) and f < factor[y0 + oy, x]:
                                    factor[y0 + oy, x] = f
                        e -= column[0, ox]
                        a -= column[1, ox]
                        b -= column[2, ox]
            for y in range(y0, y1):
                for x in range(x0, x1):
                    if factor[y, x] > FULL:
                        factor[y, x] = 1.0


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


def remerge_resampled(codes: np.ndarray, code_max: int, limits, cells: np.ndarray | None,
                      cell: int, reference: int, estimates: np.ndarray, noise: np.ndarray,
                      allowed: np.ndarray, weights: np.ndarray, remerge,
                      radiance: np.ndarray) -> None:
    """Re-merge ``radiance`` ``(H, W, C)`` in bands of rows with every bracket's keep
    weight on ``cells`` (or 1) times, but for the ``reference`` (never warped), its
    :func:`resampling_confidence` in the cells :func:`edge_cells` finds (:data:`EDGE`;
    0: every cell) where it can carry :data:`hdrio.align.shares.SHARE` of the merge's
    ``weights`` (``(P, C, levels)``, :func:`hdrio.align.shares.weighty_cells`; 0: every
    cell).

    ``limits``: the merge's saturation limits, ``(C,)`` codes; ``estimates``, ``noise``,
    ``allowed``: ``(P, C, levels)`` tables (see :func:`resampling_confidence`).
    ``remerge`` (``codes, keep, radiance, first_row, rows, factors, lowered``)
    re-merges one band (:func:`hdrio.merge.masked.remerge_masked` with the merge's
    tables, its cells of ``cell`` pixels). Staged brackets' pages are given back after
    each band.
    """
    count, height, width, channels = codes.shape
    limits = np.asarray(limits)
    if cells is None:
        cells = np.ones((count, -(-height // cell), -(-width // cell)), np.float32)
    tables = range_tables(weights, limits)
    kept = np.stack([scipy.ndimage.minimum_filter(k, 3, mode="nearest") for k in cells])
    band = max(1, BAND_PIXELS // max(1, width) // cell) * cell
    step = max(1, int(np.sqrt(height * width / SAMPLES)))
    grid = np.ascontiguousarray(codes[:, step // 2::step, step // 2::step]).reshape(
        count, -1, channels)
    scales = [disagreement_scale(grid[j], grid[reference], estimates[[j, reference]],
                                 allowed[[j, reference]], limits) for j in range(count)]
    for top in range(0, height, band):
        bottom = min(height, top + band)
        # the halo's rows and their neighbours (edge_cells' Laplacian at the halo's edge)
        above, below = max(0, top - HALO - 1), min(height, bottom + HALO + 1)
        rows = slice(top // cell, -(-bottom // cell))
        found = [edge_cells(codes[j, above:below], code_max, cell, EDGE, top - above,
                            bottom - top) for j in range(count)]
        near = np.stack([f[0] for f in found]) | (EDGE <= 0)
        near &= weighty_cells(np.stack([f[1] for f in found]), np.stack([f[2] for f in found]),
                              kept[:, rows], tables, limits, shares.SHARE)
        factors = np.empty((count, bottom - top, width), np.float32)  # read where lowered
        lowered = np.zeros(near.shape, np.bool_)
        for j in range(count):
            if j == reference or not near[j].any():
                continue
            pair = [j, reference]
            resampling_confidence(
                codes[j, above:below], codes[reference, above:below], estimates[pair],
                noise[pair], allowed[pair], limits, scales[j], near[j], cell, top - above,
                bottom - top, factors[j])
            low = factors[j] < 1.0
            lowered[j] = np.pad(low, ((0, (-low.shape[0]) % cell), (0, (-width) % cell))
                                ).reshape(lowered.shape[1], cell, lowered.shape[2], cell
                                          ).any(axis=(1, 3))
        remerge(codes, cells, radiance, top, bottom - top, factors, lowered)
        release(codes, None, 0, bottom)
