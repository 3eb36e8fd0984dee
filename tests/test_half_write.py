"""Half floats made on every core (hdrio.io.half), and the write that uses them: bit for
bit NumPy's conversion, the same file and the same check report whatever the threads."""

from __future__ import annotations

import threading

import numpy as np
import OpenImageIO as oiio
import pytest

from hdrio.cms.checks import StreamingCheck, check_exr
from hdrio.io.half import to_half
from hdrio.io.write import HALF_MAX, HALF_MIN_POSITIVE, write_exr
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files
from hdrio.parallel import map_on_threads


def _float32_patterns() -> np.ndarray:
    """float32 values of every sign and exponent: each top-16-bit pattern with random low
    bits, with low bits at the rounding boundaries (the half's last bit, ties), and the
    edges of half's range (its subnormals, overflow, infinities)."""
    rng = np.random.default_rng(3)
    high = np.arange(1 << 16, dtype=np.uint32) << 16
    low = rng.integers(0, 1 << 16, size=high.size, dtype=np.uint32)
    edges = np.array([0x33000000, 0x32FFFFFF, 0x33000001, 0x38000000, 0x387FE000,
                      0x387FF000, 0x477FE000, 0x477FF000, 0x477FEFFF, 0x47800000,
                      0x7F800000, 0xFF800000], np.uint32)
    bits = np.concatenate([high | low, high, high | 0x1000, high | 0x0FFF, high | 0x3000,
                           high | 0x1001, edges,
                           rng.integers(0, 1 << 32, size=1 << 20, dtype=np.uint64
                                        ).astype(np.uint32)])
    values = bits.view(np.float32)
    return values[~np.isnan(values)]


@pytest.mark.parametrize("budget", ["1", "3"])
def test_half_bits_are_numpys_for_every_exponent(monkeypatch, budget):
    # Exact: the EXR's pixels must not change by a bit when the conversion moved from
    # NumPy's astype to the kernel (round to nearest, ties to even, subnormals, infinity).
    monkeypatch.setenv("HDRIO_THREADS", budget)
    values = _float32_patterns()
    values = values[: values.size - values.size % 3].reshape(-1, 1, 3)
    unbounded = [np.inf] * 3
    made = to_half(values, [1.0] * 3, [-np.inf] * 3, unbounded)
    with np.errstate(over="ignore"):
        expected = values.astype(np.float16)
    assert made.dtype == np.float16
    assert np.array_equal(made.view(np.uint16), expected.view(np.uint16))


def test_a_nan_stays_a_nan():
    values = np.array([[[np.nan, 1.0, -np.nan]]], np.float32)
    made = to_half(values, [2.0] * 3, [0.0] * 3, [HALF_MAX] * 3)
    assert np.isnan(made[0, 0, 0]) and made[0, 0, 1] == 2.0 and np.isnan(made[0, 0, 2])


@pytest.mark.parametrize("channels", [3, 5])
def test_each_channel_is_scaled_and_clipped_in_float32_first(channels):
    # As write_exr did with NumPy: scale (float32 product), clip, then round to half;
    # with every channel alike (one flat loop) and with a channel's own numbers.
    rng = np.random.default_rng(5)
    pixels = (rng.standard_normal((37, 29, channels)) * 4.0).astype(np.float32)
    pixels = np.exp(pixels) * np.sign(rng.standard_normal(pixels.shape)).astype(np.float32)
    alike = channels == 3
    scales = [0.25] * channels if alike else [0.25, 0.25, 0.25, 1.0, 1.0]
    lows = [HALF_MIN_POSITIVE] * channels if alike else [HALF_MIN_POSITIVE] * 3 + [
        0.0, -HALF_MAX]
    highs = [HALF_MAX] * channels
    expected = np.clip(pixels * np.asarray(scales, np.float32), np.asarray(lows, np.float32),
                       np.asarray(highs, np.float32)).astype(np.float16)
    made = to_half(pixels, scales, lows, highs)
    assert np.array_equal(made.view(np.uint16), expected.view(np.uint16))


def test_every_row_is_observed_once_as_stored(monkeypatch):
    monkeypatch.setenv("HDRIO_THREADS", "4")
    pixels = np.arange(50 * 7 * 3, dtype=np.float32).reshape(50, 7, 3) / 10.0
    seen, lock = [], threading.Lock()

    def observe(rows: np.ndarray) -> None:
        with lock:
            seen.append(np.array(rows))

    made = to_half(pixels, [1.0] * 3, [0.0] * 3, [HALF_MAX] * 3, observe)
    rows = np.concatenate(seen)
    # the halves stored, bit for bit
    assert rows.dtype == np.float16 and rows.shape == made.shape
    # pieces arrive in any order: each row once (rows are distinct), as stored
    order = np.argsort(rows[:, 0, 0])
    assert np.array_equal(rows[order].view(np.uint16), made.view(np.uint16))


