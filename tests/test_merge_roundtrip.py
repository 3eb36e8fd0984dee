"""Merging: the tutorial's saturation policy, and round trips on real scene radiance."""

from __future__ import annotations

import glob

import numpy as np
import pytest

import hdrio
from hdrio.merge.weighted_mean import merge_brackets
from hdrio.radiometry.curve import CameraResponse
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import radiance_error, render_brackets, tabulated_response, well_exposed

SCENES = ["CandleGlass", "Desk", "GoldenGate", "MtTamWest", "StillLife", "Tree"]
# Evenly spaced DoRF curves. Curves with a strong toe (e.g. 120, 200) reach 2.0-2.6 %
# median error: a known bias of the recovered g at low codes, tracked in docs/method.md.
DORF_CURVES = [0, 50, 100, 150]


def _gamma_response() -> CameraResponse:
    z = np.arange(256)
    g = 2.2 * np.log(np.maximum(z, 0.5) / 255.0)
    return CameraResponse(np.stack([g] * 3, axis=1), 255, np.ones((256, 3), bool))


def test_tutorial_saturation_policy_drops_bracket_and_longer_ones():
    # Pixel saturated (one channel at 255) in the 2nd bracket: only the 1st counts.
    codes = np.array([[[[100, 100, 100]]], [[[255, 120, 120]]], [[[255, 255, 255]]]], np.uint8)
    stack = ExposureStack.from_arrays(codes, [1.0, 4.0, 16.0])
    response = _gamma_response()
    radiance, stats = merge_brackets(stack, response, "tutorial-hat", saturation="pixel")
    expected = np.exp(response.log_inverse[100, 0]) / 1.0
    np.testing.assert_allclose(radiance[0, 0], expected, rtol=1e-6)  # float32 output
    assert stats.clipped_everywhere == 0


def test_channel_saturation_policy_keeps_the_unsaturated_channels():
    # Red saturates in the 2nd bracket; green and blue (code 120 there) keep it.
    codes = np.array([[[[100, 100, 100]]], [[[255, 120, 120]]], [[[255, 255, 255]]]], np.uint8)
    stack = ExposureStack.from_arrays(codes, [1.0, 4.0, 16.0])
    response = _gamma_response()
    radiance, _ = merge_brackets(stack, response, "tutorial-hat")
    g = response.log_inverse[:, 0]
    w100, w120 = 101.0, 121.0  # the tutorial hat: z + 1 below the midpoint
    green = np.exp((w100 * g[100] + w120 * (g[120] - np.log(4.0))) / (w100 + w120))
    np.testing.assert_allclose(radiance[0, 0], [np.exp(g[100]), green, green], rtol=1e-6)


def test_saturated_everywhere_takes_shortest_estimate():
    codes = np.full((3, 2, 2, 3), 255, np.uint8)
    stack = ExposureStack.from_arrays(codes, [1.0, 4.0, 16.0])
    for domain in ("log", "linear"):
        radiance, stats = merge_brackets(stack, _gamma_response(), "Debevec1997", domain)
        np.testing.assert_allclose(radiance, 1.0, rtol=1e-6)  # g(255) = 0, dt = 1
        assert stats.clipped_everywhere == 4


def test_black_everywhere_with_zero_weights_is_finite_and_positive():
    codes = np.zeros((3, 2, 2, 3), np.uint8)
    stack = ExposureStack.from_arrays(codes, [1.0, 4.0, 16.0])
    radiance, stats = merge_brackets(stack, _gamma_response(), "Debevec1997")
    assert np.all(np.isfinite(radiance)) and np.all(radiance > 0)
    assert stats.black_everywhere == 4


@pytest.fixture(scope="module")
def dorf(shared_data):
    import scipy.io

    folder = shared_data("crf_database")
    table = scipy.io.loadmat(folder / "dorf" / "201_CRF_data.mat")
    return table["I"], table["B"]


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.slow
def test_round_trip_on_real_radiance(scene, dorf, shared_data):
    import OpenImageIO as oiio

    path = shared_data("openexr_scenes") / f"{scene}.exr"
    truth = np.maximum(oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[..., :3], 0)
    key = np.exp(np.mean(np.log(1e-4 + truth.mean(axis=-1))))
    times = 0.18 / key * 4.0 ** (np.arange(7) - 3)  # 7 exposures, 2 EV apart
    irradiance, brightness = dorf
    for curve in DORF_CURVES:
        codes = render_brackets(truth, times, tabulated_response(irradiance[curve],
                                                                 brightness[curve]),
                                shot_noise=3e-5, read_noise=2e-4, seed=curve)
        result = hdrio.merge_stack(ExposureStack.from_arrays(codes, times))
        assert np.all(np.isfinite(result.radiance)) and np.all(result.radiance > 0)
        error = radiance_error(result.radiance, truth, well_exposed(codes, 255))
        # The bound: median relative error <= 2 % after one global scale.
        assert error["median"] <= 0.02, (scene, curve, error)


