"""--highlights reconstruct (hdrio.merge.highlights): channels clipped in every bracket
estimated from the unclipped ones and the colour around the clip."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.merge.highlights import border_chromaticity
from hdrio.merge.weighted_mean import clipped_everywhere_mask
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import gamma_inverse_response, hue_angle_error, render_brackets

LAMP = np.array([1.0, 0.45, 0.12])  # an orange lamp (linear Rec. 709, relative)
PEAK = 1e5  # its centre, relative to a background of 0.05 .. 2
TIMES = [4e-4 * 4.0**k for k in range(5)]  # R clips where E_R > 2500 even in the shortest


def lamp_scene(height: int = 96, width: int = 128) -> np.ndarray:
    """``(H, W, 3)``: a grey ramp with an orange lamp whose red clips in every bracket
    out to 16 px from its centre, green to 14 px and blue to 11 px (a fully clipped core
    inside a partly clipped ring); its glow is unclipped in the shortest bracket beyond."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    background = 0.05 * 40.0 ** (x / (width - 1))
    glow = PEAK * np.exp(-((x - 64.0) ** 2 + (y - 48.0) ** 2) / (2 * 6.0**2))
    return background[..., None] + glow[..., None] * LAMP


def _chromaticity_error(estimate, truth, mask) -> np.ndarray:
    """``|(r, g) - (r, g)_true|`` over ``mask``: r, g = R, G over R + G + B."""
    def rg(rgb):
        rgb = np.asarray(rgb, dtype=np.float64)[mask]
        return rgb[:, :2] / rgb.sum(axis=-1, keepdims=True)
    return np.linalg.norm(rg(estimate) - rg(truth), axis=-1)


def _merge(highlights: str, saturation: str = "auto", seed: int = 3):
    scene = lamp_scene()
    codes = render_brackets(scene, TIMES, seed=seed)
    stack = ExposureStack.from_arrays(codes, TIMES, files=[f"f{j}.png" for j in range(5)])
    response, _ = gamma_inverse_response()
    options = MergeOptions(highlights=highlights, saturation=saturation, align="off",
                           deghost="off")
    return scene, merge_stack(stack, options, response=response)


@pytest.mark.parametrize("saturation", ["auto", "safe"])
def test_lamp_hue_is_restored_and_nothing_is_darker(saturation):
    scene, clip = _merge("clip", saturation)
    _, rebuilt = _merge("reconstruct", saturation)
    limits = clip.statistics.limits
    shortest = clip.stack.codes[0]
    region = clipped_everywhere_mask(shortest, limits) > 0
    fully = np.all(shortest >= np.asarray(limits), axis=-1)
    partly = region & ~fully
    assert partly.sum() > 100 and fully.sum() > 100  # the scene has both
    # Chromaticity (r, g) = (R, G) / (R + G + B) against the truth's, p99 over the
    # clipped pixels: clip 0.307 (the lamp's whole chroma: neutral, or red at its bound),
    # reconstruct 0.0020-0.0022 (auto, per channel) and 0.0007-0.0010 (safe) on seeds 3-5.
    # 0.01 (3 % of the lamp's chroma, about 2 degrees of hue) leaves room for the ring's
    # share of grey background and noise; clip is 30x beyond it.
    assert np.percentile(_chromaticity_error(clip.radiance, scene, region), 99) > 0.25
    assert np.percentile(_chromaticity_error(rebuilt.radiance, scene, region), 99) < 0.01
    if not clip.statistics.policy.neutral:  # clip keeps the partly clipped pixels' hue angle
        # Measured: 53.8 degrees p99 (red at its bound), 0.35 reconstructed.
        assert np.percentile(hue_angle_error(rebuilt.radiance, scene, partly), 99) < 2.0
    out = rebuilt.radiance
    assert np.isfinite(out).all() and (out > 0).all()
    np.testing.assert_array_equal(out[~region], clip.radiance[~region])  # only the clip
    lost = shortest >= np.asarray(limits)
    if not clip.statistics.policy.neutral:  # the merge's values are each channel's own bound
        assert (out[partly] >= clip.radiance[partly])[lost[partly]].all()
    # Fully clipped: never darker than the neutral bound (the channels' mean).
    assert (out[fully].mean(-1) >= clip.radiance[fully].mean(-1) * (1 - 1e-6)).all()
    # Red of the clipped lamp, against the truth (scaled as the unclipped pixels are):
    # median 0.165 with clip (a lower bound), 0.985 reconstructed. 15 % either side:
    # the core is reconstructed at the least brightness its clipped blue allows.
    scale = np.median(clip.radiance[~region] / scene[~region])
    assert np.median(clip.radiance[region][:, 0] / scale / scene[region][:, 0]) < 0.3
    assert 0.85 < np.median(out[region][:, 0] / scale / scene[region][:, 0]) < 1.15
    assert rebuilt.highlights is not None
    assert rebuilt.highlights.partly == partly.sum()
    assert rebuilt.highlights.fully == fully.sum()


