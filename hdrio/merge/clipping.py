"""What a stack shows about its clipping: white levels, the noise margin, where the clip
test starts, and whether the camera mixed its channels after the clip.

Measured on a regular grid of at most :data:`MIXING_GRID_LIMIT` pixels of every bracket
(:func:`hdrio.radiometry.noise.noise_grid`); :mod:`hdrio.merge.saturation` decides the policy
from these measures and :mod:`hdrio.radiometry.cliptest` applies it.
"""

from __future__ import annotations

import numpy as np

from hdrio.radiometry.cliptest import ClipTables
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel
from hdrio.radiometry.noise_fit import grid_stride, noise_grid
from hdrio.stack import every_channel, some_channel

_PILE_UP = 8.0  # a white level's count is this many times its neighbours' median
_TOP_FRACTION = 0.75  # white levels are looked for above this fraction of the code range
_MIN_PILE_FRACTION = 1e-3  # and must hold this fraction of the sampled observations
_MARGIN_SIGMAS = 2.0  # the margin: codes within this many sigmas of the white level
_GATE = 0.9  # observations with a channel at this fraction of its white level's exposure
_SURELY_CLIPPED = 2.0  # predicted at this multiple of the white level's exposure: clipped
_GATE_PERCENTILE = 5.0  # the gate: this percentile of the codes of clipped observations
MIXING_COUNT = 50  # observations needed to say so
_SPREAD_FLOOR = 0.01  # the least spread (ln E): codes' rounding, 16-bit data
_INTERIOR_RADIUS = 4  # pixels: partly clipped evidence only where the clip extends this far
MIXING_GRID_LIMIT = 2**16  # pixels sampled for the white levels and the mixing test
_MID = (0.1,)  # the least code (fraction of Z_max) of the channels compared


def unexcluded(shape: tuple[int, ...], exclude: np.ndarray | None,
               limit: int = MIXING_GRID_LIMIT) -> np.ndarray | None:
    """``(n,)`` booleans on the grid of :func:`~hdrio.radiometry.noise.noise_grid` of codes
    of ``shape`` ``(P, H, W, C)`` (at most ``limit`` pixels): the pixels no bracket
    excludes (``exclude``: ``(P, H, W)`` or ``(H, W)``, ``--mask`` and ``--exclude-color``),
    or ``None`` when nothing is excluded. What the user masked out is no evidence of a
    clip: a masked block of one colour piled up at a code, as a white level below it."""
    if exclude is None:
        return None
    count, height, width = shape[:3]
    stride = grid_stride(height, width, limit)
    held = np.broadcast_to(exclude, (count, height, width))[:, ::stride, ::stride]
    return ~held.reshape(count, -1).any(axis=0)


def white_levels(grid: np.ndarray, code_max: int) -> np.ndarray:
    """Each channel's white level (code), ``(C,)`` int64, from sampled codes ``(P, n, C)``.

    A clipped channel piles up at one code: ``Z_max`` for most files, lower where the
    camera's white balance scaled the raw white level below the top code. The white level
    is ``Z_max`` when it holds at least 0.1 % of the observations; otherwise the code of
    the largest pile-up above 75 % of the range (at least 8 times the median count of the
    8 codes below it, and 0.1 % of the observations); otherwise ``Z_max``.
    """
    channels = grid.shape[-1]
    levels = np.full(channels, code_max, dtype=np.int64)
    for c in range(channels):
        codes = grid[..., c].reshape(-1)
        counts = np.bincount(codes, minlength=code_max + 1).astype(np.float64)
        least = _MIN_PILE_FRACTION * codes.size
        if counts[code_max] >= least or codes.size == 0:
            continue
        start = max(int(_TOP_FRACTION * code_max), 8)
        best = 0.0
        for z in range(start, code_max):
            below = np.median(counts[z - 8:z])
            if counts[z] >= least and counts[z] >= _PILE_UP * max(below, 1.0) \
                    and counts[z] > best:
                best, levels[c] = counts[z], z
    return levels


