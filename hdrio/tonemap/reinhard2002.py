"""Reinhard et al. (2002) photographic tone reproduction: global and local operators.

Both take linear RGB (any positive scale: relative or absolute radiance) and return
display-linear RGB in [0, 1] (encode for a display before writing 8-bit files).

Paper variants (``tonemap_Reinhard2002_global``, ``tonemap_Reinhard2002_local``)
    * log-average key ``L_bar = exp(mean(ln(delta + L)))``, ``delta = 1e-4`` (eq. 1)
    * scaling ``L_m = a / L_bar * L`` (eq. 2); global ``L_d = L_m / (1 + L_m)`` (eq. 3), or
      with a white point ``L_d = L_m (1 + L_m / L_white^2) / (1 + L_m)`` (eq. 4)
    * local: Gaussian blurs ``V1(s)`` of ``L_m`` at ``s = 1.6^i`` (i = 0..8), ``sigma = s /
      (2 sqrt 2)``; centre-surround activity ``V(s) = (V1(s) - V1(1.6 s)) / (2^phi a / s^2
      + V1(s))`` (eq. 7); the largest scale whose activity (and that of every smaller
      scale) stays within ``epsilon`` is ``s_max`` (eq. 8); ``L_d = L_m / (1 + V1(s_max))``
      (eq. 9). Blurs mirror the image at its borders.
    * colour re-applied as ``C_d = (C / L)^saturation * L_d`` and clamped to [0, 1].
    * luminance from colour-science for the working space's primaries.

Tutorial variants (``..._tutorial``) reproduce the tutorial's MATLAB listing exactly,
where it departs from the paper: luminance ``0.2125 R + 0.7154 G + 0.0721 B``; the local
operator does not apply ``a / L_bar`` (it adapts raw ``L``), normalises every scale's
activity with the *last* scale's ``s = 1.6^8`` and ``key = 0.18``, blurs with kernels
truncated at ``ceil(2 sigma)`` and zero padding (MATLAB ``conv2(..., 'same')``), and only
clamps values above 1.

References
----------
Reinhard, E., Stark, M., Shirley, P., & Ferwerda, J. (2002). Photographic tone
reproduction for digital images. ACM Transactions on Graphics, 21(3), 267-276.
doi:10.1145/566654.566575
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.ndimage

from hdrio.cms.luminance import DEFAULT_SPACE, luminance

DELTA = 1e-4
SCALE_RATIO = 1.6
SCALES = 8
ALPHA_1 = 1.0 / (2.0 * math.sqrt(2.0))
TUTORIAL_LUMINANCE = (0.2125, 0.7154, 0.0721)


def log_average_luminance(L: np.ndarray, delta: float = DELTA) -> float:
    """The key of the scene, ``exp(mean(ln(delta + L)))`` (the paper's eq. 1).

    Negative luminance (radiance maps can hold small negatives) counts as 0, so one such
    pixel cannot turn the key, and with it the whole image, into NaN.
    """
    return float(np.exp(np.mean(np.log(delta + np.maximum(L.astype(np.float64), 0.0)))))


def _reapply_colour(rgb: np.ndarray, L: np.ndarray, L_d: np.ndarray, saturation: float
                    ) -> np.ndarray:
    """``(C / L)^saturation * L_d`` clamped to [0, 1]; black where ``L <= 0``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(L[..., None] > 0, rgb / L[..., None], 0.0)
    ratio = np.maximum(ratio, 0.0)
    return np.clip(ratio**saturation * L_d[..., None], 0.0, 1.0).astype(np.float32)


def tonemap_Reinhard2002_global(rgb: np.ndarray, key: float = 0.72, saturation: float = 0.6,
                                white: float | None = None, delta: float = DELTA,
                                space: str = DEFAULT_SPACE) -> np.ndarray:
    """The global operator (eqs. 1-4). ``key`` is ``a``; ``white`` enables eq. 4."""
    rgb = np.asarray(rgb, dtype=np.float32)
    L = luminance(rgb, space)
    L_m = (key / log_average_luminance(L, delta)) * L
    if white is None:
        L_d = L_m / (1.0 + L_m)
    else:
        L_d = L_m * (1.0 + L_m / white**2) / (1.0 + L_m)
    return _reapply_colour(rgb, L, L_d, saturation)


def _adapting_luminance(L: np.ndarray, blur: Callable[[np.ndarray, float], np.ndarray],
                        key: float, phi: float, epsilon: float,
                        normaliser_scale: Callable[[float], float]) -> np.ndarray:
    """``V1(s_max)`` per pixel: the widest blur whose activity stays within ``epsilon``.

    Scales are visited from the smallest; a pixel keeps the last scale before its first
    activity above ``epsilon`` (the smallest scale if even that one exceeds it; the
    eighth if none does). Once every pixel has settled, wider blurs are skipped.
    """
    v1 = blur(L, ALPHA_1)
    chosen = v1
    open_ = np.ones(L.shape, dtype=bool)
    for i in range(SCALES):
        s = SCALE_RATIO**i
        v1_next = blur(L, ALPHA_1 * SCALE_RATIO ** (i + 1))
        activity = np.abs(v1 - v1_next) / (2.0**phi * key / normaliser_scale(s) ** 2 + v1)
        open_ &= ~(activity > epsilon)
        chosen = np.where(open_, v1, chosen)
        if not open_.any():
            break
        v1 = v1_next
    return chosen


def _gaussian_mirrored(image: np.ndarray, sigma: float) -> np.ndarray:
    return scipy.ndimage.gaussian_filter(image, sigma, mode="mirror", truncate=4.0)


def tonemap_Reinhard2002_local(rgb: np.ndarray, key: float = 0.18, phi: float = 8.0,
                               epsilon: float = 0.05, saturation: float = 0.6,
                               delta: float = DELTA, space: str = DEFAULT_SPACE) -> np.ndarray:
    """The local dodging-and-burning operator (eqs. 1, 2, 5-9), ``key`` is ``a``."""
    rgb = np.asarray(rgb, dtype=np.float32)
    L = luminance(rgb, space)
    L_m = ((key / log_average_luminance(L, delta)) * L).astype(np.float32)
    V1 = _adapting_luminance(L_m, _gaussian_mirrored, key, phi, epsilon, lambda s: s)
    return _reapply_colour(rgb, L, L_m / (1.0 + V1), saturation)


def fspecial_gaussian(sigma: float) -> np.ndarray:
    """MATLAB ``fspecial('gaussian', [2 ceil(2 sigma) + 1, 1], sigma)`` as a 1-D kernel."""
    radius = math.ceil(2.0 * sigma)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    h = np.exp(-(x * x) / (2.0 * sigma * sigma))
    h[h < np.finfo(np.float64).eps * h.max()] = 0.0
    return h / h.sum()


def _gaussian_zero_padded(image: np.ndarray, sigma: float) -> np.ndarray:
    kernel = fspecial_gaussian(sigma)
    rows = scipy.ndimage.convolve1d(image, kernel, axis=0, mode="constant", cval=0.0)
    return scipy.ndimage.convolve1d(rows, kernel, axis=1, mode="constant", cval=0.0)


def _tutorial_luminance(hdr: np.ndarray) -> np.ndarray:
    return hdr @ np.asarray(TUTORIAL_LUMINANCE)


def tonemap_Reinhard2002_global_tutorial(hdr: np.ndarray, a: float = 0.72,
                                         saturation: float = 0.6) -> np.ndarray:
    """The tutorial's ``reinhardGlobal.m`` (float64; ``NaN`` where luminance is 0, as there)."""
    hdr = np.asarray(hdr, dtype=np.float64)
    L = _tutorial_luminance(hdr)
    key = np.exp(np.mean(np.log(L + DELTA)))
    scaled = L * (a / key)
    compressed = scaled / (scaled + 1.0)
    ldr = (hdr / L[..., None]) ** saturation * compressed[..., None]
    return np.where(ldr > 1.0, 1.0, ldr)


def tonemap_Reinhard2002_local_tutorial(hdr: np.ndarray, saturation: float = 0.6,
                                        eps: float = 0.05, phi: float = 8.0) -> np.ndarray:
    """The tutorial's ``reinhardLocal.m`` (float64; no ``a / key`` scaling, as there)."""
    hdr = np.asarray(hdr, dtype=np.float64)
    L = _tutorial_luminance(hdr)
    last_scale = SCALE_RATIO**SCALES
    V1 = _adapting_luminance(L, _gaussian_zero_padded, 0.18, phi, eps, lambda s: last_scale)
    compressed = L / (1.0 + V1)
    ldr = (hdr / L[..., None]) ** saturation * compressed[..., None]
    return np.where(ldr > 1.0, 1.0, ldr)
