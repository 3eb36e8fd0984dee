"""What the consistency test compares: each bracket's estimates with the response's
systematic error divided out (:func:`comparametric_correction`), the bounds that clipped
and black codes still put on the radiance (:func:`bounds`), and the variance two
brackets may disagree by (:func:`consistency_variance`). (Split from
:mod:`hdrio.align.consistency`, which runs the test.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hdrio.skips import well_exposed_codes

LIMIT = 0.7
"""Samples whose estimates differ by more than this in ``ln`` (a factor 2) are left out
of :func:`comparametric_correction` (motion, not a response error)."""
CLIP_MARGIN = 2.5
"""A clipped code bounds the radiance from below by its last well-exposed code's
estimate over this factor (:func:`bounds`)."""
JPEG_TAIL = 4.0
"""Code units squared (2 codes r.m.s.) more that JPEG brackets may disagree by in the
consistency test (:func:`consistency_variance`)."""


@njit(cache=True, nogil=True)
def _log_ratios(codes, log_estimates, variance, reference, target, stride, limit, sums,
                counts):  # pragma: no cover - compiled
    """Per channel and code of bracket ``target``: sums and counts of ``ln x_target -
    ln x_chain`` (``log_estimates``: the tables' ``ln``, so that no sample takes a
    logarithm) over every ``stride``-th pixel, where both are usable and within ``limit``
    of each other (a moving object is left out)."""
    count, height, width, channels = codes.shape
    direction = 1 if target > reference else -1
    chain = np.empty(channels)
    chain_var = np.empty(channels)
    for y in range(stride // 2, height, stride):
        for x in range(stride // 2, width, stride):
            for c in range(channels):
                z = codes[reference, y, x, c]
                chain[c] = log_estimates[reference, c, z]
                chain_var[c] = variance[reference, c, z]
            j = reference + direction
            while j != target:
                for c in range(channels):
                    z = codes[j, y, x, c]
                    if not np.isfinite(chain_var[c]) and np.isfinite(variance[j, c, z]):
                        chain[c] = log_estimates[j, c, z]
                        chain_var[c] = variance[j, c, z]
                j += direction
            for c in range(channels):
                z = codes[target, y, x, c]
                if np.isfinite(chain_var[c]) and np.isfinite(variance[target, c, z]):
                    r = log_estimates[target, c, z] - chain[c]
                    if abs(r) < limit:
                        sums[c, z] += r
                        counts[c, z] += 1


def comparametric_correction(codes: np.ndarray, estimates: np.ndarray, variance: np.ndarray,
                             reference: int, samples: int = 100_000) -> np.ndarray:
    """``estimates`` with each bracket's systematic disagreement with the reference (a
    function of its code value: the response's error, an exposure time's rounding)
    divided out, bracket by bracket outwards from the reference.

    Without it a still scene's brackets disagree by several standard deviations where
    the solved response is a few per cent off (mean ``d^2`` of 6 on StillLife), which a
    consistency test would take for motion.
    """
    import scipy.ndimage
    count, height, width, channels = codes.shape
    stride = max(1, int(math.sqrt(height * width / samples)))
    corrected = np.array(estimates, np.float64)
    levels = corrected.shape[2]
    order = [*range(reference - 1, -1, -1), *range(reference + 1, count)]
    # The samples, gathered once into a small array: each bracket's test walks the chain
    # of brackets between it and the reference, and strided reads of the full brackets
    # missed the cache at every sample of every walk.
    grid = np.ascontiguousarray(codes[:, stride // 2::stride, stride // 2::stride])
    for j in order:
        sums = np.zeros((channels, levels))
        counts = np.zeros((channels, levels))
        with np.errstate(divide="ignore"):
            logs = np.log(corrected)
        _log_ratios(grid, logs, variance, reference, j, 1, LIMIT, sums, counts)
        # Deep codes in blocks of codes (at most 1024 of them, as many as the solve has
        # levels at 16 bits): a Gaussian of 512 codes over 65536 took 0.27 s a channel and bracket.
        block = max(1, levels // 1024)
        bins = -(-levels // block)
        centres = np.minimum(np.arange(bins) * block + (block - 1) / 2.0, levels - 1)
        for c in range(channels):
            weight, total = (scipy.ndimage.gaussian_filter1d(
                np.add.reduceat(a[c], np.arange(0, levels, block)), max(1.0, bins / 128.0),
                mode="nearest") for a in (counts, sums))
            known = weight > 4
            if not known.any():
                continue
            bias = np.interp(np.arange(levels), centres[known], total[known] / weight[known])
            corrected[j, c] *= np.exp(-bias)
    return corrected


def bounds(estimates: np.ndarray, variance: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(dark, bright, bound_variance)``, ``(P, C, levels)``: for each code below a
    bracket's usable codes (``variance`` infinite there), the estimate of its first usable
    code, which bounds the radiance from above; for each code above them, the estimate of
    its last well-exposed code (:data:`hdrio.skips.WELL_EXPOSED`) over :data:`CLIP_MARGIN`,
    which bounds it from below (a camera's roll-off and JPEG bend the codes next to a
    clip: on JPEG tripod stacks the last usable code's estimate flagged a third of a
    bright window); and that code's variance. ``nan`` and ``inf`` elsewhere."""
    dark = np.full(variance.shape, np.nan)
    bright = np.full(variance.shape, np.nan)
    bound_variance = np.full(variance.shape, np.inf)
    usable = np.isfinite(variance)
    _, high = well_exposed_codes(variance.shape[2] - 1)
    for j in range(variance.shape[0]):
        for c in range(variance.shape[1]):
            codes = np.flatnonzero(usable[j, c])
            if codes.size:
                first, last = codes[0], codes[-1]
                dark[j, c, :first] = estimates[j, c, first]
                bound_variance[j, c, :first] = variance[j, c, first]
                top = min(last, high)
                bright[j, c, last + 1:] = estimates[j, c, top] / CLIP_MARGIN
                bound_variance[j, c, last + 1:] = variance[j, c, top] / CLIP_MARGIN**2
    return dark, bright, bound_variance


