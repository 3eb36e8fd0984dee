"""A direct NumPy port of the merge, kept as the oracle for the fused kernel.

Vectorised over pixels, looping over brackets exactly as the tutorial's ``hdr.m`` does,
with the per-channel saturation policy and the clip test beside the tutorial's
per-pixel one. Slow (it makes several full-size temporaries per bracket) but obviously
right.
"""

from __future__ import annotations

import numpy as np

from hdrio.merge.saturation import ClipPolicy
from hdrio.radiometry.tables import estimate_tables
from hdrio.radiometry.weighting import weights_table

FLOAT32_TINY = float(np.finfo(np.float32).tiny)
FLOAT32_MAX = float(np.finfo(np.float32).max)


def dropped_reference(codes, j, policy) -> np.ndarray:
    """``(H, W, C)``: the channels of bracket ``j``'s observations (``codes`` ``(P, H, W,
    C)``) that ``policy`` (:class:`hdrio.merge.saturation.ClipPolicy`) drops besides
    those at their limits, written from its description (hdrio/radiometry/cliptest.py), not
    from the kernel's code."""
    limits = np.asarray(policy.limits)
    gates = limits if policy.gates is None else np.asarray(policy.gates)
    z = codes[j].astype(np.int64)
    clipped = z >= limits
    partly = np.any(clipped, axis=-1) & ~np.all(clipped, axis=-1)
    if policy.rule == "channel":
        return np.zeros(z.shape, dtype=bool)
    if policy.rule == "pixel":
        return np.repeat(np.any(clipped, axis=-1, keepdims=True), z.shape[-1], -1)
    if j == 0:
        return np.repeat((partly & policy.neutral)[..., None], z.shape[-1], -1)
    near = np.any(z >= gates, axis=-1) & ~np.all(clipped, axis=-1)
    y = codes[j - 1].astype(np.int64)
    channel = np.arange(z.shape[-1])
    x, v = policy.tables.estimates, policy.tables.variances
    difference = x[j][channel, z] - x[j - 1][channel, y]
    spread = np.ones(z.shape[-1]) if policy.spreads is None else policy.spreads[j]
    allowed = (policy.tables.sigmas * spread) ** 2 * (v[j][channel, z] + v[j - 1][channel, y])
    below = ~clipped & near[..., None]
    grew = below & (y >= limits)  # clipped in the shorter bracket, not here
    whole = np.any(below & ((difference**2 > allowed) | grew), axis=-1, keepdims=True)
    return np.repeat(whole, z.shape[-1], -1)


def merge_reference(stack, response, weighting="Debevec1997", domain="log",
                    saturation="channel", policy=None):
    """Radiance ``(H, W, C)`` float32 and ``(clipped, black)`` pixel counts.

    ``policy``: a :class:`hdrio.merge.saturation.ClipPolicy` (its limits, and the
    observations it drops whole); else ``saturation`` (``channel`` or ``pixel``) at the
    top code."""
    count, height, width, channels = stack.codes.shape
    if policy is None:
        policy = ClipPolicy.at_top(stack.code_max, channels, saturation)
    limits = np.asarray(policy.limits)
    weights = weights_table(weighting, stack.code_max)[:, None] * response.supported
    tables = estimate_tables(response, stack.exposures, domain)
    channel_index = np.arange(channels)
    numerator = np.zeros((height, width, channels))
    denominator = np.zeros((height, width, channels))
    dropped = np.zeros((height, width, channels), dtype=bool)
    fallback = None
    for j in range(count):
        codes = stack.codes[j].astype(np.int64)
        saturated = (codes >= limits) | dropped_reference(stack.codes, j, policy)
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
