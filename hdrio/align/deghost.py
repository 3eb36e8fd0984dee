"""Deghosting: drop the observations that disagree with the reference bracket.

Each bracket's estimate ``x_j(z) = f^-1(z) / dt_j`` (relative radiance) is tested against
the reference bracket's, per channel, with the variance of both estimates (the noise
model's table, ``(P, C, levels)``, relative radiance squared):
``d^2 = (x_j - x_r)^2 / (var_j + var_r)``, which is about 1 on average for a still scene.
Where the reference is clipped in a channel, the nearest bracket towards ``j`` that is
not takes over as the reference there (so a bright window is tested against the shorter
brackets). Where it is black, it bounds the radiance from above, and the nearest bracket
within that bound takes over (a dark corner is tested against the longer brackets; dark
clothes in front of a brighter floor are not replaced by the floor).

The test is made per *cell* of :data:`CELL` x :data:`CELL` pixels on every
:data:`STRIDE`-th pixel each way (the mean of the capped ``d^2`` of its samples: noise
averages out, a moving object does not), so a cell is flagged only when its mean is
above :data:`THRESHOLD`. Flags are grown by one cell (an object's edge falls in cells
only partly covered) and feathered by a Gaussian of one cell, so the keep weight goes
from 0 to 1 over a few cells and no seam shows; the merge takes per-bracket weights
bilinearly interpolated between cell centres (:func:`hdrio.merge.masked.remerge_masked`).
The reference bracket is never dropped. A cell a warped bracket does not fully cover
gets weight 0 for that bracket (:func:`hdrio.align.warp.coverage`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.ndimage
from numba import njit

from hdrio.io.staging import is_staged, release
from hdrio.jit import INNER
from hdrio.parallel import on_threads
from hdrio.skips import well_exposed_codes

CELL = 8
"""Side of a test cell, pixels."""
STRIDE = 2
"""Pixels tested each way within a cell (every second: a quarter of the pixels)."""
THRESHOLD = 20.0
"""A cell is inconsistent when the mean of its samples' capped ``d^2`` exceeds this
(still stacks: cell means 0.5-2.2 at the median, at most 16 on five truth scenes with
the interim noise model; a 25 % disagreement alone gives about 35)."""
SCALED_MAX = 60.0
"""The most the threshold is raised for a bracket whose still cells disagree more than
the noise model says (see :func:`deghost`)."""
CAP = 100.0
"""Each sample's ``d^2`` is capped here, so a few outliers (an edge, a hot pixel) cannot
flag a cell alone: it takes at least 5 % of a cell's samples far out."""
LIMIT = 0.7
"""Samples whose estimates differ by more than this in ``ln`` (a factor 2) are left out
of :func:`comparametric_correction` (motion, not a response error)."""
MIN_SAMPLES = 8
"""Cells with fewer usable samples of a bracket are not judged (kept)."""
COARSE = 4
"""The quick look's samples are at least this many times sparser than the fine test's,
its cells as many times wider (the same count of samples a cell)."""
QUICK_SAMPLES = 100_000
"""... and sparser still on large images: about this many samples a bracket."""
QUICK = 5.0
"""A coarse cell is looked at finely when its mean capped ``d^2`` is above this (times
the bracket's scale): about one sample of its sixteen far out."""
SUSPECT = 4.0
"""A sample's ``d^2`` above this (two standard deviations) is looked at more closely: is
some channel clipped nearby (:data:`CLIP_RADIUS`)?"""
TEST_BANDS = 16
"""Bands of cell rows a test of staged brackets runs in (each band's pages given back)."""
CLIP_RADIUS = 2
"""Pixels: a sample this close to a channel above the well-exposed codes or at black
(:data:`BLACK`), in either bracket compared, says nothing when it disagrees (JPEG's
chroma is half resolution and its blocks ring; a colour clipped at black in two
channels bends the third: the truth harness's StillLife JPEG, its saturated reds, 10 %
flagged)."""
BLACK = 0.01
"""Codes at most this fraction of ``Z_max`` are clipped at black."""
BRIGHT = 0.85
BRIGHT_RADIUS = 4
"""... and this close when the sample is itself bright (some channel above
:data:`BRIGHT` of the well-exposed codes): a camera's highlight roll-off and sharpening
bend the bright pixels around a clipped region (frobisher_001's window sill, 4 px from
the clipped sky in the 8 s JPEG, half as bright as the 1 s one says). Farther or darker
samples keep counting: people walking in front of a bright window are motion."""


