"""Shifts found by correlating whole images (FFT), for the gradient method to refine.

Two uses in registration (:func:`hdrio.align.registration.estimate_alignment`):

* :func:`masked_ncc_shift`: the shift that best matches two brackets' log radiance where
  both are usable, by masked normalised cross-correlation (Padfield 2012). Log radiance
  is exposure-invariant up to an offset, which the normalisation removes, and only the
  pixels usable in both count at every shift. It is the guess a pair starts from when
  the median-threshold bitmaps' guess failed: a bracket clipped over most of the frame
  has its median at the clip, and its bitmap says nothing of where its few usable pixels
  are.
* :func:`hdrio.align.highlight_shift.highlight_shift`: two masks (a highlight's shape)
  matched by plain cross-correlation.

Reference
---------
Padfield, D. (2012). Masked object registration in the Fourier domain. IEEE Transactions
on Image Processing 21(5), 2706-2718.
"""

from __future__ import annotations

import numpy as np

from hdrio.align.lucaskanade import translation

NCC_PIXELS = 2**17
"""The pyramid level :func:`masked_ncc_shift` is run on: the finest with at most this many
pixels (at 24 MP the base is 1500x1000 and the level 375x250)."""

MIN_SHARE = 0.5
"""At the best shift, at least this share of the smaller mask's pixels overlaps the other
mask (a shift that matches a sliver of the two says nothing)."""

MIN_SCORE = 0.5
"""The lowest normalised correlation a shift is taken at (lower, the shifts of pairs that
share only dark, noisy regions won on the misfit and put a bracket of a dark still life's
5 x 2 EV JPEG ladder 5 px off)."""


def correlate(a: np.ndarray, b: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``C(d) = sum_x a(x) b(x + d)`` for every shift ``d``, the images zero-padded to
    ``shape`` (twice their size: no wrap-around); index ``d`` modulo ``shape``."""
    return np.fft.irfft2(np.conj(np.fft.rfft2(a, shape)) * np.fft.rfft2(b, shape), shape)


def shifts(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The shift ``(dy, dx)`` each row and column of a :func:`correlate` result stands for."""
    return (np.fft.fftfreq(shape[0], 1.0 / shape[0]).astype(int),
            np.fft.fftfreq(shape[1], 1.0 / shape[1]).astype(int))


def within_reach(c: np.ndarray, reach: int) -> np.ndarray:
    """``c`` with every shift beyond ``reach`` (either way) set to ``-inf``."""
    dy, dx = shifts(c.shape)
    return np.where((np.abs(dy)[:, None] <= reach) & (np.abs(dx)[None, :] <= reach), c,
                    -np.inf)


def sub_pixel(c: np.ndarray, py: int, px: int) -> tuple[float, float]:
    """The shift ``(dy, dx)`` at ``c``'s peak ``(py, px)``, refined by a parabola through
    its neighbours each way."""
    dy, dx = shifts(c.shape)
    peak = c[py, px]
    return (dy[py] + _vertex(c[(py - 1) % c.shape[0], px], peak, c[(py + 1) % c.shape[0], px]),
            dx[px] + _vertex(c[py, (px - 1) % c.shape[1]], peak, c[py, (px + 1) % c.shape[1]]))


def _vertex(before: float, peak: float, after: float) -> float:
    """The parabola's vertex through three equally spaced values, relative to the middle
    one (within half a step)."""
    if not (np.isfinite(before) and np.isfinite(after)):
        return 0.0
    curvature = before - 2.0 * peak + after
    if curvature >= 0.0:
        return 0.0
    return float(np.clip(0.5 * (before - after) / curvature, -0.5, 0.5))


def masked_ncc_shift(fixed: np.ndarray, fixed_valid: np.ndarray, moving: np.ndarray,
                     moving_valid: np.ndarray, reach: int) -> np.ndarray | None:
    """``x_moving = W x_fixed`` (3x3, a whole-pixel translation of this grid) maximising
    the normalised cross-correlation of ``fixed`` and ``moving`` (``(h, w)`` log
    radiance) over the pixels valid in both at each shift, up to ``reach`` pixels each
    way; ``None`` when no shift overlaps enough of the masks (:data:`MIN_SHARE`) or
    correlates well enough (:data:`MIN_SCORE`).

    Every sum over the overlap of the masks at every shift is a correlation of the
    masked images and their squares with the masks (:func:`correlate`'s way)."""
    shape = (2 * fixed.shape[0], 2 * fixed.shape[1])
    mf, mg = fixed_valid.astype(np.float64), moving_valid.astype(np.float64)
    smaller = min(mf.sum(), mg.sum())
    if smaller == 0:
        return None
    # Centred on their means, so the sums of squares lose nothing to cancellation.
    f = np.where(fixed_valid, fixed - fixed[fixed_valid].mean(), 0.0)
    g = np.where(moving_valid, moving - moving[moving_valid].mean(), 0.0)
    # Each image's transforms once (six), each sum one inverse (six).
    fixed_parts = [np.conj(np.fft.rfft2(a, shape)) for a in (mf, f, f * f)]
    moving_parts = [np.fft.rfft2(a, shape) for a in (mg, g, g * g)]

    def summed(a: int, b: int) -> np.ndarray:  # C(d) of fixed part a and moving part b
        return np.fft.irfft2(fixed_parts[a] * moving_parts[b], shape)

    overlap = np.rint(summed(0, 0))
    sum_f, sum_g = summed(1, 0), summed(0, 1)
    counted = np.maximum(overlap, 1.0)
    cross = summed(1, 1) - sum_f * sum_g / counted
    spread = (np.maximum(summed(2, 0) - sum_f ** 2 / counted, 0.0)
              * np.maximum(summed(0, 2) - sum_g ** 2 / counted, 0.0))
    score = np.full(shape, -np.inf)
    usable = (overlap >= MIN_SHARE * smaller) & (spread > 0.0)
    score[usable] = cross[usable] / np.sqrt(spread[usable])
    score = within_reach(score, reach)
    py, px = np.unravel_index(int(np.argmax(score)), shape)
    if not score[py, px] >= MIN_SCORE:
        return None
    dy, dx = shifts(shape)
    return translation(float(dx[px]), float(dy[py]))
