"""Highlight reconstruction: pixels clipped in every bracket (``--highlights``).

A pixel with a channel at or above its limit even in the shortest bracket
(:func:`hdrio.merge.weighted_mean.clipped_everywhere_mask`) has no measurement of that
channel, only a lower bound. ``clip`` (the default) leaves the merge's value: the
channel's own lower bound per channel, or a neutral lower bound (every channel the
largest of the shortest bracket's estimates) where the saturation policy drops the
shortest bracket's partly clipped observations whole or every channel is clipped
(:func:`hdrio.merge.kernel.merge_kernel`). A coloured light source whose one or two
channels clip in every bracket then comes out too pale (the clipped channel too
low against the others) or white.

``reconstruct`` estimates the clipped channels from the unclipped ones and the
neighbours' colour, after darktable's *inpaint opposed* highlight reconstruction
(H. Ritter, darktable 4.2, ``src/iop/hlreconstruct/opposed.c``) in its per-segment form
(darktable's *segmentation*), with channel ratios in place of its cube-root differences:

1. Each connected region (8-neighbours) of clipped pixels takes a chromaticity
   ``rho`` (channel over channel sum) from the unclipped pixels around it, 2 to 8 px
   away (the ring skips the pixels next to the clip, where a lossy codec's chroma and
   a lens's flare mix in the clip's false colour): the ring's channel sums over its
   sum of all channels, so its brightest pixels (the light's own glow) count most.
2. A **partly clipped** pixel (some channel below its limit in the shortest bracket).
   Per-channel rule: its unclipped channels keep their measurements ``m_u`` and each
   clipped channel ``k`` becomes the value the ring's ratios predict,
   ``rho_k * sum(m_u) / sum(rho_u)``, when that is above the merge's value (a clipped
   channel is only raised). Neutral (the stack mixes its channels after the clip, so a
   partly clipped pixel's other channels are biased too): the whole pixel takes the
   ring's colour ``rho * sum(m_u) / sum(rho_u)``, ``m_u`` the shortest bracket's own
   estimates (which the neutral bound had replaced), scaled up where a clipped channel
   would fall below ``f^-1(limit) / dt``, the least its clip implies (the neutral bound
   comes from codes above the limit, the margin the policy dropped as unreliable).
3. A **fully clipped** pixel takes the chromaticity of the ring around its own fully
   clipped region (where the partly clipped pixels are already reconstructed), scaled
   so that its channel mean is no lower than the merge's neutral bound and no channel
   below ``f^-1(limit) / dt``: never darker than the bound. (Every channel at or above
   the neutral bound would scale a coloured border's hue until its smallest channel
   reaches it: on frobisher_001, a bright yellow cloud; docs/highlights.md.)

Chromaticities are floored at 1/20 of their largest channel. A region with no unclipped
pixel around it stays as the merge left it. Only boxes around groups of 32-px blocks
that hold clipped pixels are looked at (:func:`clip_groups`); an image with no clipped
pixel is left untouched (the skip :attr:`hdrio.skips.SkipReport.highlights`). Greyscale
stacks have no other channel to reconstruct from and are left as they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HIGHLIGHT_MODES = ("clip", "reconstruct")
HIGHLIGHT_HELP = {
    "clip": "the merge's lower bound (neutral where every channel is clipped)",
    "reconstruct": "clipped channels estimated from the unclipped ones and the colour "
                   "of the unclipped pixels around the clip",
}
"""Each mode in a few words, for the front ends."""

RING = (2, 8)
"""Pixels (Chebyshev distance) from a clipped region whose colour it takes: from 2 (the
first pixel next to the clip is skipped) to 8."""
_RATIO_FLOOR = 0.05  # a chromaticity's channel is at least this fraction of its largest
_EIGHT = np.ones((3, 3), dtype=bool)  # 8-connected regions
BLOCK = 32
"""Pixels: clipped pixels are grouped by blocks of this side (:func:`clip_groups`)."""


@dataclass(frozen=True)
class HighlightReport:
    """What ``--highlights reconstruct`` did, for the summary and the header."""

    partly: int
    """Pixels with some channel clipped in every bracket, reconstructed from the others."""
    fully: int
    """Pixels with every channel clipped in every bracket, given their border's colour."""
    regions: int
    """Connected clipped regions."""
    pixels: int
    """Pixels of the image."""

    def text(self) -> str:
        """One line: ``reconstructed 1.20 % partly and 0.30 % fully clipped pixels (14
        regions) from their neighbours' colour``."""
        return (f"reconstructed {100 * self.partly / self.pixels:.2f} % partly and "
                f"{100 * self.fully / self.pixels:.2f} % fully clipped pixels "
                f"({self.regions} regions) from their neighbours' colour")