@pytest.mark.slow
def test_memorial_merge_and_opencv_reference(shared_data, tmp_path):
    from hdrio.cli import main
    from hdrio.io.header import read_header

    folder = shared_data("memorial_debevec")
    output = tmp_path / "memorial.exr"
    code = main(["merge", "-q", *sorted(glob.glob(str(folder / "memorial00*.png"))),
                 "--exposures-from", str(folder / "exposures.csv"),
                 "--exclude-color", "0,0,255", "-o", str(output)])
    assert code == 0
    import OpenEXR

    exr = OpenEXR.File(str(output))  # OpenEXR's own reader, beside OpenImageIO's below
    assert exr.channels()["RGB"].pixels.shape == (768, 512, 3)
    assert len(exr.header()["chromaticities"]) == 8
    assert len(exr.header()["hdrio:responseG"]) == 256
    header = read_header(output)
    assert len(header["chromaticities"]) == 8 and header["hdrio:exposureSource"] == "sidecar"
    assert len(header["hdrio:sourceFiles"]) == 16
    ours = np.exp(np.stack([header[f"hdrio:response{c}"] for c in "RGB"], axis=1))
    reference = np.loadtxt(folder / "reference" / "opencv_extra_calibrate_debevec.csv",
                           delimiter=",")[:, ::-1]  # stored B, G, R
    z = np.arange(256)
    well = (z >= 20) & (z <= 235)
    for c in range(3):
        scale = np.exp(np.median(np.log(reference[well, c] / ours[well, c])))
        relative = np.abs(scale * ours[well, c] - reference[well, c]) / reference[well, c]
        # Median within OpenCV's 10 % (measured 4.2-5.6 %). The pointwise maximum is 35-42 %:
        # the stored curve (70 samples, lambda 10) wiggles by +-0.3 stops between codes and
        # OpenCV 5's own CalibrateDebevec misses it by 26-63 % (docs/method.md).
        assert np.median(relative) <= 0.10, (c, np.median(relative), relative.max())


def test_solver_reproduces_opencv_calibrate_debevec_on_its_samples(shared_data):
    # Same samples (OpenCV's default grid of 70 points), same settings (lambda 10, the
    # never-zero hat = OpenCV's triangleWeights): hdrio's solve must agree with
    # cv2.createCalibrateDebevec run here, within OpenCV's own test tolerance of 10 %
    # over the well-exposed codes 20-235 (measured 1.7-7.0 %; OpenCV solves in float32).
    cv2 = pytest.importorskip("cv2", reason="OpenCV is a benchmark extra: pip install .[bench]")
    from hdrio.radiometry.weighting import weighting_tutorial_hat
    from hdrio.response.debevec1997 import g_solve_Debevec1997

    folder = shared_data("memorial_debevec")
    images = [cv2.imread(f) for f in sorted(glob.glob(str(folder / "memorial00*.png")))]
    times = np.array([32 / 2**k for k in range(16)], np.float32)
    expected = cv2.createCalibrateDebevec().process(images, times).reshape(256, 3)
    height, width = images[0].shape[:2]
    x_points = int(np.sqrt(70 * width / height))
    step_x, step_y = width // x_points, height // (70 // x_points)
    points = [(x, y) for x in range(step_x // 2, step_x // 2 + step_x * x_points, step_x)
              for y in range(step_y // 2, step_y // 2 + step_y * (70 // x_points), step_y)]
    weights = weighting_tutorial_hat(np.arange(256))
    well = slice(20, 236)
    for c in range(3):  # OpenCV's B, G, R
        Z = np.array([[image[y, x, c] for image in images] for x, y in points])
        g, _ = g_solve_Debevec1997(Z, np.log(times.astype(np.float64)), 10.0, weights)
        relative = np.abs(np.exp(g[well]) - expected[well, c]) / expected[well, c]
        assert relative.max() <= 0.10, (c, relative.max())
