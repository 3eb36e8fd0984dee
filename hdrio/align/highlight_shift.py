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
highlight's own pixels by hundredths of one).
"""

from __future__ import annotations

import numpy as np

from hdrio.align.correlation import correlate, sub_pixel, within_reach
from hdrio.align.lucaskanade import translation

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
