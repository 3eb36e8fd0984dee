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
"""

from __future__ import annotations

import math

import numpy as np

from hdrio.registry import MethodRegistry

DEFAULT_SAMPLES = 1000
_CANDIDATE_LIMIT = 1_000_000
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
    """Indices covering every bracket's code range evenly (see module docstring)."""
    count, height, width, _ = codes.shape
    stride = max(1, math.ceil(math.sqrt(height * width / _CANDIDATE_LIMIT)))
    grid = codes[:, ::stride, ::stride, :]
    grid_h, grid_w = grid.shape[1:3]
    # One bracket at a time: the temporaries are a few bytes per candidate, not per
    # candidate and bracket (this solve's memory must not grow with the bracket count).
    unclipped = np.empty((count, grid_h * grid_w), dtype=bool)  # (P, M)
    for j in range(count):
        frame = grid[j].reshape(grid_h * grid_w, -1)
        unclipped[j] = np.all((frame > 0) & (frame < code_max), axis=1)
    informative = np.count_nonzero(unclipped, axis=0) >= 2
    if exclude is not None:
        informative &= ~np.asarray(exclude, dtype=bool)[::stride, ::stride].reshape(-1)
    candidates = np.flatnonzero(informative)
    if candidates.size == 0:
        return np.empty(0, dtype=np.int64)
    rng = np.random.default_rng(seed)
    per_bin = max(1, math.ceil(n_samples / (count * _BINS)))
    chosen: list[np.ndarray] = []
    for j in range(count):
        level = grid[j].reshape(grid_h * grid_w, -1)[candidates].mean(axis=1)  # mean code
        bins = np.minimum((level / (code_max + 1) * _BINS).astype(np.int64), _BINS - 1)
        members = np.flatnonzero(unclipped[j, candidates])
        members = members[rng.permutation(members.size)]
        order = members[np.argsort(bins[members], kind="stable")]
        sorted_bins = bins[order]
        first_of_bin = np.searchsorted(sorted_bins, sorted_bins, side="left")
        rank_in_bin = np.arange(order.size) - first_of_bin
        chosen.append(order[rank_in_bin < per_bin])
    picked = np.unique(np.concatenate(chosen)) if chosen else np.empty(0, np.int64)
    if picked.size > n_samples:
        picked = np.sort(rng.choice(picked, size=n_samples, replace=False))
    elif picked.size < n_samples:
        free = np.ones(candidates.size, dtype=bool)
        free[picked] = False
        rest = np.flatnonzero(free)
        extra = rng.choice(rest, size=min(n_samples - picked.size, rest.size), replace=False)
        picked = np.sort(np.concatenate([picked, extra]))
    grid_index = candidates[picked]
    rows, cols = (grid_index // grid_w) * stride, (grid_index % grid_w) * stride
    return rows * width + cols


SAMPLING_METHODS: MethodRegistry = MethodRegistry(
    "sampling", {"stratified": samples_stratified, "tutorial": samples_tutorial}
)


def sample_codes(codes: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Code values at flat pixel ``indices``: shape ``(N, P, C)`` (sample, bracket, channel)."""
    count, height, width, channels = codes.shape
    return codes.reshape(count, height * width, channels)[:, indices, :].transpose(1, 0, 2)