@njit(nogil=True, **INNER)
def _local_range(codes, estimates, variance, j, y, x, c):  # pragma: no cover - compiled
    """Smallest and largest usable estimate of bracket ``j`` around ``(y, x)`` (3x3)."""
    height, width = codes.shape[1], codes.shape[2]
    low = np.inf
    high = -np.inf
    for yy in range(max(0, y - 1), min(height, y + 2)):
        for xx in range(max(0, x - 1), min(width, x + 2)):
            z = codes[j, yy, xx, c]
            if np.isfinite(variance[j, c, z]):
                e = estimates[j, c, z]
                low = min(low, e)
                high = max(high, e)
    return low, high


@njit(nogil=True, **INNER)
def _clipped_near(codes, j, y, x, black, high, radius):  # pragma: no cover - compiled
    """Whether some channel of bracket ``j`` is above ``high`` or at most ``black``
    within ``radius`` pixels of ``(y, x)`` (within :data:`BRIGHT_RADIUS` when ``(y, x)``
    is itself bright: above :data:`BRIGHT` of ``high``)."""
    height, width, channels = codes.shape[1], codes.shape[2], codes.shape[3]
    for c in range(channels):
        if codes[j, y, x, c] > BRIGHT * high:
            radius = BRIGHT_RADIUS
    for yy in range(max(0, y - radius), min(height, y + radius + 1)):
        for xx in range(max(0, x - radius), min(width, x + radius + 1)):
            for c in range(channels):
                z = codes[j, yy, xx, c]
                if z > high or z <= black:
                    return True
    return False


@njit(nogil=True, **INNER)
def _near(codes, j, y, x, black, high, radius, known):  # pragma: no cover - compiled
    """:func:`_clipped_near`, remembered in ``known[j]`` (-1: not yet asked) for one sample."""
    if known[j] < 0:
        known[j] = 1 if _clipped_near(codes, j, y, x, black, high, radius) else 0
    return known[j] == 1


