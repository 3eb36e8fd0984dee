"""The clip test (hdrio.radiometry.cliptest): observations a clip corrupted before the colour
matrix, found from the stack itself, on crafted codes, generated stacks and the
hand-held canal stack; white levels only where the codes pile up."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.merge.saturation import ClipPolicy, clip_policy
from hdrio.merge.weighted_mean import merge_brackets
from hdrio.radiometry.cliptest import clip_tables, dropped_observations
from hdrio.radiometry.noise import NoiseModel
from hdrio.skips import srgb_decoded
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import gamma_inverse_response, gamma_response, render_brackets

TIMES = np.array([0.25, 1.0])


def _code(exposure: float) -> int:
    """The gamma 2.2 code of sensor exposure ``exposure`` (relative to full scale)."""
    return int(np.rint(255 * gamma_response(np.array(exposure))))


def _policy(neutral: bool = False) -> ClipPolicy:
    response, _ = gamma_inverse_response()
    noise = NoiseModel.quantisation_only(3)
    return ClipPolicy(np.array([255, 255, 255]), np.array([250, 250, 250]), "test", neutral,
                      clip_tables(response, TIMES, noise))


def test_a_partly_clipped_observation_is_dropped_where_its_channels_disagree():
    # Four pixels, two brackets 2 EV apart; red clips in the longer one. Green and blue
    # of the longer bracket: as the shorter one predicts (clean), 30 % high (what a
    # colour matrix does to them after the red raw channel clipped), or red at 251
    # (above its gate, below its limit) though the shorter bracket has it clipped (a
    # clip only grows: JPEG's ringing, a misregistered edge). The fourth pixel is
    # nowhere near the clip.
    short = np.array([[200, 80, 60], [200, 80, 60], [255, 80, 60], [100, 80, 60]])
    long = np.array([[_code(4 * (v / 255) ** 2.2) for v in pixel] for pixel in short])
    long[:3, 0] = 255
    long[1, 1:] = [_code(1.3 * 4 * (v / 255) ** 2.2) for v in short[1, 1:]]
    long[2, 0] = 251
    codes = np.stack([short, long]).astype(np.uint8)
    dropped = dropped_observations(codes, _policy())
    assert not dropped[0].any()  # the shortest: nothing to test against (not neutral)
    assert list(dropped[1]) == [0, 0b111, 0b111, 0]  # clean, whole, whole, untested
    # Where the stack mixes its channels after the clip, a partly clipped observation of
    # the shortest bracket is dropped whole too (the neutral lower bound).
    mixing = dropped_observations(codes, _policy(neutral=True))
    assert list(mixing[0]) == [0, 0, 0b111, 0]
    assert list(mixing[1]) == [0, 0b111, 0b111, 0]
    # The channel rule keeps them all (a channel at its limit dropped alone, by the
    # kernel's resets, not here).
    assert not dropped_observations(codes, replace(_policy(), rule="channel")).any()


def test_a_stack_where_nothing_clips_is_merged_channel_by_channel():
    # No code at the white level: nothing is tested, nothing dropped whole, and the
    # merge is the per-channel one, to the bit.
    response, _ = gamma_inverse_response()
    texture = np.exp(0.3 * np.random.default_rng(2).standard_normal((32, 64, 1)))
    radiance = 0.01 * 50 ** np.linspace(0, 1, 64)[None, :, None] * texture
    times = [0.05, 0.2, 0.6]
    codes = render_brackets(radiance * [1.0, 0.9, 0.8], times, seed=1)
    assert codes.max() < 240
    stack = ExposureStack.from_arrays(codes, times)
    policy = clip_policy("auto", stack.codes, response, None, stack.exposures)
    assert policy.rule == "channel"
    auto, _ = merge_brackets(stack, response, domain="linear", saturation="auto")
    channel, _ = merge_brackets(stack, response, domain="linear", saturation="channel")
    np.testing.assert_array_equal(auto, channel)


def _soft_shoulder_stack(peak: float, white: int = 255, seed: int = 0):
    """Three brackets 2 EV apart of a textured ramp whose tone curve rolls off softly
    towards the top code, differently in each bracket (as a phone renders each frame);
    ``peak`` is the longest bracket's largest sensor exposure (above 1: a clip, whose
    codes pile up at ``white``)."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0, 1, 160)[None, :]
    lum = 400 ** u * (1 + 0.3 * np.linspace(0, 1, 120)[:, None]) * np.exp(
        0.2 * rng.standard_normal((120, 160)))
    scene = np.stack([lum, 0.95 * lum, 0.8 * lum], axis=-1)
    scene *= peak / (4.0 * scene.max())
    times = [0.25, 1.0, 4.0]
    frames = []
    for j, t in enumerate(times):
        knee = (0.8, 0.45, 0.15)[j]

        def curve(x, knee=knee):
            y = np.where(x < knee, x, knee + (1 - knee) * (1 - np.exp(-(x - knee) / (1 - knee))))
            return (y / (knee + (1 - knee) * (1 - np.exp(-1.0)))) ** (1 / 2.2) * white / 255

        frames.append(render_brackets(scene, [t], curve, seed=seed + j)[0])
    return ExposureStack.from_arrays(np.stack(frames), times,
                                     files=[f"f{j}.jpg" for j in range(3)])