def test_default_is_clip_and_bit_identical():
    assert MergeOptions().highlights == "clip"
    _, default = _merge("clip")
    scene = lamp_scene()
    codes = render_brackets(scene, TIMES, seed=3)
    stack = ExposureStack.from_arrays(codes, TIMES, files=[f"f{j}.png" for j in range(5)])
    response, _ = gamma_inverse_response()
    plain = merge_stack(stack, MergeOptions(align="off", deghost="off"), response=response)
    assert plain.radiance.tobytes() == default.radiance.tobytes()
    assert plain.highlights is None


def test_nothing_clipped_is_skipped_and_said():
    scene = lamp_scene() * 1e-4  # the lamp within range in the shortest bracket
    codes = render_brackets(scene, [0.05, 0.2, 0.8], seed=1)
    stack = ExposureStack.from_arrays(codes, [0.05, 0.2, 0.8], files=["a.png", "b.png",
                                                                     "c.png"])
    response, _ = gamma_inverse_response()
    options = MergeOptions(align="off", deghost="off")
    plain = merge_stack(stack, options, response=response)
    assert plain.statistics.clipped_everywhere == 0
    rebuilt = merge_stack(stack, MergeOptions(align="off", deghost="off",
                                              highlights="reconstruct"), response=response)
    assert rebuilt.highlights is None and rebuilt.skipped.highlights
    assert any("highlight reconstruction" in line for line in rebuilt.skipped.lines(3))
    assert rebuilt.radiance.tobytes() == plain.radiance.tobytes()


def test_border_chromaticity_takes_each_region_its_own_ring():
    values = np.ones((40, 60, 3))
    values[:, :30] = [2.0, 1.0, 1.0]  # reddish left half, neutral right half
    mask = np.zeros((40, 60), dtype=bool)
    mask[15:25, 8:14] = True  # inside the red half
    mask[15:25, 44:50] = True  # inside the neutral half
    rho, regions = border_chromaticity(values, mask)
    assert regions == 2
    labels = mask[mask]  # row-major order: left region first in each row
    left = np.zeros(mask.shape, bool)
    left[:, :30] = True
    on_left = left[mask]
    np.testing.assert_allclose(rho[on_left], [[0.5, 0.25, 0.25]] * on_left.sum())
    np.testing.assert_allclose(rho[~on_left], [[1 / 3] * 3] * (~on_left).sum())
    assert labels.all()


def test_unknown_mode_is_refused():
    scene = lamp_scene()
    codes = render_brackets(scene, TIMES[:2], seed=1)
    stack = ExposureStack.from_arrays(codes, TIMES[:2], files=["a.png", "b.png"])
    with pytest.raises(ValueError, match="highlights 'inpaint'"):
        merge_stack(stack, MergeOptions(highlights="inpaint"))


def test_groups_of_blocks_give_what_the_whole_image_as_one_box_gives():
    # Lamps far apart (three groups of blocks) and an L-shaped clip: each region and
    # its ring lie in one group, so cutting the image into groups changes nothing.
    from hdrio.merge.highlights import _reconstruct_box, clip_groups, reconstruct_highlights
    from hdrio.radiometry.tables import estimate_tables

    scene = lamp_scene(256, 320)
    y, x = np.mgrid[0:256, 0:320]
    scene[(y > 230) & (x < 60)] += 4e4 * np.array([0.3, 1.0, 0.6])  # the L's foot
    scene[(x < 12) & (y > 200)] += 4e4 * np.array([0.3, 1.0, 0.6])  # and its stem
    scene[20:26, 250:256] += 3e4 * np.array([1.0, 0.2, 0.9])  # a small magenta lamp
    codes = render_brackets(scene, TIMES, seed=2)
    stack = ExposureStack.from_arrays(codes, TIMES, files=[f"f{j}.png" for j in range(5)])
    response, _ = gamma_inverse_response()
    result = merge_stack(stack, MergeOptions(align="off", deghost="off"), response=response)
    limits = np.asarray(result.statistics.limits)
    estimates = estimate_tables(response, stack.channel_exposures, "linear")[0]
    clipped = np.any(codes[0] >= limits, axis=-1)
    boxes = list(clip_groups(clipped))
    assert len(boxes) >= 3
    grouped = result.radiance.copy()
    reconstruct_highlights(grouped, codes[0], limits, estimates, False)
    whole = result.radiance.copy()
    bound = estimates[limits, np.arange(3)]
    _reconstruct_box(whole, codes[0], limits, clipped, ~clipped, bound, estimates, False)
    np.testing.assert_array_equal(grouped, whole)
    assert not np.array_equal(grouped, result.radiance)
