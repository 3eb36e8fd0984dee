"""Input encodings, white balance, OCIO display previews, and their command-line options."""

from __future__ import annotations

from pathlib import Path

import colour
import numpy as np
import OpenImageIO as oiio
import pytest

from hdrio.cli import main
from hdrio.cms.display import preview_OCIO_display
from hdrio.cms.encoding import encoding, encoding_from_metadata, resolve_encoding
from hdrio.errors import InputError
from hdrio.io.brackets import read_brackets
from hdrio.io.header import read_header
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files, merge_stack
from hdrio.radiometry.luminance import luminance


def test_encoding_names_and_aliases():
    assert encoding("adobergb").name == "Adobe RGB (1998)"
    assert encoding("Display-P3").linear_interop_id == "lin_p3d65_scene"
    assert encoding("SRGB").colour_science == "ITU-R BT.709"
    with pytest.raises(KeyError, match="unknown input encoding 'ProPhoto'"):
        encoding("ProPhoto")


@pytest.mark.parametrize(("metadata", "expected"), [
    ({"ICCDescription": "Adobe RGB (1998)"}, "Adobe RGB (1998)"),
    ({"ICCDescription": "sRGB IEC61966-2.1", "ExifColorSpace": 65535}, "sRGB"),
    ({"ICCDescription": "Display P3"}, "Display P3"),
    ({"ICCDescription": "ITU-R BT.2020"}, "Rec.2020"),
    ({"ICCDescription": "ProPhoto RGB", "ExifColorSpace": 65535}, ""),  # not one we read
    ({"ICCDescription": "Camera RGB Profile"}, None),  # canal's: names no encoding
    ({"ExifColorSpace": 1}, "sRGB"),
    ({"ExifColorSpace": 65535}, None),  # 'uncalibrated': the file does not say
    ({}, None)])
def test_encoding_from_metadata(metadata, expected):
    found = encoding_from_metadata(metadata)
    assert (found[0] if found else None) == expected


def test_metadata_wins_then_option_then_srgb():
    srgb = {"ExifColorSpace": 1}
    assert resolve_encoding(["a", "b"], [srgb, {}], "Display P3")[0].name == "sRGB"
    assert resolve_encoding(["a", "b"], [{}, {}], "Display P3") == (encoding("p3"), "option")
    assert resolve_encoding(["a", "b"], [{}, {}]) == (encoding("sRGB"), "default")
    with pytest.raises(InputError, match="b.jpg: is Adobe RGB .* but a.jpg is sRGB"):
        resolve_encoding(["a.jpg", "b.jpg"], [srgb, {"ICCDescription": "Adobe RGB (1998)"}])


def test_a_profile_of_another_encoding_is_refused_unless_the_option_says():
    prophoto = {"ICCDescription": "ProPhoto RGB"}
    with pytest.raises(InputError, match="b.tif: its ICC profile 'ProPhoto RGB' is not an "
                                         "encoding hdrio reads .* --input-encoding"):
        resolve_encoding(["a.tif", "b.tif"], [{}, prophoto])
    assert resolve_encoding(["a.tif", "b.tif"], [prophoto, prophoto], "Rec.2020") == (
        encoding("Rec.2020"), "option")


def test_a_prophoto_stack_stops_before_the_solve(write_brackets, monkeypatch):
    # As a Lightroom 16-bit TIFF export reads (its profile's description, as OpenImageIO
    # gives it): refused at the first stage, before the response is solved.
    from dataclasses import replace

    from hdrio.job import stages

    stack = read_brackets(write_brackets())
    stack = replace(stack, metadata=[{**m, "ICCDescription": "ProPhoto RGB"}
                                     for m in stack.metadata])
    solved = []
    monkeypatch.setattr(stages, "response_solver", lambda *a, **k: solved.append(1))
    with pytest.raises(InputError, match="ICC profile 'ProPhoto RGB' is not an encoding"):
        merge_stack(stack, MergeOptions())
    assert not solved


def test_frobisher_icc_profile_says_srgb(shared_data):
    stack = read_brackets(sorted(shared_data("frobisher_001").glob("IMG_26*.jpg")))
    found, evidence = resolve_encoding(stack.files, stack.metadata)
    assert found.name == "sRGB" and evidence == "ICC profile 'sRGB'"


