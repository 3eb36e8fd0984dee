"""Luminance and chromaticities of an RGB working space, from colour-science.

colour-science is imported lazily (it takes about a second), and the weights of a space
are computed once.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

DEFAULT_SPACE = "ITU-R BT.709"


@lru_cache(maxsize=16)
def rgb_colourspace(name: str):
    """colour-science's ``RGB_Colourspace`` called ``name`` (cached; a clear error if unknown)."""
    import colour

    try:
        return colour.RGB_COLOURSPACES[name]
    except KeyError:
        raise KeyError(f"unknown RGB colour space {name!r} (colour-science names, e.g. "
                       f"'ITU-R BT.709', 'ACEScg')") from None


@lru_cache(maxsize=16)
def luminance_weights(space: str = DEFAULT_SPACE) -> tuple[float, float, float]:
    """``Y`` of each primary (the middle row of the RGB to XYZ matrix), summing to 1.

    For linear Rec.709 / sRGB primaries: 0.2126, 0.7152, 0.0722.
    """
    import colour

    colourspace = rgb_colourspace(space)
    matrix = colour.normalised_primary_matrix(colourspace.primaries, colourspace.whitepoint)
    return tuple(float(v) for v in matrix[1])


def luminance(rgb: np.ndarray, space: str = DEFAULT_SPACE) -> np.ndarray:
    """Relative luminance ``Y`` of linear ``rgb`` (``(..., 3)``) in ``space``, same units.

    A greyscale image (``(..., 1)``) is its own luminance: its one channel is returned.
    """
    rgb = np.asarray(rgb)
    if rgb.shape[-1:] == (1,):
        return np.asarray(rgb[..., 0], dtype=np.float32)
    weights = np.asarray(luminance_weights(space), dtype=np.float32)
    return np.asarray(rgb, dtype=np.float32) @ weights


@lru_cache(maxsize=16)
def rgb_chromaticities(space: str = DEFAULT_SPACE) -> tuple[float, ...]:
    """OpenEXR ``chromaticities``: red, green, blue and white ``x, y`` (8 floats)."""
    colourspace = rgb_colourspace(space)
    primaries = np.asarray(colourspace.primaries, dtype=np.float64).reshape(-1)
    white = np.asarray(colourspace.whitepoint, dtype=np.float64)
    return tuple(float(v) for v in (*primaries, *white))