def clip_groups(mask: np.ndarray, block: int = BLOCK):
    """Boxes that hold ``mask``'s pixels ``(H, W)`` and the ring around them, apart.

    ``mask`` is cut into ``block`` x ``block`` blocks; the blocks with a true pixel,
    grown by one block (more than :data:`RING`'s 8 px), are grouped 8-connected. Yields
    ``(box, own)`` per group: ``box`` a pair of slices (the group's bounding box in
    pixels), ``own`` ``(h, w)`` bool the box's pixels in the group's blocks. A clipped
    region and its ring lie in one group; two groups' boxes may overlap, their ``own``
    pixels never do.
    """
    from scipy import ndimage
    height, width = mask.shape
    rows, cols = -(-height // block), -(-width // block)
    padded = np.zeros((rows * block, cols * block), dtype=bool)
    padded[:height, :width] = mask
    blocks = padded.reshape(rows, block, cols, block).any(axis=3).any(axis=1)
    grown = ndimage.binary_dilation(blocks, structure=_EIGHT)
    labels, _ = ndimage.label(grown, structure=_EIGHT)
    for group, (r, c) in enumerate(ndimage.find_objects(labels), start=1):
        box = (slice(r.start * block, min(r.stop * block, height)),
               slice(c.start * block, min(c.stop * block, width)))
        own = (labels[r, c] == group).repeat(block, axis=0).repeat(block, axis=1)
        yield box, own[:box[0].stop - box[0].start, :box[1].stop - box[1].start]


def border_chromaticity(values: np.ndarray, mask: np.ndarray,
                        seen: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Each ``mask`` pixel's chromaticity from the unmasked pixels around its region.

    Parameters
    ----------
    values : ndarray, (H, W, C)
        Linear radiance (relative units); only the unmasked pixels are read.
    mask : ndarray of bool, (H, W)
        The pixels whose colour is wanted.
    seen : ndarray of bool, (H, W), optional
        Pixels whose values may be used (not clipped, not masked out of the merge).

    Returns
    -------
    rho : ndarray, (N, C) float64
        For the ``N`` true pixels of ``mask`` (row-major order): the chromaticity (sums
        to 1, each channel at least 1/20 of the largest) of the ring :data:`RING` around
        the pixel's 8-connected region, weighted by brightness (a ring pixel within
        8 px of two regions counts for one of them); NaN where the ring has no positive
        pixel.
    regions : int
        The number of regions.
    """
    from scipy import ndimage
    labels, regions = ndimage.label(mask, structure=_EIGHT)
    gap, width = RING
    outer = ndimage.maximum_filter(labels, size=2 * width + 1)  # the region within 8 px
    near = ndimage.maximum_filter(mask.view(np.uint8), size=2 * gap - 1) > 0
    ring = (outer > 0) & ~near
    if seen is not None:
        ring &= seen
    ring_values = values[ring].astype(np.float64)
    ring_values = np.where(np.isfinite(ring_values) & (ring_values > 0), ring_values, 0.0)
    owner = outer[ring]
    sums = np.stack([np.bincount(owner, ring_values[:, c], regions + 1)
                     for c in range(values.shape[-1])], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.maximum(sums, _RATIO_FLOOR * sums.max(axis=-1, keepdims=True))
        rho /= rho.sum(axis=-1, keepdims=True)
    rho[sums.sum(axis=-1) <= 0] = np.nan
    return rho[labels[mask]], regions


def reconstruct_highlights(radiance: np.ndarray, shortest: np.ndarray, limits,
                           estimates: np.ndarray, neutral: bool,
                           seen: np.ndarray | None = None) -> HighlightReport | None:
    """Reconstruct the channels clipped in every bracket, in place (see the module).

    Parameters
    ----------
    radiance : ndarray, (H, W, C) float32
        The merge's relative radiance, changed in place at clipped pixels only.
    shortest : ndarray, (H, W, C) int
        The shortest bracket's codes.
    limits : sequence of int, (C,)
        The first code of each channel the saturation policy drops
        (:attr:`hdrio.merge.weighted_mean.MergeStatistics.limits`).
    estimates : ndarray, (code_max + 1, C)
        The shortest bracket's radiance estimate of each code, ``f^-1(z) / dt`` (relative
        units): the measurement of a channel below its limit.
    neutral : bool
        Whether the merge dropped the shortest bracket's partly clipped observations
        whole (:attr:`hdrio.merge.saturation.ClipPolicy.neutral`: then its partly
        clipped pixels hold the neutral bound, and their unclipped channels are read from
        ``estimates``).
    seen : ndarray of bool, (H, W), optional
        Pixels taken from the shortest bracket (not excluded from it); others are left.

    Returns
    -------
    HighlightReport or None
        None when nothing was clipped (or the image has one channel): nothing changed.
    """
    channels = radiance.shape[-1]
    limits = np.asarray(limits, dtype=np.int64)
    any_clipped = shortest[..., 0] >= limits[0]
    for c in range(1, channels):
        any_clipped |= shortest[..., c] >= limits[c]
    if seen is not None:
        any_clipped &= seen
    if channels < 2 or not any_clipped.any():
        return None
    # A clipped channel is at least its estimate at its limit (the first dropped code).
    bound = estimates[np.minimum(limits, estimates.shape[0] - 1), np.arange(channels)]
    counts = np.zeros(3, dtype=np.int64)
    for box, own in clip_groups(any_clipped):
        region = any_clipped[box] & own
        usable = ~any_clipped[box] if seen is None else ~any_clipped[box] & seen[box]
        counts += _reconstruct_box(radiance[box], shortest[box], limits, region, usable,
                                   bound, estimates, neutral)
    return HighlightReport(partly=int(counts[0]), fully=int(counts[1]),
                           regions=int(counts[2]), pixels=int(any_clipped.size))


def _reconstruct_box(crop: np.ndarray, codes: np.ndarray, limits: np.ndarray,
                     region: np.ndarray, usable: np.ndarray, bound: np.ndarray,
                     estimates: np.ndarray, neutral: bool) -> tuple[int, int, int]:
    """:func:`reconstruct_highlights` on one box (:func:`clip_groups`): ``crop`` ``(h, w,
    C)`` radiance changed in place at ``region``'s pixels, from ``usable`` pixels'
    colour; ``codes`` the shortest bracket's there. Returns the counts of partly and
    fully clipped pixels and of regions."""
    channels = crop.shape[-1]
    fully = region.copy()
    for c in range(channels):
        fully &= codes[..., c] >= limits[c]
    partly = region & ~fully
    # Stage 1: partly clipped pixels from their unclipped channels and the ring's ratios.
    rho, regions = border_chromaticity(crop, region, usable)
    rho = rho[partly[region]]
    today = crop[partly].astype(np.float64)
    partly_codes = codes[partly]
    lost = partly_codes >= limits
    measured = today
    if neutral:  # the neutral bound replaced the unclipped channels' measurements
        measured = estimates[partly_codes, np.arange(channels)]
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = (np.where(lost, 0, measured).sum(-1)
                 / np.where(lost, 0, rho).sum(-1))[:, None]
        if neutral:  # the whole pixel in the ring's colour, no channel below its bound
            scale = np.maximum(scale, np.where(lost, bound / rho, 0).max(-1, keepdims=True))
        predicted = rho * scale
    fine = np.isfinite(predicted).all(axis=-1, keepdims=True)
    raised = predicted if neutral else np.where(lost, np.maximum(today, predicted),
                                                   measured)
    crop[partly] = np.minimum(np.where(fine, raised, today), np.finfo(np.float32).max)
    # Stage 2: fully clipped pixels take their border's colour (the partly clipped ones'
    # now reconstructed), their channel mean no lower than the neutral bound's and each
    # channel no lower than its clip's bound.
    if fully.any():
        rho_full, _ = border_chromaticity(crop, fully, usable | partly)
        today = crop[fully].astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.maximum(today.mean(-1) * channels, (bound / rho_full).max(-1))
            scaled = rho_full * scale[:, None]
        fine = np.isfinite(scaled).all(axis=-1, keepdims=True)
        crop[fully] = np.minimum(np.where(fine, scaled, today), np.finfo(np.float32).max)
    return int(partly.sum()), int(fully.sum()), int(regions)
