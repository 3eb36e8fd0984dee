"""The disagreement of each bracket with a reference, per cell: what deghosting reads.

Each bracket's estimate ``x_j(z) = f^-1(z) / dt_j`` (relative radiance) is tested against
the reference bracket's, per channel, with the variance of both estimates (the noise
model's disagreement view, ``(P, C, levels)``, relative radiance squared:
:func:`hdrio.align.comparametric.consistency_variance`): ``d^2 = (x_j - x_r)^2 / (var_j +
var_r)``, about 1 on average for a still scene. Where the reference is clipped in a
channel, the nearest bracket towards ``j`` that is not takes over as the reference there
(a bright window is
tested against the shorter brackets). Where it is black, it bounds the radiance from
above, and the nearest bracket within that bound takes over (a dark corner is tested
against the longer brackets; dark clothes in front of a brighter floor are not replaced
by the floor). A systematic, code-dependent disagreement (the response's error) is
divided out first (:func:`hdrio.align.comparametric.comparametric_correction`).

:func:`cell_disagreement` returns, per bracket and cell of ``size`` pixels (on every
``stride``-th pixel), the mean of the samples' capped ``d^2``: noise averages out in a
cell, a moving object does not. (Split from :mod:`hdrio.align.deghost`, which decides
from these what to keep.)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from hdrio.align.comparametric import bounds, comparametric_correction
from hdrio.io.staging import is_staged, release
from hdrio.jit import INNER
from hdrio.parallel import on_threads
from hdrio.radiometry.cliptest import dropped_channels_call
from hdrio.skips import well_exposed_codes

CAP = 100.0
"""Each sample's ``d^2`` is capped here, so a few outliers (an edge, a hot pixel) cannot
flag a cell alone: it takes at least 5 % of a cell's samples far out."""
SUSPECT = 4.0
"""A sample's ``d^2`` above this (two standard deviations) is looked at more closely: is
some channel clipped nearby (:data:`CLIP_RADIUS`)?"""
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
BENT = 6.0
"""... but only a sample within this factor of the reference's: a camera bends a
channel next to a clip by up to a factor 2 (that sill; at its edge, where the 8 s
frame blooms, up to 5), a mover far darker or brighter than what it hides is motion
even there (in a scene with clipped texture everywhere, a stained-glass window, such
samples were all left out and movers kept)."""


class Tables(NamedTuple):
    """The test's per-code tables, ``(P, C, levels)`` each: the (corrected) estimates,
    their variance (``inf`` where a code says nothing), and for codes below or above a
    bracket's usable ones the bound on the radiance and its variance (:func:`bounds`)."""

    estimates: np.ndarray
    variance: np.ndarray
    dark_bound: np.ndarray
    bright_bound: np.ndarray
    bound_variance: np.ndarray


class Rules(NamedTuple):
    """How the samples are read and judged (see :func:`_consistency`)."""

    reference: int
    cell: int
    stride: int
    cap: float
    resampled: bool
    black: int
    high: int
    suspect: float


class Tallies(NamedTuple):
    """``(P, rows, cols)``: sums and counts of the capped ``d^2``, the samples where a
    shorter bracket stood in for a clipped reference, and those off by more than
    :data:`EFFECT`."""

    sums: np.ndarray
    counts: np.ndarray
    takeovers: np.ndarray
    fars: np.ndarray


EFFECT = 1.5
"""A sample whose estimate is off the reference's by more than this factor is *far*:
:func:`cell_disagreement` says what fraction of a cell's are (noise can make a bright,
clean sample many sigmas off by 20 %; a moving object is off by a factor)."""
TEST_BANDS = 16
"""Bands of cell rows a test of staged brackets runs in (each band's pages given back)."""


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
def _clip_edge(codes, j, y, x, high, radius):  # pragma: no cover - compiled
    """Whether bracket ``j`` has a pixel with every channel at most ``high`` within
    ``radius`` of ``(y, x)``: a clipped pixel there is at the edge of its clip, where a
    camera blooms and JPEG rings."""
    height, width, channels = codes.shape[1], codes.shape[2], codes.shape[3]
    for yy in range(max(0, y - radius), min(height, y + radius + 1)):
        for xx in range(max(0, x - radius), min(width, x + radius + 1)):
            below = True
            for c in range(channels):
                below &= codes[j, yy, xx, c] <= high
            if below:
                return True
    return False


@njit(nogil=True, **INNER)
def _near(codes, j, y, x, black, high, radius, known):  # pragma: no cover - compiled
    """:func:`_clipped_near`, remembered in ``known[j]`` (-1: not yet asked) for one sample."""
    if known[j] < 0:
        known[j] = 1 if _clipped_near(codes, j, y, x, black, high, radius) else 0
    return known[j] == 1


