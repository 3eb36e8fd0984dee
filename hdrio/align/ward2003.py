"""Median threshold bitmaps, coarse to fine (Ward 2003): an exposure-invariant translation.

Each image is thresholded at its own median code, which splits a still scene into the
same two halves whatever the exposure; pixels within :data:`NOISE_CODES` of the median
are excluded (noise flips them). From the coarsest level of a 2x pyramid down, the
shift is doubled and the best of its nine neighbours (fewest differing bits) kept, so
a pyramid of ``n`` levels finds shifts up to ``2^n - 1`` pixels at ``9 n`` bitmap
comparisons.

References
----------
Ward, G. (2003). Fast, robust image registration for compositing high dynamic range
photographs from hand-held exposures. Journal of Graphics Tools, 8(2), 17-30.
"""

from __future__ import annotations

import numpy as np

from hdrio.align.pyramid import downsample

NOISE_CODES = 4.0
"""Half-width of the exclusion band around the median, in code values of 8-bit (scaled
for deeper codes): Ward's value."""


_OFFSETS = sorted(((ox, oy) for oy in (-1, 0, 1) for ox in (-1, 0, 1)),
                  key=lambda o: abs(o[0]) + abs(o[1]))
"""The nine candidate steps, nearest first: where every candidate differs by as many bits
(a nearly saturated bracket, thresholded at a median of ``Z_max``, has no bits) the
shift stays where it was, rather than walking to ``(-1, -1)`` at every level."""


MEDIAN_SAMPLES = 65536
"""The median is taken on a strided grid of about this many pixels (a threshold needs no
more; the full median of every level was a quarter of the alignment's time)."""


def _bitmaps(grey: np.ndarray, noise: float) -> tuple[np.ndarray, np.ndarray]:
    step = max(1, int(np.sqrt(grey.size / MEDIAN_SAMPLES)))
    median = float(np.median(grey[step // 2::step, step // 2::step]))
    return grey > median, np.abs(grey - median) > noise


def _difference(ref, ref_keep, mov, mov_keep, dx: int, dy: int) -> int:
    """Differing, non-excluded bits of ``ref(x, y)`` and ``mov(x + dx, y + dy)`` over
    their overlap."""
    h, w = ref.shape
    ys, ye = max(0, -dy), min(h, h - dy)
    xs, xe = max(0, -dx), min(w, w - dx)
    if ye <= ys or xe <= xs:
        return ref.size
    a = ref[ys:ye, xs:xe]
    b = mov[ys + dy:ye + dy, xs + dx:xe + dx]
    keep = ref_keep[ys:ye, xs:xe] & mov_keep[ys + dy:ye + dy, xs + dx:xe + dx]
    return int(np.count_nonzero((a ^ b) & keep))


def align_Ward2003(reference: np.ndarray, moving: np.ndarray, levels: int,
                   code_max: int = 255) -> tuple[int, int]:
    """The integer shift ``(dx, dy)`` with ``moving(x + dx, y + dy) ~ reference(x, y)``.

    Parameters
    ----------
    reference, moving
        Grey code values ``(H, W)`` (any scale: mean code values of a bracket).
    levels
        Pyramid levels: shifts up to ``2^levels - 1`` pixels are found.
    code_max
        Saturation code (scales the exclusion band).
    """
    noise = NOISE_CODES * code_max / 255.0
    pyramid = [(reference.astype(np.float32, copy=False), moving.astype(np.float32, copy=False))]
    for _ in range(levels - 1):
        ref, mov = pyramid[-1]
        if min(ref.shape) < 16:
            break
        pyramid.append((downsample(ref), downsample(mov)))
    dx = dy = 0
    for ref, mov in reversed(pyramid):
        dx, dy = 2 * dx, 2 * dy
        ref_bits, ref_keep = _bitmaps(ref, noise)
        mov_bits, mov_keep = _bitmaps(mov, noise)
        best = None
        for ox, oy in _OFFSETS:  # a tie keeps the smaller step (no evidence, no shift)
            score = _difference(ref_bits, ref_keep, mov_bits, mov_keep, dx + ox, dy + oy)
            if best is None or score < best[0]:
                best = (score, dx + ox, dy + oy)
        _, dx, dy = best
    return dx, dy
