"""The fused merge kernel against the direct NumPy port (tests/merge_reference.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.merge.saturation import ClipPolicy
from hdrio.merge.weighted_mean import merge_brackets
from hdrio.radiometry.cliptest import clip_tables, dropped_observations
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel
from hdrio.stack import ExposureStack
from tests.merge_reference import dropped_reference, merge_reference


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
@pytest.mark.parametrize("rule", ["channel", "pixel", "limits", "test", "test neutral"])
@pytest.mark.parametrize("weighting", ["Debevec1997", "tutorial-hat", "gaussian"])
def test_kernel_matches_numpy_port(code_max, domain, rule, weighting):
    stack = _ringing(_stack(code_max))
    # Part of the code range unsupported, as after a solve that saw no dark samples.
    response = _response(code_max, supported_from=code_max // 20)
    policy = _policy(stack, response, rule)
    radiance, stats = merge_brackets(stack, response, weighting, domain, policy=policy)
    expected, (clipped, black) = merge_reference(stack, response, weighting, domain,
                                                 policy=policy)
    np.testing.assert_allclose(radiance, expected, rtol=_rtol(domain))
    assert (stats.clipped_everywhere, stats.black_everywhere) == (clipped, black)
    assert clipped > 0 and black > 0


def _ringing(stack: ExposureStack) -> ExposureStack:
    """``stack`` with a JPEG's ringing: in rows 5-8 (red clips early) the red of every
    other pixel of the fourth bracket a few codes below its limit, though the third
    bracket's is clipped (a clip only grows with exposure)."""
    codes = stack.codes.copy()
    limit = int(np.rint(stack.code_max * 0.97))  # red's limit in _policy
    codes[3, 5:9, ::2, 0] = np.where(codes[2, 5:9, ::2, 0] >= limit, limit - 3,
                                     codes[3, 5:9, ::2, 0])
    return ExposureStack.from_arrays(codes, stack.exposures, code_max=stack.code_max)


def _policy(stack: ExposureStack, response: CameraResponse, rule: str) -> ClipPolicy:
    """``channel``, ``pixel`` at the top code; ``limits``: each channel dropped alone from
    its own limit (white levels less a margin, different per channel, below the top
    code: applied in the kernel's tables and resets); ``test``: the clip test at those
    limits (gates lower still), the shortest bracket per channel or (``neutral``) whole."""
    channels = stack.codes.shape[-1]
    if rule in ("channel", "pixel"):
        return ClipPolicy.at_top(stack.code_max, channels, rule)
    limits = np.rint(stack.code_max * np.array([0.97, 0.9, 0.99])).astype(np.int64)
    if rule == "limits":
        return ClipPolicy(limits)
    gates = np.rint(stack.code_max * np.array([0.9, 0.8, 0.95])).astype(np.int64)
    noise = NoiseModel.quantisation_only(channels)
    return ClipPolicy(limits, gates, "test", rule.endswith("neutral"),
                      clip_tables(response, stack.exposures, noise, sigmas=2.0))


def test_clip_test_drops_observations_whole():
    # The "test" rule must drop some partly clipped observations whole and keep others,
    # or the comparison with the NumPy port above would prove little about it; the
    # compiled test is the port's, observation by observation.
    stack = _ringing(_stack(255))
    response = _response(255)
    codes = stack.codes
    for rule in ("test", "test neutral"):
        policy = _policy(stack, response, rule)
        near = np.any(codes >= policy.gates, axis=-1) & ~np.all(codes >= policy.limits,
                                                                axis=-1)
        dropped = np.stack([dropped_reference(codes, j, policy)
                            for j in range(codes.shape[0])])
        whole = dropped.all(axis=-1)
        assert 0 < np.count_nonzero(whole[1:]) < np.count_nonzero(near[1:])
        assert not np.any(dropped.any(axis=-1) & ~whole)  # whole, or not at all
        assert not np.any(dropped.any(axis=-1) & ~near)
        bits = dropped_observations(codes.reshape(codes.shape[0], -1, 3), policy)
        expected = (dropped * (1 << np.arange(3))).sum(axis=-1)
        np.testing.assert_array_equal(bits.reshape(expected.shape), expected)


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


@pytest.mark.parametrize("saturation", ["channel", "pixel"])
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
