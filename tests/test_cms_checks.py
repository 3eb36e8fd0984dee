"""``hdrio check``: each check against a case whose answer is known."""

from __future__ import annotations

import colour
import numpy as np
import OpenImageIO as oiio
import pytest

from hdrio.cli import main
from hdrio.cms.chart import COLORCHECKER
from hdrio.cms.checks import REC709_D65, check_exr, check_pixels
from hdrio.cms.spaces import chromaticities
from hdrio.errors import HdrioError
from hdrio.io.write import write_exr

ACESCG = chromaticities("ACEScg")


def chart_image(scale: float = 3.7) -> np.ndarray:
    """An 80x60 Rec.709 image holding the ColorChecker's reference colours at (10, 8)."""
    chart = colour.CCS_COLOURCHECKERS[COLORCHECKER]
    rgb = colour.XYZ_to_RGB(colour.xyY_to_XYZ(np.asarray(list(chart.data.values()))),
                            "ITU-R BT.709", chart.illuminant,
                            chromatic_adaptation_transform="Bradford")
    image = np.full((60, 80, 3), 0.05)
    for k, patch in enumerate(rgb):
        row, column = divmod(k, 6)
        image[8 + 10 * row: 8 + 10 * (row + 1), 10 + 10 * column: 10 + 10 * (column + 1)] = patch
    return image * scale


def test_chart_at_reference_values_has_no_colour_error():
    report = check_pixels(chart_image(), REC709_D65, chart=(10, 8, 60, 40))
    # Same colours at an unknown exposure: only float rounding remains (< 1e-6 Delta E).
    assert max(report.delta_E) < 1e-6


def test_chart_error_lands_on_the_wrong_patch():
    image = chart_image()
    image[8:18, 20:30] *= [1.15, 1.0, 1.0]  # patch 2, light skin, 15 % too red
    dE = check_pixels(image, REC709_D65, chart=(10, 8, 60, 40)).delta_E
    assert int(np.argmax(dE)) == 1 and dE[1] > 2.0  # 15 % in R is clearly visible
    assert max(dE[:1] + dE[2:]) < 1e-6


def test_chart_region_outside_the_image_is_refused():
    with pytest.raises(HdrioError, match="chart region 50,40,60,40 must lie inside the 80x60"):
        check_pixels(chart_image(), REC709_D65, chart=(50, 40, 60, 40))


def test_range_negatives_and_non_finite_are_counted():
    rgb = np.ones((4, 256, 3))
    rgb[:, :, :] *= (2.0 ** np.linspace(0, 10, 256))[None, :, None]  # 1 .. 1024: 10 stops
    rgb[0, 0] = [np.nan, 1, 1]
    rgb[0, 1] = [np.inf, 1, 1]
    rgb[1, 0] = [-0.5, 1, 1]
    report = check_pixels(rgb)
    assert report.non_finite == 2 and report.negative == 1
    # Luminance spans the negative-red pixel's Y (about 0.681, the lowest) to 2**10;
    # exact up to float rounding (1e-9 stops).
    weights = colour.normalised_primary_matrix([[0.64, 0.33], [0.3, 0.6], [0.15, 0.06]],
                                               [0.3127, 0.329])[1]
    lowest = float(np.dot(weights, [-0.5, 1.0, 1.0]))
    assert report.dynamic_range_stops == pytest.approx(np.log2(1024 / lowest), abs=1e-9)


def test_luminance_uses_the_files_own_primaries(tmp_path):
    red = np.zeros((4, 4, 3), dtype=np.float32)
    red[..., 0] = 1.0
    path = write_exr(tmp_path / "red.exr", red, {"chromaticities": ACESCG}, pixel_type="float")
    report = check_exr(path)
    expected = colour.RGB_COLOURSPACES["ACEScg"].matrix_RGB_to_XYZ[1, 0]  # Y of AP1 red
    # Chromaticities are stored as float32: Y agrees to 1e-6.
    assert report.luminance_percentiles["median"] == pytest.approx(expected, abs=1e-6)
    assert report.units == "unknown" and report.notes == []


def test_out_of_gamut_fraction_for_a_target_space():
    rgb = np.full((10, 10, 3), 0.2)
    rgb[:3] = [0.0, 1.0, 0.0]  # ACEScg green lies outside Rec.709
    report = check_pixels(rgb, ACESCG, gamut="ITU-R BT.709")
    assert report.out_of_gamut == pytest.approx(0.3)
    assert check_pixels(rgb, ACESCG).out_of_gamut == 0.0  # inside its own primaries


def test_hdrio_check_command(tmp_path, capsys):
    path = write_exr(tmp_path / "chart.exr", chart_image(), {"hdrio:clippedFraction": 0.25})
    assert main(["check", str(path), "--chart", "10,8,60,40", "--gamut", "ACEScg"]) == 0
    out = capsys.readouterr().out
    assert f"check:     {path}" in out
    assert "clipped:      25.00 % of pixels saturated in every bracket" in out
    assert "no chromaticities: assumed Rec.709" in out
    # Half floats (the default) round to 2**-11: Delta E stays well below 0.5.
    mean = float(out.split("Delta E 2000 mean ")[1].split(",")[0])
    assert mean < 0.5
    assert main(["check", str(tmp_path / "missing.exr")]) == 2
    assert "missing.exr: no such file" in capsys.readouterr().err


def test_frobisher_colorchecker_delta_e(shared_data, tmp_path):
    from hdrio.job.run import merge_files

    files = sorted(shared_data("frobisher_001").glob("IMG_26*.jpg"))
    path = tmp_path / "frobisher.exr"
    merge_files(files, path)
    chart = (404, 212, 37, 23)  # the Passport's 24-patch half: about 6 x 6 pixels a patch
    mean = float(np.mean(check_exr(path, chart=chart).delta_E))
    # A camera JPEG's rendering of a tiny chart under room light: measured 7.3. The same
    # patches read in the wrong order (chart mirrored) give about 40, so 12 separates a
    # correctly read chart from a misread one.
    assert mean < 12.0
    image = oiio.ImageInput.open(str(path))
    mirrored = np.asarray(image.read_image("float"))[:, ::-1]
    image.close()
    width = mirrored.shape[1]
    wrong = check_pixels(mirrored, chart=(width - 404 - 37, 212, 37, 23)).delta_E
    assert float(np.mean(wrong)) > 25.0