def consistency_variance(response, exposures: np.ndarray, noise=None) -> np.ndarray:
    """The variance the consistency test allows each ``x_j(z) = f^-1(z) / dt_j``,
    ``(P, C, levels)``, relative radiance squared.

    The stack's noise model, its disagreement view
    (:func:`hdrio.radiometry.noise.observation_variance`), plus 3 % of the value for the
    response's own error, which two brackets see alike only where the curve is right,
    and for JPEG brackets (a noise model with a ``common`` term) :data:`JPEG_TAIL` codes
    squared: JPEG's error is a heavy tail at edges, which a cell's mean of capped
    ``d^2`` feels and the fit's robust spread does not (without it a third of a JPEG
    tripod stack's bright window was flagged); codes at ``Z_max`` and below the
    well-exposed range
    (:data:`hdrio.skips.WELL_EXPOSED`: where a solved ``g`` is extrapolated and noise
    dominates) say nothing (``inf``). Without a noise model, rounding of the codes alone.
    """
    from hdrio.radiometry.noise import NoiseModel, code_slope, observation_variance

    code_max = response.code_max
    low, _ = well_exposed_codes(code_max)
    if noise is None:
        noise = NoiseModel.quantisation_only(response.channels)
    exposure = np.exp(response.log_inverse)  # (levels, C): f^-1(z)
    dt = np.asarray(exposures, np.float64)[:, None, None]
    variance = observation_variance(response, exposures, noise, disagreement=True) \
        + (0.03 * exposure.T[None]) ** 2 / dt**2
    if noise.common is not None:
        variance += JPEG_TAIL * code_slope(response).T[None] ** 2 / dt**2
    variance[:, :, :low] = np.inf
    variance[:, :, code_max] = np.inf
    return np.ascontiguousarray(variance)
