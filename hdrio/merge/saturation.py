"""Saturation policies: which observations near the top of the code range the merge drops.

A camera clips its *raw* channels at the sensor's white level, then white-balances and
mixes them with its colour matrix before the response curve. Once one raw channel has
clipped, every output channel of that pixel is wrong, and most of them are below the top
code: dropping only the codes at ``Z_max`` (``channel``) keeps those biased observations
and gives partly clipped highlights a false hue (the orange and yellow-green bands at a
clipped cloud's edge). On brackets rendered through such a camera
(:func:`hdrio.tools.synthetic.render_camera_brackets`: the 5D Mark II's matrix) the hue error
on clip-transition pixels reaches p99 90 degrees with ``channel``.

``auto`` (the default)
    ``safe`` where the stack shows its channels mixed after the clip
    (:func:`channel_mixing` inside clips, :func:`clip_interior`: a partly clipped
    observation's unclipped channels disagree with the shorter bracket's), else per
    channel (as ``channel``) at the white levels less the noise margin. On the truth
    harness's renders (no mixing) the pixel rule costs accuracy for nothing: their
    channels are right to keep (JPEG stacks' median error 3.93 % per channel, 4.24 %
    with the pixel rule and the shoulders; ``python -m benchmarks.truth --group jpeg``).
``safe``
    an observation (one bracket at one pixel) counts only where *every* channel is
    safely below clipping: below its own white level, found in the data
    (:func:`white_levels`), by more than the noise model's margin (the shoulder,
    :func:`saturation_limits`). Otherwise the whole observation is dropped, from its
    bracket and every longer one (as the others).
``pixel`` (the tutorial's ``hdr.m``)
    any channel at ``Z_max`` drops the observation.
``channel``
    a channel at ``Z_max`` drops that channel alone: right only for a camera that does
    not mix its channels after the clip (the truth harness's renders).

Pixels dropped even from the shortest bracket (clipped in every bracket) take a neutral
lower bound in the kernel (:func:`hdrio.merge.kernel.merge_kernel`): every channel the
largest of the shortest bracket's estimates, so they carry no colour cast;
``--highlights reconstruct`` (:mod:`hdrio.merge.highlights`) estimates them from their
neighbours' colour instead.
"""

from __future__ import annotations

import numpy as np

from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel
from hdrio.radiometry.noise_fit import noise_grid

SATURATION_POLICIES = ("auto", "safe", "channel", "pixel")

_PILE_UP = 8.0  # a white level's count is this many times its neighbours' median
_TOP_FRACTION = 0.75  # white levels are looked for above this fraction of the code range
_MIN_PILE_FRACTION = 1e-3  # and must hold this fraction of the sampled observations
_MARGIN_SIGMAS = 2.0  # the shoulder: codes within this many sigmas of the white level
_MIXING_SHIFT = 1.0  # partly clipped observations this many spreads off show mixing
_MIXING_COUNT = 50  # observations needed to say so
_SPREAD_FLOOR = 0.01  # the least spread (ln E): codes' rounding, 16-bit data
_INTERIOR_RADIUS = 4  # pixels: partly clipped evidence only where the clip extends this far
MIXING_GRID_LIMIT = 2**16  # pixels sampled for the white levels and the mixing test
_MID = (0.1,)  # the least code (fraction of Z_max) of the channels compared
_BASELINE = (0.25, 0.65)  # codes (fractions of Z_max) whose ln ratio is the reference
_SHOULDER_FROM = 0.7  # shoulders are looked for above this fraction of the range
_SHOULDER_BIAS = 0.10  # a bin of codes off by more than this (ln E) is in the shoulder
_SHOULDER_COUNT = 20  # observations a bin needs


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
        # Channel by channel: np.all(..., axis=-1) over 3 channels costs 10x more.
        safe, clipped = short[:, 0] < limits[0], long[:, 0] >= limits[0]
        for c in range(1, grid.shape[-1]):
            safe &= short[:, c] < limits[c]
            clipped |= long[:, c] >= limits[c]
        yield j, short, long, safe, clipped


