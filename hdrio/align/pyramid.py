"""Exposure-normalised, linearised images for registration, and their pyramids.

Alignment never looks at full resolution: one pass over each bracket's codes builds a
*base* image, block-averaged ``factor x factor``, of the bracket's linear estimate
``sum_c f_c^-1(Z_c) / dt`` (relative radiance, the same for every bracket of a still
scene), its ``log``, and whether every pixel of the block was well exposed in every
channel. Estimation then works on the base and on its 2x pyramid above it, so memory
and time stay bounded at 24 MP (a base of at most :data:`BASE_PIXELS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from hdrio.parallel import on_threads
from hdrio.skips import well_exposed_codes

REGISTRABLE = (0.02, 0.95)
"""Codes strictly inside these fractions of the range register a bracket (the base's
``valid``): darker than the well-exposed range's 5 %, so that the longest brackets of a
long ladder, clipped but in the shadows, share edges with their neighbours (a hand-held
7 x 2 EV ladder's two longest were left unregistered at 5 %). Deeper than 8 bits, as far
in light as these fractions reach on sRGB codes (:func:`hdrio.skips.well_exposed_codes`)."""

BASE_PIXELS = 1_600_000
"""Largest base image: above this the base is block-averaged 2x, 4x, ... (24 MP -> 4x)."""


def base_factor(height: int, width: int, base_pixels: int = BASE_PIXELS) -> int:
    """The power of two ``f`` that block-averages ``height x width`` to at most
    ``base_pixels``."""
    factor = 1
    while (height // factor) * (width // factor) > base_pixels:
        factor *= 2
    return factor


@njit(cache=True, nogil=True)
def _base_rows(start, stop, codes, linear, low, high, factor, out, valid,
               grey):  # pragma: no cover - compiled
    """Base rows ``start .. stop - 1``: block means of ``sum_c linear[c, z_c]`` and of the
    codes, and the blocks whose every code lies in ``low .. high``. Each block's row of
    ``factor`` pixels is summed on its own and added to the block's running sums (short
    chains of dependent float additions: one long chain a block was latency-bound)."""
    cols = out.shape[1]
    channels = codes.shape[2]
    inverse = np.float32(1.0 / (factor * factor))
    totals = np.empty(cols, np.float32)
    code_totals = np.empty(cols, np.int64)
    goods = np.empty(cols, np.bool_)
    for by in range(start, stop):
        for bx in range(cols):  # not slice assignments: 0.3 s less to compile
            totals[bx] = 0.0
            code_totals[bx] = 0
            goods[bx] = True
        for y in range(by * factor, by * factor + factor):
            row = codes[y]
            for bx in range(cols):
                total = np.float32(0.0)
                code_total = 0
                good = True
                for x in range(bx * factor, bx * factor + factor):
                    if channels == 3:  # spelt out: 1.6x faster than the loop
                        z0, z1, z2 = row[x, 0], row[x, 1], row[x, 2]
                        total += linear[0, z0] + linear[1, z1] + linear[2, z2]
                        code_total += np.int64(z0) + z1 + z2
                        good &= ((min(z0, min(z1, z2)) >= low)
                                 & (max(z0, max(z1, z2)) <= high))
                        continue
                    value = np.float32(0.0)
                    for c in range(channels):
                        z = row[x, c]
                        value += linear[c, z]
                        code_total += z
                        good &= (z >= low) & (z <= high)
                    total += value
                totals[bx] += total
                code_totals[bx] += code_total
                goods[bx] &= good
        for bx in range(cols):
            out[by, bx] = totals[bx] * inverse
            grey[by, bx] = np.float32(code_totals[bx]) * inverse / channels
            valid[by, bx] = goods[bx]


@dataclass
class BaseImage:
    """One bracket at base resolution.

    Attributes
    ----------
    log
        ``ln`` of the block mean of the linear estimate (relative radiance), float32.
    valid
        Blocks with every code well exposed (:data:`hdrio.skips.WELL_EXPOSED`).
    grey
        Block mean of the code values (for the median threshold bitmaps).
    factor
        Full-resolution pixels per base pixel, each way.
    """

    log: np.ndarray
    valid: np.ndarray
    grey: np.ndarray
    factor: int


def base_image(codes: np.ndarray, linear: np.ndarray, code_max: int,
               factor: int) -> BaseImage:
    """The base of one bracket.

    Parameters
    ----------
    codes
        ``(H, W, C)`` code values.
    linear
        ``(C, levels)`` float32: ``f_c^-1(z) / dt``, relative radiance per code value.
    code_max
        Saturation code.
    factor
        Block size (from :func:`base_factor`).
    """
    height, width = codes.shape[0] // factor, codes.shape[1] // factor
    out = np.empty((height, width), np.float32)
    grey = np.empty((height, width), np.float32)
    valid = np.empty((height, width), np.bool_)
    low, high = well_exposed_codes(code_max, REGISTRABLE, linear)
    on_threads(_base_rows, height, codes, np.ascontiguousarray(linear, np.float32), low, high,
               factor, out, valid, grey)
    np.maximum(out, np.float32(1e-30), out=out)  # in place: no full-size temporaries
    return BaseImage(np.log(out, out=out), valid, grey, factor)


def base_blocks(mask: np.ndarray, factor: int) -> np.ndarray:
    """``(H, W)`` bool at base resolution (``factor`` full-resolution pixels a side,
    trailing rows and columns dropped as :func:`base_image` drops them): a base pixel is
    set where any of its pixels is."""
    height, width = mask.shape[0] // factor, mask.shape[1] // factor
    mask = mask[:height * factor, :width * factor]
    return mask.reshape(height, factor, width, factor).any(axis=(1, 3))


def downsample(image: np.ndarray) -> np.ndarray:
    """2x2 block mean (a trailing odd row or column is dropped)."""
    h, w = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
    image = image[:h, :w].astype(np.float32, copy=False)
    return 0.25 * (image[0::2, 0::2] + image[1::2, 0::2] + image[0::2, 1::2]
                   + image[1::2, 1::2])


def downsample_valid(valid: np.ndarray) -> np.ndarray:
    """2x2 blocks all valid."""
    h, w = valid.shape[0] // 2 * 2, valid.shape[1] // 2 * 2
    valid = valid[:h, :w]
    return valid[0::2, 0::2] & valid[1::2, 0::2] & valid[0::2, 1::2] & valid[1::2, 1::2]


def levels_above(height: int, width: int, smallest: int = 48) -> int:
    """Pyramid levels above a base of ``height x width`` before a side drops under
    ``smallest`` pixels."""
    return max(0, int(math.floor(math.log2(max(1, min(height, width) / smallest)))))
