"""Merging brackets into a radiance map with a recovered response (Debevec & Malik 1997).

Two domains, one saturation policy:

``log`` (the tutorial's ``hdr.m``)
    ``ln E = sum_j w(Z_j) (g(Z_j) - ln dt_j) / sum_j w(Z_j)``, then ``E = exp(ln E)``.
``linear``
    ``E = sum_j w(Z_j) f^-1(Z_j) / dt_j / sum_j w(Z_j)`` with ``f^-1 = exp(g)``: the
    weighted mean of the brackets' linear estimates (less biased where brackets disagree
    by noise, since the mean of logs underestimates).

Weights are per channel, ``w`` of that channel's own code. Saturation, as in the
tutorial: a pixel with any channel at ``Z_max`` in bracket ``j`` is dropped from ``j`` and
from every longer exposure. A pixel saturated even in the shortest bracket takes that
bracket's estimate alone; a pixel with zero total weight otherwise (only possible with a
weighting that is zero at the ends, for pixels black in every bracket) takes the longest
usable bracket's estimate. Every output value is therefore finite and positive.

The tutorial finds its fallback pixels as those whose sum is exactly 0; we track the
saturation instead, which agrees except where a sum happens to cancel to 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hdrio.merge.weighting import weights_table
from hdrio.registry import MethodRegistry
from hdrio.response.curve import CameraResponse
from hdrio.stack import ExposureStack

_BLOCK_PIXELS = 1 << 20
_FLOAT32_TINY = float(np.finfo(np.float32).tiny)
_FLOAT32_MAX = float(np.finfo(np.float32).max)
_LOG_FLOAT32_MAX = float(np.log(_FLOAT32_MAX))


@dataclass(frozen=True)
class MergeStatistics:
    """What the merge saw: counts of pixels, per whole image."""

    pixels: int
    clipped_everywhere: int
    """Saturated (a channel at ``Z_max``) even in the shortest bracket."""
    black_everywhere: int
    """Code 0 in every channel even in the longest bracket."""
    used_per_bracket: tuple[int, ...]
    """Pixels each bracket contributed to (not dropped by saturation, weight above 0)."""


def _estimate_tables(response: CameraResponse, exposure: float, domain: str) -> np.ndarray:
    if domain == "log":
        return response.log_inverse - np.log(exposure)
    return np.exp(response.log_inverse) / exposure


def merge_brackets(stack: ExposureStack, response: CameraResponse,
                   weighting: str = "Debevec1997", domain: str = "log"
                   ) -> tuple[np.ndarray, MergeStatistics]:
    """Merge ``stack`` into relative radiance, float32 ``(H, W, C)``, finite and positive.

    Units: relative scene-linear radiance ``E`` with ``E * dt = f^-1(Z)``: exposures in
    seconds and ``g(z_mid) = 0`` make 1.0 the radiance that a 1-second exposure records at
    the middle code value.
    """
    if domain not in ("log", "linear"):
        raise ValueError(f"merge domain must be 'log' or 'linear', not {domain!r}")
    if response.code_max != stack.code_max:
        raise ValueError(
            f"response is for codes 0..{response.code_max}, brackets are 0..{stack.code_max}"
        )
    count, height, width, channels = stack.codes.shape
    if response.log_inverse.shape[1] != channels:
        raise ValueError(f"response has {response.log_inverse.shape[1]} channels, "
                         f"brackets have {channels}")
    # Per channel: codes where g is extrapolated (no weighted sample fell there) say little
    # about radiance, so they get no weight; the fallbacks below still cover every pixel.
    weights = weights_table(weighting, stack.code_max)[:, None] * response.supported
    tables = [_estimate_tables(response, t, domain) for t in stack.exposures]
    channel_index = np.arange(channels)
    radiance = np.empty((height, width, channels), dtype=np.float32)
    used = np.zeros(count, dtype=np.int64)
    clipped = black = 0
    rows_per_block = max(1, _BLOCK_PIXELS // max(1, width))
    for top in range(0, height, rows_per_block):
        block = stack.codes[:, top: top + rows_per_block]
        numerator = np.zeros(block.shape[1:], dtype=np.float64)
        denominator = np.zeros(block.shape[1:], dtype=np.float64)
        dropped = np.zeros(block.shape[1:3], dtype=bool)
        fallback = None
        for j in range(count):
            codes = block[j]
            dropped |= np.any(codes == stack.code_max, axis=-1)
            keep = ~dropped[..., np.newaxis]
            estimate = tables[j][codes, channel_index]
            weight = np.where(keep, weights[codes, channel_index], 0.0)
            numerator += weight * estimate
            denominator += weight
            fallback = estimate if fallback is None else np.where(keep, estimate, fallback)
            used[j] += int(np.count_nonzero(np.any(weight > 0, axis=-1)))
            if j == 0:
                clipped += int(np.count_nonzero(dropped))
        black += int(np.count_nonzero(np.all(block[-1] == 0, axis=-1)))
        with np.errstate(invalid="ignore", divide="ignore"):
            merged = np.where(denominator > 0, numerator / denominator, fallback)
        if domain == "log":
            merged = np.exp(np.minimum(merged, _LOG_FLOAT32_MAX))
        radiance[top: top + rows_per_block] = np.clip(merged, _FLOAT32_TINY, _FLOAT32_MAX)
    statistics = MergeStatistics(
        pixels=height * width, clipped_everywhere=clipped, black_everywhere=black,
        used_per_bracket=tuple(int(u) for u in used),
    )
    return radiance, statistics


def _merge_log(stack, response, weighting="Debevec1997"):
    return merge_brackets(stack, response, weighting, domain="log")


def _merge_linear(stack, response, weighting="Debevec1997"):
    return merge_brackets(stack, response, weighting, domain="linear")


MERGE_METHODS: MethodRegistry = MethodRegistry(
    "merge", {"log": _merge_log, "linear": _merge_linear},
    aliases={"Debevec1997": "log", "tutorial": "log"},
)
