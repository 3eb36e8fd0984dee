"""Choosing the pixels whose code values feed the response solve.

Two strategies, both returning flat (row-major) pixel indices into an ``H x W`` image:

``tutorial``
    The tutorial's rule: ``N`` samples with ``N (P - 1) > Z_max - Z_min``, doubled twice
    for safety, ``N = ceil(2 (Z_max - Z_min) / (P - 1)) * 2`` (34 for 16 8-bit brackets),
    taken at a uniform stride through the pixels in MATLAB's column-major order. Cheap,
    but blind: samples may be saturated or black in every bracket, or all land in one
    region, and the mid-tones of some brackets may go unsampled.

``stratified`` (default)
    Covers the code range evenly: for each bracket, the candidates' mean code value is
    split into bins across the range and the same number of pixels is drawn from every
    bin (seeded, so reruns match). Only pixels seen unclipped (neither 0 nor ``Z_max`` in
    any channel) in at least two brackets are candidates: a pixel clipped in all but one
    bracket only ties its own unknown radiance and adds nothing about the curve.
    Pixels in an exclusion mask (registration borders, say) are never drawn.

    Candidates lie on a regular grid ``codes[:, ::stride, ::stride]`` of at most
    :data:`hdrio.io.staging.CANDIDATE_LIMIT` (2^14) pixels, the stride following from the
    image size (39 at 6000 x 4000: a 103 x 154 grid), and the sampler reads nothing else
    of the codes.
    The grid used to hold a million candidates, and sampling 24 MP took 0.7 s; at 2^14
    it takes about 2.5 ms, mostly the one read of the grid's memory. Coarser grids
    did not cost accuracy: on the speed benchmark's scene (7 brackets 2 EV apart) the
    response error over seeds 0-5 is 0.027 stops RMS on average (0.025 to 0.028), against
    0.030 with the million candidates.

    Within a bin of ``n`` members (in raster order) the draws are a systematic sample
    with a random phase: ranks ``floor((k + u) n / m)`` for ``m`` draws per bin. Where
    the bins give fewer than ``N`` distinct pixels, the rest are drawn uniformly from
    the remaining candidates; where they give more, a random ``N`` of them are kept.
"""

from __future__ import annotations

import math

import numpy as np

from hdrio.io.staging import candidate_stride, gather_pixels, strided_copy
from hdrio.method_registry import MethodRegistry

DEFAULT_SAMPLES = 1000
_BINS = 32


def tutorial_sample_count(count: int, n_levels: int = 256) -> int:
    """The tutorial's ``N = ceil(2 (n_levels - 1) / (P - 1)) * 2`` for ``P = count`` brackets."""
    return math.ceil(2 * (n_levels - 1) / (count - 1)) * 2


def samples_tutorial(codes: np.ndarray, code_max: int, n_levels: int | None = None,
                     **_ignored) -> np.ndarray:
    """The tutorial's uniform-stride sample indices (see module docstring).

    ``n_levels`` is the number of code levels the solve uses (256 for 8-bit; the bin
    count for binned 16-bit input), so the rule scales with it.
    """
    count, height, width = codes.shape[:3]
    n_levels = code_max + 1 if n_levels is None else n_levels
    n_samples = tutorial_sample_count(count, n_levels)
    pixels = height * width
    n_samples = min(n_samples, pixels)
    step = pixels / n_samples
    one_based = np.floor(1 + step * np.arange(n_samples)).astype(np.int64)
    column_major = one_based - 1
    rows, cols = column_major % height, column_major // height
    return rows * width + cols