@pytest.mark.parametrize("layers", [False, True])
def test_the_file_and_its_check_do_not_depend_on_the_threads(tmp_path, monkeypatch, layers):
    # The report fed while writing (the merge's) on any budget is the one `hdrio check`
    # reads back from the file: counts and extremes exact, the same histogram.
    rng = np.random.default_rng(8)
    rgb = np.exp(rng.standard_normal((300, 64, 3)) * 3).astype(np.float32)
    rgb[5, 5] = -1.0
    extra = {"uncertainty": rng.random((300, 64, 1)).astype(np.float32)} if layers else None
    written, reports = {}, {}
    for budget in ("1", "4"):
        monkeypatch.setenv("HDRIO_THREADS", budget)
        check = StreamingCheck()
        path = tmp_path / f"b{budget}.exr"
        write_exr(path, rgb, {"hdrio:units": "relative", "DateTime": "2026:01:01 00:00:00"},
                  scale=0.5, layers=extra,
                  observe=check.add)
        written[budget] = path.read_bytes()
        reports[budget] = check.report()
        assert check.pixels == rgb.shape[0] * rgb.shape[1]
    assert written["1"] == written["4"]
    read_back = check_exr(tmp_path / "b4.exr")
    for report in reports.values():
        assert report.luminance_percentiles == read_back.luminance_percentiles
        assert report.dynamic_range_stops == read_back.dynamic_range_stops
        assert report.negative == read_back.negative == 1  # kept, as a float EXR keeps it


def test_map_on_threads_keeps_the_items_order(monkeypatch):
    monkeypatch.setenv("HDRIO_THREADS", "4")
    assert map_on_threads(lambda k: k * k, list(range(20))) == [k * k for k in range(20)]
    assert map_on_threads(str, []) == []


@pytest.mark.parametrize("channels", [3, 5])
def test_floors_raise_values_from_0_and_leave_negative_ones(channels):
    # A merge's colour: 0 and tiny values become half's smallest subnormal (no pixel 0),
    # a negative one (outside the output's gamut) stays as float would keep it.
    values = np.array([0.0, 1e-9, -1e-9, -3.5, 2.0, HALF_MIN_POSITIVE, np.nan],
                      np.float32)
    pixels = np.repeat(values[:, None, None], channels, axis=2)
    floors = [HALF_MIN_POSITIVE] * 3 + [0.0] * (channels - 3)
    made = to_half(pixels, [1.0] * channels, [-HALF_MAX] * channels, [HALF_MAX] * channels,
                   floors=floors).astype(np.float32)
    floored = np.array([HALF_MIN_POSITIVE, HALF_MIN_POSITIVE, -0.0, -3.5, 2.0,
                        HALF_MIN_POSITIVE, np.nan], np.float32)
    np.testing.assert_array_equal(made[:, 0, 0], floored)
    if channels == 5:  # no floor: as NumPy rounds
        np.testing.assert_array_equal(made[:, 0, 4], values.astype(np.float16))


def test_half_and_float_merges_agree_outside_the_gamut(write_brackets, tmp_path):
    # Display P3 brackets merged to linear Rec.709: saturated colours come out negative.
    # The half EXR clamped them to half's smallest value; the float one kept them.
    from tests.conftest import DEFAULT_EXPOSURES

    paths = write_brackets(DEFAULT_EXPOSURES, size=(24, 32))
    for path in paths:  # a saturated green patch, in every bracket
        buffer = oiio.ImageBuf(str(path))
        codes = buffer.get_pixels(oiio.UINT8)
        codes[4:12, 4:12] = (np.asarray(codes[4:12, 4:12], np.int32) * (0, 1, 0)).astype(
            np.uint8)
        buffer.set_pixels(oiio.ROI(), codes)
        assert buffer.write(str(path))
    outputs = {}
    for pixel_type in ("half", "float"):
        outputs[pixel_type] = tmp_path / f"{pixel_type}.exr"
        merge_files(paths, outputs[pixel_type], pixel_type=pixel_type,
                    options=MergeOptions(input_encoding="Display P3", align="off",
                                         deghost="off"))
    half, single = (oiio.ImageBuf(str(outputs[t])).get_pixels(oiio.FLOAT)
                    for t in ("half", "float"))
    assert (single < -1e-3).any()  # the patch's red and blue, outside Rec.709
    # Half's precision (11 bits) and its scale factor, where the float EXR has one too.
    scale = float(oiio.ImageBuf(str(outputs["half"])).spec().get_float_attribute(
        "hdrio:exposureScale")) / float(oiio.ImageBuf(str(outputs["float"])).spec()
                                        .get_float_attribute("hdrio:exposureScale"))
    np.testing.assert_allclose(half / scale, single, rtol=2e-3, atol=1e-6)