def _pairs(grid: np.ndarray, limits: np.ndarray):
    """Each pair of neighbouring brackets of ``grid`` ``(P, n, C)``: ``(j, shorter,
    longer, shorter safe in every channel, longer at or above a limit in some channel)``."""
    for j in range(1, grid.shape[0]):
        short, long = grid[j - 1].astype(np.intp), grid[j].astype(np.intp)
        yield (j, short, long, every_channel(short, np.less, limits),
               some_channel(long, np.greater_equal, limits))


def saturation_limits(codes: np.ndarray, response: CameraResponse, noise: NoiseModel,
                      grid: np.ndarray | None = None) -> np.ndarray:
    """The first dropped code of each channel, ``(C,)`` int64: the white level
    (:func:`white_levels`, where the codes pile up), less the margin where the exposure
    ``f^-1(z)`` is within two of its own standard deviations (``noise``) of the white
    level's (the noise that would have taken such a code past the clip was cut off).

    ``codes`` ``(P, H, W, C)``; ``grid`` the noise fit's sample (:func:`noise_grid`),
    when already read. No code below that is called a white level: a camera's soft
    shoulder, codes that run smoothly to the top, is its response, which the solve
    recovers; what a clip did to the observations below it is the clip test's
    (:mod:`hdrio.radiometry.cliptest`), one observation at a time.
    """
    grid = noise_grid(codes) if grid is None else grid
    white = white_levels(grid, response.code_max)
    X = np.exp(response.log_inverse)
    sigma = np.sqrt(noise.exposure_variance(response))
    limits = white.copy()
    for c, level in enumerate(white):
        z = int(level)
        while z > 1 and X[level, c] - X[z - 1, c] <= _MARGIN_SIGMAS * sigma[z - 1, c]:
            z -= 1
        limits[c] = z
    return limits


def clip_gates(response: CameraResponse, grid: np.ndarray, limits: np.ndarray,
               exposures) -> np.ndarray:
    """``(C,)`` codes from which an observation is *near the clip* and tested
    (:mod:`hdrio.radiometry.cliptest`), at most ``limits``: the lower of two codes.

    * The least code whose exposure ``f^-1(z)`` is 90 % of the white level's
      (:func:`white_levels` of ``grid``): a raw channel that clipped before the colour
      matrix can leave its own output channel a little below the top code (a matrix
      row with a positive off-diagonal term: 0.25 of blue in the 5D Mark II's red).
    * The 5th percentile of the codes of observations that the next shorter bracket
      says are clipped (its unclipped code, times the exposure ratio, twice the white
      level's exposure or more), where there are 50 of them: a JPEG's ringing and
      chroma put the codes of a clipped channel below its limit next to a clip's edge
      (on the hand-held hdrtoolbox stack, 10-17 % of them below 252, the 5th percentile
      240-247).
    """
    X = np.exp(response.log_inverse)
    exposures = np.asarray(exposures, dtype=np.float64)
    white = white_levels(grid, response.code_max)
    gates = np.asarray(limits, np.int64).copy()
    for c in range(X.shape[1]):
        above = np.flatnonzero(X[:, c] >= _GATE * X[white[c], c])
        if above.size:
            gates[c] = min(gates[c], int(above[0]))
        clipped = []
        for j in range(1, grid.shape[0]):
            shorter = grid[j - 1, :, c]
            predicted = X[shorter, c] * (exposures[j] / exposures[j - 1])
            sure = (predicted >= _SURELY_CLIPPED * X[white[c], c]) & (shorter < limits[c])
            clipped.append(grid[j, sure, c])
        clipped = np.concatenate(clipped)
        if clipped.size >= MIXING_COUNT:
            gates[c] = min(gates[c], int(np.percentile(clipped, _GATE_PERCENTILE)))
    return gates


