"""OpenColorIO output spaces: conversions against colour-science, chromaticities, ACEScg EXR."""

from __future__ import annotations

from pathlib import Path

import colour
import numpy as np
import pytest

from hdrio.cms import spaces
from hdrio.errors import HdrioError
from hdrio.io.header import read_header
from hdrio.io.images import read_image
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files
from hdrio.radiometry.luminance import KNOWN_CHROMATICITIES, normalised_primary_matrix

RNG = np.random.default_rng(5)
# Scene-linear values from deep shadow to bright highlights, some saturated colours.
SAMPLES = RNG.uniform(0.0, 1.0, (500, 3)) ** 3 * np.array([1.0, 50.0, 4000.0])[
    RNG.integers(0, 3, (500, 1))]


@pytest.mark.parametrize(("target", "colour_science"), [
    ("ACEScg", "ACEScg"), ("ACES2065-1", "ACES2065-1"), ("lin_p3d65_scene", "Display P3"),
    ("Linear Rec.2020", "ITU-R BT.2020")])
def test_conversion_from_rec709_agrees_with_colour_science(target, colour_science):
    ours = spaces.convert(SAMPLES, "lin_rec709_scene", target)
    theirs = colour.RGB_to_RGB(SAMPLES, "ITU-R BT.709", colour_science,
                               chromatic_adaptation_transform="Bradford")
    # The bound, 1e-4 relative (to the largest channel of each pixel: a tiny
    # channel of a saturated colour carries the absolute error of the others). OCIO runs
    # in float32 (about 6e-8 relative), so this leaves room only for a wrong matrix or CAT.
    scale = np.max(np.abs(theirs), axis=1, keepdims=True)
    assert np.max(np.abs(ours - theirs) / scale) < 1e-4


def test_conversion_keeps_shape_and_input_and_round_trips():
    image = SAMPLES.reshape(10, 50, 3).astype(np.float32)
    before = image.copy()
    there = spaces.convert(image, "Linear Rec.709 (sRGB)", "lin_ap1_scene")
    back = spaces.convert(there, "ACES - ACEScg", "lin_rec709")
    assert there.shape == image.shape and np.array_equal(image, before)
    # float32 matrix there and back: a few ulps of the largest channel.
    assert np.max(np.abs(back - image) / np.max(image, axis=-1, keepdims=True)) < 1e-5


@pytest.mark.parametrize(("name", "colour_science"), [
    ("ACEScg", "ACEScg"), ("ACES2065-1", "ACES2065-1"), ("lin_rec709_scene", "ITU-R BT.709"),
    ("Linear Rec.2020", "ITU-R BT.2020"), ("Linear P3-D65", "Display P3")])
def test_chromaticities_are_colour_sciences(name, colour_science):
    space = colour.RGB_COLOURSPACES[colour_science]
    expected = [*np.ravel(space.primaries), *space.whitepoint]
    assert spaces.chromaticities(name) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("name", sorted(KNOWN_CHROMATICITIES))
def test_known_chromaticities_and_matrices_are_colour_sciences(name):
    # hdrio keeps these so that a merge or a check never imports colour-science (1-2 s);
    # they must be its values exactly, and the hand-written normalised primary matrix
    # its matrix to float64 rounding (1e-12).
    space = colour.RGB_COLOURSPACES[name]
    assert KNOWN_CHROMATICITIES[name] == tuple(
        float(v) for v in (*np.ravel(space.primaries), *space.whitepoint))
    np.testing.assert_allclose(
        normalised_primary_matrix(KNOWN_CHROMATICITIES[name]),
        colour.normalised_primary_matrix(space.primaries, space.whitepoint), atol=1e-12)


@pytest.mark.parametrize("name", ["ACEScg", "ACES2065-1"])
def test_derived_chromaticities_match_the_table_for_aces_white_spaces(name):
    # Spaces outside the interop table get chromaticities from the config's matrix to
    # ACES2065-1; for spaces whose white is the ACES white that derivation is exact up
    # to the config's 6-decimal matrices: 1e-4 in x, y.
    assert spaces.derived_chromaticities(name) == pytest.approx(
        spaces.chromaticities(name), abs=1e-4)


