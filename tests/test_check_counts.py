"""The check's counting kernel (the writer's) counts exactly what the NumPy check
(``hdrio check``'s) counts: the report after a merge and ``hdrio check`` of its file
print the same numbers."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.cms.check_counts import count_pixels
from hdrio.cms.checks import _BIN_SHIFT, _BINS, StreamingCheck


def _numpy_counts(r, g, b, weights, to_gamut):
    """The NumPy check's counts (what ``hdrio check`` runs), in the kernel's order."""
    check = StreamingCheck()
    check._weights, check._to_gamut = weights, to_gamut
    check._use_gamut = to_gamut is not None
    pixels, partial, bins = check._count_numpy(r, g, b)
    histogram = np.zeros(_BINS, np.int64)
    for first, counts in bins:
        histogram[first:first + counts.size] += counts
    return (*partial, histogram)


def _awkward_pixels(seed: int, count: int) -> np.ndarray:
    """float32 RGB over 60 stops of both signs, with NaN, infinities, zeros of both signs,
    half's subnormals and overflow, and pixels one channel slightly negative."""
    rng = np.random.default_rng(seed)
    pixels = np.exp2(rng.uniform(-30, 30, (count, 3))).astype(np.float32)
    pixels *= np.where(rng.random((count, 3)) < 0.1, -1, 1).astype(np.float32)
    special = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 6e-8, 65504.0, 70000.0, -1e-9],
                       np.float32)
    where = rng.random((count, 3)) < 0.05
    pixels[where] = rng.choice(special, int(where.sum()))
    pixels[: count // 10, 1] = -1e-7 * pixels[: count // 10, 0]  # just outside, or not
    return pixels


@pytest.mark.parametrize("gamut", [False, True])
@pytest.mark.parametrize("stored", ["float32", "half"])
def test_the_kernel_counts_what_the_numpy_check_counted(gamut, stored):
    pixels = _awkward_pixels(11, 20000)
    if stored == "half":
        with np.errstate(over="ignore"):
            pixels = pixels.astype(np.float16)
    weights = np.array([0.2126, 0.7152, 0.0722], np.float32)
    to_gamut = np.array([[1.6, -0.5, -0.1], [-0.1, 1.1, 0.0], [0.0, -0.1, 1.1]], np.float32)
    as_float = pixels.astype(np.float32)
    expected = _numpy_counts(*(np.ascontiguousarray(as_float[:, c]) for c in range(3)),
                             weights, to_gamut if gamut else None)
    stored_planes = pixels.view(np.uint16) if stored == "half" else pixels
    # the planes as the writer gives them: strided columns of interleaved pixels
    *found, first, counts = count_pixels(*(stored_planes[:, c] for c in range(3)), weights,
                                         to_gamut, gamut, _BIN_SHIFT)
    histogram = np.zeros(_BINS, np.int64)
    histogram[first:first + counts.size] = counts
    assert tuple(found) == tuple(expected[:5])
    assert np.array_equal(histogram, expected[5])
    assert all(count > 0 for count in expected[:3])  # every count is tried


def test_no_positive_luminance_gives_an_empty_histogram():
    planes = [np.array([-1.0, np.nan, 0.0], np.float32)] * 3
    found = count_pixels(*planes, np.ones(3, np.float32), np.eye(3, dtype=np.float32), False,
                         _BIN_SHIFT)
    assert found[:3] == (1, 1, 1)  # the NaN; the negative one, outside its own primaries
    assert found[3] == np.inf and found[4] == 0.0 and found[6].size == 0
