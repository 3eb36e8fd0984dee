"""Files tell the truth: metadata carried through the chain, display-referred labels,
capture time and camera from EXIF, one adoptedNeutral rule, short exposure decimals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from hdrio.cms.checks import REC709_D65
from tests.conftest import DEFAULT_EXPOSURES
from tests.conftest import run_cli as run


def _header(path: Path) -> dict:
    with OpenEXR.File(str(path)) as file:
        return dict(file.header())


def _channels(path: Path) -> dict[str, np.ndarray]:
    image = oiio.ImageInput.open(str(path))
    spec = image.spec()
    pixels = image.read_image("float")
    image.close()
    return {name: pixels[..., c] for c, name in enumerate(spec.channelnames)}


@pytest.fixture
def foreign_rgba(tmp_path: Path) -> Path:
    """An RGBA half EXR written by another program, with Copyright, capDate and GPS."""
    path = tmp_path / "foreign.exr"
    spec = oiio.ImageSpec(8, 6, 4, "half")
    spec.attribute("Copyright", "(c) A. Photographer")
    spec.attribute("DateTime", "2019:05:04 10:11:12")  # EXR capDate
    spec.attribute("GPS:Latitude", oiio.TypeDesc("float[3]"), (51.0, 30.0, 12.5))
    spec.attribute("GPS:LatitudeRef", "N")
    spec.attribute("ExposureTime", 0.01)
    spec.attribute("screenWindowWidth", 1.5)
    output = oiio.ImageOutput.create(str(path))
    output.open(str(path), spec)
    rng = np.random.default_rng(1)
    output.write_image(rng.uniform(0.05, 1.0, (6, 8, 4)).astype(np.float16))
    output.close()
    return path


def test_chain_keeps_alpha_and_source_metadata(foreign_rgba, tmp_path, capsys):
    out = tmp_path / "out.exr"
    code, _, err = run(capsys, foreign_rgba, "--exposure", "1", "-o", out)
    assert code == 0, err
    before, after = _channels(foreign_rgba), _channels(out)
    assert list(after) == ["R", "G", "B", "A"]
    np.testing.assert_array_equal(after["A"], before["A"])  # alpha untouched
    # x2 is exact in half floats (no value here is near the top of the range).
    np.testing.assert_array_equal(after["R"], 2 * before["R"])
    header = _header(out)
    assert header["owner"] == "(c) A. Photographer"  # OpenEXR's name for Copyright
    assert header["capDate"] == "2019:05:04 10:11:12"
    assert tuple(header["GPS:Latitude"]) == (51.0, 30.0, 12.5)
    assert header["GPS:LatitudeRef"] == "N"
    assert header["expTime"] == pytest.approx(0.01)
    assert header["screenWindowWidth"] == 1.5
    assert header["hdrio:exposureScale"] == 2.0


def test_chain_keeps_an_inputs_zeros_and_negative_values(tmp_path, capsys):
    # Another program's scene-linear pixels (Desk.exr has 10,794 negative values): a
    # copy through the chain keeps them, as half floats hold them (they were clamped to
    # half's smallest positive value, the floor of a merge's radiance).
    values = np.array([-0.011917, -1.5, 0.0, 0.25, 3.0, -2.0**-20], np.float16)
    pixels = np.resize(values, (4, 6, 3)).astype(np.float16)
    source = tmp_path / "signed.exr"
    output = oiio.ImageOutput.create(str(source))
    output.open(str(source), oiio.ImageSpec(6, 4, 3, "half"))
    output.write_image(pixels)
    output.close()
    copy, brighter = tmp_path / "copy.exr", tmp_path / "brighter.exr"
    code, _, err = run(capsys, source, "-o", copy, "--exposure", "1", "-o", brighter)
    assert code == 0, err
    for name, c in zip("RGB", range(3)):  # x1 and x2 are exact in half floats
        np.testing.assert_array_equal(_channels(copy)[name], pixels[..., c])
        np.testing.assert_array_equal(_channels(brighter)[name], 2 * pixels[..., c])


def _write_channels(path: Path, names: tuple[str, ...], pixels: np.ndarray) -> None:
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], len(names), "half")
    spec.channelnames = names
    output = oiio.ImageOutput.create(str(path))
    output.open(str(path), spec)
    output.write_image(pixels.astype(np.float16))
    output.close()


def test_chain_carries_an_inputs_other_channels(tmp_path, capsys):
    # A renderer's EXR: colour, alpha and other channels (depth, normals, a mask). The
    # chain's operations act on the colour; the rest is carried along, resized with the
    # image, and written back under its own names (it was dropped without a word).
    names = ("R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "motion.Y")
    pixels = np.random.default_rng(4).uniform(0.0, 4.0, (6, 8, len(names)))
    pixels[..., 3] = 1.0
    source = tmp_path / "aovs.exr"
    _write_channels(source, names, pixels)
    brighter, small = tmp_path / "brighter.exr", tmp_path / "small.exr"
    code, _, err = run(capsys, source, "--exposure", "1", "-o", brighter, "--resize", "50%",
                       "-o", small)
    assert code == 0, err
    before, after, resized = _channels(source), _channels(brighter), _channels(small)
    assert sorted(after) == sorted(resized) == sorted(names)
    assert "with alpha, Z, N.X, N.Y, N.Z, motion.Y" in run(capsys, source, "--info")[1]
    for name in names:  # x2 is exact in half floats
        expected = 2 * before[name] if name in "RGB" else before[name]
        np.testing.assert_array_equal(after[name], expected, err_msg=name)
        assert resized[name].shape == (3, 4)
    # Each channel resized as the colour is (the same filter, applied alone).
    from hdrio.tools.imageops import resize

    for name in ("Z", "motion.Y"):
        np.testing.assert_allclose(resized[name], resize(before[name][..., None], 4, 3)[..., 0],
                                   rtol=1e-3)  # half's precision


def test_chain_resizes_the_merges_layers_with_it(brackets, tmp_path, capsys):
    # The uncertainty and motion layers went missing from a resized merge.
    out = tmp_path / "small.exr"
    code, _, err = run(capsys, *brackets, "--uncertainty", "--motion-layer", "--merge",
                       "--resize", "50%", "-o", out)
    assert code == 0, err
    channels = _channels(out)
    assert {"uncertainty.R", "uncertainty.G", "uncertainty.B", "motion.Y"} <= set(channels)
    assert channels["uncertainty.R"].shape == channels["R"].shape == (24, 32)


def test_chain_says_it_reads_the_first_part_of_a_multi_part_exr(tmp_path, capsys):
    # A second part (here a depth pass) was dropped without a word.
    source, out = tmp_path / "multi.exr", tmp_path / "out.exr"
    specs = [oiio.ImageSpec(8, 6, 3, "half"), oiio.ImageSpec(8, 6, 1, "half")]
    specs[0].attribute("name", "beauty")
    specs[1].attribute("name", "depth")
    specs[1].channelnames = ("Z",)
    output = oiio.ImageOutput.create(str(source))
    assert output.open(str(source), specs)
    output.write_image(np.full((6, 8, 3), 0.5, np.float16))
    assert output.open(str(source), specs[1], "AppendSubimage")
    output.write_image(np.full((6, 8, 1), 2.0, np.float16))
    output.close()
    code, _, err = run(capsys, source, "--exposure", "1", "-o", out)
    assert code == 0, err
    assert "2 parts (beauty, depth); the chain reads and writes the first alone" in err
    np.testing.assert_array_equal(_channels(out)["R"], 1.0)


def test_chain_keeps_a_crops_place_in_its_frame(tmp_path, capsys):
    # An 8x6 crop at (2, 1) of a 16x12 plate (OpenEXR's data and display windows): it
    # was written as an 8x6 image of its own, at the frame's corner.
    spec = oiio.ImageSpec(8, 6, 3, "half")
    spec.x, spec.y, spec.full_width, spec.full_height = 2, 1, 16, 12
    source = tmp_path / "crop.exr"
    output = oiio.ImageOutput.create(str(source))
    output.open(str(source), spec)
    output.write_image(np.full((6, 8, 3), 0.5, np.float16))
    output.close()
    brighter, small = tmp_path / "brighter.exr", tmp_path / "small.exr"
    code, _, err = run(capsys, source, "--exposure", "1", "-o", brighter, "--resize", "50%",
                       "-o", small)
    assert code == 0, err
    for path, data, display in ((brighter, ([2, 1], [9, 6]), [15, 11]),
                                (small, ([1, 0], [4, 2]), [7, 5])):  # the frame halved too
        header = _header(path)
        assert [list(corner) for corner in header["dataWindow"]] == list(data)
        assert list(header["displayWindow"][1]) == display
    np.testing.assert_array_equal(_channels(brighter)["G"], 1.0)
    assert "8x6 at (2, 1) of a 16x12 frame" in run(capsys, "info", brighter)[1]


def test_chain_writes_a_float_exr_as_float_unless_told(tmp_path, capsys):
    # A float EXR beyond half's range (a sun at 1e5, depth at 123456) came out as half,
    # its colour halved (recorded only in hdrio:exposureScale) and its depth clamped.
    spec = oiio.ImageSpec(8, 6, 4, "float")
    spec.channelnames = ("R", "G", "B", "Z")
    pixels = np.full((6, 8, 4), 0.5, np.float32)
    pixels[0, 0, :3], pixels[..., 3] = 1e5, 123456.0
    source, copy, small = tmp_path / "sun.exr", tmp_path / "copy.exr", tmp_path / "half.exr"
    output = oiio.ImageOutput.create(str(source))
    output.open(str(source), spec)
    output.write_image(pixels)
    output.close()
    code, _, err = run(capsys, source, "-o", copy, "-d", "half", "-o", small)
    assert code == 0, err
    for name, c in zip("RGBZ", range(4)):
        np.testing.assert_array_equal(_channels(copy)[name], pixels[..., c])
    assert _header(copy)["hdrio:exposureScale"] == 1.0
    assert "(half)" in run(capsys, "info", small)[1].splitlines()[0]


def test_colorconvert_from_another_space_than_the_label_is_noted(tmp_path, capsys):
    source, out = tmp_path / "aces.exr", tmp_path / "out.exr"
    spec = oiio.ImageSpec(8, 6, 3, "half")
    spec.attribute("hdrio:colorSpace", "ACEScg")
    output = oiio.ImageOutput.create(str(source))
    output.open(str(source), spec)
    output.write_image(np.full((6, 8, 3), 0.5, np.float16))
    output.close()
    code, _, err = run(capsys, source, "--colorconvert", "lin_rec709_scene", "ACEScg",
                       "-o", out)
    assert code == 0, err
    assert "is labelled ACEScg; converted from lin_rec709_scene as told" in err
    code, _, err = run(capsys, source, "--colorconvert", "ACEScg", "lin_rec709_scene",
                       "-o", out)
    assert code == 0 and "labelled" not in err, err


def test_chain_writes_a_grey_exr_with_alpha(tmp_path, capsys):
    # Y and A: an internal error before (the writer named two channels none).
    pixels = np.stack([np.linspace(0.1, 3.0, 48).reshape(6, 8), np.ones((6, 8))], axis=-1)
    source, out = tmp_path / "grey.exr", tmp_path / "out.exr"
    _write_channels(source, ("Y", "A"), pixels)
    code, _, err = run(capsys, source, "--exposure", "1", "-o", out)
    assert code == 0, err
    channels = _channels(out)
    assert list(channels) == ["Y", "A"]
    np.testing.assert_array_equal(channels["Y"], 2 * _channels(source)["Y"])
    np.testing.assert_array_equal(channels["A"], 1.0)


def test_chain_writes_no_capture_time_an_input_did_not_have(tmp_path, capsys):
    # OpenImageIO stamps the time of writing as capDate where none is given: a Radiance
    # HDR (or an EXR without capDate) copied by the chain would claim to be captured now.
    source = tmp_path / "plain.hdr"
    output = oiio.ImageOutput.create(str(source))
    output.open(str(source), oiio.ImageSpec(8, 6, 3, "float"))
    output.write_image(np.full((6, 8, 3), 0.25, np.float32))
    output.close()
    out = tmp_path / "plain.exr"
    code, _, err = run(capsys, source, "--exposure", "1", "-o", out)
    assert code == 0, err
    assert "capDate" not in _header(out)


def test_preview_of_premultiplied_rgba_shows_light_where_alpha_is_0(tmp_path, capsys):
    # OpenEXR's colour is premultiplied: alpha 0 with light is a glow that covers
    # nothing (CandleGlass's flame and the inside of its glass); alpha 0 and no light is
    # hdrio's own "masked in every bracket", shown black and left out of the key.
    rng = np.random.default_rng(3)
    pixels = np.concatenate([rng.uniform(0.05, 0.5, (6, 8, 3)), np.ones((6, 8, 1))], axis=-1)
    pixels[0, :4] = (8.0, 4.0, 1.0, 0.0)  # a flame: alpha 0, the brightest light
    pixels[5, 4:] = 0.0  # masked: no light, alpha 0
    path = tmp_path / "flame.exr"
    output = oiio.ImageOutput.create(str(path))
    output.open(str(path), oiio.ImageSpec(8, 6, 4, "half"))
    output.write_image(pixels.astype(np.float16))
    output.close()
    preview = tmp_path / "flame.png"
    code, _, err = run(capsys, path, "--tonemap", "reinhard-global", "-o", preview)
    assert code == 0, err
    shown = oiio.ImageBuf(str(preview)).get_pixels(oiio.FLOAT)
    assert shown.shape == (6, 8, 3)
    # The flame is the brightest thing shown (was black), the masked pixels black.
    assert shown[0, :4].mean(axis=-1).min() > shown[1:5].mean(axis=-1).max()
    assert shown[0, :4, 0].min() > 0.9
    assert not shown[5, 4:].any()


def test_preview_of_a_masked_merge_is_the_same_from_the_chain(write_brackets, tmp_path,
                                                              capsys):
    # Masked in every bracket (--exclude-color): alpha 0 and no light in the EXR, black
    # in the preview and out of its key, whether the merge renders it or the chain does
    # from the EXR.
    paths = write_brackets(size=(48, 64))
    for path in paths:
        buffer = oiio.ImageBuf(str(path))
        codes = buffer.get_pixels(oiio.UINT8)
        codes[10:30, 20:40] = (0, 0, 255)
        buffer.set_pixels(oiio.ROI(), codes)
        assert buffer.write(str(path))
    exr, merged, chained = (tmp_path / name for name in ("m.exr", "m.png", "chain.png"))
    code, _, err = run(capsys, "merge", *paths, "--exclude-color", "0,0,255", "-o", exr,
                       "--preview", merged, "-q")
    assert code == 0, err
    assert not _channels(exr)["A"][10:30, 20:40].any()
    code, _, err = run(capsys, exr, "--tonemap", "reinhard-global", "-o", chained)
    assert code == 0, err
    from_merge = oiio.ImageBuf(str(merged)).get_pixels(oiio.UINT8).astype(int)
    from_chain = oiio.ImageBuf(str(chained)).get_pixels(oiio.UINT8).astype(int)
    assert not from_chain[10:30, 20:40].any()
    # One code: the chain reads the radiance back from half floats (3 decimal digits).
    assert np.abs(from_chain - from_merge).max() <= 1


def test_tone_mapped_exr_is_labelled_display_referred(brackets, tmp_path, capsys):
    out = tmp_path / "display.exr"
    code, _, err = run(capsys, *brackets, "--colorspace", "ACEScg", "--merge",
                       "--tonemap", "reinhard-global", "-o", out)
    assert code == 0, err
    header = _header(out)
    assert header["hdrio:units"] == "display-referred"
    assert header["hdrio:colorSpace"] == "sRGB - Display"
    assert header["hdrio:rendering"] == "reinhard-global (sRGB)"
    np.testing.assert_allclose(np.ravel(header["chromaticities"]), REC709_D65, atol=1e-6)
    for scene_only in ("hdrio:exposureScale", "colorInteropID", "adoptedNeutral"):
        assert scene_only not in header
    # Read back, the chain knows it is display-referred.
    code, _, err = run(capsys, out, "--exposure", "1", "-o", tmp_path / "again.exr")
    assert code == 2 and "display-referred" in err, err


def test_capture_time_camera_and_exposures_from_exif(write_brackets, tmp_path, capsys):
    times = (0.015625, 0.0625, 0.25, 1.0)  # exact as EXIF rationals
    files = write_brackets(times, attributes=[
        {"ExposureTime": t, "Exif:DateTimeOriginal": "2021:07:08 09:10:11", "Make": "Acme",
         "Model": "HDR-1"} for t in times])
    out = tmp_path / "out.exr"
    code, _, err = run(capsys, "merge", *files, "-o", out, "-q")
    assert code == 0, err
    header = _header(out)
    assert header["capDate"] == "2021:07:08 09:10:11"
    assert (header["Make"], header["Model"]) == ("Acme", "HDR-1")
    assert list(header["hdrio:exposures"]) == ["0.015625", "0.0625", "0.25", "1"]


def test_no_capture_time_is_written_as_none_not_now(brackets, tmp_path, capsys):
    out = tmp_path / "out.exr"
    assert run(capsys, "merge", *brackets, "-o", out, "-q")[0] == 0
    assert "capDate" not in _header(out)


def test_one_adopted_neutral_rule(brackets, tmp_path, capsys):
    """ACEScg from the merge, or converted to in the chain: the ACES white either way."""
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert run(capsys, "merge", *brackets, "--colorspace", "ACEScg", "-o", a, "-q")[0] == 0
    assert run(capsys, *brackets, "--merge", "--colorspace", "ACEScg", "-o", b)[0] == 0
    white_a, white_b = _header(a)["adoptedNeutral"], _header(b)["adoptedNeutral"]
    chromaticities = np.ravel(_header(a)["chromaticities"])
    np.testing.assert_allclose(white_a, chromaticities[6:8], atol=1e-6)
    np.testing.assert_allclose(white_b, white_a, atol=1e-6)
    assert abs(white_a[0] - REC709_D65[6]) > 1e-3  # not D65


def test_exposure_text_is_short_and_exact():
    from hdrio.job.output import exposure_text

    assert exposure_text(np.float32(0.01)) == "0.01"
    assert exposure_text(1 / 3) == repr(1 / 3)  # a 64-bit time keeps every digit
    for t in DEFAULT_EXPOSURES:
        assert float(exposure_text(t)) == t


def test_source_paths_are_absolute_and_relative_to_the_exr(write_brackets, tmp_path,
                                                           capsys, monkeypatch):
    """``hdrio:sourceFiles`` and ``hdrio:alignReference`` hold the paths resolved, and
    their ``...Relative`` twins the paths from the EXR's folder: after the shot folder is
    moved (to a farm node, say), the relative ones still lead to the brackets."""
    shot = tmp_path / "shot"
    write_brackets(folder=shot / "brackets")
    monkeypatch.chdir(shot)
    names = sorted(str(p.relative_to(shot)) for p in (shot / "brackets").iterdir())
    code, _, err = run(capsys, "merge", *names, "--align", "translation", "-o",
                       "hdr/out.exr", "-q")
    assert code == 0, err
    code, _, err = run(capsys, "hdr/out.exr", "--tonemap", "reinhard-global", "-o",
                       "display/view.exr")  # a display-referred EXR carries them too
    assert code == 0, err
    resolved = [str((shot / name).resolve()) for name in names]
    for exr, relative in (("hdr/out.exr", "../brackets"), ("display/view.exr", "../brackets")):
        header = _header(shot / exr)
        sources = list(header["hdrio:sourceFiles"])  # shortest exposure first
        assert sorted(sources) == sorted(resolved)
        assert list(header["hdrio:sourceFilesRelative"]) == [
            f"{relative}/{Path(source).name}" for source in sources]
        reference = header["hdrio:alignReference"]
        assert reference in resolved
        assert header["hdrio:alignReferenceRelative"] == f"{relative}/{Path(reference).name}"
    moved = tmp_path / "farm" / "shot"
    moved.parent.mkdir()
    shot.rename(moved)
    header = _header(moved / "hdr" / "out.exr")
    assert all((moved / "hdr" / rel).is_file() for rel in header["hdrio:sourceFilesRelative"])
