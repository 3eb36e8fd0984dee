"""White balance from a neutral region: per-channel gains that keep luminance.

The brackets were already white balanced by the camera (JPEG, PNG, TIFF output), so
hdrio applies a balance only when asked, from a region the user knows is neutral (a grey
card, a white wall). Gains ``k_c = Y / mean_c`` make the region's mean ``(Y, Y, Y)``:
neutral, with its luminance ``Y`` unchanged. Camera metadata white balance (as-shot
multipliers) exists only for RAW files, which hdrio does not read yet.
"""

from __future__ import annotations

import numpy as np

from hdrio.cms.calibration import Region, region_mean_luminance
from hdrio.errors import HdrioError


def neutral_gains(radiance: np.ndarray, region: Region, space: str) -> np.ndarray:
    """Gains ``(3,)`` that make the mean of ``region`` neutral, keeping its luminance.

    ``radiance`` is linear RGB ``(H, W, 3)`` in colour-science space ``space``; units do
    not matter (relative or cd/m^2).
    """
    if radiance.ndim != 3 or radiance.shape[-1] != 3:
        raise HdrioError("white balance needs an RGB image")
    Y = region_mean_luminance(radiance, region, space)
    x, y, w, h = region
    means = radiance[y: y + h, x: x + w].reshape(-1, 3).astype(np.float64).mean(axis=0)
    if not (Y > 0 and np.all(means > 0)):
        raise HdrioError(f"white balance region {x},{y},{w},{h} has a channel with no light")
    return Y / means


def apply_gains(radiance: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """``radiance * gains`` as a new float32 array (the input is not modified)."""
    return (np.asarray(radiance, dtype=np.float32) * np.asarray(gains, dtype=np.float32))
