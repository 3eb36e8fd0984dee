"""How far a warped bracket's observations can be trusted: its resampling error.

A warp resamples a bracket between its pixels, and an image sampled without a
band-limiting filter (a sensor's pixel integrates a box; most real scenes have edges
sharper than a pixel) is not recovered exactly between its samples by any interpolator:
at a sharp edge a warped bracket is off by a fraction of the edge's step, which the noise
model knows nothing about. On the GoldenGate truth stack a bracket's ideal radiance,
warped and warped back by a cubic spline in floating point, is off by 41-57 % at its 99th
percentile (1 % at the median).

Each warped bracket ``j`` is given, per cell of the merge's keep weights
(:data:`hdrio.align.deghost.CELL` pixels), an extra variance ``var_resample_j``, and its
weight there is multiplied by ``var_noise / (var_noise + var_resample)``: the
inverse-variance weight becomes ``1 / (var_noise + var_resample)``. The extra variance is
measured against the bracket the others were aligned to, which is never warped:
``E[(x_j - x_r)^2] = var_j + var_r + var_resample_j`` (``x = f^-1(z) / dt``, relative
radiance; ``var``: the deghosting test's allowance, noise plus the response's error,
:func:`hdrio.align.deghost.consistency_variance`), so

``var_resample_j = max(0, mean over the cell of ((x_j - x_r)^2 - var_j - var_r) - its sd)``

on every :data:`STRIDE`-th pixel each way (the variances scaled by
:func:`disagreement_scale` when a real camera disagrees more than the model says) where
both are usable at enough of them; elsewhere (the reference clipped or black) from the
bracket's own discrete Laplacian ``h_j = x_j - (mean of its 4 neighbours)``:
``var_resample_j = mean of h_j^2`` (the energy above the sampling rate that the warp
could not interpolate). At edges the reference so takes over where it is well exposed.
Only cells where the bracket has an edge (a code off the mean of its 4 neighbours by
:data:`EDGE` of the code range) and can carry :data:`hdrio.align.shares.SHARE` of the
merge's weight are measured; a factor above :data:`FULL` is taken as 1.

On the truth stack (``python -m tests.align_truth``, seeds 0-3, aligned to the bracket
that carries most of the merge, :func:`hdrio.align.registration.reference_bracket`) the
merge's p99 error is 1.55-1.81x the still stack's; 3.5-4.4x without these weights. The
factors were first computed per pixel over a 5x5 window (p99 0.04-0.07x lower than these,
aligned the same way) at 6.9x the merge's time on the 24 MP speed benchmark. The factors
are per-cell keep weights for :func:`hdrio.merge.masked.remerge_masked` (the fused
kernel's tables are untouched; a still stack is not re-merged at all), applied in bands
of cell rows so that memory stays bounded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from hdrio.align import shares
from hdrio.align.shares import range_tables, weighty_cells
from hdrio.io.staging import release
from hdrio.parallel import on_threads

STRIDE = 1
"""Pixels: a cell is measured on every STRIDE-th pixel each way (every second: the truth
stack's p99 error 0.1x the still stack's higher, its edge test at 8 codes missing edges
between the samples, another 0.1x)."""
SIGNIFICANCE = 1.0
"""Standard deviations of its own estimate a cell's excess disagreement must exceed to
count (the reference's noise alone makes it positive half the time: on the hand-held
JPEG stack a longer warped bracket, whose noise is a sixteenth of the reference's, lost
most of its weight in flat shadows)."""
COVERED = 0.3
"""The fraction of a cell's samples where both brackets must be usable for the
disagreement to be used (else the Laplacian)."""
SAMPLES = 100_000
"""About this many pixels a bracket measure :func:`disagreement_scale`."""
FULL = 0.7
"""Factors above this are taken as 1 (the cell is not re-merged for them): on the truth
stack the p99 error moved by at most 0.01x the still stack's between 0.999 and 0.7."""
BANDS = 16
"""Bands of cell rows the factors are measured and the cells re-merged in, each band's
pages given back after it when the brackets are staged (memory stays bounded)."""
SPREAD = 8.0 / 255.0
"""The fraction of the code range a warped bracket's codes must span in a cell (on
:data:`hdrio.align.shares.STRIDE`'s samples) for the cell to be looked at for edges
(:data:`EDGE`): a quick test that leaves out most smooth cells."""
EDGE = 4.0 / 255.0
"""The fraction of the code range by which a warped bracket's code must differ from the
mean of its 4 neighbours (in any channel) at some pixel of a cell for the cell to be
measured (a straight step of 16 codes does, at its foot): elsewhere the bracket is smooth,
a warp interpolates it well and the factor is 1. Measured on the truth stack (seeds 0-3),
against every cell measured: these gates raise the p99 error by 0.2-0.7 %; with 8 codes
here, by 2.0-2.2 %."""


