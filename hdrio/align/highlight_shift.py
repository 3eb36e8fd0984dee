"""Registering a bracket by the highlights its neighbour clipped.

The shortest bracket of a long ladder may see only the brightest things in the scene (a
sun, lamps): too little of it is well exposed where its neighbour is for the edges of
:func:`hdrio.align.registration.estimate_alignment` to register it, and yet it alone
reads the highlights, where an HDRI's lighting lives. Its neighbour clipped those very
highlights, so the two share a shape: the region where the scene is brighter than the
neighbour's clip. That region, thresholded in each bracket (the neighbour's codes at
its top, the short bracket's radiance above the neighbour's clip level), is matched by
cross-correlation, and the shift read at sub-pixel from the peak: a translation, which
is what matters across a highlight (a rotation of a few tenths of a degree moves a
highlight's own pixels by hundredths of one). The shift is then refined by the
centroids of the highlights' radiance in both brackets (:func:`refine_by_centroids`).
"""

from __future__ import annotations

import numpy as np

from hdrio.align.correlation import correlate, sub_pixel, within_reach
from hdrio.align.lucaskanade import translation
from hdrio.align.pyramid import base_blocks

MIN_PIXELS = 16
"""Base pixels the clipped region must hold in each bracket to be matched."""

MAX_SHIFT = 64
"""Base pixels: the largest shift looked for (the bitmaps' reach, six levels)."""

MIN_OVERLAP = 0.6
"""The matched regions' intersection over union at the best shift, at least."""


def highlight_shift(clipped: np.ndarray, bright: np.ndarray) -> np.ndarray | None:
    """``x_short = W x_neighbour`` (3x3, base pixels, a translation) matching
    ``clipped`` (``(h, w)`` bool: the neighbour's clipped pixels) to ``bright`` (the
    shorter bracket's pixels brighter than the neighbour's clip), or ``None`` when the
    regions are too small, the shift beyond :data:`MAX_SHIFT`, or they do not match
    (:data:`MIN_OVERLAP`)."""
    a, b = clipped.astype(np.float64), bright.astype(np.float64)
    if min(a.sum(), b.sum()) < MIN_PIXELS:
        return None
    shape = (2 * a.shape[0], 2 * a.shape[1])  # zero-padded: no wrap-around
    # C(d) = sum_x a(x) b(x + d): the peak is where b's region sits relative to a's.
    c = within_reach(correlate(a, b, shape), MAX_SHIFT)
    py, px = np.unravel_index(int(np.argmax(c)), c.shape)
    overlap = c[py, px]
    if not overlap / (a.sum() + b.sum() - overlap) >= MIN_OVERLAP:
        return None
    sy, sx = sub_pixel(c, py, px)
    return translation(sx, sy)