def clip_interior(codes: np.ndarray, limits: np.ndarray, limit: int = MIXING_GRID_LIMIT,
                  radius: int = _INTERIOR_RADIUS, grid: np.ndarray | None = None
                  ) -> np.ndarray:
    """``(P, n)`` booleans on the grid of :func:`noise_grid` (``codes`` ``(P, H, W, C)``,
    at most ``limit`` pixels): true in the first bracket where the pixel has a channel at
    or above its ``limits`` (codes), when that is not the shortest bracket and some
    channel is still below (partly clipped), and the clip pattern (which channels are
    at or above their limits) is the same at the 8 pixels ``radius`` away in that
    bracket (rows, columns, diagonals; clamped at the image's edge).

    A clip's edge is where a lossy codec biases the unclipped channels: JPEG's 4:2:0
    chroma and its 8 x 8 transform blocks mix a pixel with its neighbours, so next to a
    clipped pixel the others take some of its false colour. Inside a clip nothing
    differs to mix, while a camera's colour matrix biases every partly clipped pixel.
    Only the partly clipped pixels' neighbours are read, in that one bracket; ``grid``
    is ``noise_grid(codes, limit)`` when already read.
    """
    from hdrio.io.staging import candidate_stride, gather_pixels

    count, height, width, channels = codes.shape
    stride = candidate_stride(height, width, limit)
    rows, cols = np.arange(0, height, stride), np.arange(0, width, stride)
    y, x = (a.reshape(-1) for a in np.meshgrid(rows, cols, indexing="ij"))
    limits = np.asarray(limits, dtype=np.int64)

    def pattern(grid: np.ndarray) -> np.ndarray:  # (P, m, C) codes -> (P, m) bit sets
        bits = np.zeros(grid.shape[:2], dtype=np.uint64)
        for c in range(channels):
            bits |= (grid[..., c] >= limits[c]).astype(np.uint64) << np.uint64(c)
        return bits

    centre = pattern(gather_pixels(codes, y * width + x) if grid is None else grid)
    # The one pair that counts: the first bracket with a channel at its limit, if it is
    # not the shortest and does not have every channel there (nothing left to compare).
    first = np.argmax(centre > 0, axis=0)
    at_first = np.take_along_axis(centre, first[None], axis=0)[0]
    picked = (first > 0) & (at_first != (1 << channels) - 1)
    out = np.zeros(centre.shape, dtype=bool)
    for j in range(1, count):
        pick = np.flatnonzero(picked & (first == j))
        same = np.ones(pick.size, dtype=bool)
        for dy in (-radius, 0, radius):
            for dx in (-radius, 0, radius):
                if pick.size and (dy or dx):
                    index = (np.clip(y[pick] + dy, 0, height - 1) * width
                             + np.clip(x[pick] + dx, 0, width - 1))
                    same &= pattern(gather_pixels(codes[j:j + 1], index))[0] \
                        == centre[j, pick]
        out[j, pick] = same
    return out