@dataclass(frozen=True)
class ResamplingTables:
    """The ``(P, C, levels)`` tables the resampling weights read.

    Attributes
    ----------
    estimates
        ``x(z)``, relative radiance (with the response's systematic error divided out:
        :func:`hdrio.align.comparametric.comparametric_correction`).
    noise
        ``var(x | z)`` of the noise model, relative radiance squared.
    allowed
        The variance the deghosting test allows (``inf`` where a code says nothing).
    """

    estimates: np.ndarray
    noise: np.ndarray
    allowed: np.ndarray


def cell_factors(codes: np.ndarray, reference: int, tables: ResamplingTables, limits,
                 scales, todo: np.ndarray, cell: int, *, first: int = 0,
                 code_max: int | None = None) -> np.ndarray:
    """``var_noise / (var_noise + var_resample)`` of every warped bracket per cell (module
    docstring), ``(P, rows, cols)`` float32 for the cell rows ``first .. first + rows -
    1``; 1 for ``reference``, where a bracket is smooth or ``todo`` is false, and where the
    factor is above :data:`FULL`.

    Parameters
    ----------
    codes
        ``(P, H, W, C)`` codes, every bracket but ``reference`` warped onto it.
    reference
        The bracket the others were aligned to (not warped).
    tables
        The estimates, their noise and the variance the test allows
        (:class:`ResamplingTables`).
    limits
        ``(C,)`` the first code the merge's saturation policy drops per channel.
    scales
        ``(P,)`` how far the variances under-state each bracket's disagreement with the
        reference on the whole (:func:`disagreement_scale`): both are multiplied by it.
    todo
        ``(P, rows, cols)`` bool: the cells measured (:func:`hdrio.align.shares.weighty_cells`).
    cell, first
        Cell side (pixels) and the first cell row.
    code_max
        The codes' largest value (for :data:`EDGE`; the tables' last code by default).
    """
    count, rows, cols = todo.shape
    code_max = tables.estimates.shape[-1] - 1 if code_max is None else code_max
    out = np.ones((count, rows, cols), np.float32)
    on_threads(_cell_factors, rows, codes, reference,
               *(np.ascontiguousarray(t, np.float64)
                 for t in (tables.estimates, tables.noise, tables.allowed)),
               np.ascontiguousarray(limits, np.int64),
               np.ascontiguousarray(scales, np.float64), np.ascontiguousarray(todo, np.bool_),
               cell, first, float(4.0 * EDGE * code_max), out)
    return out


@njit(cache=True, nogil=True)
def _cell_factors(start, stop, codes, reference, estimates, noise, allowed, limits, scales,
                  todo, cell, first, edge, out):  # pragma: no cover - compiled
    """Cell rows ``start .. stop - 1`` (of the band from cell row ``first``) of
    :func:`cell_factors`: per channel, the excess disagreement, its allowance, the
    samples usable in both, the noise variance, the Laplacian energy and the samples usable."""
    count, height, width, channels = codes.shape
    half = STRIDE // 2
    for cy in range(start, stop):
        y0 = (first + cy) * cell
        y1 = min(height, y0 + cell)
        for cx in range(todo.shape[2]):
            x0 = cx * cell
            x1 = min(width, x0 + cell)
            for j in range(count):
                if j == reference or not todo[j, cy, cx]:
                    continue
                sharp = False  # an edge at some sample, in some channel
                for y in range(y0 + half, y1, STRIDE):
                    up, down = max(y - 1, 0), min(y + 1, height - 1)
                    for x in range(x0 + half, x1, STRIDE):
                        left, right = max(x - 1, 0), min(x + 1, width - 1)
                        for c in range(channels):
                            h = abs(4 * np.int64(codes[j, y, x, c])
                                    - np.int64(codes[j, up, x, c])
                                    - np.int64(codes[j, down, x, c])
                                    - np.int64(codes[j, y, left, c])
                                    - np.int64(codes[j, y, right, c]))
                            sharp |= h > edge
                        if sharp:
                            break
                    if sharp:
                        break
                if not sharp:
                    continue
                scale = scales[j]
                samples = float(len(range(y0 + half, y1, STRIDE))
                                * len(range(x0 + half, x1, STRIDE)))
                factor = 1.0
                # Channel by channel, the sums in local variables: accumulated in an
                # array, every sample stored them to memory (the arrays may alias, so
                # nothing stayed in registers).
                for c in range(channels):
                    excess = allowance = both = energy = 0.0
                    noise_sum = usable = 0.0
                    for y in range(y0 + half, y1, STRIDE):
                        up, down = max(y - 1, 0), min(y + 1, height - 1)
                        for x in range(x0 + half, x1, STRIDE):
                            left, right = max(x - 1, 0), min(x + 1, width - 1)
                            z = codes[j, y, x, c]
                            if z >= limits[c]:
                                continue
                            zr = codes[reference, y, x, c]
                            e = estimates[j, c, z]
                            a = allowed[j, c, z] + allowed[reference, c, zr]
                            if np.isfinite(a) and zr < limits[c]:
                                a *= scale
                                d = e - estimates[reference, c, zr]
                                excess += d * d - a
                                allowance += a
                                both += 1.0
                            h = e - 0.25 * (estimates[j, c, codes[j, up, x, c]]
                                            + estimates[j, c, codes[j, down, x, c]]
                                            + estimates[j, c, codes[j, y, left, c]]
                                            + estimates[j, c, codes[j, y, right, c]])
                            noise_sum += scale * noise[j, c, z]
                            energy += h * h
                            usable += 1.0
                    if usable == 0.0:
                        continue
                    if both > COVERED * samples:
                        # The mean of a chi-square of one degree has a standard deviation
                        # of sqrt(2 / n) of its allowance: only what is above
                        # SIGNIFICANCE of them counts.
                        resample = max(0.0, (excess - SIGNIFICANCE * math.sqrt(2.0 / both)
                                             * allowance) / both)
                    else:
                        resample = energy / usable
                    if resample > 0.0:
                        v = noise_sum / usable
                        f = v / (v + resample)
                        if np.isfinite(f) and f < factor:
                            factor = f
                out[j, cy, cx] = 1.0 if factor > FULL else factor


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


