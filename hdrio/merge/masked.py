"""Merging with per-pixel, per-bracket weights (deghosting, uncovered borders).

The fused kernel (:mod:`hdrio.merge.kernel`) stays as it is and merges every pixel;
this pass then re-merges only the pixels where some bracket's keep weight ``m_j`` is
below 1, from the same tables (:func:`hdrio.radiometry.tables.merge_tables`), and
overwrites them:

``sum = sum * (1 - m_j s_j) + m_j t_j(z_j)`` over the brackets, longest first,

with ``s_j`` 1 where the code is at or above the saturation policy's limit or the policy
drops the channel (:func:`hdrio.radiometry.cliptest.dropped_channels`: the kernel's
reset, so ``m_j = 1`` everywhere gives the kernel's result) and ``t_j`` the
table's term. A dropped bracket
(``m_j = 0``) neither adds its term nor resets the sums with its saturation: a moving
object that clips says nothing about the scene behind it. Weights are given on a grid
of cells and interpolated bilinearly between cell centres (the masks are feathered:
no seam). A channel saturated in every bracket keeps the kernel's lower bound, and so
does one dropped from the shortest bracket where that bracket is kept (so from every
one: the most-kept bracket's estimate of its clipped code was the speckled yellow fringe
along the hand-held canal stack's sky, whose blue is at its limit even in the shortest
bracket). Otherwise a channel with no weight (a dark reference, a channel no bracket
saw) takes the estimate of the most-kept bracket not saturated there, or where every kept bracket
is saturated, the saturated estimate of the shortest of the most-kept ones: a lower
bound, what the kept brackets saw. (Deghosting never drops a shorter bracket that stands
in for a clipped reference, :mod:`hdrio.align.consistency`; one it drops there is
inconsistent with the reference's clip, a moving object: keeping the kernel's merge
there, as this pass once did, kept that object a second time.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from hdrio.jit import size_numba_threads
from hdrio.merge.kernel import FLOAT32_MAX, FLOAT32_TINY, LOG_FLOAT32_MAX, LOG_FLOAT32_TINY
from hdrio.merge.saturation import ClipPolicy
from hdrio.radiometry.cliptest import dropped_channels


@njit(cache=True, nogil=True)
def _corner(position, size):  # pragma: no cover - compiled
    f = position - 0.5
    i0 = max(0, min(int(math.floor(f)), size - 1))
    i1 = min(i0 + 1, size - 1)
    w = min(max(f - i0, 0.0), 1.0)
    return i0, i1, w


@njit(parallel=True, cache=True, nogil=True)
def _remerge(codes, keep, touched, cell, terms, estimates, policy, log_domain, out, first,
             factors):  # pragma: no cover - compiled
    count, height, width, channels = codes.shape
    # Unpacked once: the tuple handed on per pixel costs an atomic reference count per
    # array and call (hdrio.radiometry.cliptest.dropped_channels).
    limits, gates, rule, neutral, clip_estimates, variances, threshold = policy
    height = min(height, first + touched.shape[0] * cell)  # the band's rows
    rows, cols = keep.shape[1], keep.shape[2]
    scaled = factors.shape[1] > 0
    for cy in prange(touched.shape[0]):
        m = np.empty(count)
        held = np.empty(count)
        dropped = np.empty(count, dtype=np.int64)
        values = np.empty(channels)
        for cx in range(cols):
            if not touched[cy, cx]:
                continue
            for y in range(first + cy * cell, min(height, first + (cy + 1) * cell)):
                y0, y1, wy = _corner((y + 0.5) / cell, rows)
                for x in range(cx * cell, min(width, (cx + 1) * cell)):
                    x0, x1, wx = _corner((x + 0.5) / cell, cols)
                    for j in range(count):
                        k = keep[j]
                        m[j] = ((1.0 - wy) * ((1.0 - wx) * k[y0, x0] + wx * k[y0, x1])
                                + wy * ((1.0 - wx) * k[y1, x0] + wx * k[y1, x1]))
                        held[j] = m[j]
                        if scaled:
                            m[j] *= factors[j, cy, cx]
                    for j in range(count):
                        # The clip test reads the next shorter bracket kept here: one
                        # masked out or moving says nothing of the pixel.
                        k = max(j - 1, 0)
                        while k > 0 and held[k] < 0.5:
                            k -= 1
                        if j > 0 and held[k] < 0.5 and rule == 2:
                            dropped[j] = 0  # no shorter bracket kept: nothing to test
                            continue
                        loosen = 1.0
                        if scaled and j > 0:
                            # A resampling factor f is noise / (noise + resampling
                            # error): the two brackets disagree by that much more.
                            f = max(min(factors[j, cy, cx], factors[k, cy, cx]), 1e-3)
                            if f < 1.0:
                                loosen = f
                        dropped[j] = dropped_channels(
                            codes[j, y, x], codes[k, y, x], 0, j, k, limits, gates,
                            rule, neutral, clip_estimates, variances, threshold, loosen)
                    for c in range(channels):
                        numerator = 0.0
                        denominator = 0.0
                        best = -1
                        for j in range(count - 1, -1, -1):
                            z = codes[j, y, x, c]
                            gone = (dropped[j] >> c) & 1 == 1
                            saturated = z >= limits[c] or gone
                            # A code at its limit has no term; a channel the policy
                            # drops none either, whatever its code.
                            term = terms[j, c, z] * (0.0 if gone else 1.0)
                            # A clip resets as far as the bracket is kept (a resampled
                            # bracket's clip is the scene's, a mover's says nothing);
                            # the longer brackets above a kept clip are no fallback.
                            reset = 1.0 - held[j] * saturated
                            numerator = numerator * reset + m[j] * term.real
                            denominator = denominator * reset + m[j] * term.imag
                            if saturated and held[j] >= 0.5:
                                best = -1
                            if not saturated and (best < 0 or m[j] > m[best]):
                                best = j
                        if (denominator <= 0.0 and best < 0) or (saturated and m[0] >= 0.5):
                            # Saturated in every bracket, or dropped from the shortest one
                            # (so from every one) where it is kept: the kernel's lower
                            # bound stands (not the most-kept bracket's estimate of a
                            # clipped code, nor the longer ones' a soft reset leaves).
                            values[c] = out[y, x, c]
                            continue
                        if denominator > 0.0:
                            value = numerator / denominator
                        else:
                            j = best if best >= 0 and m[best] > 0.0 else int(np.argmax(m))
                            value = estimates[j, c, codes[j, y, x, c]]
                        if log_domain:
                            value = math.exp(min(max(value, LOG_FLOAT32_TINY), LOG_FLOAT32_MAX))
                        values[c] = min(max(value, FLOAT32_TINY), FLOAT32_MAX)
                    for c in range(channels):
                        out[y, x, c] = values[c]


def remerge_masked(codes: np.ndarray, keep: np.ndarray, cell: int, terms: np.ndarray,
                   estimates: np.ndarray, policy: ClipPolicy, log_domain: bool,
                   radiance: np.ndarray, *, first_row: int = 0, rows: int | None = None,
                   factors: np.ndarray | None = None) -> int:
    """Re-merge, in place in ``radiance`` ``(H, W, C)`` float32, the pixels where a keep
    weight is below 1; returns how many cells were re-merged.

    Parameters
    ----------
    codes
        ``(P, H, W, C)`` code values, shortest exposure first.
    keep
        ``(P, rows, cols)`` weights in [0, 1] at cell centres ``(i + 0.5) * cell``
        (float32 or float64; ``cell`` 1 gives per-pixel weights).
    terms, estimates
        :func:`hdrio.radiometry.tables.merge_tables`' tables, ``(P, C, levels)``.
    policy, log_domain
        The merge's saturation policy (:attr:`hdrio.merge.weighted_mean.MergeStatistics.
        policy`: a code at or above its limit, or an observation it drops whole, resets
        the sums as a saturated one, so that keep weights of 1 give the kernel's merge)
        and domain (``log``).
    first_row, rows, factors
        A band: only rows ``first_row .. first_row + rows - 1`` (``first_row`` a multiple
        of ``cell``; all rows by default) are re-merged. ``factors`` ``(P, cell rows of
        the band, cols)`` multiply the keep weights per cell, not interpolated
        (:mod:`hdrio.align.resampling`); the cells where one is below 1 are re-merged too.

    The clip test (:mod:`hdrio.radiometry.cliptest`) reads, for each bracket, the next shorter
    one whose keep weight (before ``factors``) is 0.5 or more: the codes of a bracket
    masked out (``--mask``, ``--exclude-color``) or dropped as a mover say nothing of the
    pixel. A bracket only down-weighted for its resampling error is still read: it saw
    the same scene, a clip there is the scene's. A factor ``f`` (noise over noise plus
    resampling error) on either bracket of a test widens the disagreement the test
    allows by ``1 / f``: on the hand-held GoldenGate truth stack
    (``python -m tests.align_truth``) testing at the noise alone raised the p99 error
    0.1-0.14x the still stack's; reading the factored weight instead of the keep weight
    (a factor under 0.5 switched the test off) left a row of cyan specks along a boat's
    edge in the hand-held canal stack.
    """
    import scipy.ndimage
    rows = codes.shape[1] - first_row if rows is None else rows
    start, stop = first_row // cell, -(-(first_row + rows) // cell)
    above = max(0, start - 1)  # the band's cells and their neighbours
    low = keep[:, above:stop + 1].min(axis=0) < 1.0
    # Cells' weights reach the neighbouring cells (bilinear); a pixel's (cell 1) do not.
    touched = low if cell == 1 or not low.any() else scipy.ndimage.binary_dilation(
        low, np.ones((3, 3), bool))
    touched = touched[start - above:stop - above]
    if factors is None:
        factors = np.ones((codes.shape[0], 0, 0), np.float32)
    else:
        touched = touched | (factors < 1.0).any(axis=0)
    if not touched.any():
        return 0
    arguments = policy.kernel_args()
    terms = np.array(terms, np.complex128)  # a copy: dropped codes never count
    for c, limit in enumerate(arguments[0]):
        terms[:, c, limit:] = 0.0
    size_numba_threads()
    _remerge(codes, np.ascontiguousarray(
        keep, keep.dtype if keep.dtype == np.float32 else np.float64), touched, cell,
             terms, np.ascontiguousarray(estimates, np.float64), arguments, log_domain,
             radiance, first_row, np.ascontiguousarray(factors, np.float32))
    return int(np.count_nonzero(touched))