@njit(cache=True, nogil=True)
def _consistency(start, stop, codes, estimates, variance, dark_bound, dark_variance,
                 reference, cell, stride, cap, resampled, black, high, suspect, todo, sums,
                 counts, takeovers):  # pragma: no cover - compiled
    """Per bracket and cell (those ``todo``, in cell rows ``start .. stop - 1``), the sum
    and count of the capped ``d^2`` of its samples.

    ``d`` is the distance from ``x_j`` to the *range* of the reference's estimates in a
    3x3 neighbourhood (0 inside it) when the brackets were ``resampled``: a resampled
    bracket differs from the reference at sharp edges by a fraction of a pixel's blur,
    which is not motion. Otherwise from the reference's own estimate (9x fewer reads).

    A sample whose ``d^2`` is above ``suspect`` is left out for a channel when either
    bracket compared has some channel above ``high`` within :data:`CLIP_RADIUS` pixels: a
    camera bends the other channels next to a clipped one (highlight roll-off,
    white balance of a clipped channel, JPEG's ringing and half-resolution chroma),
    and that is not motion. (Asked only of suspect samples: a few per cent of them.)

    Where the reference is below its usable codes in a channel it still says something:
    the radiance is at most ``dark_bound`` (its first usable code's estimate, with that
    code's ``dark_variance``; :func:`dark_bounds`). A bracket is tested against that
    bound, and the first one within it takes over as the reference there. (Dark clothes
    under a dark reference: the brighter background a shorter or longer bracket shows
    there is a ghost; taken over untested it merged channel by channel with the
    reference's, in coloured speckle.)

    A row of samples is gathered from every bracket first, bracket by bracket along the
    row (loads only: the reads miss the cache, and the prefetcher follows a stride), then
    tested; reading every bracket at each sample in turn waited on memory at each."""
    count, height, width, channels = codes.shape
    cols = sums.shape[2]
    start_low = np.empty(channels)
    start_high = np.empty(channels)
    start_var = np.empty(channels)
    low = np.empty(channels)
    high_e = np.empty(channels)
    chain_var = np.empty(channels)
    chain = np.empty(channels, np.int64)
    start_bounded = np.empty(channels, np.bool_)
    bounded = np.empty(channels, np.bool_)  # the chain's value is the dark bound
    known = np.empty(count, np.int8)
    gathered = np.empty((cols * (cell // stride + 1), count, channels), codes.dtype)
    for cy in range(start, stop):
        for y in range(cy * cell + stride // 2, min(height, (cy + 1) * cell), stride):
            for j in range(count):
                i = 0
                for cx in range(cols):
                    if todo[cy, cx]:
                        for x in range(cx * cell + stride // 2, min(width, (cx + 1) * cell),
                                       stride):
                            for c in range(channels):
                                gathered[i, j, c] = codes[j, y, x, c]
                            i += 1
            i = 0
            for cx in range(cols):
                if not todo[cy, cx]:
                    continue
                for x in range(cx * cell + stride // 2, min(width, (cx + 1) * cell), stride):
                    sample = gathered[i]
                    i += 1
                    for k in range(count):  # not known[:] = -1: less to compile
                        known[k] = -1
                    for c in range(channels):
                        z = sample[reference, c]
                        start_var[c] = variance[reference, c, z]
                        start_bounded[c] = False
                        if np.isfinite(start_var[c]):
                            if resampled:
                                start_low[c], start_high[c] = _local_range(
                                    codes, estimates, variance, reference, y, x, c)
                            else:
                                start_low[c] = start_high[c] = estimates[reference, c, z]
                        elif np.isfinite(dark_variance[reference, c, z]):
                            start_var[c] = dark_variance[reference, c, z]
                            start_bounded[c] = True
                            start_low[c] = -np.inf
                            start_high[c] = dark_bound[reference, c, z]
                    for direction in (-1, 1):
                        # Element by element: `low[:] = start_low` would compile numba's
                        # shape-mismatch message (string formatting: 2.8 s of a first run).
                        for c in range(channels):
                            low[c] = start_low[c]
                            high_e[c] = start_high[c]
                            chain_var[c] = start_var[c]
                            chain[c] = reference
                            bounded[c] = start_bounded[c]
                        j = reference + direction
                        while 0 <= j < count:
                            total = 0.0
                            used = 0
                            for c in range(channels):
                                z = sample[j, c]
                                v = variance[j, c, z]
                                if not np.isfinite(v):
                                    continue  # clipped or black here: says nothing
                                e = estimates[j, c, z]
                                if np.isfinite(chain_var[c]):
                                    d = max(0.0, e - high_e[c], low[c] - e)
                                    d2 = d * d / (v + chain_var[c])
                                    # (A bound's bracket is black there by definition.)
                                    if d2 > suspect and (
                                            _near(codes, j, y, x, black, high, CLIP_RADIUS,
                                                  known)
                                            or not bounded[c] and _near(
                                                codes, chain[c], y, x, black, high,
                                                CLIP_RADIUS, known)):
                                        continue  # next to clipping: says nothing
                                    total += min(d2, cap)
                                    used += 1
                                    if not bounded[c] or d2 > suspect:
                                        continue
                                    bounded[c] = False  # within the dark bound
                                elif direction < 0:  # a shorter bracket for a clipped one
                                    takeovers[j, cy, cx] += 1
                                # j takes over as the reference here.
                                chain_var[c] = v
                                chain[c] = j
                                if resampled:
                                    low[c], high_e[c] = _local_range(
                                        codes, estimates, variance, j, y, x, c)
                                else:
                                    low[c] = high_e[c] = e
                            sums[j, cy, cx] += total
                            counts[j, cy, cx] += used
                            j += direction


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
        smooth = max(1.0, levels / 128.0)
        for c in range(channels):
            weight = scipy.ndimage.gaussian_filter1d(counts[c], smooth, mode="nearest")
            total = scipy.ndimage.gaussian_filter1d(sums[c], smooth, mode="nearest")
            known = weight > 4
            if not known.any():
                continue
            bias = np.interp(np.arange(levels), np.flatnonzero(known),
                             total[known] / weight[known])
            corrected[j, c] *= np.exp(-bias)
    return corrected


@dataclass
class Deghosting:
    """Per-bracket keep weights on a grid of cells.

    Attributes
    ----------
    keep
        ``(P, rows, cols)`` float32 in [0, 1], cell centres at ``(i + 0.5) * cell``;
        1 everywhere for the reference.
    cell
        Cell side, pixels.
    reference
        The reference bracket.
    fraction
        Fraction of the image's pixels where some bracket was dropped for motion
        (weight below 1; borders a warp does not cover are not counted).
    """

    keep: np.ndarray
    cell: int
    reference: int
    fraction: float

    def motion_mask(self, height: int, width: int) -> np.ndarray:
        """``(H, W)`` float32: ``1 - min_j keep_j`` at full resolution (the EXR layer)."""
        low = 1.0 - self.keep.min(axis=0)
        zoom = scipy.ndimage.zoom(low, self.cell, order=1, grid_mode=True,
                                  mode="nearest")
        out = np.zeros((height, width), np.float32)
        h, w = min(height, zoom.shape[0]), min(width, zoom.shape[1])
        out[:h, :w] = zoom[:h, :w]
        return np.clip(out, 0.0, 1.0)


def dark_bounds(estimates: np.ndarray, variance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(bound, bound_variance)``, ``(P, C, levels)``: for each code below a bracket's
    usable codes (``variance`` infinite there), the estimate and variance of its first
    usable code, which bounds the radiance from above; ``nan`` and ``inf`` elsewhere."""
    bound = np.full(variance.shape, np.nan)
    bound_variance = np.full(variance.shape, np.inf)
    usable = np.isfinite(variance)
    for j in range(variance.shape[0]):
        for c in range(variance.shape[1]):
            first = np.flatnonzero(usable[j, c])
            if first.size:
                bound[j, c, :first[0]] = estimates[j, c, first[0]]
                bound_variance[j, c, :first[0]] = variance[j, c, first[0]]
    return bound, bound_variance


def deghost(codes: np.ndarray, estimates: np.ndarray, variance: np.ndarray, reference: int,
            coverage: np.ndarray | None = None, cell: int = CELL,
            threshold: float = THRESHOLD, resampled: bool = True) -> Deghosting:
    """Keep weights for every bracket of ``codes`` against bracket ``reference``.

    Parameters
    ----------
    codes
        ``(P, H, W, C)`` code values, aligned, sorted by exposure.
    estimates
        ``(P, C, levels)``: ``x_j(z) = f^-1(z) / dt_j``, relative radiance.
    variance
        ``(P, C, levels)``: the variance of each estimate (relative radiance squared);
        ``inf`` where a code says nothing (clipped, black).
    reference
        The bracket the others are tested against (never dropped for motion):
        :func:`hdrio.align.registration.best_exposed_bracket`. It need not be the bracket
        the others were aligned to; if it was warped, its own uncovered cells still go.
    coverage
        ``(P, rows, cols)`` cells each warped bracket covers (1) or not (0; 1 for the
        bracket the others were aligned to), or ``None``.
    resampled
        Whether the brackets were warped (then each is tested against the reference's
        3x3 range, not its pixel).
    """
    count, height, width, _ = codes.shape
    rows, cols = -(-height // cell), -(-width // cell)
    variance = np.ascontiguousarray(variance, np.float64)
    estimates = comparametric_correction(codes, estimates, variance, reference)
    dark_bound, dark_variance = dark_bounds(estimates, variance)
    code_max = int(variance.shape[2]) - 1  # the tables have a row per code value
    _, high = well_exposed_codes(code_max)
    black = int(BLACK * code_max)

    def test(size: int, stride: int, todo: np.ndarray):
        shape = (count, *todo.shape)
        sums, counts, takeovers = np.zeros(shape), np.zeros(shape, np.int64), \
            np.zeros(shape, np.int64)
        # Staged brackets: a band of cell rows at a time, each band's pages given back
        # after it, so what the test maps does not grow with the bracket count (9 x 24
        # MP: the process peaked at 790 MB here, its merge at 600).
        rows_of_cells = todo.shape[0]
        band = -(-rows_of_cells // TEST_BANDS) if is_staged(codes) else rows_of_cells
        for first in range(0, rows_of_cells, band):
            last = min(rows_of_cells, first + band)
            on_threads(lambda start, stop, *rest, first=first: _consistency(
                first + start, first + stop, *rest),
                       last - first, codes, estimates, variance, dark_bound, dark_variance,
                       reference, size, stride, CAP, resampled, black, high, SUSPECT, todo,
                       sums, counts, takeovers)
            release(codes, None, 0, min(height, last * size))
        return sums / np.maximum(counts, 1), counts, takeovers

    # A quick look first (:data:`COARSE`): cells that many times wider, samples that many
    # times sparser (the same count a cell). Its median cell says how far the noise model
    # under-states the noise (about 1 when it is right; 4.9 for frobisher's 1/8 s JPEG
    # against its 8 s); the threshold is raised by that factor, up to SCALED_MAX (a moving
    # object's cells sit near CAP). Only the coarse cells where a few samples disagree
    # (mean above QUICK, so raised), and their neighbours, are tested finely: on a still
    # stack, none.
    stride = max(STRIDE * COARSE, int(math.sqrt(height * width / QUICK_SAMPLES)))
    size = stride * cell // STRIDE  # the fine test's samples a cell
    coarse, coarse_counts, _ = test(size, stride,
                                    np.ones((-(-height // size), -(-width // size)), bool))
    coarse_judged = coarse_counts >= MIN_SAMPLES
    scale = np.ones(count)
    for j in range(count):
        if coarse_judged[j].any():
            scale[j] = max(1.0, float(np.median(coarse[j][coarse_judged[j]])))
    limits = np.minimum(SCALED_MAX, threshold * scale)
    suspect = (coarse > (QUICK * scale)[:, None, None]) & coarse_judged
    suspect[reference] = False
    suspect = scipy.ndimage.binary_dilation(suspect.any(axis=0), np.ones((3, 3), bool))
    # Fine cells touching a suspect coarse one.
    fine_rows = np.minimum(np.arange(rows) * cell // size, suspect.shape[0] - 1)
    fine_cols = np.minimum(np.arange(cols) * cell // size, suspect.shape[1] - 1)
    last_rows = np.minimum((np.arange(rows) * cell + cell - 1) // size, suspect.shape[0] - 1)
    last_cols = np.minimum((np.arange(cols) * cell + cell - 1) // size, suspect.shape[1] - 1)
    todo = (suspect[fine_rows][:, fine_cols] | suspect[last_rows][:, last_cols]
            | suspect[fine_rows][:, last_cols] | suspect[last_rows][:, fine_cols])
    keep = np.ones((count, rows, cols), np.float32)
    if not todo.any():  # nothing disagrees anywhere (a still stack): no fine test
        if coverage is not None:
            keep *= coverage
        return Deghosting(keep, cell, reference, 0.0)
    mean, counts, takeovers = test(cell, STRIDE, np.ascontiguousarray(todo))
    judged = counts >= MIN_SAMPLES
    flagged = (mean > limits[:, None, None]) & judged
    flagged[reference] = False
    moved = np.zeros((rows, cols), bool)
    for j in range(count):
        if not flagged[j].any():
            continue
        grown = scipy.ndimage.binary_dilation(flagged[j], np.ones((3, 3), bool))
        soft = scipy.ndimage.gaussian_filter(grown.astype(np.float32), 1.0, mode="nearest")
        drop = np.maximum(grown, np.clip(2.0 * soft, 0.0, 1.0))
        drop[drop < 0.02] = 0.0
        # Where a shorter j stands in for a clipped reference it is the scene's only
        # observation: growing and feathering must not drop it there. (Not for a longer
        # j under a dark reference: dark clothes fall below the usable codes, and the
        # background a longer bracket shows there is a ghost.)
        drop[(takeovers[j] > counts[j]) & ~flagged[j]] = 0.0
        keep[j] = 1.0 - drop
        moved |= drop > 0
    if coverage is not None:
        keep *= coverage
    fraction = float(np.count_nonzero(moved)) / moved.size
    return Deghosting(keep, cell, reference, fraction)


def consistency_variance(response, exposures: np.ndarray, noise=None) -> np.ndarray:
    """The variance the consistency test allows each ``x_j(z) = f^-1(z) / dt_j``,
    ``(P, C, levels)``, relative radiance squared.

    The stack's noise model (:func:`hdrio.radiometry.noise.observation_variance`: shot, read
    and code noise, JPEG's floor) plus 3 % of the value for the response's own error,
    which the noise model leaves out and which two brackets see alike only where the
    curve is right; codes at ``Z_max`` and below the well-exposed range
    (:data:`hdrio.skips.WELL_EXPOSED`: where a solved ``g`` is extrapolated and noise
    dominates) say nothing (``inf``). Without a noise model, rounding of the codes alone.
    """
    from hdrio.radiometry.noise import NoiseModel, observation_variance

    code_max = response.code_max
    low, _ = well_exposed_codes(code_max)
    if noise is None:
        noise = NoiseModel.quantisation_only(response.channels)
    exposure = np.exp(response.log_inverse)  # (levels, C): f^-1(z)
    dt = np.asarray(exposures, np.float64)[:, None, None]
    variance = observation_variance(response, exposures, noise) \
        + (0.03 * exposure.T[None]) ** 2 / dt**2
    variance[:, :, :low] = np.inf
    variance[:, :, code_max] = np.inf
    return np.ascontiguousarray(variance)