def samples_stratified(codes: np.ndarray, code_max: int, n_samples: int = DEFAULT_SAMPLES,
                       exclude: np.ndarray | None = None, seed: int = 0,
                       **_ignored) -> np.ndarray:
    """Indices covering every bracket's code range evenly (see module docstring).

    Reads only the candidate grid ``codes[:, ::stride, ::stride]`` (and the same grid of
    ``exclude``): at most :data:`hdrio.io.staging.CANDIDATE_LIMIT` pixels, whatever the image size.
    """
    count, height, width, channels = codes.shape
    stride = candidate_stride(height, width)
    grid = strided_copy(codes, stride)  # staged codes: a bracket's pages at a time
    grid_w = grid.shape[2]
    unclipped, labels = _scan_candidates(grid, code_max)
    informative = np.count_nonzero(unclipped, axis=0) >= 2
    if exclude is not None:
        informative &= ~np.asarray(exclude)[::stride, ::stride].astype(bool).reshape(-1)
    if not informative.any():
        return np.empty(0, dtype=np.int64)
    unclipped &= informative
    np.copyto(labels, np.uint8(_BINS), where=~unclipped)  # no candidate in that bracket
    rng = np.random.default_rng(seed)
    per_bin = max(1, math.ceil(n_samples / (count * _BINS)))
    picked = _draw_from_bins(labels, rng.random((count, _BINS)), per_bin)
    if picked.size > n_samples:
        picked = rng.choice(picked, size=n_samples, replace=False)
    elif picked.size < n_samples:
        free = informative.copy()
        free[picked] = False
        rest = np.flatnonzero(free)
        picked = np.concatenate([picked, rng.choice(
            rest, size=min(n_samples - picked.size, rest.size), replace=False)])
    picked = np.sort(picked)
    rows, cols = (picked // grid_w) * stride, (picked % grid_w) * stride
    return rows * width + cols


def _draw_from_bins(labels: np.ndarray, phase: np.ndarray, per_bin: int) -> np.ndarray:
    """Up to ``per_bin`` pixels of every bin of every bracket, each pixel once.

    ``labels`` is ``(P, M)`` ``uint8``: each grid pixel's bin in each bracket, or
    ``B = phase.shape[1]`` or more where it is no candidate there. A bin of ``n``
    members, in raster order, gives its members of rank ``floor((k + u) n / per_bin)``
    for ``k = 0 .. per_bin - 1``, ``u = phase[j, b]``: a systematic sample, every member
    equally likely and the draws spread over the image; a bin of at most ``per_bin``
    members gives them all (ranks repeat). Bracket by bracket, in raster order, without
    the pixels an earlier bracket drew.

    NumPy (a stable argsort per bracket, about 1 ms more than a numba loop at 24 MP,
    which cost seconds of compiling on a first run).
    """
    count, size = labels.shape
    n_bins = phase.shape[1]
    taken = np.zeros(size, bool)
    ranks_k = np.arange(per_bin)
    drawn = []
    for j in range(count):
        candidates = np.flatnonzero(labels[j] < n_bins)
        bins = labels[j, candidates]
        members = np.bincount(bins, minlength=n_bins)
        starts = np.cumsum(members) - members
        by_bin = candidates[np.argsort(bins, kind="stable")]
        ranks = ((ranks_k[None, :] + phase[j][:, None]) * members[:, None]
                 / per_bin).astype(np.int64)
        distinct = np.ones(ranks.shape, bool)
        distinct[:, 1:] = ranks[:, 1:] != ranks[:, :-1]
        distinct &= ranks < members[:, None]  # an empty bin gives nothing
        chosen = np.sort(by_bin[(starts[:, None] + ranks)[distinct]])
        chosen = chosen[~taken[chosen]]
        taken[chosen] = True
        drawn.append(chosen)
    return np.concatenate(drawn) if drawn else np.empty(0, np.int64)


def _scan_candidates(grid: np.ndarray, code_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Per bracket and grid pixel: unclipped in every channel, and the bin of its mean code.

    ``grid`` is the ``(P, h, w, C)`` candidate grid. It is copied once into channel
    planes; every test
    then runs in place on small contiguous arrays of the narrowest integer type (tests
    on the interleaved view cost about twice as much, and grid-sized float64 temporaries
    are slow to allocate: a float64 bin division took 0.5 ms of the 9 ms call in a
    profile). Returns ``(P, h * w)`` booleans and ``uint8`` bins.
    """
    count, grid_h, grid_w, channels = grid.shape
    planes = grid.transpose(3, 0, 1, 2).reshape(channels, count, grid_h * grid_w)
    unclipped = np.ones(planes.shape[1:], dtype=bool)
    level = np.zeros(planes.shape[1:], dtype=np.min_scalar_type(channels * code_max * _BINS))
    for plane in planes:
        unclipped &= plane > 0
        unclipped &= plane < code_max
        level += plane
    level *= _BINS
    level //= channels * (code_max + 1)
    return unclipped, level.astype(np.uint8)


SAMPLING_METHODS: MethodRegistry = MethodRegistry(
    "sampling", {"stratified": samples_stratified, "tutorial": samples_tutorial}
)


def matched_quantiles(codes: np.ndarray, count: int = DEFAULT_SAMPLES) -> np.ndarray:
    """Each bracket's codes at ``count`` evenly spaced quantiles, channel by channel:
    ``(count, P, C)`` integer codes, sample first like :func:`sample_codes`.

    A response is monotone, so on a still scene the pixel at a quantile of one bracket
    is the pixel at the same quantile of every other: samples of one scene point each
    that camera shake does not misplace (a histogram moves little when the frame does;
    noise widens it, so a curve solved on them is biased where the noise is large).
    Read on the candidate grid (:func:`hdrio.io.staging.candidate_stride`).
    """
    height, width = codes.shape[1:3]
    grid = strided_copy(codes, candidate_stride(height, width))
    at = (np.arange(count) + 0.5) / count
    pixels = grid.reshape(grid.shape[0], -1, grid.shape[-1])
    return np.rint(np.quantile(pixels, at, axis=1)).astype(np.int64)


def sample_codes(codes: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Code values at flat pixel ``indices``: shape ``(N, P, C)`` (sample, bracket, channel)."""
    return gather_pixels(codes, indices).transpose(1, 0, 2)
