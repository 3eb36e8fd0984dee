"""Brackets are turned upright by their EXIF orientation (hdrio.io.orientation), as every
photo viewer shows them: a phone held in portrait stores landscape pixels and says
"turned 90 degrees clockwise"; merged as stored, the EXR and preview were sideways."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from hdrio.io.brackets import read_brackets, read_codes, read_header
from hdrio.io.orientation import DESCRIPTIONS, stored_view, upright_size
from hdrio.io.write import write_image
from tests.conftest import ramp_radiance, run_cli

INVERSE = {1: 1, 2: 2, 3: 3, 4: 4, 5: 5, 6: 8, 7: 7, 8: 6}
"""The orientation that undoes each (turning 90 degrees one way undoes the other)."""


def reoriented(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """``pixels`` tagged with ``orientation``, turned upright by OpenImageIO's own
    ``ImageBufAlgo.reorient``: the reference the reader is held to."""
    height, width, channels = pixels.shape
    spec = oiio.ImageSpec(width, height, channels, "uint16")
    spec.attribute("Orientation", orientation)
    buffer = oiio.ImageBuf(spec)
    buffer.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels))
    return oiio.ImageBufAlgo.reorient(buffer).get_pixels(oiio.UINT16)


def stored_as(upright: np.ndarray, orientation: int) -> np.ndarray:
    """The pixels a file tagged ``orientation`` stores to show ``upright`` (OpenImageIO's
    reorient by the inverse orientation)."""
    return reoriented(upright, INVERSE[orientation])


@pytest.mark.parametrize("orientation", sorted(DESCRIPTIONS))
def test_stored_view_turns_pixels_as_openimageio_does(orientation):
    rng = np.random.default_rng(orientation)
    stored = rng.integers(0, 65535, (5, 7, 3), dtype=np.uint16)
    upright = np.empty((*upright_size(5, 7, orientation), 3), np.uint16)
    stored_view(upright, orientation)[...] = stored
    np.testing.assert_array_equal(upright, reoriented(stored, orientation))


def _write(path: Path, pixels: np.ndarray, orientation: int, exposure: float) -> Path:
    return write_image(path, pixels, "uint8", {"Orientation": orientation,
                                               "ExposureTime": exposure})


@pytest.mark.parametrize("kind", ["uint8", "uint16"])  # RGB; one grey channel
@pytest.mark.parametrize("orientation", sorted(DESCRIPTIONS))
def test_a_bracket_reads_upright_in_every_orientation(tmp_path, orientation, kind):
    rng = np.random.default_rng(0)
    channels = 3 if kind == "uint8" else 1
    upright = rng.integers(0, np.iinfo(kind).max + 1, (6, 9, channels), dtype=kind)
    stored = stored_as(upright.astype(np.uint16), orientation).astype(kind)
    path = write_image(tmp_path / "bracket.tif", stored, kind,
                       {"Orientation": orientation, "ExposureTime": 0.01})
    codes, _, exif = read_codes(path)
    np.testing.assert_array_equal(codes, upright)
    assert read_header(path).shape == upright.shape
    assert exif.get("Orientation", 1) == orientation
    # As stored where asked (the Blender node's solve, whose images Blender loads so).
    np.testing.assert_array_equal(read_codes(path, upright=False)[0], stored)
    assert "Orientation" not in read_codes(path, upright=False)[2]


def _ladder(exposures, size=(40, 60)) -> list[np.ndarray]:
    from hdrio.tools.synthetic import render_brackets

    radiance = ramp_radiance(*size) * np.linspace(0.5, 1.5, size[1])[None, :, None]
    return list(render_brackets(radiance, list(exposures)))


def test_a_portrait_set_merges_upright_whatever_each_file_stores(tmp_path, capsys):
    # The same upright ladder written twice: as stored pixels tagged 1, and as a phone
    # writes a portrait set (landscape pixels, "turned 90 degrees clockwise"), one
    # bracket re-saved mirrored (tagged 2) by an editor. The merges are the same,
    # pixel for pixel, and the second says what it turned.
    exposures = [1 / 64, 1 / 16, 1 / 4, 1.0]
    frames = [np.ascontiguousarray(np.rot90(f, 1)) for f in _ladder(exposures)]  # portrait
    plain, phone = tmp_path / "plain", tmp_path / "phone"
    plain.mkdir()
    phone.mkdir()
    tags = [6, 6, 2, 6]
    for k, (frame, t, tag) in enumerate(zip(frames, exposures, tags, strict=True)):
        _write(plain / f"b{k}.tif", frame, 1, t)
        stored = stored_as(frame.astype(np.uint16), tag).astype(np.uint8)
        assert stored.shape != frame.shape or tag == 2
        _write(phone / f"b{k}.tif", stored, tag, t)
    results = {}
    for folder in (plain, phone):
        out = tmp_path / f"{folder.name}.exr"
        code, text, err = run_cli(capsys, "merge", *sorted(folder.glob("*.tif")), "-o", out)
        assert code == 0, err
        results[folder.name] = (out, text)
    pixels = {name: oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)
              for name, (out, _) in results.items()}
    assert pixels["phone"].shape == (*frames[0].shape[:2], 3)  # portrait, as shown
    np.testing.assert_array_equal(pixels["phone"], pixels["plain"])
    phone_text, plain_text = results["phone"][1], results["plain"][1]
    assert ("upright:   as the EXIF says, mirrored left to right (orientation 2): b2.tif; "
            "turned 90 degrees clockwise (orientation 6): b0.tif, b1.tif, b3.tif") in phone_text
    assert "upright:" not in plain_text
    header = oiio.ImageInput.open(str(results["phone"][0])).spec()
    assert header.getattribute("hdrio:sourceOrientation") == ("6", "6", "2", "6")
    plain_header = oiio.ImageInput.open(str(results["plain"][0])).spec()
    assert plain_header.getattribute("hdrio:sourceOrientation") is None


def test_brackets_of_one_size_once_upright_are_one_set(tmp_path):
    # Stored landscape and tagged "turned 90 degrees counter-clockwise" beside portrait
    # files tagged upright: the same size once turned, so one set. As stored they
    # differ, and reading them so names the odd one out.
    exposures = [1 / 16, 1 / 4, 1.0]
    frames = [np.ascontiguousarray(np.rot90(f, 1)) for f in _ladder(exposures)]
    paths = []
    for k, (frame, t) in enumerate(zip(frames, exposures, strict=True)):
        tag = 8 if k == 1 else 1
        paths.append(_write(tmp_path / f"b{k}.tif",
                            stored_as(frame.astype(np.uint16), tag).astype(np.uint8), tag, t))
    stack = read_brackets(paths)
    np.testing.assert_array_equal(stack.codes, np.stack(frames))
    from hdrio.errors import InputError

    with pytest.raises(InputError, match="b1.tif.*brackets must match"):
        read_brackets(paths, upright=False)


def test_a_mask_is_read_upright_like_the_brackets(tmp_path):
    # A mask saved by a tool that kept the photo's EXIF (landscape pixels tagged "turned
    # 90 degrees clockwise") excludes the same pixels of the upright brackets as the
    # upright mask does.
    from hdrio.io.masks import read_masks

    upright = np.full((40, 30, 1), 255, np.uint8)
    upright[5:12, 3:20] = 0  # excluded
    stored = stored_as(upright.astype(np.uint16), 6).astype(np.uint8)
    assert stored.shape[:2] == (30, 40)
    path = write_image(tmp_path / "mask.tif", stored, "uint8", {"Orientation": 6})
    excluded = read_masks([str(path)], ["a.jpg", "b.jpg"], (40, 30))
    np.testing.assert_array_equal(excluded, np.stack([upright[..., 0] == 0] * 2))