def remerge_resampled(codes: np.ndarray, tables: ResamplingTables, remerge,
                      radiance: np.ndarray, *, reference: int, cell: int,
                      cells: np.ndarray | None, limits, code_max: int,
                      weights: np.ndarray, warped: np.ndarray) -> None:
    """Re-merge ``radiance`` ``(H, W, C)`` in bands of cell rows with every bracket's keep
    weight on ``cells`` (or 1) times, for each ``warped`` bracket (``(P,)`` bool: never
    the ``reference``), its :func:`cell_factors` in the cells where
    it can carry :data:`hdrio.align.shares.SHARE` of the merge's ``weights`` (``(P, C,
    levels)``, :func:`hdrio.align.shares.weighty_cells`). A bracket that was not warped
    (it did not move, or it could not be registered) was not resampled: its steep
    gradients are the scene's, not a warp's error. (Taken for one, the glow beside a sun
    of a moved sun set lost the unwarped filtered frame that saw it well, and took the
    noisy estimate of the darkest one: 2.5x too bright in speckle.)

    ``limits``: the merge's saturation limits, ``(C,)`` codes; ``tables``: see
    :class:`ResamplingTables`. ``remerge``
    (``codes, keep, radiance, first_row, rows, factors``) re-merges one band
    (:func:`hdrio.merge.masked.remerge_masked` with the merge's tables, its cells of
    ``cell`` pixels). Staged brackets' pages are given back after each band.
    """
    import scipy.ndimage
    count, height, width, channels = codes.shape
    limits = np.asarray(limits)
    rows, cols = -(-height // cell), -(-width // cell)
    if cells is None:
        cells = np.ones((count, rows, cols), np.float32)
    ranges = range_tables(weights, limits)
    kept = np.stack([scipy.ndimage.minimum_filter(k, 3, mode="nearest") for k in cells])
    step = max(1, int(np.sqrt(height * width / SAMPLES)))
    grid = np.ascontiguousarray(codes[:, step // 2::step, step // 2::step]).reshape(
        count, -1, channels)
    scales = [disagreement_scale(grid[j], grid[reference], tables.estimates[[j, reference]],
                                 tables.allowed[[j, reference]], limits)
              for j in range(count)]
    band = -(-rows // BANDS)
    for top in range(0, rows, band):
        bottom = min(rows, top + band)
        todo = weighty_cells(codes, cell, top, bottom, kept[:, top:bottom], ranges, limits,
                             share=shares.SHARE, spread=int(SPREAD * code_max))
        todo &= np.asarray(warped, bool)[:, None, None]
        factors = cell_factors(codes, reference, tables, limits, scales, todo, cell,
                               first=top, code_max=code_max)
        remerge(codes, cells, radiance, top * cell, min(height, bottom * cell) - top * cell,
                factors)
        release(codes, None, 0, min(height, bottom * cell))