@njit(cache=True, nogil=True)
def _consistency(start, stop, codes, tables, clip, rules, todo,
                 tallies):  # pragma: no cover - compiled
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
    code's variance; :func:`bounds`); where it is above them, at least ``bright_bound``
    (its last usable code's). A bracket is tested against that bound, and the first one
    within it takes over as the reference there; where a shorter one took over for a
    clipped reference, the longer brackets are tested against it, not against the
    clip's bound (a dark object in front of a window that only the longest bracket
    shows unclipped passed "at least this bright", bent the re-solved response and was
    two thirds missed). (Dark clothes under a dark reference:
    the brighter background a shorter or longer bracket shows there is a ghost; taken
    over untested it merged channel by channel with the reference's, in coloured
    speckle. A dark object that only a short bracket shows where the reference is
    clipped is a ghost too: kept, it appeared twice.)

    A row of samples is gathered from every bracket first, bracket by bracket along the
    row (loads only: the reads miss the cache, and the prefetcher follows a stride), then
    tested; reading every bracket at each sample in turn waited on memory at each.

    An observation the merge's saturation policy drops whole (``clip``,
    :meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`;
    :func:`hdrio.radiometry.cliptest.dropped_channels`: a clip before the camera's colour
    matrix bent its other channels) says nothing about motion: the merge never reads it.
    Such a bracket is passed over in the chain, and a sample whose reference's
    observation is one is left out. (A candle's flame through a camera that mixes its
    channels after the clip "moved", and its re-merge took the flame's hue from a bent
    bracket: 78 degrees of hue error where the merge alone has 4.)

    ``tables`` (:class:`Tables`), ``rules`` (:class:`Rules`) and ``tallies``
    (:class:`Tallies`, added to) group the arrays and settings."""
    estimates, variance, dark_bound, bright_bound, bound_variance = tables
    limits, gates, rule, neutral, clip_estimates, clip_variances, threshold = clip
    whole = (1 << codes.shape[3]) - 1
    reference, cell, stride, cap, resampled, black, high, suspect = rules
    sums, counts, takeovers, fars = tallies
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
    bounded = np.empty(channels, np.bool_)  # the chain's value is a bound
    known = np.empty(count, np.int8)
    by_clip = np.empty(count, np.bool_)  # dropped whole by the clip policy
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
                    for k in range(count):  # one call site: less to compile
                        by_clip[k] = rule != 0 and dropped_channels_call(
                            sample[k], sample[max(k - 1, 0)], 0, k, max(k - 1, 0), limits,
                            gates, rule, neutral, clip_estimates, clip_variances,
                            threshold) == whole
                    if by_clip[reference]:
                        continue  # the reference's observation is bent by a clip
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
                        elif np.isfinite(bound_variance[reference, c, z]):
                            start_var[c] = bound_variance[reference, c, z]
                            start_bounded[c] = True
                            if np.isfinite(dark_bound[reference, c, z]):  # at most
                                start_low[c] = -np.inf
                                start_high[c] = dark_bound[reference, c, z]
                            else:  # at least
                                start_low[c] = bright_bound[reference, c, z]
                                start_high[c] = np.inf
                    for direction in (-1, 1):
                        # Element by element: `low[:] = start_low` would compile numba's
                        # shape-mismatch message (string formatting: 2.8 s of a first run).
                        for c in range(channels):
                            if (direction > 0 and start_bounded[c]
                                    and start_high[c] == np.inf and not bounded[c]):
                                # A shorter bracket took over for a clipped reference:
                                # the longer ones are tested against what it saw, not
                                # against the clip's bound alone.
                                continue
                            low[c] = start_low[c]
                            high_e[c] = start_high[c]
                            chain_var[c] = start_var[c]
                            chain[c] = reference
                            bounded[c] = start_bounded[c]
                        j = reference + direction
                        while 0 <= j < count:
                            if by_clip[j]:
                                j += direction  # bent by a clip: the merge drops it
                                continue
                            total = 0.0
                            used = 0
                            far = 0
                            for c in range(channels):
                                z = sample[j, c]
                                v = variance[j, c, z]
                                if not np.isfinite(v):
                                    # Clipped or black here: j bounds the radiance. A
                                    # chain beyond the bound is inconsistent with it (an
                                    # object the reference shows dark where j, longer,
                                    # clips); j never takes over.
                                    vb = bound_variance[j, c, z]
                                    if not (np.isfinite(vb) and np.isfinite(chain_var[c])):
                                        continue
                                    dark = dark_bound[j, c, z]
                                    bright = bright_bound[j, c, z]
                                    if np.isfinite(dark):
                                        d = max(0.0, low[c] - dark)
                                    else:
                                        d = max(0.0, bright - high_e[c])
                                    d2 = d * d / (vb + chain_var[c])
                                    if d2 > suspect and np.isfinite(bright) and _clip_edge(
                                            codes, j, y, x, high, BRIGHT_RADIUS):
                                        continue  # at the edge of j's clip: says nothing
                                    total += min(d2, cap)
                                    used += 1
                                    far += low[c] > EFFECT * dark or bright > EFFECT * high_e[c]
                                    continue
                                e = estimates[j, c, z]
                                if np.isfinite(chain_var[c]):
                                    d = max(0.0, e - high_e[c], low[c] - e)
                                    d2 = d * d / (v + chain_var[c])
                                    # (A bound's bracket is black there by definition.)
                                    bent = e < BENT * high_e[c] and e * BENT > low[c]
                                    if d2 > suspect and (bent and (
                                            _near(codes, j, y, x, black, high, CLIP_RADIUS,
                                                  known)
                                            or not bounded[c] and _near(
                                                codes, chain[c], y, x, black, high,
                                                CLIP_RADIUS, known))
                                            or bounded[c] and high_e[c] == np.inf
                                            and _clip_edge(codes, chain[c], y, x, high,
                                                           BRIGHT_RADIUS)):
                                        continue  # next to clipping: says nothing
                                    total += min(d2, cap)
                                    used += 1
                                    far += e > EFFECT * high_e[c] or e * EFFECT < low[c]
                                    if not bounded[c] or d2 > suspect:
                                        continue
                                    bounded[c] = False  # within the bound
                                    if direction < 0 and high_e[c] == np.inf:
                                        takeovers[j, cy, cx] += 1  # for a clipped one
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
                            fars[j, cy, cx] += far
                            j += direction


def test_tables(codes: np.ndarray, estimates: np.ndarray, variance: np.ndarray,
                reference: int) -> Tables:
    """The :class:`Tables` of a test against ``reference``: the estimates with the
    response's systematic error divided out (:func:`comparametric_correction`) and the
    bounds of the codes below and above the usable ones (:func:`bounds`)."""
    variance = np.array(variance, np.float64)  # a copy: the codes above are cut below
    # Codes above the well-exposed ones say nothing exact, as those below them do not:
    # they bound the radiance from below (:func:`bounds`). Read as estimates, a JPEG's
    # codes just short of its clip (243-254 of 255, where ringing and a camera's
    # roll-off bend them) made the still speed scene's windows "move": 2-6 % of its 5,
    # 7 and 9 brackets at quality 95 deghosted, none with the cut.
    variance[:, :, well_exposed_codes(variance.shape[2] - 1)[1] + 1:] = np.inf
    estimates = comparametric_correction(codes, estimates, variance, reference)
    return Tables(estimates, variance, *bounds(estimates, variance))


def cell_disagreement(codes: np.ndarray, tables: Tables, clip: tuple, reference: int,
                      size: int, stride: int, todo: np.ndarray, resampled: bool
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per bracket and cell of ``size`` pixels (those ``todo``, ``(rows, cols)``), on
    every ``stride``-th pixel: the mean capped ``d^2`` against ``reference``, the samples
    counted, the takeovers (:class:`Tallies`) and the fraction of samples off by more
    than :data:`EFFECT`, each ``(P, rows, cols)``. ``clip``: the merge's saturation
    policy (:meth:`hdrio.merge.saturation.ClipPolicy.kernel_args`), whose observations
    dropped whole are not tested (:func:`_consistency`).

    Staged brackets are read a band of cell rows at a time (:data:`TEST_BANDS`), each
    band's pages given back after it, so what the test maps does not grow with the
    bracket count (9 x 24 MP: the process peaked at 790 MB here, its merge at 600)."""
    count, height = codes.shape[0], codes.shape[1]
    code_max = int(tables.variance.shape[2]) - 1  # a row per code value
    _, high = well_exposed_codes(code_max)
    rules = Rules(reference, size, stride, CAP, resampled, int(BLACK * code_max), high,
                  SUSPECT)
    shape = (count, *todo.shape)
    tallies = Tallies(np.zeros(shape), np.zeros(shape, np.int64), np.zeros(shape, np.int64),
                      np.zeros(shape, np.int64))
    todo = np.ascontiguousarray(todo, np.bool_)
    rows = todo.shape[0]
    band = -(-rows // TEST_BANDS) if is_staged(codes) else rows
    for first in range(0, rows, band):
        last = min(rows, first + band)
        on_threads(lambda start, stop, *rest, first=first: _consistency(
            first + start, first + stop, *rest), last - first, codes, tables, clip, rules,
                   todo, tallies)
        release(codes, None, 0, min(height, last * size))
    counted = np.maximum(tallies.counts, 1)
    # The sums divided in place (P x cells float64: 21 MB at 24 MP, ten tests a merge).
    return (np.divide(tallies.sums, counted, out=tallies.sums), tallies.counts,
            tallies.takeovers, tallies.fars / counted)


