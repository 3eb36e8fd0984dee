"""The reference (oracle) for the fast Reinhard (2002) paper operators: the original
vectorised numpy/scipy implementation, kept here unchanged so the kernels in
``hdrio/tonemap/reinhard2002_kernels.py`` can be compared with it. Not part of the package.

It shares ``_adapting_luminance`` (the scale selection, eq. 8) with the package's tutorial
variant, which ``test_tonemap_reinhard2002.py`` checks against a direct loop port.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

from hdrio.radiometry.luminance import DEFAULT_SPACE, luminance
from hdrio.tonemap.reinhard2002 import DELTA, _adapting_luminance


def log_average_luminance(L: np.ndarray, delta: float = DELTA) -> float:
    """The key of the scene, ``exp(mean(ln(delta + L)))`` (the paper's eq. 1).

    Negative luminance (radiance maps can hold small negatives) counts as 0, so one such
    pixel cannot turn the key, and with it the whole image, into NaN.
    """
    return float(np.exp(np.mean(np.log(delta + np.maximum(L.astype(np.float64), 0.0)))))


def reapply_colour(rgb: np.ndarray, L: np.ndarray, L_d: np.ndarray, saturation: float
                   ) -> np.ndarray:
    """``(C / L)^saturation * L_d`` clamped to [0, 1]; black where ``L <= 0``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(L[..., None] > 0, rgb / L[..., None], 0.0)
    ratio = np.maximum(ratio, 0.0)
    return np.clip(ratio**saturation * L_d[..., None], 0.0, 1.0).astype(np.float32)


def reference_global(rgb: np.ndarray, key: float = 0.72, saturation: float = 0.6,
                     white: float | None = None, delta: float = DELTA,
                     space: str = DEFAULT_SPACE) -> np.ndarray:
    """The global operator (eqs. 1-4), numpy."""
    rgb = np.asarray(rgb, dtype=np.float32)
    L = luminance(rgb, space)
    L_m = (key / log_average_luminance(L, delta)) * L
    if white is None:
        L_d = L_m / (1.0 + L_m)
    else:
        L_d = L_m * (1.0 + L_m / white**2) / (1.0 + L_m)
    return reapply_colour(rgb, L, L_d, saturation)


def gaussian_mirrored(image: np.ndarray, sigma: float) -> np.ndarray:
    return scipy.ndimage.gaussian_filter(image, sigma, mode="mirror", truncate=4.0)


def reference_local(rgb: np.ndarray, key: float = 0.18, phi: float = 8.0,
                    epsilon: float = 0.05, saturation: float = 0.6, delta: float = DELTA,
                    space: str = DEFAULT_SPACE) -> np.ndarray:
    """The local operator (eqs. 1, 2, 5-9): nine full-image scipy blurs."""
    rgb = np.asarray(rgb, dtype=np.float32)
    L = luminance(rgb, space)
    L_m = ((key / log_average_luminance(L, delta)) * L).astype(np.float32)
    V1 = _adapting_luminance(L_m, gaussian_mirrored, key, phi, epsilon, lambda s: s)
    return reapply_colour(rgb, L, L_m / (1.0 + V1), saturation)