def shoulders(grid: np.ndarray, response: CameraResponse, exposures,
              limits: np.ndarray) -> np.ndarray:
    """Where each channel's observations stop agreeing with the shorter bracket's,
    ``(C,)`` codes (``limits`` where they agree up to it).

    Near the top of the range a camera's codes can be off by more than noise: its
    rendering rolls the highlights off, a raw channel clipped in a bracket pulls the
    others through the colour matrix, or the recovered response is wrong there. For each
    channel, observations (``grid`` ``(P, n, C)``, shortest first) whose shorter
    neighbour is safe in every channel are compared with it (``ln`` ratio, less its
    median over codes at 25-65 % of the range) in bins of 1/32 of the range above 70 %;
    the shoulder is the start of the run of top bins (20 observations or more) whose
    median is off by more than 10 %.
    """
    exposures = np.asarray(exposures, dtype=np.float64)
    code_max = response.code_max
    g = response.log_inverse
    width = max(1, (code_max + 1) // 32)
    mid = (int(_BASELINE[0] * code_max), int(_BASELINE[1] * code_max))
    out = np.asarray(limits, dtype=np.int64).copy()
    channels = grid.shape[-1]
    values: list[list[np.ndarray]] = [[] for _ in range(channels)]
    codes: list[list[np.ndarray]] = [[] for _ in range(channels)]
    for j, short, long, safe_short, clipped_long in _pairs(grid, limits):
        both = safe_short & ~clipped_long
        for c in range(channels):
            ok = both & (short[:, c] >= int(_MID[0] * code_max))
            values[c].append((g[long[ok, c], c] - np.log(exposures[j]))
                             - (g[short[ok, c], c] - np.log(exposures[j - 1])))
            codes[c].append(long[ok, c])
    for c in range(channels):
        d, z = np.concatenate(values[c]), np.concatenate(codes[c])
        base = d[(z >= mid[0]) & (z <= mid[1])]
        if base.size < _SHOULDER_COUNT:
            continue
        d = d - np.median(base)
        start = int(_SHOULDER_FROM * code_max) // width * width
        shoulder = int(limits[c])
        for low in range((int(limits[c]) - 1) // width * width, start - 1, -width):
            inside = d[(z >= low) & (z < min(low + width, int(limits[c])))]
            if inside.size < _SHOULDER_COUNT:
                continue
            if abs(float(np.median(inside))) <= _SHOULDER_BIAS:
                break
            shoulder = low
        out[c] = min(out[c], shoulder)
    return out


def saturation_limits(codes: np.ndarray, response: CameraResponse, noise: NoiseModel,
                      grid: np.ndarray | None = None, exposures=None) -> np.ndarray:
    """The first dropped code of each channel, ``(C,)`` int64: the white level, or lower
    by the shoulder where the exposure ``f^-1(z)`` is within two of its own standard
    deviations (``noise``) of the white level's, or lower still where the data disagree
    with the shorter bracket by more than 10 % (:func:`shoulders`; when ``exposures``,
    seconds, are given).

    ``codes`` ``(P, H, W, C)``; ``grid`` the noise fit's sample (:func:`noise_grid`),
    when already read.
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
    if exposures is not None and grid.shape[0] > 1:
        limits = shoulders(grid, response, exposures, limits)
    return limits


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
        if weight >= _MIXING_COUNT:
            shift = max(shift, total / weight)
    return shift


def policy_limits(policy: str, codes: np.ndarray, response: CameraResponse,
                  noise: NoiseModel | None, exposures=None) -> tuple[np.ndarray, bool]:
    """``(limits, pixel_rule)`` of ``policy`` for the kernel: the first dropped code per
    channel, and whether a dropped channel drops the whole observation.

    ``safe``: the white levels less the noise margin and the shoulders
    (:func:`saturation_limits`), the pixel rule. ``auto``: the same where
    :func:`channel_mixing` (inside clips, :func:`clip_interior`) exceeds 1, else the
    white levels less the noise margin alone, per channel: with the channels kept apart
    the shoulders' codes are worth keeping (on the truth harness's JPEG stacks they cost
    0.06 points of median error). Without ``exposures`` (seconds) or with one bracket,
    as ``safe`` without the shoulders.
    """
    if policy not in SATURATION_POLICIES:
        raise ValueError(f"saturation policy must be one of {SATURATION_POLICIES}, "
                         f"not {policy!r}")
    channels = codes.shape[-1]
    if policy in ("channel", "pixel"):
        return np.full(channels, response.code_max, np.int64), policy == "pixel"
    if noise is None:
        noise = NoiseModel.quantisation_only(channels)
    grid = noise_grid(codes, MIXING_GRID_LIMIT)
    limits = saturation_limits(codes, response, noise, grid)
    if exposures is None or codes.shape[0] < 2:
        return limits, True
    if policy == "auto":
        # The mixing test at the white levels: the shoulders would take away its evidence.
        interior = clip_interior(codes, limits, grid=grid)
        if channel_mixing(grid, response, exposures, limits, interior) <= _MIXING_SHIFT:
            return limits, False
    return shoulders(grid, response, exposures, limits), True
