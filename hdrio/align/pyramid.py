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
from numba import njit, prange

from hdrio.skips import well_exposed_codes

BASE_PIXELS = 1_600_000
"""Largest base image: above this the base is block-averaged 2x, 4x, ... (24 MP -> 4x)."""


def base_factor(height: int, width: int, base_pixels: int = BASE_PIXELS) -> int:
    """The power of two ``f`` that block-averages ``height x width`` to at most
    ``base_pixels``."""
    factor = 1
    while (height // factor) * (width // factor) > base_pixels:
        factor *= 2
    return factor


@njit(parallel=True, cache=True, nogil=True)
def _base_kernel(codes, linear, low, high, factor, out, valid, grey):  # pragma: no cover
    """Block means of ``sum_c linear[c, z_c]`` and of the codes, and the blocks whose every
    code lies in ``low .. high``."""
    rows, cols = out.shape
    channels = codes.shape[2]
    inverse = np.float32(1.0 / (factor * factor))
    for by in prange(rows):
        for bx in range(cols):
            total = np.float32(0.0)
            code_total = np.float32(0.0)
            good = True
            for y in range(by * factor, by * factor + factor):
                for x in range(bx * factor, bx * factor + factor):
                    for c in range(channels):
                        z = codes[y, x, c]
                        total += linear[c, z]
                        code_total += np.float32(z)
                        good &= (z >= low) & (z <= high)
            out[by, bx] = total * inverse
            grey[by, bx] = code_total * inverse / channels
            valid[by, bx] = good


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
    low, high = well_exposed_codes(code_max)
    _base_kernel(codes, np.ascontiguousarray(linear, np.float32), low, high, factor, out,
                 valid, grey)
    return BaseImage(np.log(np.maximum(out, np.float32(1e-30))), valid, grey, factor)


def downsample(image: np.ndarray) -> np.ndarray:
    """2x2 block mean (a trailing odd row or column is dropped)."""
    h, w = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
    image = image[:h, :w].astype(np.float32)
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