@pytest.mark.parametrize("peak, white", [(0.95, 255), (3.0, 255), (3.0, 231)])
def test_a_white_level_is_reported_only_where_the_codes_pile_up(peak, white):
    # Soft shoulders (codes run smoothly towards the top), with no clip (peak 0.95) and
    # with one (a third of the longest bracket's pixels beyond the raw clip), whose
    # codes pile up at the top code or, white-balanced, at 231. A phone's night bracket
    # once reported limits 184, 184, 251 where nothing piled up, and lost a third of its
    # best bracket: now a limit is a white level less the noise margin (a few codes),
    # and the clip test drops only what disagrees.
    stack = _soft_shoulder_stack(peak, white)
    result = merge_stack(stack, MergeOptions(align="off", deghost="off"))
    limits = np.asarray(result.statistics.limits)
    if white == 255:
        assert np.all(limits >= 248)
    else:
        assert np.all((limits >= 224) & (limits <= 231))
    longest = stack.codes[-1].reshape(-1, 3)
    policy = result.statistics.policy
    dropped = dropped_observations(stack.codes.reshape(3, -1, 3), policy)[-1] == 0b111
    near = np.any(longest >= (policy.gates if policy.gates is not None else limits), axis=-1)
    # Measured: at most 1 % of the longest bracket dropped whole beyond its clipped
    # pixels (its partly clipped ones that disagree); 3 % leaves room for the noise.
    assert np.count_nonzero(dropped & ~np.all(longest >= limits, axis=-1)) \
        <= max(0.03 * longest.shape[0], 0.5 * np.count_nonzero(near))



def test_a_longer_observation_below_a_shorter_clip_is_dropped_whole_far_from_any_gate():
    # The shorter bracket clips red; the longer one (4x the exposure) reads every channel
    # far below its gates: it must have clipped, so it saw something else (a mover, a
    # misregistered edge). The kernel's resets drop its red alone; kept, its green and
    # blue stood beside the shorter brackets' red, a speck of no scene's colour (the
    # hand-held canal stack's laundry edge: (30, 28) from the longest frame, 442 in blue
    # from the shortest). The test drops it whole; the same codes with the shorter
    # bracket unclipped stay untested.
    short = np.array([[255, 80, 60], [200, 80, 60]])
    long = np.array([[90, 70, 50], [90, 70, 50]])
    codes = np.stack([short, long]).astype(np.uint8)
    dropped = dropped_observations(codes, _policy())
    assert list(dropped[1]) == [0b111, 0]
    assert not dropped_observations(codes, replace(_policy(), rule="channel")).any()
    # The kernel drops it as the test does: the pixel is the shorter bracket's alone.
    response, _ = gamma_inverse_response()
    stack = ExposureStack.from_arrays(codes[:, None], TIMES)
    merged, _ = merge_brackets(stack, response, domain="linear", policy=_policy())
    X = np.exp(response.log_inverse)
    for c in (1, 2):
        np.testing.assert_allclose(merged[0, 0, c], X[short[0, c], c] / TIMES[0], rtol=1e-5)
    # (Red: clipped in the shorter bracket, dropped from the longer: the lower bound.)
    assert merged[0, 0, 0] >= 0.99 * X[254, 0] / TIMES[0]

