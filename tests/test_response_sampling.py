"""The stratified sampler's promises: every bracket's bins, the unclipped-in-two rule,
exclusion, determinism, and reading only the candidate grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdrio.io.staging import CANDIDATE_LIMIT, candidate_stride
from hdrio.response.sampling import _BINS, sample_codes, samples_stratified
from hdrio.tools.synthetic import demo_scene, render_brackets

EXPOSURES = (1 / 64, 1 / 16, 1 / 4, 1.0, 4.0)


@pytest.fixture(scope="module")
def codes() -> np.ndarray:
    """Five 8-bit brackets of the demo scene, 300 x 450: larger than the candidate grid."""
    radiance = demo_scene(300, 450, seed=1) * 40.0
    return render_brackets(radiance, EXPOSURES, seed=1)


def unclipped(samples: np.ndarray, code_max: int) -> np.ndarray:
    """``(N, P)``: sample unclipped (every channel in 1 .. code_max - 1) in each bracket."""
    return np.all((samples > 0) & (samples < code_max), axis=-1)


def bin_of(samples: np.ndarray, code_max: int) -> np.ndarray:
    """``(N, P)``: the bin of each sample's mean code in each bracket."""
    return np.floor(samples.mean(axis=-1) / (code_max + 1) * _BINS).astype(int)


@pytest.mark.parametrize(("height", "width"), [(4000, 6000), (300, 450), (128, 128),
                                               (1, 100_000), (7, 3)])
def test_candidate_grid_is_the_largest_within_the_limit(height, width):
    stride = candidate_stride(height, width)
    grid = math.ceil(height / stride) * math.ceil(width / stride)
    assert grid <= CANDIDATE_LIMIT
    if stride > 1:
        assert math.ceil(height / (stride - 1)) * math.ceil(width / (stride - 1)) > CANDIDATE_LIMIT


def test_every_bin_of_every_bracket_is_drawn_from(codes):
    # N = P * bins * m: at most N distinct draws, so none is trimmed away and every
    # (bracket, bin) must give min(m, its members on the grid) samples.
    count, height, width, _ = codes.shape
    per_bin = 3
    indices = samples_stratified(codes, 255, n_samples=count * _BINS * per_bin)
    samples = sample_codes(codes, indices)
    stride = candidate_stride(height, width)
    grid = codes[:, ::stride, ::stride].reshape(count, -1, 3).transpose(1, 0, 2)
    grid_ok = unclipped(grid, 255)
    grid_ok &= (grid_ok.sum(axis=1) >= 2)[:, None]
    grid_bins, sample_bins = bin_of(grid, 255), bin_of(samples, 255)
    sample_ok = unclipped(samples, 255)
    bins_with_members = 0
    for j in range(count):
        for b in range(_BINS):
            members = np.count_nonzero(grid_ok[:, j] & (grid_bins[:, j] == b))
            drawn = np.count_nonzero(sample_ok[:, j] & (sample_bins[:, j] == b))
            assert drawn >= min(per_bin, members), (j, b, members, drawn)
            bins_with_members += members > 0
    assert bins_with_members >= count * _BINS // 2  # the scene fills most bins


def test_samples_are_unclipped_in_two_brackets_and_on_the_grid(codes):
    count, height, width, _ = codes.shape
    indices = samples_stratified(codes, 255, n_samples=1000, seed=3)
    assert indices.size == 1000 and np.unique(indices).size == 1000
    assert np.all(np.diff(indices) > 0)  # sorted, flat row-major
    assert np.all(unclipped(sample_codes(codes, indices), 255).sum(axis=1) >= 2)
    stride = candidate_stride(height, width)
    assert np.all(indices // width % stride == 0) and np.all(indices % width % stride == 0)


def test_exclusion_mask_is_respected(codes):
    _, height, width, _ = codes.shape
    exclude = np.ones((height, width), dtype=np.uint8)  # a non-bool mask works too
    exclude[100:200, 150:300] = 0
    indices = samples_stratified(codes, 255, n_samples=500, exclude=exclude)
    rows, cols = indices // width, indices % width
    assert indices.size > 0
    assert np.all((rows >= 100) & (rows < 200) & (cols >= 150) & (cols < 300))
    everything = np.ones((height, width), dtype=bool)
    assert samples_stratified(codes, 255, exclude=everything).size == 0


def test_seeded_and_deterministic(codes):
    first = samples_stratified(codes, 255, seed=7)
    np.testing.assert_array_equal(first, samples_stratified(codes, 255, seed=7))
    assert not np.array_equal(first, samples_stratified(codes, 255, seed=8))


def test_reads_only_the_candidate_grid():
    # Off the grid every pixel is a perfect candidate, on it every pixel is clipped: a
    # sampler that looked anywhere but the grid would find samples.
    height, width = 200, 300
    stride = candidate_stride(height, width)
    assert stride > 1  # more pixels than CANDIDATE_LIMIT
    codes = np.empty((3, height, width, 3), dtype=np.uint8)
    codes[:] = np.array([60, 120, 180], dtype=np.uint8)[:, None, None, None]
    codes[:, ::stride, ::stride] = 255
    assert samples_stratified(codes, 255).size == 0


def test_sixteen_bit_and_single_channel():
    radiance = demo_scene(120, 180, seed=2)[..., :1] * 40.0
    codes = render_brackets(radiance, EXPOSURES, bit_depth=16, seed=2)
    indices = samples_stratified(codes, 65535, n_samples=400)
    assert indices.size == 400
    assert np.all(unclipped(sample_codes(codes, indices), 65535).sum(axis=1) >= 2)