def test_interop_ids_and_aliases():
    assert spaces.interop_id("ACEScg") == "lin_ap1_scene"
    assert spaces.canonical_space("lin_ap1") == "ACEScg"
    assert spaces.interop_id("Linear Rec.709 (sRGB)") == "lin_rec709_scene"
    assert "ACEScg" in spaces.linear_space_names()
    assert "ACEScct" not in spaces.linear_space_names()


def test_unknown_and_non_linear_spaces_are_refused_with_the_config_named():
    with pytest.raises(HdrioError, match=r"cg-config-latest.*no colour space 'ACEScgg'"):
        spaces.canonical_space("ACEScgg")
    with pytest.raises(HdrioError, match="'ACEScct' is not a scene-linear"):
        spaces.require_scene_linear("ACEScct")


def test_missing_config_file_is_named(tmp_path):
    missing = tmp_path / "nope.ocio"
    with pytest.raises(HdrioError, match=f"{missing}: OCIO config not found"):
        spaces.load_config(missing)


def test_ocio_environment_variable_is_used(monkeypatch, tmp_path):
    path = tmp_path / "studio.ocio"
    spaces.load_config("ocio://studio-config-latest").serialize(str(path))
    monkeypatch.setenv("OCIO", str(path))
    assert spaces.config_source() == str(path)
    assert spaces.load_config().getName().startswith("studio-config")


def test_display_view_renders_mid_grey_like_the_srgb_standard_view():
    grey = np.full((1, 3), 0.18, dtype=np.float32)
    # The un-tone-mapped view is the sRGB inverse EOTF: 0.18 -> 0.4614 (colour-science).
    encoded = spaces.display_view(grey, "lin_rec709_scene", "sRGB - Display", "Un-tone-mapped")
    assert encoded[0] == pytest.approx(colour.models.eotf_inverse_sRGB(0.18), abs=1e-4)
    with pytest.raises(HdrioError, match="no view 'Filmic'"):
        spaces.display_view(grey, "ACEScg", "sRGB - Display", "Filmic")


def _merge(brackets: list[Path], output: Path, space: str):
    # Float pixels: half floats would round each value to 2**-11 (5e-4) relative, and a
    # round trip through ACEScg mixes channels, which would eat the 1e-3 budget below.
    return merge_files(brackets, output, options=MergeOptions(output_space=space),
                       pixel_type="float")


def _pixels(path: Path) -> np.ndarray:
    return read_image(path)[0].astype(np.float64)


def test_acescg_merge_reads_back_as_acescg_and_converts_back_to_rec709(write_brackets,
                                                                      tmp_path):
    brackets = write_brackets()
    _merge(brackets, tmp_path / "aces.exr", "ACEScg")
    _merge(brackets, tmp_path / "rec709.exr", "lin_rec709_scene")
    header = read_header(tmp_path / "aces.exr")
    acescg = colour.RGB_COLOURSPACES["ACEScg"]
    assert header["oiio:ColorSpace"] == "lin_ap1_scene"
    assert header["colorInteropID"] == "lin_ap1_scene"
    # Stored as 32-bit floats: 1e-7 absolute is float32 rounding of values near 1.
    assert header["chromaticities"] == pytest.approx(
        [*np.ravel(acescg.primaries), *acescg.whitepoint], abs=1e-7)
    assert read_header(tmp_path / "rec709.exr")["colorInteropID"] == "lin_rec709_scene"
    back = colour.RGB_to_RGB(_pixels(tmp_path / "aces.exr"), "ACEScg", "ITU-R BT.709",
                             chromatic_adaptation_transform="Bradford")
    reference = _pixels(tmp_path / "rec709.exr")
    # The acceptance bound: 1e-3 relative (to each pixel's largest channel).
    error = np.abs(back - reference) / np.max(np.abs(reference), axis=-1, keepdims=True)
    assert error.max() < 1e-3