def test_masked_remerge_applies_the_clip_test_as_the_kernel():
    # Keep weights of (nearly) 1 give the kernel's merge: the re-merge drops the same
    # observations whole (deghosting, alignment's resampling and --mask re-merge through
    # it).
    from hdrio.merge.masked import remerge_masked
    from hdrio.radiometry.tables import merge_tables
    from tests.test_merge_kernel import _policy as kernel_policy
    from tests.test_merge_kernel import _response, _stack

    stack, response = _stack(255), _response(255)
    policy = kernel_policy(stack, response, "test neutral")
    merged, _ = merge_brackets(stack, response, domain="linear", policy=policy)
    terms, estimates = merge_tables(response, stack.exposures, "Debevec1997", "linear")
    again = merged.copy()
    keep = np.full((stack.count, 3, 5), 0.9999)
    remerge_masked(stack.codes, keep, 8, terms, estimates, policy, False, again)
    # The re-merge sums in float64, the kernel in float32 (1e-6), and the weights of
    # 0.9999 leave 1e-4 of a dropped observation's reset undone, of sums whose weights
    # can be 1e4 times those left after it in a dark pixel: measured 0.4 % at most, in 5
    # pixels of 2553 values; a channel dropped but kept (or kept but dropped) is off by
    # a factor (the neutral bound 64 against 0.01 before the re-merge followed the
    # shortest bracket's drops).
    np.testing.assert_allclose(again, merged, rtol=0.01)
    whole = dropped_observations(stack.codes.reshape(stack.count, -1, 3), policy) == 0b111
    assert whole[1:].any()  # the test dropped some observations whole here



def test_resampling_factors_widen_the_clip_test_and_never_turn_it_off():
    # Alignment's resampling factors (hdrio.align.resampling) lower a warped bracket's
    # weight where its resampling error outweighs its noise: f = noise / (noise +
    # resampling error). The bracket still saw the scene, so the clip test still reads
    # it, allowing a disagreement 1 / f times the variance more. The same factor on every
    # bracket scales every sum alike, so the re-merge is the kernel's merge under the
    # test at K / sqrt(f). The test once read the factored weight, and a factor under 0.5
    # on the shorter bracket switched it off there: the hand-held canal stack kept a
    # middle bracket's partly clipped red channel by channel along a boat's edge, a row
    # of cyan specks (red 55 beside green 1462).
    from dataclasses import replace

    from hdrio.merge.masked import remerge_masked
    from hdrio.radiometry.tables import merge_tables
    from tests.test_merge_kernel import _policy as kernel_policy
    from tests.test_merge_kernel import _response, _stack

    stack, response = _stack(255), _response(255)
    policy = kernel_policy(stack, response, "test neutral")
    factor = 0.3
    wider = replace(policy, tables=replace(policy.tables,
                                           sigmas=policy.tables.sigmas / np.sqrt(factor)))
    merged, _ = merge_brackets(stack, response, domain="linear", policy=wider)
    terms, estimates = merge_tables(response, stack.exposures, "Debevec1997", "linear")
    whole = dropped_observations(stack.codes.reshape(stack.count, -1, 3), wider) == 0b111
    assert whole[1:].any()  # the wider test still drops some observations whole here
    height, width = stack.codes.shape[1:3]
    keep = np.ones((stack.count, height, width))
    again = merged.copy()  # a channel saturated in every bracket keeps the kernel's bound
    factors = np.full((stack.count, height, width), factor, np.float32)
    remerge_masked(stack.codes, keep, 1, terms, estimates, policy, False, again,
                   factors=factors)
    # The re-merge sums in float64, the kernel in float32: 1e-5 relative.
    np.testing.assert_allclose(again, merged, rtol=1e-5)

def _canal(shared_data):
    folder = shared_data("hdrtoolbox_stacks")
    return sorted((folder / "alignment").glob("*.jpg")), folder / "exposures.csv"


_MERGED = {}


def _canal_merged(shared_data):
    """The default merge of the canal stack, merged once for this module's tests."""
    from hdrio.job.run import merge_paths

    files, exposures = _canal(shared_data)
    key = tuple(files)
    if key not in _MERGED:
        _MERGED[key] = merge_paths(files, exposures_from=exposures)
    return _MERGED[key]


def isolated_colour(preview: np.ndarray) -> np.ndarray:
    """Pixels of an ``(H, W, 3)`` preview (display values, 0-1) whose chromaticity
    (``rgb / (r + g + b)``) is more than 0.08 from its 5 x 5 median in some channel,
    where the pixel is brighter than 0.15 (a mean of the channels): coloured specks that
    no neighbour shares."""
    total = preview.sum(axis=-1, keepdims=True) + 1e-6
    chroma = preview / total
    median = np.stack([ndimage.median_filter(chroma[..., c], 5)
                       for c in range(chroma.shape[-1])], axis=-1)
    return (np.abs(chroma - median).max(axis=-1) > 0.08) & (preview.mean(axis=-1) > 0.15)


