"""Absolute luminance: EXIF meter equation, user references, and the frobisher acceptance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdrio.cms.calibration import (
    Calibration,
    exif_scale,
    meter_luminance,
    reference_code,
    region_mean_luminance,
)
from hdrio.errors import HdrioError, InputError
from hdrio.io.brackets import read_brackets
from hdrio.io.header import read_header
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files, merge_stack
from hdrio.radiometry.luminance import luminance

EXPOSURES = (1 / 16, 1 / 4, 1.0, 4.0)


def exif(seconds: float, f_number: float = 8.0, iso: int = 100) -> dict[str, object]:
    """EXIF attributes as OpenImageIO writes them into a PNG."""
    return {"ExposureTime": seconds, "FNumber": f_number, "Exif:PhotographicSensitivity": iso}


def test_meter_equation():
    # f/8, 1 s, ISO 100, K = 12.5: 12.5 * 64 / 100 = 8 cd/m^2 (exact in binary floats).
    assert meter_luminance(8.0, 1.0, 100.0) == 8.0
    assert meter_luminance(8.0, 1.0, 100.0, K=14.0) == pytest.approx(8.96, rel=1e-15)
    assert reference_code(255) == 118 and reference_code(65535) == 30326


def test_exif_scale_puts_the_reference_code_at_the_meter_luminance(write_brackets):
    paths = write_brackets(EXPOSURES, attributes=[exif(t, 4.0, 200) for t in EXPOSURES])
    stack = read_brackets(paths)
    result = merge_stack(stack)
    scales = exif_scale(stack, result.response, "ITU-R BT.709")
    # Every bracket implies the same factor: exact up to float rounding (1e-12).
    assert np.ptp(scales) <= 1e-12 * scales.max()
    reference = result.response.linearise(np.full((1, 3), 118))
    # A pixel at code 118 in the 1 s bracket has E = f^-1(118) / 1 s, and must read as
    # K N^2 / (t S) = 12.5 * 16 / 200 = 1 cd/m^2; 1e-6 is float rounding.
    assert float(luminance(reference, "ITU-R BT.709")[0]) * scales[2] == pytest.approx(
        meter_luminance(4.0, 1.0, 200.0), rel=1e-6)


def test_doubling_iso_halves_luminance(write_brackets, tmp_path):
    cd = {}
    for iso in (100, 200):
        paths = write_brackets(EXPOSURES, folder=tmp_path / str(iso),
                               attributes=[exif(t, 8.0, iso) for t in EXPOSURES])
        result = merge_stack(read_brackets(paths), MergeOptions(calibration=Calibration()))
        cd[iso] = result.colour.luminance_scale
    # Same pixels, same response: the factor is the meter equation's 1/S exactly (1e-9).
    assert cd[200] / cd[100] == pytest.approx(0.5, rel=1e-9)


def test_exif_calibration_without_iso_names_the_file(write_brackets):
    paths = write_brackets(EXPOSURES, attributes=[{"ExposureTime": t, "FNumber": 8.0}
                                                  for t in EXPOSURES])
    with pytest.raises(InputError, match=rf"{paths[0].name}: no EXIF ISO"):
        merge_stack(read_brackets(paths), MergeOptions(calibration=Calibration()))


def test_spot_meter_and_grey_card_references(write_brackets):
    stack = read_brackets(write_brackets(EXPOSURES))
    region = (10, 5, 8, 6)
    spot = merge_stack(stack, MergeOptions(
        calibration=Calibration("luminance", region=region, luminance=250.0)))
    # The region then reads as the meter said; 1e-5 is float32 rounding of the mean.
    assert region_mean_luminance(spot.radiance, region, "ITU-R BT.709") == pytest.approx(
        250.0, rel=1e-5)
    card = merge_stack(stack, MergeOptions(calibration=Calibration(
        "illuminance", region=region, illuminance=1000.0, reflectance=0.18)))
    assert region_mean_luminance(card.radiance, region, "ITU-R BT.709") == pytest.approx(
        0.18 * 1000.0 / math.pi, rel=1e-5)


def test_bad_references_are_refused(write_brackets):
    with pytest.raises(ValueError, match="needs a region"):
        Calibration("luminance", luminance=100.0)
    with pytest.raises(ValueError, match="K must be positive"):
        Calibration(K=0.0)
    stack = read_brackets(write_brackets(EXPOSURES))
    with pytest.raises(HdrioError, match="region 60,40,10,10 is not inside the 64x48"):
        merge_stack(stack, MergeOptions(calibration=Calibration(
            "luminance", region=(60, 40, 10, 10), luminance=1.0)))


def test_frobisher_exif_calibration_agrees_across_exposures(shared_data, tmp_path):
    folder = shared_data("frobisher_001")
    output = tmp_path / "frobisher.exr"
    result = merge_files(sorted(folder.glob("IMG_26*.jpg")), output,
                         options=MergeOptions(calibration=Calibration()), pixel_type="float")
    header = read_header(output)
    assert header["hdrio:units"] == "cd/m^2"
    assert header["whiteLuminance"] == 1.0  # float pixels: no half-range scaling
    stack, response, scale = result.stack, result.response, result.colour.luminance_scale
    merged = luminance(result.radiance, "ITU-R BT.709")
    per_bracket = []
    for j, t in enumerate(stack.exposures):
        codes = stack.codes[j]
        # Well exposed: every channel between 10 % and 90 % of the code range.
        good = np.all((codes > 25) & (codes < 230), axis=-1)
        L = scale * luminance(response.linearise(codes), "ITU-R BT.709") / t
        per_bracket.append((good, L))
        ratio = np.median(L[good] / merged[good])
        # The acceptance bound: 5 % (measured: within 1 % on these files).
        assert abs(ratio - 1.0) < 0.05, (stack.files[j], ratio)
    for (good_a, L_a), (good_b, L_b) in zip(per_bracket, per_bracket[1:]):
        both = good_a & good_b
        assert both.sum() > 1000
        assert abs(np.median(L_b[both] / L_a[both]) - 1.0) < 0.05
