"""The fused merge kernel against the direct NumPy port (tests/merge_reference.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.merge.weighted_mean import merge_brackets
from hdrio.radiometry.curve import CameraResponse
from hdrio.stack import ExposureStack
from tests.merge_reference import merge_reference


def _stack(code_max: int, count: int = 5, shape=(23, 37, 3), seed: int = 0) -> ExposureStack:
    """Random radiance through a gamma curve, with flat clipped and black patches."""
    rng = np.random.default_rng(seed)
    radiance = np.exp(rng.uniform(-6, 3, shape))
    radiance[:4, :6] = 1e6          # clipped in every bracket
    radiance[-4:, -6:] = 1e-9       # black in every bracket
    radiance[5:9, :, 0] *= 50       # red clips early, green and blue do not
    exposures = 4.0 ** np.arange(count) / 64
    codes = [np.clip(np.rint(code_max * np.clip(radiance * t, 0, 1) ** (1 / 2.2)
                             + rng.normal(0, code_max / 500, shape)), 0, code_max)
             for t in exposures]
    dtype = np.uint8 if code_max == 255 else np.uint16
    return ExposureStack.from_arrays(np.stack(codes).astype(dtype), exposures,
                                     code_max=code_max)


def _response(code_max: int, supported_from: int = 0) -> CameraResponse:
    z = np.arange(code_max + 1)
    g = 2.2 * np.log(np.maximum(z, 0.5) / code_max) + np.array([[0.0, 0.05, -0.05]]).T
    supported = np.zeros((code_max + 1, 3), bool)
    supported[supported_from:] = True
    return CameraResponse(g.T.copy(), code_max, supported)


def _rtol(domain: str) -> float:
    """The oracle sums in float64; the kernel in float32, so each of its table entries
    and fused multiply-adds rounds once (2^-24 = 6e-8 relative), about 2P + 2 roundings
    for P = 5 brackets, plus the output's float32 rounding.

    Linear domain: every term is positive, so the sums' relative error is at most
    (2P + 2) 2^-24 = 7e-7 (rounding errors of random sign add up to about 3e-7, the
    worst observed); 1e-6 covers the bound. Log domain: ``ln E`` is a weighted mean of
    terms ``g - ln dt`` of up to 27 in size here, so its absolute error (E's relative
    error) is up to 27 times that, 2e-5 in the worst case and about sqrt(2P + 2) 27
    2^-24 = 6e-6 for errors of random sign; plus the kernel's ``exp``, 1.3 ulp. The worst
    observed is 1e-6; 4e-6 leaves room for an unluckier rounding and still catches any
    wrong term (a code off by one changes E by 1e-3 or more)."""
    return 1e-6 if domain == "linear" else 4e-6


@pytest.mark.parametrize("code_max", [255, 4095, 65535])
@pytest.mark.parametrize("domain", ["log", "linear"])
@pytest.mark.parametrize("saturation", ["channel", "pixel", "safe", "auto"])
@pytest.mark.parametrize("weighting", ["Debevec1997", "tutorial-hat", "gaussian"])
def test_kernel_matches_numpy_port(code_max, domain, saturation, weighting):
    stack = _stack(code_max)
    # Part of the code range unsupported, as after a solve that saw no dark samples.
    response = _response(code_max, supported_from=code_max // 20)
    # "safe" and "auto": each channel dropped from its own limit (a white level and
    # shoulder below the top code, different per channel); "auto" here as it is on
    # stacks without channel mixing: those limits, each channel dropped alone (applied
    # in the kernel's tables and resets, not by remapping the rows).
    limits = np.rint(code_max * np.array([0.97, 0.9, 0.99])).astype(int)
    radiance, stats = merge_brackets(stack, response, weighting, domain, saturation,
                                     limits=limits, pixel_rule=False)
    expected, (clipped, black) = merge_reference(stack, response, weighting, domain,
                                                 saturation, limits)
    np.testing.assert_allclose(radiance, expected, rtol=_rtol(domain))
    assert (stats.clipped_everywhere, stats.black_everywhere) == (clipped, black)
    assert clipped > 0 and black > 0


def test_channel_policy_differs_from_pixel_policy_only_where_a_channel_clips_alone():
    stack = _stack(255)
    response = _response(255)
    by_channel, _ = merge_brackets(stack, response, saturation="channel")
    by_pixel, _ = merge_brackets(stack, response, saturation="pixel")
    saturated = stack.codes == 255
    alone = np.any(np.any(saturated, axis=-1) & ~np.all(saturated, axis=-1), axis=0)
    # The two policies take different paths through the kernel (pair tables, one table
    # per bracket), which round differently: "differs" is beyond that rounding.
    differs = np.any(~np.isclose(by_channel, by_pixel, rtol=_rtol("log"), atol=0), axis=-1)
    assert np.all(alone[differs]) and np.count_nonzero(differs) > 20


def test_single_row_single_column_and_single_channel():
    for shape in [(1, 40, 3), (40, 1, 3), (9, 9, 1)]:
        stack = _stack(255, count=3, shape=shape)
        response = CameraResponse(_response(255).log_inverse[:, : shape[-1]], 255,
                                  np.ones((256, shape[-1]), bool))
        radiance, _ = merge_brackets(stack, response)
        expected, _ = merge_reference(stack, response)
        np.testing.assert_allclose(radiance, expected, rtol=_rtol("log"))


def test_rejects_unknown_saturation_policy():
    with pytest.raises(ValueError, match="saturation policy"):
        merge_brackets(_stack(255, count=2), _response(255), saturation="any")


@pytest.mark.parametrize("saturation", ["channel", "pixel", "safe"])
def test_early_stop_skips_saturated_rows_and_changes_nothing(saturation):
    # Rows 0-5 are bright enough to saturate every channel from the third bracket on:
    # the kernel never reads those bracket rows, and the result is still the oracle's.
    stack = _stack(255, count=5, shape=(20, 30, 3), seed=3)
    codes = stack.codes.copy()
    codes[2:, :6] = 255
    stack = ExposureStack.from_arrays(codes, stack.exposures)
    response = _response(255)
    radiance, stats = merge_brackets(stack, response, saturation=saturation)
    expected, _ = merge_reference(stack, response, saturation=saturation)
    np.testing.assert_allclose(radiance, expected, rtol=_rtol("log"))
    assert stats.observations_skipped == 3 * 6 * 30  # brackets 2, 3, 4 of rows 0-5


def test_kernel_exp_is_within_two_ulp_over_the_whole_clamped_range():
    # The kernel's vectorised exp (Cephes expf) against float64 exp, on a dense grid of
    # ln E from the clamp's lower end (k = -126) to its upper end (k = 128, where 2^k is
    # built as 2^127 * 2). Cephes documents 1.3 ulp; 2 ulp (2^-23) is the bound here.
    from hdrio.merge.kernel import (
        FLOAT32_MAX,
        FLOAT32_TINY,
        LOG_FLOAT32_MAX,
        LOG_FLOAT32_TINY,
        _exp_row,
    )

    values = np.linspace(LOG_FLOAT32_TINY, LOG_FLOAT32_MAX, 1_000_003).astype(np.float32)
    values[:2] = np.float32(LOG_FLOAT32_TINY), np.float32(LOG_FLOAT32_MAX)
    expected = np.exp(values.astype(np.float64))
    result = values.copy()
    _exp_row(result, np.empty(result.size, np.int32))
    assert np.all(np.isfinite(result))
    assert result.min() >= FLOAT32_TINY and result.max() <= FLOAT32_MAX
    assert np.max(np.abs(result / expected - 1)) <= 2.0 ** -23