def test_display_p3_brackets_convert_from_p3_primaries(write_brackets, tmp_path):
    paths = write_brackets()
    result = merge_files(paths, tmp_path / "p3.exr", pixel_type="float",
                         options=MergeOptions(input_encoding="Display P3"))
    assert result.options.colourspace == "Display P3"
    image = oiio.ImageInput.open(str(tmp_path / "p3.exr"))
    written = np.asarray(image.read_image("float"), dtype=np.float64)
    image.close()
    expected = colour.RGB_to_RGB(result.radiance.astype(np.float64), "Display P3",
                                 "ITU-R BT.709")
    # Same white (D65), so a plain matrix; 1e-4 relative to each pixel's largest channel
    # (the bound for OCIO against colour-science).
    scale = np.max(np.abs(expected), axis=-1, keepdims=True)
    assert np.max(np.abs(written - expected) / scale) < 1e-4
    assert read_header(tmp_path / "p3.exr")["hdrio:inputEncoding"] == "Display P3 (option)"


def test_white_balance_makes_the_region_neutral_and_keeps_its_luminance(write_brackets):
    stack = read_brackets(write_brackets())  # the ramp is tinted 1.05 : 1 : 0.85
    region = (20, 10, 8, 8)
    plain = merge_stack(stack)
    balanced = merge_stack(stack, MergeOptions(white_balance=region))
    x, y, w, h = region

    def mean(image):
        return image[y: y + h, x: x + w].reshape(-1, 3).astype(np.float64).mean(axis=0)

    # float32 pixels, mean of 64: 1e-5 relative.
    assert mean(balanced.radiance) == pytest.approx([mean(balanced.radiance)[1]] * 3, rel=1e-5)
    assert luminance(mean(balanced.radiance)) == pytest.approx(
        luminance(mean(plain.radiance)), rel=1e-5)
    gains = np.asarray(balanced.colour.gains)
    assert gains[0] < 1.0 < gains[2]  # red was high, blue low
    assert np.allclose(balanced.radiance, plain.radiance * gains.astype(np.float32),
                       rtol=1e-6)


def test_ocio_display_preview_puts_the_key_at_mid_grey():
    rng = np.random.default_rng(2)
    rgb = np.repeat(rng.lognormal(0.0, 2.0, (40, 50, 1)), 3, axis=-1).astype(np.float32)
    plain = preview_OCIO_display(rgb, "lin_rec709_scene", "sRGB - Display", "Un-tone-mapped")
    geometric_mean = float(np.exp(np.mean(np.log(1e-4 + rgb[..., 0]))))
    at_key = np.argmin(np.abs(rgb[..., 0] - geometric_mean))
    # The key (log-average) renders at sRGB(0.18) = 0.4614 (within the nearest pixel's
    # distance from the exact key: 2e-2).
    assert plain[..., 0].flat[at_key] == pytest.approx(0.4614, abs=2e-2)
    aces = preview_OCIO_display(rgb * 1000.0, "lin_rec709_scene", "sRGB - Display",
                                "ACES 2.0 - SDR 100 nits (Rec.709)")
    assert aces.min() >= 0.0 and aces.max() <= 1.0
    order = np.argsort(rgb[..., 0], axis=None)
    assert np.all(np.diff(aces[..., 0].flat[order]) >= -1e-6)  # monotone: a tone curve


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_merge_colour_options_end_to_end(write_brackets, tmp_path, capsys):
    paths = write_brackets()
    exr, jpg = tmp_path / "o.exr", tmp_path / "o.jpg"
    code, out, err = _run(capsys, "merge", *paths, "-o", exr, "--preview", jpg,
                          "--colorspace", "ACES2065-1", "--white-balance", "20,10,8,8",
                          "--absolute", "luminance", "--reference-region", "30,20,6,6",
                          "--reference-luminance", "100", "--ocio-display", "sRGB - Display")
    assert code == 0, err
    assert "preview:   " in out and "sRGB - Display / ACES 2.0" in out
    assert "check:     " in out and "(cd/m^2)" in out
    header = read_header(exr)
    assert header["colorInteropID"] == "lin_ap0_scene" and header["hdrio:units"] == "cd/m^2"
    assert jpg.is_file()


@pytest.mark.parametrize(("extra", "needle"), [
    (["--colorspace", "ACEScct"], "'ACEScct' is not a scene-linear colour space"),
    (["--colorspace", "nope"], "no colour space 'nope'"),
    (["--ocio-config", "missing.ocio"], "missing.ocio: OCIO config not found"),
    (["--absolute", "exif"], "no EXIF"),
    (["--absolute", "luminance"], "needs a region"),
    (["--input-encoding", "ProPhoto"], "unknown input encoding"),
    (["--ocio-display", "Cinema"], "no display 'Cinema'")])
def test_bad_colour_options_exit_2_with_one_line_and_no_output(write_brackets, tmp_path,
                                                              capsys, extra, needle):
    paths = write_brackets()
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code, out, err = _run(capsys, "merge", *paths, "-o", out_dir / "o.exr", "-q", *extra)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err, err
    assert list(Path(out_dir).iterdir()) == []
