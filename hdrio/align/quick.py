"""Is anything moving? A sparse full-resolution check that lets ``--align auto`` skip the
pyramid on a still stack.

The strongest gradients of the reference are found on a strided sample (every
:data:`STRIDE`-th row and column or sparser, about :data:`GRID` pixels; on large images
on fewer rows, :data:`SPREAD`), then, at up to
:data:`POINTS` of them, each bracket's linearised log radiance and the reference's
full-resolution gradient are read (five pixels a point: the whole check reads a few
hundred kilobytes, not the brackets). One
Gauss-Newton step of translation + rotation from the identity, Huber-weighted, with a
free offset, estimates each bracket's motion against its neighbour towards the
reference; when every estimate moves the image's corners by less than :data:`STILL`
pixels, the stack is still. Otherwise the full registration runs.

A pair of dark brackets gives a noisy estimate: on the demo stack the two shortest
(1/1024 and 1/256 s, 2,800 points usable in both) moved the corners by 0.054 px, with a
standard error of 0.039 px, on a stack that does not move at all, and every such stack
was registered in full. So an estimate also counts as still when it is under
:data:`hdrio.align.registration.WITHIN` (``auto``'s own bound) and within
:data:`SIGMAS` standard errors of :data:`STILL` (the error from the Gauss-Newton step's
normal matrix and its residuals, those of a :data:`BLOCK`-pixel block counted once).
A pair that is not still at once is measured again, at other points, and the most
precise of its measurements decides (:func:`looks_still`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hdrio.align.pyramid import base_factor
from hdrio.align.registration import WITHIN, unusable
from hdrio.io.staging import release
from hdrio.skips import well_exposed_codes

STRIDE = 4
"""At least; larger images are sampled more sparsely, about :data:`GRID` pixels."""
GRID = 400_000
POINTS = 20_000
STILL = 0.05
"""Pixels: half of ``--align auto``'s 0.1 px (one Gauss-Newton step from the identity
is exact to first order only)."""
SIGMAS = 2.0
"""Standard errors an estimate may lie above :data:`STILL` and still count as still
(under :data:`hdrio.align.registration.WITHIN` only)."""
BLOCK = 16
"""Pixels: a still pair's residuals are not independent from point to point. A JPEG's
error is shared within its 8 x 8 blocks (16 x 16 for 4:2:0 chroma), and demosaicing and
noise reduction spread a pixel's noise to its neighbours. Counted as independent, the
standard error of a dense measurement shrinks with its point count while an error its
points share does not. The step's covariance counts each block of this size once (a
cluster-robust sandwich)."""
SPREAD = 4
SPREAD_PIXELS = 4_000_000
"""From this many pixels the points are chosen on :data:`SPREAD` times fewer rows (and
as many times more columns): each point reads three rows of every bracket, and a
bracket staged in a file (:mod:`hdrio.io.staging`) maps a page of memory for each row
read, then gives it back. On every 7th row of a 24 MP stack the check mapped 43 % of
every bracket's pages (0.1 s of page faults, as much as the rest of the check); on
every 28th, 11 %."""
USABLE_SAMPLES = 65536
"""About this many pixels of each bracket (a strided grid) tell how much of it is usable."""


@njit(cache=True, nogil=True)
def _read(codes, linear, ys, xs, low, high, values, gx, gy, good):  # pragma: no cover
    """``ln sum_c linear[c, z_c]`` at each point, its central differences, and whether the
    point and its four neighbours are well exposed in every channel. The codes are
    gathered first, in a loop of loads only (the reads miss the cache, and independent
    loads wait for memory together), then worked on."""
    height, width, channels = codes.shape
    n = ys.size
    # Only the points inside the border are gathered, and only they are read. (np.empty,
    # not np.zeros: deghosting compiles it for the same types; 0.3 s less to compile.)
    gathered = np.empty((n, 5, channels), codes.dtype)
    for i in range(n):
        y, x = ys[i], xs[i]
        if 0 < y < height - 1 and 0 < x < width - 1:
            for c in range(channels):
                gathered[i, 0, c] = codes[y, x, c]
                gathered[i, 1, c] = codes[y + 1, x, c]
                gathered[i, 2, c] = codes[y - 1, x, c]
                gathered[i, 3, c] = codes[y, x + 1, c]
                gathered[i, 4, c] = codes[y, x - 1, c]
    logs = np.empty(5)
    for i in range(n):
        y, x = ys[i], xs[i]
        if not (0 < y < height - 1 and 0 < x < width - 1):
            good[i] = False
            values[i] = gx[i] = gy[i] = 0.0
            continue
        ok = True
        for k in range(5):
            total = 0.0
            for c in range(channels):
                z = gathered[i, k, c]
                ok &= (z >= low) & (z <= high)
                total += linear[c, z]
            logs[k] = np.log(max(total, 1e-30))
        good[i] = ok
        values[i] = logs[0]
        gy[i] = 0.5 * (logs[1] - logs[2])
        gx[i] = 0.5 * (logs[3] - logs[4])


@njit(cache=True, nogil=True)
def _grid(codes, linear, low, high, rows, cols, logs, usable):  # pragma: no cover
    """On every ``rows``-th row and ``cols``-th column (from ``rows // 2``, ``cols // 2``):
    ``ln sum_c linear[c, z_c]`` into ``logs`` (when it has the grid's shape; else not
    computed) and whether every channel lies in ``low .. high`` into ``usable``."""
    want_logs = logs.shape[0] == usable.shape[0]
    for i in range(usable.shape[0]):
        y = rows // 2 + i * rows
        for k in range(usable.shape[1]):
            x = cols // 2 + k * cols
            total = 0.0
            ok = True
            for c in range(codes.shape[2]):
                z = codes[y, x, c]
                ok &= (z >= low) & (z <= high)
                if want_logs:
                    total += linear[c, z]
            usable[i, k] = ok
            if want_logs:
                logs[i, k] = np.log(max(total, 1e-30))


def _grid_shape(height: int, width: int, rows: int, cols: int) -> tuple[int, int]:
    """The shape of ``array[rows // 2::rows, cols // 2::cols]``."""
    return -(-(height - rows // 2) // rows), -(-(width - cols // 2) // cols)


def _points(codes: np.ndarray, linear: np.ndarray, usable_only: bool = False,
            excluded: np.ndarray | None = None, partner: np.ndarray | None = None,
            least: int = STRIDE) -> tuple[np.ndarray, np.ndarray]:
    """Full-resolution ``(ys, xs)`` of the strongest gradients of a strided sample (every
    ``least``-th row and column or sparser, about :data:`GRID` pixels; on large images
    :data:`SPREAD` times fewer rows, as many times more columns); with ``usable_only``,
    among the sample's well-exposed pixels only (a dark bracket's strongest gradients
    are at its clipped highlights), and those of ``partner`` (another bracket's codes)
    too when given; never where any bracket of ``excluded`` (``(P, H, W)``) is left out."""
    height, width = codes.shape[:2]
    stride = max(least, int(np.sqrt(height * width / GRID)))
    rows, cols = stride, stride
    if height * width >= SPREAD_PIXELS:
        rows, cols = stride * SPREAD, max(1, stride // SPREAD)
    shape = _grid_shape(height, width, rows, cols)
    image = np.empty(shape)
    good = np.empty(shape, np.bool_)
    low, high = (well_exposed_codes(int(linear.shape[-1]) - 1, linear=linear) if usable_only
                 else (0, 0))
    _grid(codes, np.ascontiguousarray(linear, np.float64), low, high, rows, cols, image, good)
    gy, gx = np.gradient(image, rows, cols)  # per pixel: the grid's steps differ
    strength = gx * gx + gy * gy
    if usable_only:
        strength[~good] = -1.0
    if usable_only and partner is not None:
        _grid(partner, np.zeros((partner.shape[2], 1)), low, high, rows, cols,
              np.empty((0, 0)), good)
        strength[~good] = -1.0
    if excluded is not None:
        strength[excluded[:, rows // 2::rows, cols // 2::cols].any(axis=0)] = -1.0
    strength = strength.reshape(-1)
    count = min(POINTS, strength.size)
    index = np.sort(np.argpartition(strength, -count)[-count:])  # in memory order
    i, k = np.divmod(index, image.shape[1])
    return i * rows + rows // 2, k * cols + cols // 2


def usable(codes: np.ndarray, code_max: int, stride: int, linear: np.ndarray | None = None
           ) -> np.ndarray:
    """``(h, w)``: every ``stride``-th pixel of one bracket ``(H, W, C)``, whether every
    channel is well exposed (unclipped, above the noise; ``linear``, ``(C, levels)``: the
    response's ``f^-1``, which sets the window of deep codes,
    :func:`hdrio.skips.well_exposed_codes`)."""
    low, high = well_exposed_codes(code_max, linear=linear)
    out = np.empty(_grid_shape(codes.shape[0], codes.shape[1], stride, stride), np.bool_)
    _grid(codes, np.zeros((codes.shape[2], 1)), low, high, stride, stride,
          np.empty((0, 0)), out)
    return out


def usable_masks(codes: np.ndarray, code_max: int, excluded: np.ndarray | None = None,
                 linear: np.ndarray | None = None) -> list[np.ndarray]:
    """:func:`usable` of every bracket of ``codes`` ``(P, H, W, C)`` on the grid of about
    :data:`USABLE_SAMPLES` pixels (the grid
    :func:`hdrio.align.registration.reference_bracket` scores on), outside ``excluded``
    (``(P, H, W)``: the observations the merge leaves out; ``linear`` as :func:`usable`)."""
    height, width = codes.shape[1:3]
    stride = max(1, int(np.sqrt(height * width / USABLE_SAMPLES)))
    masks = []
    for j in range(codes.shape[0]):
        masks.append(usable(codes[j], code_max, stride, linear))
        release(codes, j)  # a staged bracket's pages: a sparse grid maps most of them
        if excluded is not None:
            masks[j] &= ~excluded[j, stride // 2::stride, stride // 2::stride]
    return masks


def corner_motion_error(delta: np.ndarray, covariance: np.ndarray, half: float
                        ) -> tuple[float, float]:
    """The corner motion (pixels) of a Gauss-Newton step ``delta`` (shift ``delta[0:2]``
    and rotation ``delta[2]``, in units of ``half`` pixels; ``delta[3]`` the offset) and
    its standard error from ``covariance`` ``(4, 4)``, to first order."""
    shift = float(np.hypot(delta[0], delta[1]))
    motion = half * (shift + abs(delta[2]) * np.sqrt(2.0))
    gradient = half * np.array([delta[0] / shift if shift else 1.0,
                                delta[1] / shift if shift else 0.0,
                                np.sqrt(2.0) * (1.0 if delta[2] >= 0 else -1.0), 0.0])
    return motion, float(np.sqrt(max(0.0, gradient @ covariance @ gradient)))


def _read_all(codes: np.ndarray, linear: np.ndarray, brackets, ys, xs, low: int, high: int,
              excluded: np.ndarray | None = None) -> dict[int, tuple]:
    """:func:`_read` of each of ``brackets`` at the points ``(ys, xs)``: ``{bracket:
    (values, gx, gy, good)}``, a point not good where ``excluded`` (``(P, H, W)``)
    leaves that bracket's observation out."""
    n = ys.size
    reads = {}
    for j in brackets:
        values, gx, gy, good = np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.bool_)
        _read(codes[j], np.ascontiguousarray(linear[j]), ys, xs, low, high, values, gx, gy,
              good)
        release(codes, j)
        if excluded is not None:
            good &= ~excluded[j, ys, xs]
        reads[j] = (values, gx, gy, good)
    return reads


def _pair_motion(template, moving, ys, xs, height: int, width: int
                 ) -> tuple[float, float] | None:
    """One Gauss-Newton step of translation + rotation (and an offset) from the identity
    of ``moving`` onto ``template`` (both :func:`_read` tuples at ``(ys, xs)``): its
    corner motion (pixels) and that motion's standard error
    (:func:`corner_motion_error`); ``None`` when too few points are good in both (under
    200) or the step is singular.

    The step is Huber-weighted; its covariance is the sandwich of the normal matrix
    around the points' scores summed within each :data:`BLOCK` x :data:`BLOCK` block,
    so that residuals a block shares count once (a JPEG's are: see :data:`BLOCK`)."""
    values_k, gx, gy, ok_k = template
    values, _, _, ok_j = moving
    good = ok_k & ok_j
    if np.count_nonzero(good) < 200:
        return None
    half = max(height, width) / 2.0
    u = (xs - (width - 1) / 2.0) / half
    v = (ys - (height - 1) / 2.0) / half
    sd = np.stack([gx * half, gy * half, -v * gx * half + u * gy * half,
                   np.ones(ys.size)], axis=1)[good]
    error = (values - values_k)[good]
    error = error - np.median(error)
    scale = 1.4826 * np.median(np.abs(error)) + 1e-6
    weight = np.minimum(1.0, 1.345 * scale / (np.abs(error) + 1e-12))
    weighted = sd * weight[:, None]
    normal = weighted.T @ sd
    try:
        delta = np.linalg.solve(normal, weighted.T @ error)
        bread = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        return None
    block = (ys[good] // BLOCK) * (width // BLOCK + 1) + xs[good] // BLOCK
    _, cluster = np.unique(block, return_inverse=True)
    clusters = int(cluster.max()) + 1
    if clusters < 2:
        return None
    scores = weighted * error[:, None]
    sums = np.stack([np.bincount(cluster, scores[:, c], clusters) for c in range(4)],
                    axis=1)
    covariance = clusters / (clusters - 1.0) * (bread @ (sums.T @ sums) @ bread)
    return corner_motion_error(delta, covariance, half)


def _verdict(motion: float, spread: float) -> bool | None:
    """Still (within :data:`STILL`, or within :data:`~hdrio.align.registration.WITHIN`
    and :data:`SIGMAS` standard errors of it), moved (more than :data:`SIGMAS` standard
    errors above :data:`STILL`), or ``None``: the measurement cannot tell."""
    if motion < STILL or (motion < WITHIN and motion - SIGMAS * spread < STILL):
        return True
    if motion - SIGMAS * spread >= STILL:
        return False
    return None


def looks_still(codes: np.ndarray, linear: np.ndarray, code_max: int, reference: int,
                masks: list[np.ndarray] | None = None, excluded: np.ndarray | None = None
                ) -> tuple[bool, dict[int, str]]:
    """Whether one Gauss-Newton step finds every bracket within :data:`STILL` pixels of
    its nearest registrable neighbour towards ``reference``, and the brackets too little
    of which is usable to register (:func:`hdrio.align.registration.unusable`, on
    ``masks``: :func:`usable_masks`): ``{bracket: why}``, not tested.

    Each pair is measured at the strongest gradients of ``reference`` first; a pair
    those leave too few points usable in both (the ends of a long ladder: a 9 x 2 EV
    ladder's shortest pair had 186 of 20,000, and every still 9-bracket stack was
    registered in full) is measured again at the strongest gradients of its bracket
    farther from the reference, which sees what its neighbour sees best; and where those
    leave too few too (a small image's mostly clipped longest bracket: 113 of a 300 x
    437 ladder's every-4th-pixel grid), at the strongest gradients of the pixels usable
    in both, every pixel of a small image. A pair measured but not found still (too
    uncertain to tell, or moved) is measured again the same ways, and the measurement
    with the smallest standard error decides (a small JPEG ladder's pair: 0.26 +- 0.33
    px at 923 points, then 0.008 +- 0.059 px at 14,409).

    Parameters
    ----------
    codes
        ``(P, H, W, C)`` code values.
    linear
        ``(P, C, levels)``: ``f^-1(z) / dt_j``, relative radiance.
    excluded
        ``(P, H, W)`` observations the merge leaves out (``--mask``,
        ``--exclude-color``): not read.
    """
    count, height, width, _ = codes.shape
    low, high = well_exposed_codes(code_max, linear=linear[reference])
    ys, xs = _points(codes[reference], linear[reference], excluded=excluded)
    release(codes, reference)
    reads = _read_all(codes, linear, range(count), ys, xs, low, high, excluded)
    refused: dict[int, str] = {}
    stride = max(1, int(np.sqrt(height * width / USABLE_SAMPLES)))
    scale = (stride / base_factor(height, width)) ** 2
    if masks is None:
        masks = usable_masks(codes, code_max, excluded, linear[reference])
    pairs = []
    for side in (range(reference - 1, -1, -1), range(reference + 1, count)):
        k = reference
        for j in side:
            why = unusable(masks[k], masks[j], scale)
            if why is not None:
                refused[j] = why
                continue
            pairs.append((j, k))
            k = j
    for j, k in pairs:
        best = _pair_motion(reads[k], reads[j], ys, xs, height, width)
        still = None if best is None else _verdict(*best)
        # Too little in common at the reference's points, or not still: at j's own
        # strongest usable gradients; then at the strongest usable in both, densely.
        # The most precise measurement so far decides.
        for partner, least in ((None, STRIDE), (codes[k], 1)):
            if still:
                break
            own_ys, own_xs = _points(codes[j], linear[j], usable_only=True,
                                     excluded=excluded, partner=partner, least=least)
            release(codes, j)
            own = _read_all(codes, linear, (k, j), own_ys, own_xs, low, high, excluded)
            measured = _pair_motion(own[k], own[j], own_ys, own_xs, height, width)
            if measured is not None and (best is None or measured[1] < best[1]):
                best = measured
            still = None if best is None else _verdict(*best)
        if not still:  # moved, or still too little to tell: measure properly
            return False, refused
    return True, refused
