"""The chain's colour operations through ``main([...])``: --colorspace, --colorconvert,
--ociodisplay, --ocio-config."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from hdrio.cms.spaces import chromaticities
from hdrio.io.images import read_image
from tests.conftest import run_cli as run


def _exr(path):
    pixels, header = read_image(path)
    return pixels.astype(np.float64), header


def _close_relative_to_pixel(actual, expected):
    """1e-4 of each pixel's largest channel (issue #5's bound for conversions): float EXRs
    both ways, OCIO's float32 matrices against colour-science's float64 ones; a small
    channel of a saturated colour carries the absolute error of the large ones."""
    scale = np.max(np.abs(expected), axis=-1, keepdims=True)
    assert np.max(np.abs(actual - expected) / scale) <= 1e-4


def test_colorspace_converts_the_merge_and_says_so(brackets, out_dir, capsys):
    plain, acescg = out_dir / "rec709.exr", out_dir / "acescg.exr"
    code, _, err = run(capsys, *brackets, "--merge", "-d", "float", "-o", plain,
                       "--colorspace", "ACEScg", "-o", acescg)
    assert code == 0, err
    rec709, _ = _exr(plain)
    converted, header = _exr(acescg)
    assert header["colorInteropID"] == "lin_ap1_scene"
    assert header["hdrio:colorSpace"] == "ACEScg"
    np.testing.assert_allclose(header["chromaticities"], chromaticities("ACEScg"), atol=1e-6)
    back = colour.RGB_to_RGB(converted, "ACEScg", "ITU-R BT.709",
                             chromatic_adaptation_transform="Bradford")  # as OCIO's configs
    _close_relative_to_pixel(back, rec709)


def test_colorconvert_from_to_on_an_exr_input(brackets, out_dir, capsys):
    source, target = out_dir / "in.exr", out_dir / "p3.exr"
    assert run(capsys, *brackets, "--merge", "-d", "float", "-o", source)[0] == 0
    code, _, err = run(capsys, source, "--colorconvert", "lin_rec709_scene",
                       "lin_p3d65_scene", "-d", "float", "-o", target)
    assert code == 0, err
    rec709, _ = _exr(source)
    p3, header = _exr(target)
    assert header["colorInteropID"] == "lin_p3d65_scene"
    expected = colour.RGB_to_RGB(rec709, "ITU-R BT.709", "Display P3",
                                 chromatic_adaptation_transform="Bradford")
    _close_relative_to_pixel(p3, expected)


def test_ociodisplay_renders_a_display_image(brackets, out_dir, capsys):
    code, _, err = run(capsys, *brackets, "--merge", "--ociodisplay", "sRGB - Display",
                       "ACES 2.0 - SDR 100 nits (Rec.709)", "-o", out_dir / "view.png")
    assert code == 0, err
    pixels, _ = read_image(out_dir / "view.png")
    assert pixels.min() >= 0.0 and pixels.max() <= 1.0
    # The ramp stays a ramp: the view is monotone along it, and not flat.
    grey = pixels[..., 1].mean(axis=0)
    assert np.all(np.diff(grey) >= -1 / 255) and grey[-1] - grey[0] > 0.3


@pytest.mark.parametrize("argv, fragment", [
    (["--colorspace", "no such space"], "--colorspace"),
    (["--colorspace", "ACEScct"], "--colorspace"),  # not scene-linear: refused for an EXR
    (["--tonemap", "reinhard-global", "--colorspace", "ACEScg"], "display-referred"),
    (["--ociodisplay", "nope", "nope"], "--ociodisplay"),
])
def test_colour_errors_name_the_operation(brackets, out_dir, capsys, argv, fragment):
    code, _, err = run(capsys, *brackets, "--merge", *argv, "-o", out_dir / "x.exr")
    assert code == 2 and fragment in err, err
    assert list(out_dir.iterdir()) == []


def test_ocio_config_is_used_and_a_bad_one_is_refused(brackets, out_dir, capsys):
    code, _, err = run(capsys, "--ocio-config", "ocio://studio-config-latest", *brackets,
                       "--merge", "--colorspace", "ACEScg", "-o", out_dir / "s.exr")
    assert code == 0, err
    assert "studio" in str(_exr(out_dir / "s.exr")[1]["hdrio:ocioConfig"])
    code, _, err = run(capsys, "--ocio-config", out_dir / "missing.ocio", *brackets,
                       "--merge", "-o", out_dir / "t.exr")
    assert code == 2 and "missing.ocio" in err, err
