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
from hdrio.parallel import on_threads
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
        # Edges within a pixel of each sample: on the warped bracket itself at full
        # resolution, else where the sample was taken from in the bracket.
        uncovered |= (sharp_edges(codes[i], stack.code_max) if step == 1 else
                      sharp_edges(stack.codes[j], stack.code_max, warp, (rows, cols)))
    def pick(values):
        return values if not values else tuple(values[j] for j in kept)

    return replace(stack, codes=codes, exposures=stack.exposures[kept],
                   files=pick(stack.files), exposure_sources=pick(stack.exposure_sources),
                   metadata=pick(stack.metadata), kinds=pick(stack.kinds),
                   channel_gains=None if stack.channel_gains is None
                   else stack.channel_gains[kept]), uncovered


def sharp_edges(codes: np.ndarray, code_max: int, grid: np.ndarray | None = None,
                shape: tuple[int, int] | None = None) -> np.ndarray:
    """``(H, W)``: pixels of one bracket ``(H, W, C)`` whose 3x3 neighbourhood spans more
    than :data:`EDGE_CODES` (mean of channels). With ``grid`` (``3 x 3``: a point of a
    ``shape`` grid to a pixel of ``codes``), the same test at the pixel nearest each
    grid point, into a ``shape`` mask: a coarse grid's samples tested on their own
    full-resolution neighbourhoods.

    (A test on the coarse grid itself, its neighbours a grid step apart, left out 84 %
    of the 24 MP moved speed stack's aligned sample at step 4, and its re-solve 160-269
    samples of 1000: the merge's median error 2.46x the still stack's.)"""
    if grid is None:
        grid, shape = np.eye(3), codes.shape[:2]
    edges = np.empty(shape, np.bool_)
    on_threads(_sharp_edges, shape[0], codes, np.ascontiguousarray(grid, np.float64),
               np.float32(EDGE_CODES * code_max / 255.0), edges)
    return edges


@njit(cache=True, nogil=True)
def _sharp_edges(start, stop, codes, grid, threshold, out):  # pragma: no cover - compiled
    """:func:`sharp_edges` into rows ``start .. stop - 1`` of ``out`` (on every core: one
    thread took 0.45 s of a moved 7 x 24 MP stack's re-solve, 60 ms a bracket at step
    4): for each of its points, the pixel of ``codes``
    nearest ``grid @ (x, y, 1)`` (clipped to the image), the mean of the channels of its
    3x3 neighbourhood as NumPy's ``mean(axis=-1, dtype=float32)`` makes it (a float32
    sum, divided in float64), their range (the border's neighbours the border itself, as
    ``scipy.ndimage``'s filters reflect it) and the comparison in float32, so that the
    mask on the identity grid is NumPy's and SciPy's bit for bit, in one pass (14 calls
    of SciPy's filters took 1 s of a hand-held 7 x 24 MP merge)."""
    cols = out.shape[1]
    height, width, channels = codes.shape
    for y in range(start, stop):
        for x in range(cols):
            w = grid[2, 0] * x + grid[2, 1] * y + grid[2, 2]
            sx = (grid[0, 0] * x + grid[0, 1] * y + grid[0, 2]) / w
            sy = (grid[1, 0] * x + grid[1, 1] * y + grid[1, 2]) / w
            cx = min(max(int(np.floor(sx + 0.5)), 0), width - 1)
            cy = min(max(int(np.floor(sy + 0.5)), 0), height - 1)
            low = np.float32(np.inf)
            high = np.float32(-np.inf)
            for yy in range(max(cy - 1, 0), min(cy + 2, height)):
                for xx in range(max(cx - 1, 0), min(cx + 2, width)):
                    total = np.float32(0.0)
                    for c in range(channels):
                        total += np.float32(codes[yy, xx, c])
                    grey = np.float32(np.float64(total) / channels)
                    low = min(low, grey)
                    high = max(high, grey)
            out[y, x] = high - low > threshold
