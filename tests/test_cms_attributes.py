"""Every attribute hdrio writes survives OpenEXR's own bindings and OpenImageIO, as documented."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from hdrio.cms.calibration import Calibration
from hdrio.io.header import read_header
from hdrio.io.paths import SOURCE_ATTRIBUTES
from hdrio.io.write import Float2, write_image
from hdrio.job.options import MergeOptions
from hdrio.job.output import exr_attributes
from hdrio.job.run import merge_files
from hdrio.tools.synthetic import render_brackets

ROOT = Path(__file__).resolve().parents[1]
# OpenImageIO adds these itself on write or read; hdrio does not write them.
ADDED_BY_READERS = {"oiio:ColorSpace", "oiio:RowsPerChunk", "oiio:subimages", "DateTime",
                    "openexr:lineOrder", "PixelAspectRatio", "screenWindowCenter",
                    "screenWindowWidth", "capDate", "channels", "dataWindow",
                    "displayWindow", "lineOrder", "pixelAspectRatio", "type"}


@pytest.fixture(scope="module")
def merged(tmp_path_factory):
    """A merge that exercises every optional attribute: ACEScg, white balance, cd/m^2."""
    folder = tmp_path_factory.mktemp("attributes")
    exposures = [1 / 16, 1 / 4, 1.0, 4.0]
    u = np.linspace(0.0, 1.0, 64)[np.newaxis, :, np.newaxis]
    radiance = 0.01 * 1000.0**u * np.array([1.05, 1.0, 0.85]) * np.ones((48, 1, 1))
    paths = [write_image(folder / f"b{j}.png", frame, "uint8")
             for j, frame in enumerate(render_brackets(radiance, exposures))]
    options = MergeOptions(
        output_space="ACEScg", exclude_colour=(0, 0, 255), white_balance=(20, 10, 8, 8),
        calibration=Calibration("luminance", region=(30, 20, 6, 6), luminance=5e6))
    output = folder / "all.exr"
    result = merge_files(paths, output, options=options,
                         exposures=[str(t) for t in exposures])  # half: forces a scale
    return result, output


def _expected(value):
    """What a reader should give back for a written value (float32 storage)."""
    if isinstance(value, Float2):
        return [np.float32(value.x), np.float32(value.y)]
    if isinstance(value, float):
        return np.float32(value)
    if isinstance(value, tuple | list) and value and isinstance(value[0], float):
        return [np.float32(v) for v in value]
    if isinstance(value, tuple):
        return list(value)
    return value


def _same(read, written) -> bool:
    expected = _expected(written)
    if isinstance(read, np.ndarray | tuple | list):
        read = list(np.asarray(read).reshape(-1).tolist()) if isinstance(
            read, np.ndarray) else list(read)
    if isinstance(expected, list) and expected and isinstance(expected[0], np.float32):
        return np.array_equal(np.float32(read), np.float32(expected))
    if isinstance(expected, np.float32):
        return np.float32(read) == expected
    return read == expected


def test_every_attribute_round_trips_through_openexr_and_openimageio(merged):
    result, output = merged
    written = exr_attributes(result)
    via_oiio = read_header(output)
    via_openexr = OpenEXR.File(str(output)).header()
    assert result.exposure_scale < 1.0  # the test covers a scaled half image
    for name, value in written.items():
        if name == "compression":
            continue  # an enum in OpenEXR's bindings, a string in OIIO: checked below
        if name == "DateTime" and value == "":  # capture time unknown: none written
            assert name not in via_oiio and "capDate" not in via_openexr
            continue
        assert name in via_oiio, f"{name} dropped by OpenImageIO"
        assert name in via_openexr, f"{name} dropped by OpenEXR"
        assert _same(via_oiio[name], value), (name, via_oiio[name], value)
        assert _same(via_openexr[name], value), (name, via_openexr[name], value)
    assert via_oiio["compression"] == "zip"
    assert via_openexr["compression"] == OpenEXR.ZIP_COMPRESSION
    # Added as written: the source paths relative to the EXR's own folder.
    relative = {f"{name}Relative" for name in SOURCE_ATTRIBUTES if name in written}
    assert relative <= set(via_oiio) and relative <= set(via_openexr)
    extra = set(via_oiio) - set(written) - ADDED_BY_READERS - {"compression"} - relative
    assert not {n for n in extra if not n.startswith(".")}, extra


def test_colour_attributes_say_what_the_numbers_mean(merged):
    result, output = merged
    header = read_header(output)
    assert header["colorInteropID"] == "lin_ap1_scene"
    assert header["oiio:ColorSpace"] == "lin_ap1_scene"
    assert header["hdrio:colorSpace"] == "ACEScg"
    assert header["hdrio:units"] == "cd/m^2"
    # whiteLuminance: cd/m^2 of stored (1, 1, 1) = 1 / exposure scale (float32 storage).
    assert header["whiteLuminance"] == pytest.approx(1.0 / result.exposure_scale, rel=1e-7)
    assert tuple(header["adoptedNeutral"]) == pytest.approx((0.32168, 0.33767), abs=1e-7)
    assert header["hdrio:whiteBalance"].startswith("region 20,10,8,8, gains ")
    assert header["hdrio:calibration"] == "luminance: region 30,20,6,6 = 5e+06 cd/m^2"
    assert header["hdrio:inputEncoding"] == "sRGB (default)"


def _documented_names() -> set[str]:
    text = (ROOT / "docs" / "metadata.md").read_text(encoding="utf-8")
    names = set()
    for cell in re.findall(r"^\| (.+?) \|", text, flags=re.MULTILINE):
        names.update(re.findall(r"`([^`]+)`", cell))
    # "`hdrio:responseR`, `G`, `B`" documents three names.
    if "hdrio:responseR" in names:
        names.update({"hdrio:responseG", "hdrio:responseB", "hdrio:responseY"})
    return names


def test_every_attribute_is_documented_and_short(merged):
    result, _ = merged
    documented = _documented_names()
    written = exr_attributes(result)
    relative = [f"{name}Relative" for name in SOURCE_ATTRIBUTES if name in written]
    for name in [*written, *relative]:
        assert len(name) <= 31, f"{name}: longer than 31 characters"
        assert name in documented, f"{name} missing from docs/metadata.md"
