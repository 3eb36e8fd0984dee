"""Luminance and chromaticities of an RGB working space, from colour-science.

colour-science is imported lazily: importing it takes 0.7 s, and 2 s when Matplotlib is
installed (it imports its plotting). The spaces hdrio writes are in
:data:`KNOWN_CHROMATICITIES`, colour-science's own values (a test holds them equal), so
that a merge or ``hdrio check`` never pays for that import; other names are looked up in
colour-science.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

DEFAULT_SPACE = "ITU-R BT.709"

KNOWN_CHROMATICITIES: dict[str, tuple[float, ...]] = {
    "ITU-R BT.709": (0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 0.329),
    "ACEScg": (0.713, 0.293, 0.165, 0.83, 0.128, 0.044, 0.32168, 0.33767),
    "ACES2065-1": (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767),
    "Display P3": (0.68, 0.32, 0.265, 0.69, 0.15, 0.06, 0.3127, 0.329),
    "ITU-R BT.2020": (0.708, 0.292, 0.17, 0.797, 0.131, 0.046, 0.3127, 0.329),
    "Adobe RGB (1998)": (0.64, 0.33, 0.21, 0.71, 0.15, 0.06, 0.3127, 0.329),
}
"""colour-science ``RGB_COLOURSPACES`` name -> OpenEXR ``chromaticities`` (red, green,
blue, white ``x, y``) of the spaces hdrio writes."""


def normalised_primary_matrix(chromaticities: tuple[float, ...]) -> np.ndarray:
    """The RGB to XYZ matrix of ``chromaticities`` (8 floats), white mapped to ``Y = 1``
    (SMPTE RP 177; colour-science's ``normalised_primary_matrix``)."""
    xy = np.asarray(chromaticities, dtype=np.float64).reshape(4, 2)
    xyz = np.column_stack([xy, 1.0 - xy.sum(axis=1)]) / xy[:, 1:2]  # Y = 1 each
    primaries, white = xyz[:3].T, xyz[3]
    return primaries * np.linalg.solve(primaries, white)


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
    return tuple(float(v) for v in normalised_primary_matrix(rgb_chromaticities(space))[1])


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
    if space in KNOWN_CHROMATICITIES:
        return KNOWN_CHROMATICITIES[space]
    colourspace = rgb_colourspace(space)
    primaries = np.asarray(colourspace.primaries, dtype=np.float64).reshape(-1)
    white = np.asarray(colourspace.whitepoint, dtype=np.float64)
    return tuple(float(v) for v in (*primaries, *white))


DELTA = 1e-4
"""Reinhard et al. (2002)'s ``delta`` in eq. 1: keeps black pixels out of ``ln 0``."""


def log_average_luminance(L: np.ndarray, delta: float = DELTA) -> float:
    """Reinhard et al. (2002) eq. 1, the scene's key: ``exp(mean(ln(delta + L)))`` over
    luminance ``L`` (any shape), negative luminance counted as 0. The tone-mapping
    operators (:mod:`hdrio.tonemap.reinhard2002`) and the OCIO display previews
    (:mod:`hdrio.cms.display`) expose a scene by it."""
    L = np.asarray(L, dtype=np.float64)
    return float(np.exp(np.mean(np.log(delta + np.maximum(L, 0.0)))))