def sky_edge_hue(result) -> np.ndarray:
    """Hue angle differences (degrees) between the default preview and the preview of
    the best single unclipped bracket, at pixels within 3 px of the sky's edge.

    The best single bracket: at each pixel the longest whose every channel is inside the
    well-exposed range (below 95 % of the top code), else the shortest when not every
    channel is clipped there (its estimate of a clipped channel is the lower bound the
    merge keeps); through the merge's response, tone-mapped by the same operator. The
    sky: the regions clipped in every channel in the middle bracket that touch the
    image's top edge. Pixels whose best-bracket preview has a chroma under 0.02 have no
    hue to keep (:func:`hdrio.tools.synthetic.hue_angle_error`).
    """
    from hdrio.tonemap.preview import render_preview
    from hdrio.tools.synthetic import hue_angle_error

    codes = np.asarray(result.stack.codes)
    count, top = codes.shape[0], result.stack.code_max
    times = np.asarray(result.stack.exposures, dtype=np.float64)
    X = np.exp(result.response.log_inverse)
    limits = np.asarray(result.statistics.limits)
    best = np.full(codes.shape[1:3], -1)
    for j in range(count):
        best[np.all(codes[j] < 0.95 * top, axis=-1)] = j
    best[(best < 0) & ~np.all(codes[0] >= limits, axis=-1)] = 0
    reference = result.radiance.astype(np.float64).copy()
    for j in range(count):
        here = best == j
        for c in range(3):
            reference[..., c][here] = X[codes[j][..., c][here], c] / times[j]

    def preview(radiance):  # the 8-bit preview, back to linear light
        encoded = np.round(render_preview(radiance.astype(np.float32), "reinhard-global",
                                          result.options.colourspace, result.unseen) * 255)
        return srgb_decoded(encoded / 255)

    clipped = ndimage.binary_opening(np.all(codes[count // 2] == top, axis=-1))
    labels, _ = ndimage.label(clipped)
    sky = np.isin(labels, np.unique(labels[0][labels[0] > 0]))
    edge = ndimage.binary_dilation(sky, iterations=3) & ~ndimage.binary_erosion(
        sky, iterations=3) & (best >= 0)
    return hue_angle_error(preview(result.radiance), preview(reference), edge)


def test_canal_sky_edges_keep_the_hue_of_the_best_unclipped_bracket(shared_data):
    # The hand-held canal stack (hdrtoolbox alignment/): leaves and a pole against a sky
    # whose blue is at its limit even in the shortest bracket. The default preview had
    # a speckled yellow-green fringe along those edges: 335 of 3186 edge pixels more
    # than 10 degrees off the best single bracket's hue (the re-merge of alignment's
    # cells gave a channel clipped in every bracket the most-kept bracket's estimate of
    # its clipped code; partly clipped observations were kept channel by channel).
    result = _canal_merged(shared_data)
    error = sky_edge_hue(result)
    assert error.size > 3000
    # Measured: 9 pixels above 10 degrees (10-47 degrees: partly clipped observations
    # that agree with the shorter bracket within the test's 6 standard deviations, and
    # a few where the brackets disagree away from any clip; 12 before the test's reach,
    # REACH, dropped a 1 s frame's blue read below its clip where the 1/4 s frame says it
    # must clip), p99 1.9 degrees; the issue asks for none (docs/highlights.md says why
    # not). Bounds: what is measured, so that a fringe coming back (hundreds of pixels,
    # p99 tens of degrees) fails.
    assert np.count_nonzero(error > 10) <= 9
    assert np.percentile(error, 99) <= 4.0


def test_canal_has_no_coloured_specks_at_movers_and_warped_edges(shared_data):
    # Away from the sky, the hand-held canal stack's default preview had coloured specks
    # that no source shows: 143 isolated coloured pixels (isolated_colour) at 1a7ed23.
    # A row of cyan along a boat's edge (the re-merge of warped cells switched the clip
    # test off where the shorter bracket's resampling factor was under 0.5), and blue
    # along the flapping laundry's edges (the longest frame read dark red and green
    # where the shorter ones clipped blue, and was kept channel by channel): 56 after
    # the first fix, 26 after the second. Bound: 40, so that either undone fails (the
    # second undone: 56; the first: 141).
    from hdrio.tonemap.preview import render_preview

    result = _canal_merged(shared_data)
    preview = render_preview(result.radiance, "reinhard-global",
                             result.options.colourspace, result.unseen)
    specks = isolated_colour(np.asarray(preview, np.float64))
    assert np.count_nonzero(specks) <= 40, np.count_nonzero(specks)
