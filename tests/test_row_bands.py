"""Whole-image NumPy steps done band by band of rows (:func:`hdrio.parallel.row_bands`):
the preview's encoding and 8-bit codes, colour conversions. Each must give the one-pass
result bit for bit, and hold no full-size temporary: at 24 MP each 288 MB temporary was a
fresh mapping faulted in page by page (the preview took 3.0-4.4 s and raised the merge's
peak from 0.56 to 2.0 GB; docs/speed.md)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from hdrio.cms import spaces
from hdrio.cms.display import preview_OCIO_display
from hdrio.io.write import write_preview
from hdrio.parallel import ROWS_OF_VALUES, row_bands
from hdrio.tonemap import encode_sRGB
from hdrio.tonemap.preview import render_preview

# 700 x 501 RGB: five bands of 174 rows, the last one short.
SHAPE = (700, 501, 3)


def _image(dtype=np.float32) -> np.ndarray:
    rgb = np.random.default_rng(3).lognormal(0.0, 2.0, SHAPE).astype(dtype)
    rgb[0, 0] = np.nan
    rgb[1, 1] = np.inf
    rgb[2, 2] = -0.5
    return rgb


def test_bands_cover_every_row_once():
    image = np.empty(SHAPE, np.float32)
    bands = row_bands(image)
    assert len(bands) == 5 and bands.step == ROWS_OF_VALUES // (SHAPE[1] * 3)
    rows = np.concatenate([np.arange(SHAPE[0])[top:top + bands.step] for top in bands])
    assert np.array_equal(rows, np.arange(SHAPE[0]))
    assert row_bands(np.float32(1.0)) == range(0, 1)
    assert row_bands(np.empty((3, 10**6))).step == 1  # at least a row a band


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_srgb_encoding_by_bands_is_the_one_pass_formula(dtype):
    display = np.clip(_image(dtype) / 50.0, -0.1, 1.2)
    linear = np.clip(display.astype(np.float32), 0.0, 1.0)
    curve = np.float32(1.055) * (np.power(linear, np.float32(1 / 2.4)) - np.float32(1))
    curve += np.float32(1)
    expected = np.where(linear <= np.float32(0.0031308), np.float32(12.92) * linear, curve)
    encoded = encode_sRGB(display)
    assert encoded.dtype == np.float32
    assert np.array_equal(encoded, expected, equal_nan=True)
    if dtype == np.float32:  # in place, as the preview does it
        assert np.array_equal(encode_sRGB(display, out=display), expected, equal_nan=True)
    assert encode_sRGB(np.float32(1.0)) == np.float32(1.0)  # a scalar: one band


def test_preview_codes_by_bands_are_the_one_pass_codes(tmp_path):
    import OpenImageIO as oiio

    display = np.clip(_image() / 50.0, -0.1, 1.2)
    display[0, 0] = 0.0  # a preview has no NaN left
    write_preview(tmp_path / "p.png", display)
    written = oiio.ImageInput.open(str(tmp_path / "p.png")).read_image(format="uint8")
    assert np.array_equal(written, np.round(np.clip(display, 0.0, 1.0) * 255.0).astype(np.uint8))


def test_colour_conversion_by_bands_on_threads_is_one_ocio_call(monkeypatch):
    monkeypatch.setenv("HDRIO_THREADS", "2")
    rgb = _image()
    processor = spaces._cpu("Linear Rec.709 (sRGB)", "ACEScg", None)
    expected = rgb.reshape(-1, 3).copy()
    processor.applyRGB(expected)
    converted = spaces.convert(rgb, "Linear Rec.709 (sRGB)", "ACEScg")
    assert converted.dtype == np.float32 and converted.shape == SHAPE
    assert np.array_equal(converted.reshape(-1, 3), expected, equal_nan=True)
    for other in (rgb.astype(np.float64), np.asfortranarray(rgb)):  # any dtype or layout
        assert np.array_equal(spaces.convert(other, "Linear Rec.709 (sRGB)", "ACEScg"),
                              converted, equal_nan=True)
    pixel = spaces.convert(rgb[5, 5], "Linear Rec.709 (sRGB)", "ACEScg")
    assert np.array_equal(pixel, converted[5, 5])


@pytest.mark.parametrize("name", ["reinhard-global", "reinhard-local", "ocio-display"])
def test_a_preview_holds_no_full_size_temporary(name):
    # A 3 MP image (18 MB as float32). The display is the one full-size array the
    # Reinhard operators' preview makes; the OCIO display's also scales a copy of the
    # image first. The rest is bands of ROWS_OF_VALUES values, a few of them at once.
    # Measured: 1.0 and 2.1 displays plus the bands; before, 5.3 and 3.6 displays
    # (nan_to_num's masks and copy, each step of the encoding a full-size temporary).
    rgb = np.random.default_rng(3).lognormal(0.0, 2.0, (1500, 1001, 3)).astype(np.float32)
    if name == "ocio-display":
        def render(image):
            return preview_OCIO_display(image, "Linear Rec.709 (sRGB)", "sRGB - Display",
                                        "ACES 2.0 - SDR 100 nits (Rec.709)")
        full = 2
    else:
        def render(image):
            return render_preview(image, name)
        full = 1
    render(rgb)  # kernels compiled, caches warm
    tracemalloc.start()
    try:
        result = render(rgb)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert result.shape == rgb.shape and np.all((result >= 0) & (result <= 1))
    bands = 6 * ROWS_OF_VALUES * 8  # six float64 temporaries of a band at most
    assert peak <= full * rgb.nbytes + bands, (peak / rgb.nbytes, bands / rgb.nbytes)