def channel_mixing(grid: np.ndarray, response: CameraResponse, exposures,
                   limits: np.ndarray, interior: np.ndarray | None = None) -> float:
    """How far a partly clipped observation's other channels are from the next shorter
    bracket's, in spreads of the unclipped observations of the same codes: about 0.1
    when the camera keeps its channels apart, 2 to 80 when it mixes them after the clip.

    ``grid`` ``(P, n, C)`` sampled codes, shortest first; ``interior`` ``(P, n)``
    (:func:`clip_interior`) keeps only partly clipped observations inside a clip as
    evidence (a lossy codec's bias at a clip's edge is not the camera's). For each pair
    of neighbouring brackets, pixels whose shorter bracket is safe in every channel are
    compared channel by channel (``ln`` ratio of the exposures ``f^-1(z) / t``) where the
    longer bracket's code of that channel lies from 10 % of the range up to its limit,
    in bins of 1/16 of the range. In each bin with 10 of each, the bin's score is the
    distance between the medians of the partly clipped observations (another channel
    at or above its limit in the longer bracket) and of the unclipped ones, over the
    unclipped ones' spread (1.4826 median absolute deviation, at least 0.01). The
    statistic is the largest, over channels, of the count-weighted mean of the bins'
    scores; 0 when no channel has 50 partly clipped observations to compare (nothing
    clips part-way: no evidence of mixing).
    """
    if grid.shape[0] < 2:
        return 0.0
    exposures = np.asarray(exposures, dtype=np.float64)
    code_max = response.code_max
    low = int(_MID[0] * code_max)
    width = max(1, (code_max + 1) // 16)
    g = response.log_inverse
    channels = grid.shape[-1]
    values: list[list[np.ndarray]] = [[] for _ in range(channels)]
    partly: list[list[np.ndarray]] = [[] for _ in range(channels)]
    codes: list[list[np.ndarray]] = [[] for _ in range(channels)]
    for j, short, long, safe_short, clipped_long in _pairs(grid, limits):
        ok_pixel = safe_short if interior is None else safe_short & (~clipped_long
                                                                       | interior[j])
        for c in range(channels):
            ok = ok_pixel & (short[:, c] >= low) & (long[:, c] >= low) \
                & (long[:, c] < limits[c])
            values[c].append((g[long[ok, c], c] - np.log(exposures[j]))
                             - (g[short[ok, c], c] - np.log(exposures[j - 1])))
            codes[c].append(long[ok, c])
            partly[c].append(clipped_long[ok])
    shift = 0.0
    for c in range(channels):
        d, p = np.concatenate(values[c]), np.concatenate(partly[c])
        b = np.concatenate(codes[c]) // width
        total = weight = 0.0
        for k in np.unique(b[p]):
            here = b == k
            dp, dq = d[here & p], d[here & ~p]
            if dp.size < 10 or dq.size < 10:
                continue
            centre = float(np.median(dq))
            spread = max(1.4826 * float(np.median(np.abs(dq - centre))), _SPREAD_FLOOR)
            total += dp.size * abs(float(np.median(dp)) - centre) / spread
            weight += dp.size
        if weight >= MIXING_COUNT:
            shift = max(shift, total / weight)
    return shift


_SPREAD_SAMPLES = 50  # clean pairs a spread needs


def test_spreads(grid: np.ndarray, tables: ClipTables, gates: np.ndarray) -> np.ndarray:
    """``(P, C)``, at least 1: how far clean observations of bracket ``j`` (no channel of
    it or of bracket ``j - 1`` at or above its gate) disagree with bracket ``j - 1``'s, in
    the clip test's standard deviations (:mod:`hdrio.radiometry.cliptest`): the robust spread
    (median absolute value over 0.6745) of ``(x_j - x_{j-1}) / sqrt(var x_j + var
    x_{j-1})`` over codes above 5 % of the range in both. Row 0, and a pair with fewer
    than 50 such observations, 1.

    The noise model can leave noise out (a fit that finds no shot or read noise: on the
    truth harness's StillLife stack the blue channel's clean pairs disagree by 4-7
    standard deviations of its codes' rounding alone), and a solved response is a few
    percent off at some codes; measured on the same stack, this is the disagreement that
    noise and the response explain, which the test allows.
    """
    count, _, channels = grid.shape
    estimates, variances = tables.estimates, tables.variances
    low = 0.05 * (estimates.shape[2] - 1)
    spreads = np.ones((count, channels))
    for j in range(1, count):
        longer, shorter = grid[j].astype(np.intp), grid[j - 1].astype(np.intp)
        clean = np.all(longer < gates, axis=-1) & np.all(shorter < gates, axis=-1)
        for c in range(channels):
            ok = clean & (longer[:, c] > low) & (shorter[:, c] > low)
            if np.count_nonzero(ok) < _SPREAD_SAMPLES:
                continue
            z, y = longer[ok, c], shorter[ok, c]
            t = (estimates[j, c, z] - estimates[j - 1, c, y]) / np.sqrt(
                variances[j, c, z] + variances[j - 1, c, y])
            spreads[j, c] = max(1.0, float(np.median(np.abs(t))) / 0.6745)
    return spreads
