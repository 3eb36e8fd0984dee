"""Per-pixel uncertainty: the predicted relative standard deviation of the merged radiance.

For a weighted mean ``E = sum_j w_j x_j / sum_j w_j`` of independent estimates with
variances ``v_j`` (the noise model, :mod:`hdrio.radiometry.noise`),

    var(E) = sum_j w_j^2 v_j / (sum_j w_j)^2

(``1 / sum_j w_j`` for the inverse-variance weights); the layer is ``sigma_E / E``. The
log-domain merge averages ``ln x_j``, whose variance is ``v_j / x_j^2`` to first order, so
there the layer is ``sqrt(sum_j w_j^2 v_j / x_j^2) / sum_j w_j``. The observations are
those the merge used: the same saturation policy (a saturated code drops its bracket and
every longer one), and a pixel left with no weight takes its fallback bracket's own
``sqrt(v) / x`` (for a pixel clipped in every bracket that is a lower bound on a value
that is itself a lower bound; such pixels are counted apart in the header).

What it leaves out: the response's own error, which is common to neighbouring pixels
(it moves the whole image's tone curve, not one pixel), and motion.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from hdrio.jit import size_numba_threads
from hdrio.merge.saturation import ClipPolicy
from hdrio.radiometry.cliptest import dropped_channels
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel, observation_variance
from hdrio.radiometry.tables import estimate_tables
from hdrio.stack import ExposureStack

_KERNEL = dict(cache=True, nogil=True, error_model="numpy")


@njit(parallel=True, **_KERNEL)
def _uncertainty_kernel(codes, weights, variances, estimates, policy, log_domain,
                        out):  # pragma: no cover - compiled
    """``out[y, i]``: relative sigma of channel ``i % C`` of pixel ``i // C`` of row ``y``.

    ``codes`` ``(P, H, W * C)`` shortest first; ``weights``, ``variances`` and
    ``estimates`` ``(P, C, levels)``; ``policy`` the merge's saturation policy
    (:meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`).
    """
    # Unpacked once: the tuple handed on per pixel costs an atomic reference count per
    # array and call (hdrio.radiometry.cliptest.dropped_channels).
    limits, gates, rule, neutral, clip_estimates, clip_variances, threshold = policy
    count = codes.shape[0]
    channels = weights.shape[1]
    height, n = out.shape
    for y in prange(height):
        total = np.empty(channels)
        spread = np.empty(channels)
        mean = np.empty(channels)
        kept = np.empty(channels, np.int64)  # the bracket a channel stopped at; -1: not yet
        for x in range(n // channels):
            base = x * channels
            for c in range(channels):
                total[c] = 0.0
                spread[c] = 0.0
                mean[c] = 0.0
                kept[c] = -1
            # The clip test once per pixel and bracket (it decides every channel), not
            # once per channel: a channel stops at its first saturated or dropped code.
            alive = channels
            j = 0
            while j < count and alive > 0:
                row = codes[j, y]
                dropped = dropped_channels(
                    row, codes[max(j - 1, 0), y], base, j, max(j - 1, 0), limits, gates,
                    rule, neutral, clip_estimates, clip_variances, threshold, 1.0)
                for c in range(channels):
                    if kept[c] >= 0:
                        continue
                    z = row[base + c]
                    if z >= limits[c] or (dropped >> c) & 1 == 1:
                        kept[c] = j
                        alive -= 1
                        continue
                    w = weights[j, c, z]
                    if w > 0.0:
                        v = variances[j, c, z]
                        e = estimates[j, c, z]
                        total[c] += w
                        mean[c] += w * e
                        spread[c] += w * w * (v / (e * e) if log_domain else v)
                j += 1
            for c in range(channels):
                i = base + c
                if total[c] > 0.0:
                    out[y, i] = math.sqrt(spread[c]) / total[c] if log_domain else \
                        math.sqrt(spread[c]) / mean[c]
                else:
                    used = count if kept[c] < 0 else kept[c]
                    k = used - 1 if used > 0 else 0
                    z = codes[k, y][i]
                    out[y, i] = math.sqrt(variances[k, c, z]) / estimates[k, c, z]


def relative_uncertainty(stack: ExposureStack, response: CameraResponse,
                         weights: np.ndarray, noise: NoiseModel, domain: str = "linear",
                         policy: ClipPolicy | None = None) -> np.ndarray:
    """``sigma_E / E`` of every pixel and channel, float32 ``(H, W, C)`` (module docstring).

    ``weights``: the merge's weights, ``(P, C, levels)`` or ``(1, C, levels)`` (a code
    weighting shared by every bracket), zero at ``Z_max``; ``policy``: the merge's
    saturation policy (:attr:`hdrio.merge.weighted_mean.MergeStatistics.policy`; the
    top code, channel by channel, when not given).
    """

    count, height, width, channels = stack.codes.shape
    weights = np.ascontiguousarray(np.broadcast_to(
        weights, (count, channels, response.code_max + 1)), dtype=np.float64)
    variances = np.ascontiguousarray(observation_variance(response, stack.channel_exposures,
                                                          noise))
    estimates = np.ascontiguousarray(
        estimate_tables(response, stack.channel_exposures, "linear").transpose(0, 2, 1))
    if policy is None:
        policy = ClipPolicy.at_top(stack.code_max, channels)
    out = np.empty((height, width * channels), dtype=np.float32)
    size_numba_threads()
    _uncertainty_kernel(stack.codes.reshape(count, height, width * channels), weights,
                        variances, estimates, policy.kernel_args(), domain == "log", out)
    return out.reshape(height, width, channels)
