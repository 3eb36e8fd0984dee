"""Frames that share an exposure: a ladder capped by the camera's shortest or longest
shutter time, a burst of one exposure. Each frame is merged as an observation of it;
one image given twice, or a different picture at a repeated exposure, is refused
(:func:`hdrio.merge.ladder.check_repeated_exposures`).

Until 2026-11-29 every repeat was refused ("every bracket needs its own exposure"), so a
ladder the camera had capped could not be merged at all."""

from __future__ import annotations

import shutil

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from hdrio.errors import InputError, ResponseSolveError
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_stack
from hdrio.merge.ladder import REPEAT_AGREEMENT, picture_difference
from hdrio.stack import ExposureStack, distinct_exposures, repeated_exposures
from hdrio.tools.synthetic import radiance_error, well_exposed
from tests.hard_cases import _camera, _render, hand_held, ladder, scene_crop


@pytest.fixture(autouse=True)
def _scenes(shared_data):
    shared_data("openexr_scenes")  # the generated frames render its photographs


def _scene():
    return scene_crop("Desk", 200, 300)


def _capped(times: np.ndarray, end: str) -> np.ndarray:
    """A 7-frame ladder whose shortest (``short``) or longest (``long``) exposure the
    camera could not reach: the frame before (after) it repeated."""
    return np.r_[times[0], times[:-1]] if end == "short" else np.r_[times[1:], times[-1]]


def test_repeats_are_the_exposures_within_one_percent():
    exposures = [1.0, 1.005, 2.0, 4.0, 4.0, 4.02, 8.0]
    assert repeated_exposures(exposures) == [(0, 1), (3, 4, 5)]
    assert distinct_exposures(exposures) == 4
    assert repeated_exposures([1.0, 1.02, 2.0]) == []  # 2 % apart: a third of a stop is 26 %
    assert distinct_exposures([0.5, 0.5]) == 1


@pytest.mark.parametrize("encoding", ["png", "jpeg", "16-bit"])
@pytest.mark.parametrize("end", ["short", "long"])
def test_a_ladder_capped_by_the_shutter_merges_every_frame(encoding, end):
    # Seven frames of which two share the capped exposure, against the six different
    # exposures alone: the repeat adds an observation of what its twin saw. Measured
    # median error 0.92-1.02x the six frames' (p99 0.84-0.995x); bound 1.03: the
    # response's solve also draws other samples from seven frames than from six. A still
    # stack with a repeat is left as it is: nothing deghosted, the pixels of --deghost
    # off (issue 28).
    scene = _scene()
    times = ladder(scene, 7)
    capped = _render("capped", [scene] * 7, _capped(times, end), _camera(encoding), 0)
    plain = _render("plain", [scene] * 6, times[:-1] if end == "short" else times[1:],
                    _camera(encoding), 0)
    result = merge_stack(capped.stack(), MergeOptions())
    alone = merge_stack(plain.stack(), MergeOptions())
    everywhere = np.ones(scene.shape[:2], bool)
    error = radiance_error(result.radiance, scene, everywhere)["median"]
    assert error <= 1.03 * radiance_error(alone.radiance, scene, everywhere)["median"]
    assert result.motion.deghosting.fraction == 0.0
    off = merge_stack(capped.stack(), MergeOptions(deghost="off"))
    assert np.array_equal(result.radiance, off.radiance)


def test_a_capped_hand_held_ladder_registers_every_frame():
    # hand_held(7, 0) with its shortest exposure repeated (the frames' own views kept):
    # every frame registered within 0.20 px of its true warp (seeds 0-4: 0.10-0.54 px),
    # the merge's median error 1.20x the same stack held still (seeds 0-4: 1.19-1.29x;
    # the ladder without the repeat: 1.21-1.27x). Bounds: 1 px, and issue 28's 1.3x.
    moving, still = hand_held(7, 0), hand_held(7, 0, still=True)
    times = _capped(moving.exposures, "short")
    moving = _render("capped", moving.scenes, times, moving.camera, 0, moving.warps)
    still = _render("capped_still", still.scenes, times, still.camera, 0, still.warps)
    result = merge_stack(moving.stack(), MergeOptions())
    held = merge_stack(still.stack(), MergeOptions())
    alignment = result.motion.alignment
    assert not alignment.refused
    assert max(moving.corner_errors(alignment)) <= 1.0
    inner = np.zeros(moving.codes.shape[1:3], bool)
    inner[16:-16, 16:-16] = True
    inner &= well_exposed(still.codes, still.camera.code_max)
    moved = radiance_error(result.radiance, moving.truth_in(alignment.reference), inner)
    base = radiance_error(held.radiance, still.truth_in(alignment.reference), inner)
    assert moved["median"] <= 1.3 * base["median"]


