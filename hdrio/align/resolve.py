"""The aligned sample a response is re-solved on after a warp (:func:`register`'s second
pass, deghosting's re-solve): every bracket resampled onto the reference, without the
pixels a warp invents or blurs.

A response solved on brackets that moved mixes scene points at edges; one solved on
brackets that could not be registered mixes whole regions (a hand-held ladder's two
longest, left unwarped, bent the curve by 10 % at code 30), so those are left out.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numba import njit

from hdrio.align.warp import coverage, warp_codes
from hdrio.stack import ExposureStack

EDGE_CODES = 24.0
"""Pixels whose 3x3 neighbourhood spans more than this (8-bit codes, mean of channels)
in some bracket are not sampled for the re-solve: resampled brackets differ from the
reference at sharp edges, and such samples bent the solved response (merged median
error 0.018-0.024 on the truth stacks; 0.013-0.015 without them; the still stack's
0.012)."""


def sampled_stack(stack: ExposureStack, alignment, step: int
                  ) -> tuple[ExposureStack, np.ndarray]:
    """Every ``step``-th pixel of the reference's grid, each registered bracket resampled
    there (:func:`~hdrio.align.warp.warp_codes`; ``alignment``:
    :class:`~hdrio.align.registration.Alignment`), and the ``(h, w)`` mask of pixels not
    to sample (some bracket does not cover them, or they are on a sharp edge:
    :data:`EDGE_CODES`): a small aligned stack for re-solving the response. The brackets
    that could not be registered are left out (while at least two are left)."""
    height, width = stack.shape[:2]
    rows, cols = -(-height // step), -(-width // step)
    grid = np.array([[step, 0.0, 0.0], [0.0, step, 0.0], [0.0, 0.0, 1.0]])
    refused = {j for j, _ in alignment.refused}
    kept = [j for j in range(stack.count) if j not in refused]
    kept = kept if len(kept) >= 2 else list(range(stack.count))
    codes = np.empty((len(kept), rows, cols, stack.shape[2]), stack.codes.dtype)
    uncovered = np.zeros((rows, cols), bool)
    for i, j in enumerate(kept):
        warp = alignment.transforms[j] @ grid
        warp_codes(stack.codes[j], warp, stack.code_max, codes[i])
        uncovered |= coverage(warp, rows, cols, 1, (height, width)) < 1
        uncovered |= sharp_edges(codes[i], stack.code_max)
    def pick(values):
        return values if not values else tuple(values[j] for j in kept)

    return replace(stack, codes=codes, exposures=stack.exposures[kept],
                   files=pick(stack.files), exposure_sources=pick(stack.exposure_sources),
                   metadata=pick(stack.metadata), kinds=pick(stack.kinds),
                   channel_gains=None if stack.channel_gains is None
                   else stack.channel_gains[kept]), uncovered


def sharp_edges(codes: np.ndarray, code_max: int, step: int = 1) -> np.ndarray:
    """``(H, W)``: pixels of one bracket ``(H, W, C)`` whose 3x3 neighbourhood spans more
    than :data:`EDGE_CODES` (mean of channels). With ``step`` > 1 the test is made on
    every ``step``-th pixel each way (neighbourhoods ``step`` times wider: more pixels
    excluded, ``step^2`` times less work) and each result repeated over its block."""
    height, width = codes.shape[:2]
    edges = np.empty((-(-height // step), -(-width // step)), np.bool_)
    _sharp_edges(codes, step, np.float32(EDGE_CODES * code_max / 255.0), edges)
    if step > 1:
        edges = np.repeat(np.repeat(edges, step, axis=0), step, axis=1)[:height, :width]
    return edges


@njit(cache=True, nogil=True)
def _sharp_edges(codes, step, threshold, out):  # pragma: no cover - compiled
    """:func:`sharp_edges` on the ``step`` grid, into ``out``: the mean of the channels
    as NumPy's ``mean(axis=-1, dtype=float32)`` makes it (a float32 sum, divided in
    float64), its 3x3 range (the border's neighbours the border itself, as
    ``scipy.ndimage``'s filters reflect it) and the comparison in float32, so that the
    mask is NumPy's bit for bit, in one pass and without SciPy's filters (14 calls took
    1 s of a hand-held 7 x 24 MP merge)."""
    rows, cols = out.shape
    channels = codes.shape[2]
    grey = np.empty((rows, cols), np.float32)
    for y in range(rows):
        for x in range(cols):
            total = np.float32(0.0)
            for c in range(channels):
                total += np.float32(codes[y * step, x * step, c])
            grey[y, x] = np.float32(np.float64(total) / channels)
    for y in range(rows):
        for x in range(cols):
            low = high = grey[y, x]
            for yy in range(max(y - 1, 0), min(y + 2, rows)):
                for xx in range(max(x - 1, 0), min(x + 2, cols)):
                    low = min(low, grey[yy, xx])
                    high = max(high, grey[yy, xx])
            out[y, x] = high - low > threshold
