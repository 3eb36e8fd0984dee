"""A direct NumPy port of the merge, kept as the oracle for the fused kernel.

Vectorised over pixels, looping over brackets exactly as the tutorial's ``hdr.m`` does,
with the per-channel saturation policy beside the tutorial's per-pixel one. Slow (it
makes several full-size temporaries per bracket) but obviously right.
"""

from __future__ import annotations

import numpy as np

from hdrio.radiometry.tables import estimate_tables
from hdrio.radiometry.weighting import weights_table

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
FLOAT32_MAX = float(np.finfo(np.float32).max)


def merge_reference(stack, response, weighting="Debevec1997", domain="log",
                    saturation="channel", limits=None):
    """Radiance ``(H, W, C)`` float32 and ``(clipped, black)`` pixel counts.

    ``limits`` ``(C,)``: the first dropped code per channel (``safe``, and ``auto`` where
    it chose per-channel limits: each channel dropped alone; ``Z_max`` else)."""
    if saturation not in ("safe", "auto") or limits is None:
        limits = np.full(stack.codes.shape[-1], stack.code_max)
    count, height, width, channels = stack.codes.shape
    weights = weights_table(weighting, stack.code_max)[:, None] * response.supported
    tables = estimate_tables(response, stack.exposures, domain)
    channel_index = np.arange(channels)
    numerator = np.zeros((height, width, channels))
    denominator = np.zeros((height, width, channels))
    dropped = np.zeros((height, width, channels), dtype=bool)
    fallback = None
    for j in range(count):
        codes = stack.codes[j].astype(np.int64)
        saturated = codes >= limits
        if saturation not in ("channel", "auto"):
            saturated = np.repeat(np.any(saturated, axis=-1, keepdims=True), channels, -1)
        dropped |= saturated
        keep = ~dropped
        estimate = tables[j][codes, channel_index]
        weight = np.where(keep, weights[codes, channel_index], 0.0)
        numerator += weight * estimate
        denominator += weight
        if j == 0:
            clipped = int(np.count_nonzero(np.any(codes >= limits, axis=-1)))
            # Clipped everywhere: a neutral lower bound (the largest channel's estimate),
            # where the pixel is dropped whole; a channel dropped alone keeps its own.
            whole = np.all(saturated, axis=-1, keepdims=True)
            fallback = np.where(whole, estimate.max(axis=-1, keepdims=True), estimate)
        else:
            fallback = np.where(keep, estimate, fallback)
    black = int(np.count_nonzero(np.all(stack.codes[-1] == 0, axis=-1)))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        merged = np.where(denominator > 0, numerator / denominator, fallback)
        if domain == "log":
            merged = np.exp(np.minimum(merged, np.log(FLOAT32_MAX)))
    radiance = np.clip(merged, FLOAT32_TINY, FLOAT32_MAX).astype(np.float32)
    return radiance, (clipped, black)
