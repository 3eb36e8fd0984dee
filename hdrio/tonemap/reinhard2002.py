"""Reinhard et al. (2002) photographic tone reproduction: global and local operators.

Both take linear RGB (any positive scale: relative or absolute radiance) and return
display-linear RGB in [0, 1] (encode for a display before writing 8-bit files).

Paper variants (``tonemap_Reinhard2002_global``, ``tonemap_Reinhard2002_local``)
    * log-average key ``L_bar = exp(mean(ln(delta + L)))``, ``delta = 1e-4`` (eq. 1;
      :func:`hdrio.radiometry.luminance.log_average_luminance`, shared with the OCIO
      display previews)
    * scaling ``L_m = a / L_bar * L`` (eq. 2); global ``L_d = L_m / (1 + L_m)`` (eq. 3), or
      with a white point ``L_d = L_m (1 + L_m / L_white^2) / (1 + L_m)`` (eq. 4)
    * local: Gaussian blurs ``V1(s)`` of ``L_m`` at ``s = 1.6^i`` (i = 0..8), ``sigma = s /
      (2 sqrt 2)``; centre-surround activity ``V(s) = (V1(s) - V1(1.6 s)) / (2^phi a / s^2
      + V1(s))`` (eq. 7); the largest scale whose activity (and that of every smaller
      scale) stays within ``epsilon`` is ``s_max`` (eq. 8); ``L_d = L_m / (1 + V1(s_max))``
      (eq. 9). Blurs mirror the image at its borders.
    * colour re-applied as ``C_d = (C / L)^saturation * L_d`` and clamped to [0, 1].
    * luminance from colour-science for the working space's primaries.
    * evaluated by the fused numba kernels of ``reinhard2002_kernels.py`` (float32; blurs
      are scipy's ``gaussian_filter(..., mode="mirror", truncate=4)`` kernels); the numpy
      version they replaced is the test oracle, ``tests/reinhard2002_reference.py``.

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

from hdrio.radiometry.luminance import (
    DEFAULT_SPACE,
    DELTA,
    log_average_luminance,
    luminance_weights,
)

SCALE_RATIO = 1.6
SCALES = 8
ALPHA_1 = 1.0 / (2.0 * math.sqrt(2.0))
TUTORIAL_LUMINANCE = (0.2125, 0.7154, 0.0721)


def _pixels(rgb: np.ndarray, operator: str) -> np.ndarray:
    """``rgb`` as C-contiguous float32 ``(..., 3)`` (no copy when it already is one)."""
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    if rgb.ndim == 0 or rgb.shape[-1] != 3:
        raise ValueError(f"{operator} takes RGB pixels (..., 3), got shape {rgb.shape}")
    return rgb


def _scene_key_scale(flat: np.ndarray, weights: np.ndarray, key: float, delta: float
                     ) -> np.float32:
    """``a / L_bar`` (eqs. 1 and 2) for flat float32 RGB; ``L_bar = exp(mean(ln(delta +
    L)))``, negative luminance counted as 0 (one noisy pixel cannot make it NaN)."""
    from hdrio.tonemap import reinhard2002_kernels as kernels  # numba: imported on use

    pixels = max(1, flat.size // 3)
    L_bar = math.exp(kernels.log_luminance_sum(flat, weights, float(delta)) / pixels)
    return np.float32(key / L_bar)


def tonemap_Reinhard2002_global(rgb: np.ndarray, key: float = 0.72, saturation: float = 0.6,
                                white: float | None = None, delta: float = DELTA,
                                space: str = DEFAULT_SPACE) -> np.ndarray:
    """The global operator (eqs. 1-4). ``key`` is ``a``; ``white`` enables eq. 4.

    Parameters
    ----------
    rgb
        Linear RGB ``(..., 3)`` in ``space``, relative or absolute radiance (any scale).
    key, saturation, white, delta
        ``a``, the colour exponent, ``L_white`` (in units of ``L_m``), the log offset.

    Returns
    -------
    numpy.ndarray
        Display-linear float32 RGB in [0, 1], the shape of ``rgb``.
    """
    from hdrio.tonemap import reinhard2002_kernels as kernels

    rgb = _pixels(rgb, "tonemap_Reinhard2002_global")
    flat = rgb.reshape(-1)
    weights = np.asarray(luminance_weights(space), dtype=np.float32)
    scale = _scene_key_scale(flat, weights, key, delta)
    white_squared = np.float32(0.0 if white is None else white**2)
    out = np.empty_like(rgb)
    kernels.global_operator(flat, out.reshape(-1), weights, scale, white is not None,
                            white_squared, float(saturation))
    return out


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


def tonemap_Reinhard2002_local(rgb: np.ndarray, key: float = 0.18, phi: float = 8.0,
                               epsilon: float = 0.05, saturation: float = 0.6,
                               delta: float = DELTA, space: str = DEFAULT_SPACE) -> np.ndarray:
    """The local dodging-and-burning operator (eqs. 1, 2, 5-9), ``key`` is ``a``.

    Blurs are ``scipy.ndimage.gaussian_filter(L_m, sigma, mode="mirror", truncate=4)``
    kernels, evaluated by the fused tile kernel of
    :mod:`hdrio.tonemap.reinhard2002_kernels` (float32 sums: within about 1e-6 of scipy).

    Parameters
    ----------
    rgb
        Linear RGB image ``(height, width, 3)`` in ``space``, relative or absolute radiance.
    key, phi, epsilon, saturation, delta
        ``a``, the sharpening ``phi``, the activity threshold, the colour exponent, the
        log offset of the key.

    Returns
    -------
    numpy.ndarray
        Display-linear float32 RGB in [0, 1], ``(height, width, 3)``.
    """
    from hdrio.tonemap import reinhard2002_kernels as kernels

    rgb = _pixels(rgb, "tonemap_Reinhard2002_local")
    if rgb.ndim != 3:
        raise ValueError(f"tonemap_Reinhard2002_local takes an image (height, width, 3), "
                         f"got shape {rgb.shape}")
    height, width = rgb.shape[:2]
    flat = rgb.reshape(-1)
    weights = np.asarray(luminance_weights(space), dtype=np.float32)
    scale = _scene_key_scale(flat, weights, key, delta)
    L_m = np.empty((height, width), dtype=np.float32)
    kernels.scaled_luminance(flat, L_m.reshape(-1), weights, scale)
    blurs = [kernels.gaussian_kernel_scipy(ALPHA_1 * SCALE_RATIO**i) for i in range(SCALES + 1)]
    radii = np.array([len(b) // 2 for b in blurs], dtype=np.int64)
    table = np.zeros((len(blurs), 2 * int(radii.max()) + 1), dtype=np.float32)
    for i, blur in enumerate(blurs):
        table[i, : len(blur)] = blur
    surround = np.array([2.0**phi * key / (SCALE_RATIO**i) ** 2 for i in range(SCALES)],
                        dtype=np.float32)  # eq. 7's 2^phi a / s^2, s = 1.6^i
    out = np.empty_like(rgb)
    kernels.local_operator(flat, out.reshape(-1), weights, L_m, table, radii, surround,
                           np.float32(epsilon), float(saturation))
    return out


def fspecial_gaussian(sigma: float) -> np.ndarray:
    """MATLAB ``fspecial('gaussian', [2 ceil(2 sigma) + 1, 1], sigma)`` as a 1-D kernel."""
    radius = math.ceil(2.0 * sigma)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    h = np.exp(-(x * x) / (2.0 * sigma * sigma))
    h[h < np.finfo(np.float64).eps * h.max()] = 0.0
    return h / h.sum()


def _gaussian_zero_padded(image: np.ndarray, sigma: float) -> np.ndarray:
    import scipy.ndimage
    kernel = fspecial_gaussian(sigma)
    rows = scipy.ndimage.convolve1d(image, kernel, axis=0, mode="constant", cval=0.0)
    return scipy.ndimage.convolve1d(rows, kernel, axis=1, mode="constant", cval=0.0)


def _tutorial_luminance(hdr: np.ndarray) -> np.ndarray:
    return hdr @ np.asarray(TUTORIAL_LUMINANCE)


def tonemap_Reinhard2002_global_tutorial(hdr: np.ndarray, a: float = 0.72,
                                         saturation: float = 0.6) -> np.ndarray:
    """The tutorial's ``reinhardGlobal.m`` (float64; ``NaN`` where luminance is 0, as there).

    The key counts negative luminance as 0, as the paper variants do (the listing takes
    the log of ``L + delta``, which a pixel below ``-delta`` would make NaN, and with it
    the whole picture); where luminance is not positive the result is NaN, which the
    preview shows black (:func:`hdrio.tonemap.preview.render_preview`).
    """
    hdr = np.asarray(hdr, dtype=np.float64)
    L = _tutorial_luminance(hdr)
    key = log_average_luminance(L)
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
