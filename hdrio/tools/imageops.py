"""Operations on a whole image, scene-linear or display: the steps of ``hdrio``'s chain.

Images here are float32 ``(H, W, C)`` arrays; the functions never modify their input.
"""

from __future__ import annotations

import numpy as np

from hdrio.radiometry.luminance import DEFAULT_SPACE, luminance


def apply_exposure(pixels: np.ndarray, stops: float) -> np.ndarray:
    """Scale scene-linear ``pixels`` by ``2**stops`` (same units, a new array)."""
    return np.asarray(pixels, dtype=np.float32) * np.float32(2.0**stops)


def resize(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """Resample to ``width x height`` pixels with a triangle (bilinear) filter.

    A linear filter on scene-linear values keeps total energy: downsizing averages
    radiance, as a lower-resolution sensor would. The filter is non-negative: OpenImageIO's
    default (Lanczos, Blackman-Harris) rings around a bright window, giving negative
    radiance beside it.
    """
    import OpenImageIO as oiio

    if width < 1 or height < 1:
        raise ValueError(f"size must be at least 1x1, got {width}x{height}")
    source = oiio.ImageBuf(np.ascontiguousarray(pixels, dtype=np.float32))
    roi = oiio.ROI(0, width, 0, height, 0, 1, 0, pixels.shape[-1])
    result = oiio.ImageBufAlgo.resize(source, filtername="triangle", roi=roi)
    if result.has_error:
        raise ValueError(f"resize failed: {result.geterror()}")
    return np.asarray(result.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(
        height, width, pixels.shape[-1])


def image_statistics(pixels: np.ndarray, space: str = DEFAULT_SPACE) -> dict[str, object]:
    """Per-channel ``min``, ``max``, ``mean``; counts of NaN, Inf and negative values;
    and the dynamic range in stops (log2 of the max over the min positive luminance, and
    of the 99.9 over the 0.1 percentile), in the image's own units.
    """
    pixels = np.asarray(pixels, dtype=np.float32)
    finite = np.where(np.isfinite(pixels), pixels, np.nan)
    stats: dict[str, object] = {
        "min": np.nanmin(finite, axis=(0, 1)).tolist(),
        "max": np.nanmax(finite, axis=(0, 1)).tolist(),
        "mean": np.nanmean(finite, axis=(0, 1)).tolist(),
        "nan": int(np.count_nonzero(np.isnan(pixels))),
        "inf": int(np.count_nonzero(np.isinf(pixels))),
        "negative": int(np.count_nonzero(pixels < 0)),
    }
    if pixels.shape[-1] >= 3:
        L = luminance(np.nan_to_num(pixels[..., :3], nan=0.0, posinf=0.0), space)
    else:
        L = np.nan_to_num(pixels[..., 0], nan=0.0, posinf=0.0)
    L = L[L > 0]
    if L.size:
        low, high = np.percentile(L, [0.1, 99.9])
        stats["range_stops"] = float(np.log2(L.max() / L.min()))
        stats["robust_range_stops"] = float(np.log2(high / low))
    return stats