def test_exposures_from_the_data_keep_a_repeat_together():
    # --exposures-from-data estimates each frame's exposure: the twins' estimates may
    # fall either side of each other, which is no contradiction of the order. Measured:
    # every estimate within 0.0011 stop of the metadata; bound 0.05 stop (the estimates'
    # own error on a generated stack, hdrio.merge.exposure_check.TEST_STOPS).
    scene = _scene()
    times = _capped(ladder(scene, 7), "short")
    case = _render("capped", [scene] * 7, times, _camera("png"), 0)
    result = merge_stack(case.stack(), MergeOptions(exposures_from_data=True))
    check = result.exposures
    assert np.all(np.abs(np.log2(check.estimated / check.metadata)) <= 0.05)
    # The shutter's jitter: the second frame of the repeat shot 10 % shorter than its
    # twin, the metadata the same. The data say so; the stack keeps its order (the
    # later twin takes the earlier one's estimate) instead of stopping the merge.
    shot = times.copy()
    shot[1] *= 0.9
    jittered = _render("jittered", [scene] * 7, shot, _camera("png"), 0)
    stack = ExposureStack.from_arrays(jittered.codes, times)
    result = merge_stack(stack, MergeOptions(exposures_from_data=True))
    assert result.exposures.estimated[1] < 0.95 * result.exposures.estimated[0]
    assert result.stack.exposures[1] == result.stack.exposures[0]
    assert np.all(np.diff(result.stack.exposures) >= 0)


def test_a_burst_of_one_exposure_merges_through_a_known_response():
    # Linear 16-bit frames all at one exposure: no response can be solved from them (the
    # solve once returned a curve 97 % off at the median), and through the linear one
    # four frames average the noise of two by 1/sqrt(2) (measured 0.707x; bound 0.75x).
    scene = _scene()
    exposure = ladder(scene, 7)[3]

    def burst(count):
        return _render(f"burst{count}", [scene] * count, [exposure] * count,
                       _camera("16-bit"), 0)

    with pytest.raises(ResponseSolveError, match="same exposure .*--response linear"):
        merge_stack(burst(4).stack(), MergeOptions())
    lit = well_exposed(burst(2).codes[:1], 65535)
    errors = [radiance_error(merge_stack(burst(n).stack(), MergeOptions(response="linear"))
                             .radiance, scene, lit)["median"] for n in (2, 4)]
    assert errors[1] <= 0.75 * errors[0]


def test_one_image_given_twice_is_refused_naming_both(tmp_path):
    scene = _scene()
    times = ladder(scene, 3)
    case = _render("twice", [scene] * 3, times, _camera("png"), 0)
    codes = np.concatenate([case.codes[:1], case.codes])
    stack = ExposureStack.from_arrays(codes, np.r_[times[0], times],
                                      files=["a.png", "copy of a.png", "b.png", "c.png"])
    with pytest.raises(InputError, match="the same pixels as a.png") as error:
        merge_stack(stack, MergeOptions())
    assert error.value.path == "copy of a.png"


