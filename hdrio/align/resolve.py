"""The aligned sample a response is re-solved on after a warp (alignment's second pass,
:func:`hdrio.align.registration.register`, and deghosting's re-solve on warped brackets:
both :func:`solve_on_sample`): every registered bracket resampled onto the reference's
grid through the same small blur, without the pixels a warp invents or the sharp edges
it cannot resample.

A response solved on brackets that moved mixes scene points at edges; one solved on
brackets that could not be registered mixes whole regions (a hand-held ladder's two
longest, left unwarped, bent the curve by 10 % at code 30), so those are left out; one
solved on warped brackets beside a sharp reference bends at both ends
(:func:`sampled_stack`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numba import njit

from hdrio.align.warp import coverage, warp_codes
from hdrio.errors import HdrioError
from hdrio.io.staging import candidate_stride
from hdrio.parallel import on_threads
from hdrio.radiometry.curve import CameraResponse
from hdrio.skips import well_exposed_codes
from hdrio.stack import ExposureStack

EDGE_CODES = 24.0
"""Pixels whose 3x3 neighbourhood spans more than this (8-bit codes, mean of channels)
in some bracket are not sampled for the re-solve: resampled brackets differ from the
reference at sharp edges, and such samples bent the solved response (merged median
error 0.018-0.024 on the truth stacks; 0.013-0.015 without them; the still stack's
0.012)."""


SAMPLE_POINTS = 2**16
"""Points of the aligned sample at most (:func:`sample_step`): as many as the most that
any of its readers reads (the white levels' and mixing test's grid,
:data:`hdrio.merge.clipping.MIXING_GRID_LIMIT`; the response's sampler reads
:data:`hdrio.io.staging.CANDIDATE_LIMIT` of them). A 24 MP stack's sample had 1.5
million points (its base grid, every fourth pixel), 23 times the most any reader read:
the sample took 0.85 s of a moved 7 x 24 MP merge on 2 cores, 0.35 s now with its nine
taps, and the merge's error against the scene is the same (``python -m
benchmarks.motion``'s solved rows: median 1.148x, p99 1.432x the still stack's, against
1.152x and 1.444x)."""

TAPS = ((-1, 1), (0, 2), (1, 1))
"""The binomial filter each bracket is sampled through, ``(offset, weight)`` each way
(weights sum to 4): see :func:`sampled_stack`."""


LINK_POINTS = 200
"""Points of the aligned sample at which two neighbouring brackets of it must both be
well exposed in every channel for a re-solve to tie them to one curve
(:func:`unlinked`)."""


def sample_step(height: int, width: int) -> int:
    """The aligned sample's grid step on a ``height x width`` stack (:data:`SAMPLE_POINTS`;
    1 up to 65,536 pixels)."""
    return candidate_stride(height, width, SAMPLE_POINTS)


def sampled_stack(stack: ExposureStack, alignment, step: int
                  ) -> tuple[ExposureStack, np.ndarray]:
    """Every ``step``-th pixel of the reference's grid (:func:`sample_step`), each
    registered bracket resampled there through a 3x3 binomial filter (:data:`TAPS`), and
    the ``(h, w)`` mask of pixels not to sample (some bracket does not cover them, or
    they are on a sharp edge: :data:`EDGE_CODES`): a small aligned stack for re-solving
    the response (``alignment``: :class:`~hdrio.align.registration.Alignment`). The
    brackets that could not be registered are left out (while at least two are left).

    The filter: a warped bracket is interpolated between its pixels
    (:func:`~hdrio.align.warp.warp_codes`), which blurs it, and the reference is not. The
    sampler picks each bracket's rarest codes, the darkest and brightest of a texture,
    where a blurred bracket reads nearer the texture's mean than the sharp reference
    does: the curve bends at both ends. Each bracket, the reference included, is read at
    the nine points a pixel apart around each sample (nine warps of the grid, shifted)
    and those codes weighted 1-2-1 each way, so that every bracket is blurred alike (its
    noise variance 0.14 of one pixel's, the sum of the squared weights). A channel at
    its limit at any of the nine is taken as clipped there, else one at 0 as black: the
    filter never makes a clipped code look like a measurement, nor keeps one sharp code
    beside blurred ones. On ``tests/hard_cases.py``'s ``hand_held(7)`` ladders, seeds 0-9, the
    merge's median error went from 1.34-1.67x the still stack's to 1.22-1.32x
    (docs/motion.md, "The re-solve's sample, blurred alike"); with the nearest pixel's
    own 3x3 binomial mean instead (no interpolation), 1.27-1.65x."""
    height, width = stack.shape[:2]
    rows, cols = -(-height // step), -(-width // step)
    kept = sample_brackets(stack.count, alignment)
    channels = stack.shape[2]
    codes = np.empty((len(kept), rows, cols, channels), stack.codes.dtype)
    uncovered = np.zeros((rows, cols), bool)
    read = np.empty((rows, cols, channels), stack.codes.dtype)
    total = np.empty((rows, cols, channels), np.int64)
    clipped = np.empty((rows, cols, channels), bool)  # at its limit at some tap
    black = np.empty((rows, cols, channels), bool)  # at 0 at some tap
    for i, j in enumerate(kept):
        total[...] = 0
        clipped[...] = False
        black[...] = False
        for dy, wy in TAPS:
            for dx, wx in TAPS:
                warp = alignment.transforms[j] @ np.array(
                    [[step, 0.0, dx], [0.0, step, dy], [0.0, 0.0, 1.0]])
                warp_codes(stack.codes[j], warp, stack.code_max, read)
                total += wy * wx * read.astype(np.int64)
                clipped |= read >= stack.code_max
                black |= read == 0
                if dx == 0 and dy == 0:  # edges within a pixel of the sample, in the
                    # bracket where it was taken from, at full resolution
                    uncovered |= sharp_edges(stack.codes[j], stack.code_max, warp,
                                             (rows, cols))
                elif dx != 0 and dy != 0:  # the corner taps bound the others
                    uncovered |= coverage(warp, rows, cols, 1, (height, width)) < 1
        codes[i] = np.where(clipped, stack.code_max,
                            np.where(black, 0, (total + 8) // 16)).astype(codes.dtype)

    def pick(values):
        return values if not values else tuple(values[j] for j in kept)

    return replace(stack, codes=codes, exposures=stack.exposures[kept],
                   files=pick(stack.files), exposure_sources=pick(stack.exposure_sources),
                   metadata=pick(stack.metadata), kinds=pick(stack.kinds),
                   channel_gains=None if stack.channel_gains is None
                   else stack.channel_gains[kept]), uncovered


def sample_brackets(count: int, alignment) -> list[int]:
    """The brackets of a ``count``-bracket stack that :func:`sampled_stack` samples: those
    registration did not refuse (``alignment``), while at least two are left."""
    refused = {j for j, _ in alignment.refused}
    kept = [j for j in range(count) if j not in refused]
    return kept if len(kept) >= 2 else list(range(count))


def solve_on_sample(stack: ExposureStack, alignment,
                    solve: Callable[[ExposureStack, np.ndarray], CameraResponse],
                    exclude: np.ndarray | None = None,
                    response: CameraResponse | None = None) -> CameraResponse:
    """``solve(small, exclude)`` (a response solve, :func:`hdrio.job.stages.response_solver`)
    on the aligned sample of ``stack`` (:func:`sampled_stack`, on the grid of
    :func:`sample_step`), leaving out the pixels ``exclude`` (``(H, W)``, in the
    reference's frame) too; its sample indices on the full grid (:func:`on_full_grid`).
    Alignment's re-solve (``stack`` as read, ``alignment`` as measured) and deghosting's
    on warped brackets (``stack`` warped, ``alignment``'s transforms the identity) both
    solve here.

    Raises :class:`~hdrio.errors.HdrioError` where two neighbouring brackets of the
    sample with a bracket left out between them (one registration refused) are not both
    well exposed at :data:`LINK_POINTS` of its points (:func:`unlinked`): a solve cannot
    place them on one curve, and the callers keep the response they have. (A still
    linear 16-bit ladder, 7 x 2 EV, whose middle bracket registration could not judge:
    its sample kept brackets 16 and 256 times the shortest side by side, and the curve
    re-solved on it had the green and blue channels' log range 3.4 times the true one;
    the merge was 70 % off at the median, against 0.8 % with ``--align off``.)
    ``response``: the one the stack was registered with, through which deep codes'
    window is read (:func:`hdrio.skips.well_exposed_codes`)."""
    height, width = stack.shape[:2]
    step = sample_step(height, width)
    small, uncovered = sampled_stack(stack, alignment, step)
    if exclude is not None:
        uncovered |= exclude[::step, ::step]
    gap = unlinked(small.codes, small.code_max, uncovered,
                   sample_brackets(stack.count, alignment),
                   None if response is None else np.exp(response.log_inverse).T)
    if gap is not None:
        raise HdrioError(f"the aligned sample's brackets of {small.exposures[gap]:.4g} and "
                         f"{small.exposures[gap + 1]:.4g} s are well exposed together at "
                         "too few points to solve a response on")
    return on_full_grid(solve(small, uncovered), small.shape[1], width, step)


def unlinked(codes: np.ndarray, code_max: int, uncovered: np.ndarray, kept,
             linear: np.ndarray | None = None) -> int | None:
    """The first ``j`` whose brackets ``j`` and ``j + 1`` of the sample ``codes`` ``(P, h,
    w, C)`` (sorted by exposure; ``kept``: each one's bracket in the stack) had a bracket
    left out between them and are both well exposed in every channel
    (:func:`hdrio.skips.well_exposed_codes`) at fewer than :data:`LINK_POINTS` of the
    points not ``uncovered`` (``(h, w)``), or ``None``. (Neighbours in the stack are not
    tested: the solve ties them through every code it weights, not only the well-exposed
    ones; tested, the re-solves of hand-held 8-bit ladders were refused, and their merges
    went 17x off.) ``linear``: the response's ``f^-1``, ``(C, levels)``, which sets the
    window of deep codes."""
    low, high = well_exposed_codes(code_max, linear=linear)
    for j in range(codes.shape[0] - 1):
        if kept[j + 1] == kept[j] + 1:
            continue
        both = (np.all((codes[j] >= low) & (codes[j] <= high), axis=-1)
                & np.all((codes[j + 1] >= low) & (codes[j + 1] <= high), axis=-1))
        if np.count_nonzero(both & ~uncovered) < LINK_POINTS:
            return j
    return None


def on_full_grid(response: CameraResponse, small_width: int, width: int,
                 step: int) -> CameraResponse:
    """``response`` with its ``sample_indices`` (flat pixels of the ``step`` grid it was
    solved on, ``small_width`` wide) made flat pixels of the full ``width``-wide image in
    the reference's frame, where the warped stack has them: what reads the samples
    again (:func:`hdrio.align.motion.falling_fraction`, the response plot) reads those
    pixels. (They were read as full-image pixels as they were: on a 24 MP stack, a strip
    of the top 250 rows.)"""
    indices = response.parameters.get("sample_indices")
    if indices is None or step == 1:
        return response
    indices = np.asarray(indices)
    full = (indices // small_width) * step * width + (indices % small_width) * step
    return replace(response, parameters={**response.parameters, "sample_indices": full})


def sharp_edges(codes: np.ndarray, code_max: int, grid: np.ndarray | None = None,
                shape: tuple[int, int] | None = None) -> np.ndarray:
    """``(H, W)``: pixels of one bracket ``(H, W, C)`` whose 3x3 neighbourhood spans more
    than :data:`EDGE_CODES` (mean of channels). With ``grid`` (``3 x 3``: a point of a
    ``shape`` grid to a pixel of ``codes``), the same test at the pixel nearest each
    grid point, into a ``shape`` mask: a coarse grid's samples tested on their own
    full-resolution neighbourhoods.

    (A test on the coarse grid itself, its neighbours a grid step apart, left out 84 %
    of the 24 MP moved speed stack's aligned sample at step 4, and its re-solve 160-269
    samples of 1000: the merge's median error 2.46x the still stack's.)"""
    if grid is None:
        grid, shape = np.eye(3), codes.shape[:2]
    edges = np.empty(shape, np.bool_)
    on_threads(_sharp_edges, shape[0], codes, np.ascontiguousarray(grid, np.float64),
               np.float32(EDGE_CODES * code_max / 255.0), edges)
    return edges


@njit(cache=True, nogil=True)
def _sharp_edges(start, stop, codes, grid, threshold, out):  # pragma: no cover - compiled
    """:func:`sharp_edges` into rows ``start .. stop - 1`` of ``out`` (on every core: one
    thread took 0.45 s of a moved 7 x 24 MP stack's re-solve, 60 ms a bracket at step
    4): for each of its points, the pixel of ``codes``
    nearest ``grid @ (x, y, 1)`` (clipped to the image), the mean of the channels of its
    3x3 neighbourhood as NumPy's ``mean(axis=-1, dtype=float32)`` makes it (a float32
    sum, divided in float64), their range (the border's neighbours the border itself, as
    ``scipy.ndimage``'s filters reflect it) and the comparison in float32, so that the
    mask on the identity grid is NumPy's and SciPy's bit for bit, in one pass (14 calls
    of SciPy's filters took 1 s of a hand-held 7 x 24 MP merge)."""
    cols = out.shape[1]
    height, width, channels = codes.shape
    for y in range(start, stop):
        for x in range(cols):
            w = grid[2, 0] * x + grid[2, 1] * y + grid[2, 2]
            sx = (grid[0, 0] * x + grid[0, 1] * y + grid[0, 2]) / w
            sy = (grid[1, 0] * x + grid[1, 1] * y + grid[1, 2]) / w
            cx = min(max(int(np.floor(sx + 0.5)), 0), width - 1)
            cy = min(max(int(np.floor(sy + 0.5)), 0), height - 1)
            low = np.float32(np.inf)
            high = np.float32(-np.inf)
            for yy in range(max(cy - 1, 0), min(cy + 2, height)):
                for xx in range(max(cx - 1, 0), min(cx + 2, width)):
                    total = np.float32(0.0)
                    for c in range(channels):
                        total += np.float32(codes[yy, xx, c])
                    grey = np.float32(np.float64(total) / channels)
                    low = min(low, grey)
                    high = max(high, grey)
            out[y, x] = high - low > threshold
