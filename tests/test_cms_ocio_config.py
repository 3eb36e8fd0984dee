"""ocio/config.ocio and response LUT export, checked with PyOpenColorIO, OIIO and oiiotool."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import colour
import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest

from hdrio.cms import lut, ocioconfig, spaces
from hdrio.errors import InputError
from hdrio.io.brackets import read_codes
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "ocio" / "config.ocio"


def _oiiotool() -> str:
    beside = Path(sys.executable).with_name("oiiotool")
    found = str(beside) if beside.is_file() else shutil.which("oiiotool")
    if not found:
        pytest.skip("oiiotool not found beside python or on PATH (the OpenImageIO wheel "
                    "ships it; other installs may not)")
    return found


def _to_ten_digits(text: str) -> str:
    """Every decimal number rounded to 10 significant digits: the matrices come from
    colour-science in float64, whose last digits move between BLAS builds and machines
    (seen in CI: 0.51893348759897 against 0.518933487598969)."""
    return re.sub(r"-?\d+\.\d+(?:e-?\d+)?", lambda m: f"{float(m.group()):.10g}", text)


def test_checked_in_config_is_what_the_generator_writes():
    assert (_to_ten_digits(CONFIG.read_text(encoding="utf-8"))
            == _to_ten_digits(ocioconfig.project_config().serialize()))


def test_config_loads_and_validates_with_pypi_opencolorio():
    config = ocio.Config.CreateFromFile(str(CONFIG))
    config.validate()
    assert (config.getMajorVersion(), config.getMinorVersion()) == ocioconfig.PROFILE_VERSION
    assert config.getColorSpace("lin_ap1_scene").getName() == "ACEScg"


def test_config_loads_in_openimageios_bundled_ocio():
    config = oiio.ColorConfig(str(CONFIG))
    assert config.geterror() == ""
    assert "ACEScg" in config.getColorSpaceNames()
    assert config.getColorSpaceNameByRole("scene_linear") == "Linear Rec.709 (sRGB)"


@pytest.mark.parametrize(("source", "target", "cs_source", "cs_target"), [
    ("lin_rec709_scene", "ACEScg", "ITU-R BT.709", "ACEScg"),
    ("lin_p3d65_scene", "ACES2065-1", "Display P3", "ACES2065-1"),
    ("lin_adobergb_scene", "lin_rec2020_scene", "Adobe RGB (1998)", "ITU-R BT.2020")])
def test_config_conversions_agree_with_colour_science(source, target, cs_source, cs_target):
    rgb = np.random.default_rng(1).uniform(0.0, 20.0, (300, 3))
    ours = spaces.convert(rgb, source, target, CONFIG)
    theirs = colour.RGB_to_RGB(rgb, cs_source, cs_target,
                               chromatic_adaptation_transform="Bradford")
    # 1e-4 of each pixel's largest channel (the bound); float32 gives ~1e-7.
    assert np.max(np.abs(ours - theirs) / np.max(theirs, axis=1, keepdims=True)) < 1e-4


def test_srgb_and_acescct_encodings_match_colour_science():
    x = np.array([[0.0, 0.001, 0.0031308], [0.18, 0.5, 1.0]])
    encoded = spaces.convert(x, "lin_rec709_scene", "srgb_rec709_scene", CONFIG)
    # 5e-5: the path goes through ACES2065-1 and back in float32 matrices (measured
    # 1e-5 at 1.0), then OCIO's fast power function; a wrong curve is off by >1e-2.
    assert encoded == pytest.approx(colour.models.eotf_inverse_sRGB(x), abs=5e-5)
    positive = np.maximum(x, 1e-4)  # colour-science's ACEScct takes log2 even below the toe
    cct = spaces.convert(positive, "ACEScg", "ACEScct", CONFIG)
    assert cct == pytest.approx(colour.models.log_encoding_ACEScct(positive), abs=5e-5)


@pytest.fixture(scope="module")
def memorial(shared_data, tmp_path_factory):
    """The memorial set merged once; ``(result, exr path, bracket paths)``."""
    folder = shared_data("memorial_debevec")
    brackets = sorted(folder.glob("memorial00*.png"))
    out = tmp_path_factory.mktemp("memorial")
    result = merge_files(brackets, out / "memorial.exr", exposures_from=folder / "exposures.csv",
                         options=MergeOptions(exclude_colour=(0, 0, 255)))
    return result, out / "memorial.exr", brackets


@pytest.mark.parametrize("lut_format", ["spi1d", "clf"])
@pytest.mark.slow
def test_exported_response_through_oiiotool_matches_hdrio(memorial, tmp_path, lut_format):
    result, exr, brackets = memorial
    tool = _oiiotool()
    lut_path, config_path = lut.export_response(exr, tmp_path, name="memorial",
                                                lut_format=lut_format)
    assert lut_path.is_file() and config_path.is_file()
    assert oiio.ColorConfig(str(config_path)).geterror() == ""
    for bracket in (brackets[3], brackets[9]):  # a dark and a bright exposure
        out = tmp_path / f"{bracket.stem}.exr"
        subprocess.run([tool, "--colorconfig", str(config_path), str(bracket),
                        "--colorconvert", "memorial", "lin_rec709_scene", "-d", "float",
                        "-o", str(out)], check=True, capture_output=True)
        image = oiio.ImageInput.open(str(out))
        theirs = np.asarray(image.read_image("float"), dtype=np.float64)
        image.close()
        codes, _, _ = read_codes(bracket)
        ours = result.response.linearise(codes)
        # The acceptance bound, 1 % per value; measured here about 1e-6 (float32 LUT
        # entries, and a Rec.709 -> ACES -> Rec.709 matrix round trip).
        assert np.max(np.abs(theirs - ours) / ours) < 0.01


def test_export_refuses_an_exr_without_a_response(tmp_path):
    from hdrio.io.write import write_exr

    plain = write_exr(tmp_path / "plain.exr", np.ones((2, 2, 3), np.float32))
    with pytest.raises(InputError, match="plain.exr: holds no hdrio response"):
        lut.export_response(plain, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.exr"]


def test_spi1d_text_is_read_by_ocio(tmp_path):
    table = np.stack([np.linspace(0, 4, 5)] * 3, axis=1) ** 2
    (tmp_path / "t.spi1d").write_text(lut.format_spi1d(table))
    config = ocio.Config.CreateRaw()
    config.setSearchPath(str(tmp_path))
    processor = config.getProcessor(ocio.FileTransform(src="t.spi1d")).getDefaultCPUProcessor()
    values = np.array([[0.0, 0.5, 1.0]], dtype=np.float32)
    processor.applyRGB(values)
    # Entries at 0, 0.25 .. 1 are 0, 1, 4, 9, 16; 0.5 is entry 2 exactly.
    assert values[0] == pytest.approx([0.0, 4.0, 16.0], abs=1e-6)