@pytest.mark.parametrize("encoding", ["png", "jpeg", "16-bit"])
def test_a_repeat_is_told_from_another_exposure_and_another_picture(encoding):
    # The measure the check reads (hdrio.merge.ladder.REPEAT_AGREEMENT, 0.07): two frames
    # of one exposure 0.001-0.016 here, a third of a stop apart 0.10-0.21, another scene
    # 0.64-1.17. Bounds: the agreement with the margins measured on each side.
    scene = _scene()
    exposure = ladder(scene, 7)[3]
    camera = _camera(encoding)
    same = _render("same", [scene] * 2, [exposure] * 2, camera, 1).codes
    apart = _render("apart", [scene] * 2, [exposure, exposure * 2 ** (1 / 3)], camera,
                    2).codes
    other = scene_crop("StillLife", 200, 300)
    scale = np.exp(np.mean(np.log(1e-4 + scene.mean(-1)))) / np.exp(
        np.mean(np.log(1e-4 + other.mean(-1))))
    elsewhere = _render("other", [scene, other], [exposure, exposure * scale], camera,
                        3).codes
    code_max = camera.code_max
    assert picture_difference(same[0], same[1], code_max) <= 0.5 * REPEAT_AGREEMENT
    assert picture_difference(apart[0], apart[1], code_max) >= 1.4 * REPEAT_AGREEMENT
    assert picture_difference(elsewhere[0], elsewhere[1], code_max) >= 0.5


def _write_png(path, codes):
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(codes.shape[1], codes.shape[0], 3, "uint8"))
    out.write_image(np.ascontiguousarray(codes))
    out.close()


def test_the_command_says_which_frames_share_an_exposure(tmp_path, capsys):
    from hdrio.cli import main

    scene = _scene()
    times = _capped(ladder(scene, 5), "short")
    case = _render("capped", [scene] * 5, times, _camera("png"), 0)
    paths = [tmp_path / f"frame{j}.png" for j in range(5)]
    for path, codes in zip(paths, case.codes):
        _write_png(path, codes)
    exr = tmp_path / "capped.exr"
    given = ",".join(f"{t:.9g}" for t in times)
    code = main(["merge", *map(str, paths), "--exposures", given, "-o", str(exr)])
    out = capsys.readouterr().out
    assert code == 0
    assert "repeated:  frame0.png, frame1.png at 1/" in out
    header = OpenEXR.File(str(exr)).header()
    assert len(header["hdrio:exposures"]) == 5
    assert header["hdrio:exposures"][0] == header["hdrio:exposures"][1]
    # A copy of a frame under another name is one image given twice: nothing written.
    shutil.copy(paths[0], tmp_path / "copy.png")
    again = tmp_path / "again.exr"
    code = main(["merge", str(tmp_path / "copy.png"), *map(str, paths[:1] + paths[2:]),
                 "--exposures", ",".join(f"{t:.9g}" for t in times), "-o", str(again)])
    err = capsys.readouterr().err
    assert code == 2 and "the same pixels as" in err
    assert not again.exists()


def test_a_repeat_is_not_a_pair_of_the_noise_fit():
    # Two JPEG frames of one exposure share the response's error and the quantisation
    # of one picture, so they disagree by less than two brackets do: fitted with that
    # pair, a Desk ladder with one exposure repeated predicted its other pairs'
    # disagreement 4-18 % lower than the plain ladder's model does (the median of
    # measured over predicted per channel, benchmarks.noise_model's deciles: 1.15, 1.20,
    # 1.27 against 1.11, 1.13, 1.08); left out, within 0.04 of it. Bound: 8 %.
    from benchmarks.noise_model import disagreement_deciles

    scene = _scene()
    times = ladder(scene, 7)

    def spreads(codes, exposures, result):
        ratios, _ = disagreement_deciles(codes, exposures, result.response, result.noise,
                                         result.statistics.limits)
        return np.nanmedian(ratios, axis=1)

    repeated = merge_stack(_render("repeat", [scene] * 8, np.r_[times[:4], times[3:]],
                                   _camera("jpeg"), 0).stack(), MergeOptions())
    distinct = [0, 1, 2, 3, 5, 6, 7]  # the twin left out: the pairs of distinct exposures
    measured = spreads(np.asarray(repeated.stack.codes)[distinct],
                       repeated.stack.exposures[distinct], repeated)
    plain = merge_stack(_render("plain", [scene] * 7, times, _camera("jpeg"), 0).stack(),
                        MergeOptions())
    expected = spreads(np.asarray(plain.stack.codes), plain.stack.exposures, plain)
    assert np.all(np.abs(measured / expected - 1) <= 0.08), (measured, expected)
