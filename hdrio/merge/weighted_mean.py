"""Merging brackets into a radiance map with a recovered response (Debevec & Malik 1997).

Two domains, two saturation policies:

``log`` (the tutorial's ``hdr.m``)
    ``ln E = sum_j w(Z_j) (g(Z_j) - ln dt_j) / sum_j w(Z_j)``, then ``E = exp(ln E)``.
``linear``
    ``E = sum_j w(Z_j) f^-1(Z_j) / dt_j / sum_j w(Z_j)`` with ``f^-1 = exp(g)``: the
    weighted mean of the brackets' linear estimates (less biased where brackets disagree
    by noise, since the mean of logs underestimates).

Weights are per channel, ``w`` of that channel's own code. Saturation drops an
observation in bracket ``j`` from ``j`` and from every longer exposure; which ones, the
saturation policy says (:mod:`hdrio.merge.saturation`: ``auto``, the default, tests
each partly clipped observation against the next shorter bracket; ``safe`` and the
tutorial's ``pixel`` drop an observation whole when any channel is at its limit;
``channel`` drops the saturated channel alone).

A pixel dropped even from the shortest bracket (clipped in every bracket) takes a
neutral lower bound: every channel the largest of that bracket's estimates over the
pixel's channels (where the policy dropped the shortest observation whole, or every
channel is clipped; a channel clipped alone takes that bracket's estimate). A channel
with zero total weight otherwise (only possible with a weighting that is zero at the
ends, for pixels black in every bracket) takes the longest usable bracket's estimate.
Every output value is therefore finite and positive.

The tutorial finds its fallback pixels as those whose sum is exactly 0; we track the
saturation instead, which agrees except where a sum happens to cancel to 0. The work is
done by the fused kernel in ``hdrio.merge.kernel``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hdrio.io.staging import is_staged, release
from hdrio.merge.kernel import MAX_BRACKETS, KernelTables, merge_kernel
from hdrio.merge.row_sums import PAIR_LEVELS, pair_tables
from hdrio.merge.saturation import SATURATION_POLICIES, ClipPolicy, clip_policy
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.tables import merge_tables
from hdrio.stack import ExposureStack, some_channel


@dataclass(frozen=True)
class MergeStatistics:
    """What the merge saw: counts of pixels, per whole image."""

    pixels: int
    clipped_everywhere: int
    """Dropped by the saturation policy (a channel at or above its limit) even in the
    shortest bracket."""
    black_everywhere: int
    """Code 0 in every channel even in the longest bracket."""
    observations_skipped: int = 0
    """Pixel-brackets never read: the early stop found their whole row saturated in that
    bracket or a shorter one (out of ``pixels`` x brackets)."""
    masked_everywhere: int = 0
    """Excluded in every bracket (``--exclude-color``, ``--mask``): unseen, alpha 0, and
    not counted as clipped or black (:mod:`hdrio.merge.exclusion`)."""
    limits: tuple[int, ...] = ()
    """The first code of each channel the saturation policy dropped."""
    policy: ClipPolicy | None = None
    """The saturation policy as applied (:class:`hdrio.merge.saturation.ClipPolicy`)."""

    @property
    def clipped_fraction(self) -> float:
        """Clipped everywhere, as a fraction of the pixels seen (not masked everywhere)."""
        return self.clipped_everywhere / max(1, self.pixels - self.masked_everywhere)


MERGE_BAND_ROWS = 128
"""Rows merged per kernel call when the codes are staged in a file (each band's pages are
released after it: 128 rows of seven 24 MP brackets hold 16 MB)."""


def merge_brackets(stack: ExposureStack, response: CameraResponse,
                   weighting: str = "Debevec1997", domain: str = "log",
                   saturation: str = "channel", *, early_stop: bool = True,
                   weights: np.ndarray | None = None, policy: ClipPolicy | None = None
                   ) -> tuple[np.ndarray, MergeStatistics]:
    """Merge ``stack`` into relative radiance, float32 ``(H, W, C)``, finite and positive.

    ``saturation`` is a policy of :mod:`hdrio.merge.saturation`: ``"channel"`` (a
    saturated channel is dropped on its own), ``"pixel"`` (the tutorial: any saturated
    channel drops the whole pixel), ``"safe"`` or ``"auto"``; ``policy``, when given,
    is that policy already decided (:func:`hdrio.merge.saturation.clip_policy`, with
    the stack's noise model), else it is decided here with the codes' rounding for
    noise.
    ``early_stop`` lets the kernel skip rows saturated in a shorter bracket (the same
    result to float32 rounding). ``weights``, when given, are per-bracket weights
    ``w_j(z)`` ``(P, C, code_max + 1)`` in place of ``weighting``'s ``w(z)`` (the
    estimators of :mod:`hdrio.radiometry.estimators`).

    Codes staged in a file (:mod:`hdrio.io.staging`) are merged a band of rows at a time,
    each band's pages given back once merged.

    Units: relative scene-linear radiance ``E`` with ``E * dt = f^-1(Z)``: exposures in
    seconds and ``g(z_mid) = 0`` make 1.0 the radiance that a 1-second exposure records at
    the middle code value.
    """
    if domain not in ("log", "linear"):
        raise ValueError(f"merge domain must be 'log' or 'linear', not {domain!r}")
    if saturation not in SATURATION_POLICIES:
        raise ValueError(f"saturation policy must be one of {SATURATION_POLICIES}, "
                         f"not {saturation!r}")
    if response.code_max != stack.code_max:
        raise ValueError(
            f"response is for codes 0..{response.code_max}, brackets are 0..{stack.code_max}"
        )
    count, height, width, channels = stack.codes.shape
    if response.log_inverse.shape[1] != channels:
        raise ValueError(f"response has {response.log_inverse.shape[1]} channels, "
                         f"brackets have {channels}")
    if count > MAX_BRACKETS:
        raise ValueError(f"the merge takes at most {MAX_BRACKETS} brackets, not {count}")
    terms, estimates = merge_tables(response, stack.channel_exposures, weighting, domain,
                                    weights)
    if policy is None:
        policy = clip_policy(saturation, stack.codes, response, None, stack.exposures)
    policy = replace(policy, limits=np.clip(policy.limits, 1, stack.code_max))
    limits = policy.limits
    for c, limit in enumerate(limits):  # a dropped code never counts (the kernel's resets)
        terms[:, c, limit:] = 0.0
    if channels == 3 and stack.code_max < PAIR_LEVELS:
        pairs = pair_tables(terms, limits)
    else:
        pairs = np.empty((0, channels, 1), np.complex64)  # the general path
    tables = KernelTables(terms.astype(np.complex64), estimates, pairs, stack.code_max,
                          policy.kernel_args(), domain == "log", early_stop)
    radiance = np.empty((height, width, channels), dtype=np.float32)
    counts = np.zeros((3, height), dtype=np.int64)  # clipped, black, skipped by the early stop
    codes = stack.codes.reshape(count, height, width * channels)  # a view (contiguous)
    band = MERGE_BAND_ROWS if is_staged(stack.codes) else height
    for top in range(0, height, band):
        bottom = min(height, top + band)
        merge_kernel(codes, top, bottom, tables, radiance.reshape(height, width * channels),
                     counts)
        release(stack.codes, None, top, bottom)
    statistics = MergeStatistics(
        pixels=height * width, clipped_everywhere=int(counts[0].sum()),
        black_everywhere=int(counts[1].sum()), observations_skipped=int(counts[2].sum()),
        limits=tuple(int(v) for v in limits), policy=policy,
    )
    return radiance, statistics


def clipped_everywhere_mask(shortest: np.ndarray, limits) -> np.ndarray:
    """``(H, W)`` float32: 1 where a channel of the shortest bracket's codes ``(H, W, C)``
    is at or above its limit (:attr:`MergeStatistics.limits`): the pixels the merge
    gave a neutral lower bound (or, with the ``channel`` policy, a channel's own)."""
    limits = np.asarray(limits, dtype=np.int64)
    return some_channel(shortest, np.greater_equal, limits).astype(np.float32)