def channel_clip_regions(codes_k: np.ndarray, codes_j: np.ndarray, top: int,
                         factor: int) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`highlight_shift`'s two regions read in one channel, at base resolution
    (``factor`` full-resolution pixels a side, a base pixel set where any of its pixels
    is): the neighbour's pixels (``codes_k``, ``(H, W, C)``) at or above ``top`` in that
    channel, and as many of the shorter bracket's (``codes_j``), its brightest in that
    channel. A response is monotone, so those are the same pixels of a still scene,
    whatever the curve says near the top (read through the re-solved curve, the shorter
    bracket's region came out 1.5-1.8x the neighbour's). The channel is the one the neighbour
    clips least, of those it clips at :data:`MIN_PIXELS` base pixels or more: in a warm
    interior the long brackets' red is clipped nearly everywhere, and their blue draws
    the shapes. ``None`` when none is."""
    best, clipped, fewest = None, None, 0
    for c in range(codes_k.shape[-1]):
        at_top = codes_k[..., c] >= top
        count = int(np.count_nonzero(at_top))
        if count >= MIN_PIXELS * factor * factor and (clipped is None or count < fewest):
            best, clipped, fewest = c, at_top, count
    if clipped is None:
        return None
    values = codes_j[..., best].reshape(-1)
    level = np.partition(values, values.size - fewest)[values.size - fewest]
    return base_blocks(clipped, factor), base_blocks(codes_j[..., best] >= level, factor)


FLOOR = 0.5
""":func:`refine_by_centroids` weighs the radiance above this fraction of the clip level:
there the shorter bracket is well exposed (2 EV shorter, at an eighth of its range)."""

REACH = 2
"""Base pixels around each bright region that its centroid reads (where the weights fall
to 0), and the reach within which a pixel of the neighbour that is neither well exposed
nor clipped beside its clipped region is taken as clipped (a channel at the top)."""

AGREE = (0.8, 1.25)
"""The two brackets' summed weights over a region agree within this ratio (the same
highlight, every pixel of it read by both), or the region is not used."""

MAX_REFINEMENT = 1.5
"""Base pixels: centroids that move the matched regions' shift by more than this have
matched something else (the shift is good to about half a pixel) and are not taken."""


def refine_by_centroids(step: np.ndarray, neighbour_log: np.ndarray,
                        neighbour_valid: np.ndarray, clipped: np.ndarray,
                        short_log: np.ndarray, short_valid: np.ndarray,
                        level: float) -> np.ndarray:
    """:func:`highlight_shift`'s ``step`` refined to a few hundredths of a pixel by the
    centroids of the highlights' radiance in both brackets.

    The masks' correlation peak is a cone, and the vertex of a parabola through it is
    biased: on the hand-held 9 x 2 EV ladders of :func:`tests.hard_cases.hand_held` the
    shortest bracket, registered by its sun, sat 0.05-0.19 px off at the sun's
    brightest pixel, 0.01-0.05 px refined. Both brackets' radiance (``exp`` of the base
    images' ``*_log``) is clamped at the neighbour's clip ``level`` (``ln``), where the
    neighbour ``clipped``: the two are then the same function of the scene. Each bright
    region (the neighbour's pixels above :data:`FLOOR` of the clip, grown by
    :data:`REACH`) is weighed by the radiance above that floor, in the neighbour and,
    shifted by ``step``, in the shorter bracket; the weight falls smoothly to 0 at its
    edge, so the centroids move with the scene, not in steps of a pixel, and a sensor's
    area sampling keeps them where the scene's are. A region is used only where every
    pixel of it with weight is well exposed or clipped in the neighbour and well exposed
    (or above the clip) in the shorter bracket, and their summed weights agree
    (:data:`AGREE`). The refined shift is the regions' mean centroid shift, weighted by
    their weight; ``step`` when no region is usable or they move it by more than
    :data:`MAX_REFINEMENT`. A translation only: across a highlight, where this bracket
    carries the merge, a rotation of half a degree moves nothing by more than 0.1 px."""
    import scipy.ndimage

    clip = float(np.exp(level))
    floor = FLOOR * clip
    # A pixel beside the clipped region that is not well exposed has a channel at the top.
    clipped = clipped | (~neighbour_valid & scipy.ndimage.binary_dilation(
        clipped, iterations=REACH))
    known_k = neighbour_valid | clipped
    known_j = short_valid | (short_log >= level)
    weight_k = np.minimum(np.exp(neighbour_log.astype(np.float64)), clip) - floor
    weight_k[clipped] = clip - floor
    weight_j = np.maximum(np.minimum(np.exp(short_log.astype(np.float64)), clip) - floor, 0.0)
    weight_k = np.where(known_k, np.maximum(weight_k, 0.0), 0.0)
    labels, _ = scipy.ndimage.label(scipy.ndimage.binary_dilation(weight_k > 0,
                                                                  iterations=REACH))
    dx, dy = int(round(step[0, 2])), int(round(step[1, 2]))
    height, width = clipped.shape
    shifts, weights = [], []
    for index, box in enumerate(scipy.ndimage.find_objects(labels), start=1):
        rows = slice(box[0].start - REACH, box[0].stop + REACH)
        cols = slice(box[1].start - REACH, box[1].stop + REACH)
        if (min(rows.start, cols.start, rows.start + dy, cols.start + dx) < 0
                or max(rows.stop, rows.stop + dy) > height
                or max(cols.stop, cols.stop + dx) > width):
            continue  # at the image's edge: part of the highlight may be outside
        moved_rows = slice(rows.start + dy, rows.stop + dy)
        moved_cols = slice(cols.start + dx, cols.stop + dx)
        region = labels[rows, cols] == index
        k = np.where(region, weight_k[rows, cols], 0.0)
        j = np.where(region, weight_j[moved_rows, moved_cols], 0.0)
        unknown = (region & ~known_k[rows, cols]) | ((j > 0) & ~known_j[moved_rows, moved_cols])
        total_k, total_j = k.sum(), j.sum()
        if (unknown.any() or np.count_nonzero(k) < MIN_PIXELS or total_k <= 0
                or not AGREE[0] <= total_j / total_k <= AGREE[1]):
            continue
        y, x = np.mgrid[0:k.shape[0], 0:k.shape[1]]
        shifts.append((dx + (x * j).sum() / total_j - (x * k).sum() / total_k,
                       dy + (y * j).sum() / total_j - (y * k).sum() / total_k))
        weights.append(total_k)
    if not shifts:
        return step
    sx, sy = np.average(np.array(shifts), axis=0, weights=weights)
    if np.hypot(sx - step[0, 2], sy - step[1, 2]) > MAX_REFINEMENT:
        return step
    return translation(sx, sy)
