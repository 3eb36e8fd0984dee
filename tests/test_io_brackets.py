"""Reading brackets (code values, exposures and their sources) and writing EXR atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR  # the test extra: proves our EXRs are readable by OpenEXR itself
import OpenImageIO as oiio
import pytest

from hdrio.errors import InputError
from hdrio.io.brackets import read_brackets, read_codes
from hdrio.io.write import HALF_MAX, HALF_MIN_POSITIVE, OutputError, write_exr, write_image

FROBISHER = ("IMG_2600.jpg", "IMG_2601.jpg", "IMG_2602.jpg")  # 1/8 s, 1 s, 8 s in EXIF


def exif(seconds: float, f_number: float = 8.0, iso: int = 100) -> dict[str, object]:
    """EXIF attributes as OpenImageIO writes them into a PNG."""
    return {"ExposureTime": seconds, "FNumber": f_number, "Exif:PhotographicSensitivity": iso}


def leftovers(folder: Path) -> list[str]:
    """Temp files the atomic writer may have left (they are hidden: ``.name.partial.exr``)."""
    return sorted(p.name for p in folder.iterdir() if ".partial" in p.name)


# ----------------------------------------------------------------------- exposure sources


def test_explicit_exposures(write_brackets):
    paths = write_brackets(names=["dark.png", "mid.png", "bright.png"], exposures=[1, 2, 3])
    stack = read_brackets(paths, exposures=["1/8", 0.5, "2"])
    assert stack.exposures.tolist() == [0.125, 0.5, 2.0]  # exact: binary fractions
    assert stack.exposure_sources == ("explicit",) * 3
    assert stack.files == tuple(str(p) for p in paths)


def test_explicit_exposure_count_must_match(write_brackets):
    paths = write_brackets(names=["a.png", "b.png", "c.png"], exposures=[1, 2, 3])
    with pytest.raises(InputError, match="2 exposures given for 3 images") as error:
        read_brackets(paths, exposures=["1/8", "1"])
    assert error.value.path == str(paths[2])


def test_bad_explicit_exposure_names_its_file(write_brackets):
    paths = write_brackets(names=["a.png", "b.png"], exposures=[1, 2])
    with pytest.raises(InputError) as error:
        read_brackets(paths, exposures=["1/8", "-1"])
    assert error.value.path == str(paths[1])


def test_sidecar_csv_with_relative_names(write_brackets, tmp_path):
    paths = write_brackets(names=["a.png", "b.png", "c.png"], exposures=[1, 2, 3])
    sidecar = tmp_path / "exposures.csv"
    sidecar.write_text("file,exposure_time_s\nbrackets/c.png,4\nb.png,1\na.png,1/4\n")
    stack = read_brackets(paths, exposures_from=sidecar)
    assert stack.exposures.tolist() == [0.25, 1.0, 4.0]  # exact: binary fractions
    assert stack.exposure_sources == ("sidecar",) * 3


def test_sidecar_opencv_list(write_brackets, tmp_path):
    paths = write_brackets(names=["a.png", "b.png"], exposures=[1, 2])
    sidecar = tmp_path / "list.txt"
    sidecar.write_text("a.png 8\nb.png 0.5\n")  # values are 1/t
    stack = read_brackets(paths, exposures_from=sidecar)
    assert stack.exposures.tolist() == [0.125, 2.0]  # exact: reciprocals of powers of 2


def test_sidecar_missing_a_file_names_that_file(write_brackets, tmp_path):
    paths = write_brackets(names=["a.png", "b.png", "c.png"], exposures=[1, 2, 3])
    sidecar = tmp_path / "exposures.csv"
    sidecar.write_text("file,exposure_time_s\na.png,1/4\nc.png,4\n")
    with pytest.raises(InputError, match="no exposure for this file") as error:
        read_brackets(paths, exposures_from=sidecar)
    assert error.value.path == str(paths[1])


def test_sidecar_from_shared_memorial(shared_data):
    folder = shared_data("memorial_debevec")
    paths = sorted(folder.glob("memorial00*.png"))
    stack = read_brackets(paths, exposures_from=folder / "exposures.csv")
    assert stack.count == 16
    assert stack.exposure_sources == ("sidecar",) * 16
    # exact: the set is 1/1024 s .. 32 s in whole stops, all powers of two
    assert stack.exposures.tolist() == [2.0**k for k in range(-10, 6)]
    assert Path(stack.files[0]).name == "memorial0076.png"
    assert Path(stack.files[-1]).name == "memorial0061.png"
    assert stack.codes.shape == (16, 768, 512, 3)
    assert stack.codes.dtype == np.uint8


def test_exif_from_shared_frobisher(shared_data):
    folder = shared_data("frobisher_001")
    stack = read_brackets([folder / name for name in FROBISHER])
    assert stack.exposures.tolist() == [1 / 8, 1.0, 8.0]  # exact: EXIF rationals 1/8, 1, 8
    assert stack.exposure_sources == ("exif",) * 3
    assert stack.codes.dtype == np.uint8
    assert stack.codes.shape == (3, 426, 640, 3)
    assert stack.code_max == 255
    assert stack.metadata[0]["FNumber"] == 8.0  # exact: f/8 as stored
    assert stack.metadata[0]["ISO"] == 100


def test_exif_frobisher_given_in_reverse_order_is_sorted(shared_data):
    folder = shared_data("frobisher_001")
    stack = read_brackets([folder / name for name in reversed(FROBISHER)])
    assert stack.exposures.tolist() == [1 / 8, 1.0, 8.0]  # exact: EXIF rationals
    assert [Path(f).name for f in stack.files] == list(FROBISHER)
    assert np.array_equal(stack.codes[0], read_codes(folder / FROBISHER[0])[0])


def test_exif_written_by_openimageio(write_brackets):
    paths = write_brackets(
        names=["a.png", "b.png", "c.png"], exposures=[1 / 30, 1 / 8, 1 / 2],
        attributes=[exif(1 / 30), exif(1 / 8), exif(1 / 2)],
    )
    stack = read_brackets(paths)
    assert stack.exposure_sources == ("exif",) * 3
    # rel=1e-4: OpenImageIO writes EXIF times as rationals with a decimal denominator
    # (1/30 comes back as 0.033333), then hands them back as float32
    assert stack.exposures == pytest.approx([1 / 30, 1 / 8, 1 / 2], rel=1e-4)


def test_exif_with_varying_iso_gives_relative_exposures(write_brackets):
    paths = write_brackets(
        names=["a.png", "b.png", "c.png"], exposures=[1 / 4, 1, 4],
        attributes=[exif(1 / 4, 4.0, 100), exif(1 / 4, 4.0, 400), exif(1 / 4, 4.0, 1600)],
    )
    stack = read_brackets(paths)
    assert stack.exposure_sources == ("exif",) * 3
    # rel=1e-6: float32 EXIF values; t * ISO/100 / N^2 = 1/4 * {1, 4, 16} / 16
    assert stack.exposures == pytest.approx([1 / 64, 1 / 16, 1 / 4], rel=1e-6)


def test_filename_convention(write_brackets):
    paths = write_brackets(exposures=[1 / 16, 1 / 4, 1.0, 4.0])
    stack = read_brackets(paths)
    assert [p.name for p in paths][:2] == ["bracket_1_16.png", "bracket_1_4.png"]
    assert stack.exposures.tolist() == [1 / 16, 1 / 4, 1.0, 4.0]  # exact: binary fractions
    assert stack.exposure_sources == ("filename",) * 4


def test_no_exposure_anywhere_names_a_file(write_brackets):
    paths = write_brackets(names=["dark.png", "mid.png", "bright.png"], exposures=[1, 2, 3])
    with pytest.raises(InputError, match="no exposure time") as error:
        read_brackets(paths)
    assert error.value.path == str(paths[0])


def test_exif_on_only_some_files_falls_back_to_names_for_all(write_brackets):
    paths = write_brackets(
        exposures=[1 / 4, 1.0, 4.0], attributes=[exif(1 / 100), None, exif(1 / 10)],
    )
    stack = read_brackets(paths)
    assert stack.exposure_sources == ("filename",) * 3  # one source for the whole set
    assert stack.exposures.tolist() == [0.25, 1.0, 4.0]  # exact: binary fractions


class TestPrecedence:
    """explicit > sidecar > EXIF > file name, for a set where every source is present."""

    NAMES = [1 / 16, 1 / 4, 1.0]  # what the file names say
    EXIF = [1 / 32, 1 / 8, 1 / 2]  # what EXIF says
    SIDECAR = ["1/1000", "1/100", "1/10"]
    EXPLICIT = ["2", "4", "8"]

    @pytest.fixture
    def paths(self, write_brackets):
        return write_brackets(self.NAMES, attributes=[exif(t) for t in self.EXIF])

    @pytest.fixture
    def sidecar(self, paths, tmp_path):
        path = tmp_path / "exposures.csv"
        rows = [f"{p.name},{t}" for p, t in zip(paths, self.SIDECAR, strict=True)]
        path.write_text("file,exposure_time_s\n" + "\n".join(rows) + "\n")
        return path

    def test_explicit_beats_sidecar(self, paths, sidecar):
        stack = read_brackets(paths, exposures=self.EXPLICIT, exposures_from=sidecar)
        assert stack.exposure_sources[0] == "explicit"
        assert stack.exposures.tolist() == [2.0, 4.0, 8.0]  # exact: integers

    def test_sidecar_beats_exif(self, paths, sidecar):
        stack = read_brackets(paths, exposures_from=sidecar)
        assert stack.exposure_sources[0] == "sidecar"
        assert stack.exposures.tolist() == [1 / 1000, 1 / 100, 1 / 10]  # exact: one division

    def test_exif_beats_file_names(self, paths):
        stack = read_brackets(paths)
        assert stack.exposure_sources[0] == "exif"
        assert stack.exposures == pytest.approx(self.EXIF, rel=1e-6)  # float32 EXIF values


# ------------------------------------------------------------------------ sorting, validation


def test_unsorted_input_is_sorted_with_files_and_codes(write_brackets):
    exposures = [1 / 16, 1 / 4, 1.0, 4.0]
    paths = write_brackets(exposures)
    shuffled = [2, 0, 3, 1]
    stack = read_brackets([paths[j] for j in shuffled],
                          exposures=[exposures[j] for j in shuffled])
    assert stack.exposures.tolist() == exposures  # exact: the values given, reordered
    assert stack.files == tuple(str(p) for p in paths)
    for codes, path in zip(stack.codes, paths, strict=True):
        assert np.array_equal(codes, read_codes(path)[0])  # exact: the same stored codes


def test_a_repeated_exposure_is_read_in_the_order_given(write_brackets):
    # A repeat (a ladder capped by the shutter) is a stack of its own right; whether its
    # frames are one picture is the merge's check (tests/test_repeated_exposures.py).
    paths = write_brackets(names=["a.png", "b.png", "c.png"], exposures=[1, 2, 3])
    stack = read_brackets(paths, exposures=["1/8", "1", "1/8"])
    assert stack.exposures.tolist() == [0.125, 0.125, 1.0]
    assert stack.files == (str(paths[0]), str(paths[2]), str(paths[1]))  # ties as given


def test_different_sizes_name_the_odd_file(write_brackets, tmp_path):
    big = write_brackets([1 / 4, 1.0])
    small = write_brackets([4.0], size=(24, 32), folder=tmp_path / "small")
    with pytest.raises(InputError, match="must match") as error:
        read_brackets([*big, *small])
    assert error.value.path == str(small[0])
    assert "32x24" in error.value.problem and "64x48" in error.value.problem
    assert "turned" not in error.value.problem


def test_a_bracket_turned_a_quarter_is_said_to_be(write_brackets, tmp_path):
    # A file stored in portrait among landscape ones, with no EXIF Orientation to turn
    # it: the sizes are each other's turned, and the message says what to do.
    wide = write_brackets([1 / 4, 1.0])
    tall = write_brackets([4.0], size=(64, 48), folder=tmp_path / "tall")
    with pytest.raises(InputError, match="turned a quarter against it") as error:
        read_brackets([*wide, *tall])
    assert error.value.path == str(tall[0])


def test_8_and_16_bit_brackets_do_not_mix(write_brackets, tmp_path):
    low = write_brackets([1 / 4, 1.0])
    high = write_brackets([4.0], bit_depth=16, folder=tmp_path / "deep")
    with pytest.raises(InputError, match="16-bit") as error:
        read_brackets([*low, *high])
    assert error.value.path == str(high[0])


def test_single_image_is_refused(write_brackets):
    paths = write_brackets([1.0])
    with pytest.raises(InputError, match="at least 2") as error:
        read_brackets(paths)
    assert error.value.path == str(paths[0])


def test_missing_and_unreadable_files_are_named(write_brackets, tmp_path):
    paths = write_brackets([1 / 4, 1.0])
    missing = tmp_path / "nothere_1_8.png"
    with pytest.raises(InputError, match="no such file") as error:
        read_brackets([*paths, missing])
    assert error.value.path == str(missing)
    garbage = tmp_path / "garbage_1_8.jpg"
    garbage.write_bytes(b"this is not a JPEG" * 100)
    with pytest.raises(InputError, match="cannot read") as error:
        read_brackets([*paths, garbage])
    assert error.value.path == str(garbage)


def test_truncated_png_is_named(write_brackets, tmp_path):
    paths = write_brackets([1 / 4, 1.0])
    whole = paths[1].read_bytes()
    truncated = tmp_path / "truncated_1_8.png"
    truncated.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(InputError, match="cannot decode") as error:
        read_brackets([*paths, truncated])
    assert error.value.path == str(truncated)


def test_float_images_are_not_brackets(tmp_path):
    path = tmp_path / "linear_1_8.exr"
    write_exr(path, np.full((4, 4, 3), 0.5, np.float32))
    with pytest.raises(InputError, match="8- or 16-bit") as error:
        read_codes(path)
    assert error.value.path == str(path)


# ---------------------------------------------------------------------- stored code values


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_16_bit_brackets_keep_their_stored_values(write_brackets, suffix):
    paths = write_brackets([1 / 4, 1.0, 4.0], bit_depth=16, suffix=suffix)
    stack = read_brackets(paths)
    assert stack.codes.dtype == np.uint16
    assert stack.code_max == 65535
    assert stack.codes.max() > 255  # really 16-bit content, not 8-bit scaled up
    for codes, path in zip(stack.codes, paths, strict=True):
        written = oiio.ImageBuf(str(path)).get_pixels(oiio.UINT16)
        assert np.array_equal(codes, written)  # exact: lossless format, no conversion


@pytest.mark.parametrize("suffix", [".png", ".tif"])
@pytest.mark.parametrize("bits", [8, 16])
def test_exact_code_values_round_trip(tmp_path, suffix, bits):
    dtype, pixel_type = (np.uint8, "uint8") if bits == 8 else (np.uint16, "uint16")
    top = np.iinfo(dtype).max
    rng = np.random.default_rng(bits)
    frames = rng.integers(0, top + 1, size=(2, 16, 20, 3), dtype=dtype)
    frames[0, 0, :3] = [[0, 0, 0], [1, 2, 3], [top, top - 1, top]]  # extremes survive too
    paths = [write_image(tmp_path / f"round_{n}_1{suffix}", frame, pixel_type)
             for n, frame in zip((1, 2), frames, strict=True)]
    stack = read_brackets(paths)
    assert stack.code_max == top
    assert np.array_equal(stack.codes, frames)  # exact: stored values, never converted


@pytest.mark.parametrize("colour_space", ["Gamma1.8", "lin_rec709"])
def test_declared_colour_space_does_not_convert_codes(tmp_path, colour_space):
    ramp = np.repeat(np.arange(256, dtype=np.uint8).reshape(16, 16, 1), 3, axis=-1)
    path = write_image(tmp_path / "tagged.png", ramp, "uint8",
                       {"oiio:ColorSpace": colour_space})
    assert b"gAMA" in path.read_bytes()  # the PNG really declares a transfer function
    codes, code_max, _ = read_codes(path)
    assert code_max == 255
    assert np.array_equal(codes, ramp)  # exact: the stored codes, not linearised


def test_opaque_alpha_is_dropped_and_grey_is_kept(tmp_path):
    rgba = np.random.default_rng(1).integers(0, 256, size=(8, 8, 4), dtype=np.uint8)
    rgba[..., 3] = 255
    for suffix in (".png", ".tif"):
        codes, _, _ = read_codes(write_image(tmp_path / f"rgba{suffix}", rgba, "uint8"))
        assert np.array_equal(codes, rgba[..., :3]), suffix  # exact: stored codes
    grey = rgba[..., :1]
    codes, _, _ = read_codes(write_image(tmp_path / "grey.png", grey, "uint8"))
    assert codes.shape == (8, 8, 1)
    assert np.array_equal(codes, grey)  # exact


def test_rgb_codes_of_a_png_with_translucent_alpha_are_the_stored_values(tmp_path):
    rgba = np.random.default_rng(1).integers(0, 256, size=(8, 8, 4), dtype=np.uint8)
    rgba[..., 3] = 128
    path = write_image(tmp_path / "rgba.png", rgba, "uint8", {"oiio:UnassociatedAlpha": 1})
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    image = oiio.ImageInput.open(str(path), config)
    stored = image.read_image(oiio.UINT8)
    image.close()
    assert np.array_equal(stored, rgba)  # exact: the file holds exactly what we wrote
    codes, _, _ = read_codes(path)
    assert np.array_equal(codes, rgba[..., :3])  # exact: stored codes, alpha dropped


# ------------------------------------------------------------------------------ EXR writing


def openexr_header(path: Path) -> dict:
    return OpenEXR.File(str(path)).header()


def openexr_rgb(path: Path) -> np.ndarray:
    return OpenEXR.File(str(path)).channels()["RGB"].pixels


def oiio_header(path: Path) -> dict[str, object]:
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    try:
        return {attribute.name: attribute.value for attribute in image.spec().extra_attribs}
    finally:
        image.close()


ATTRIBUTES = {
    "chromaticities": (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290),
    "hdrio:units": "relative",
    "hdrio:codeMax": 255,
    "hdrio:lambda": 50.0,
    "hdrio:sourceFiles": ["a b.png", "c/d.png", "é.png"],
    "hdrio:exposures": [1 / 8, 1 / 4, 1 / 2, 1.0, 2.0, 8.0],
    "hdrio:responseR": list(np.linspace(-6.0, 2.5, 256)),
}


@pytest.mark.parametrize("pixel_type", ["half", "float"])
def test_exr_attributes_round_trip_through_openexr_and_openimageio(tmp_path, pixel_type):
    path = write_exr(tmp_path / "attrs.exr", np.full((6, 5, 3), 0.25, np.float32),
                     ATTRIBUTES, pixel_type)
    for reader, header in (("OpenEXR", openexr_header(path)), ("OIIO", oiio_header(path))):
        # rel=1e-7: EXR stores float attributes as float32 (about 6e-8 relative)
        assert np.asarray(header["chromaticities"]).shape == (8,), reader
        assert header["chromaticities"] == pytest.approx(ATTRIBUTES["chromaticities"],
                                                         rel=1e-7), reader
        assert header["hdrio:units"] == "relative", reader
        assert header["hdrio:codeMax"] == 255, reader
        assert isinstance(header["hdrio:codeMax"], int), reader
        assert header["hdrio:lambda"] == 50.0, reader  # exact: representable in float32
        assert list(header["hdrio:sourceFiles"]) == ATTRIBUTES["hdrio:sourceFiles"], reader
        for name in ("hdrio:exposures", "hdrio:responseR"):
            stored = np.asarray(header[name], dtype=np.float64)
            assert stored.shape == (len(ATTRIBUTES[name]),), (reader, name)
            assert stored == pytest.approx(ATTRIBUTES[name], rel=1e-7), (reader, name)


@pytest.mark.parametrize("count", [1, 5, 8, 17, 256])
def test_exr_float_list_of_any_length_stays_a_flat_list(tmp_path, count):
    values = [0.5 + j for j in range(count)]
    path = write_exr(tmp_path / "list.exr", np.ones((2, 2, 3), np.float32), {"v": values})
    stored = np.asarray(openexr_header(path)["v"], dtype=np.float64)
    assert stored.shape == (count,)
    assert stored.tolist() == values  # exact: halves of small integers fit float32


@pytest.mark.parametrize("count", [2, 3, 9, 16])
def test_exr_float_lists_that_would_become_vectors_or_matrices_are_refused(tmp_path, count):
    # OpenImageIO stores float[2|3|9|16] as v2f/v3f/m33f/m44f: refuse rather than mislabel.
    with pytest.raises(TypeError, match="vector or matrix"):
        write_exr(tmp_path / "list.exr", np.ones((2, 2, 3), np.float32),
                  {"v": [0.5] * count})
    assert list(tmp_path.iterdir()) == []


def test_exr_int_bool_and_numpy_scalars(tmp_path):
    attributes = {"n": np.int64(7), "flag": True, "x": np.float32(0.1)}
    path = write_exr(tmp_path / "scalars.exr", np.ones((2, 2, 3), np.float32), attributes)
    header = openexr_header(path)
    assert header["n"] == 7 and header["flag"] == 1
    assert header["x"] == pytest.approx(0.1, rel=1e-7)  # float32 storage


@pytest.mark.parametrize("count", [1, 2, 4])
def test_exr_int_lists_are_refused_not_dropped(tmp_path, count):
    # OpenEXR has only v2i/v3i; OpenImageIO silently drops other int lists, so refuse them.
    with pytest.raises(TypeError, match="integer lists"):
        write_exr(tmp_path / "ints.exr", np.ones((2, 2, 3), np.float32),
                  {"ints": list(range(count))})


def test_exr_pixels_and_compression(tmp_path):
    rgb = np.random.default_rng(2).uniform(1e-3, 100.0, size=(7, 9, 3)).astype(np.float32)
    half = write_exr(tmp_path / "half.exr", rgb)
    single = write_exr(tmp_path / "float.exr", rgb, pixel_type="float")
    assert openexr_rgb(half).dtype == np.float16
    assert openexr_rgb(single).dtype == np.float32
    # rtol=2**-11: half has an 11-bit significand, so rounding is within half an ulp
    np.testing.assert_allclose(openexr_rgb(half), rgb, rtol=2.0**-11)
    assert np.array_equal(openexr_rgb(single), rgb)  # exact: float32 stored as float32
    assert str(openexr_header(half)["compression"]).endswith("ZIP_COMPRESSION")
    assert oiio_header(single)["compression"] == "zip"


def test_half_exr_clamps_into_the_positive_half_range(tmp_path):
    rgb = np.array([[[1e6, 70000.0, 65504.0], [np.inf, 1e-9, 1e-30],
                     [2.0**-24, 1.0, 3.0e-6]]], dtype=np.float32)
    path = write_exr(tmp_path / "clamp.exr", rgb)
    for reader, pixels in (("OpenEXR", openexr_rgb(path).astype(np.float64)),
                           ("OIIO", oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT))):
        assert np.all(np.isfinite(pixels)), reader
        assert np.all(pixels > 0), reader  # positive input never becomes 0 ...
        assert np.all(pixels <= HALF_MAX), reader  # ... nor Inf
        # exact: 65504 and 2**-24 are representable halves, so clamping lands on them
        assert pixels[0, 0].tolist() == [HALF_MAX] * 3, reader
        assert pixels[0, 1].tolist() == [HALF_MAX, HALF_MIN_POSITIVE, HALF_MIN_POSITIVE], reader
        assert pixels[0, 2, :2].tolist() == [HALF_MIN_POSITIVE, 1.0], reader
        # rel=0.02: 3e-6 is a half subnormal, spaced 2**-24 (about 1 % of it) apart
        assert pixels[0, 2, 2] == pytest.approx(3.0e-6, rel=0.02), reader


def test_float_exr_is_not_clamped(tmp_path):
    rgb = np.array([[[1e6, 1e-30, 1.0]]], dtype=np.float32)
    path = write_exr(tmp_path / "wide.exr", rgb, pixel_type="float")
    assert np.array_equal(openexr_rgb(path), rgb)  # exact: float32 round trip


def test_exr_pixel_type_is_checked(tmp_path):
    with pytest.raises(ValueError, match="half"):
        write_exr(tmp_path / "bad.exr", np.ones((2, 2, 3)), pixel_type="uint8")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------- atomic writing


def test_atomic_write_leaves_no_temp_file_and_replaces_the_old_file(tmp_path):
    path = tmp_path / "out.exr"
    write_exr(path, np.full((2, 2, 3), 1.0, np.float32))
    write_exr(path, np.full((2, 2, 3), 2.0, np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    assert np.all(openexr_rgb(path) == 2.0)  # exact: 2.0 is a half


@pytest.mark.parametrize("failure", ["returns False", "raises"])
def test_failed_write_leaves_no_temp_file_and_keeps_the_old_file(tmp_path, monkeypatch,
                                                                 failure):
    path = tmp_path / "out.exr"
    write_exr(path, np.full((2, 2, 3), 1.0, np.float32), {"generation": "old"})
    before = path.read_bytes()
    seen = []

    def broken_write_scanlines(self, *args, **kwargs):
        seen.extend(p.name for p in tmp_path.iterdir() if ".partial" in p.name)
        if failure == "raises":
            raise RuntimeError("disk full")
        return False

    monkeypatch.setattr(oiio.ImageOutput, "write_scanlines", broken_write_scanlines)
    expected = OutputError if failure == "returns False" else RuntimeError
    with pytest.raises(expected):
        write_exr(path, np.full((2, 2, 3), 2.0, np.float32), {"generation": "new"})
    assert seen, "the writer is expected to write to a temp file first"
    assert leftovers(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    assert path.read_bytes() == before


def test_failed_write_of_a_new_file_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(oiio.ImageOutput, "write_scanlines", lambda self, *a, **k: False)
    with pytest.raises(OutputError, match="new.exr"):
        write_exr(tmp_path / "new.exr", np.ones((2, 2, 3), np.float32))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", [None, [], object(), {"a": 1}])
def test_unstorable_attribute_raises_type_error_and_writes_nothing(tmp_path, value):
    path = tmp_path / "out.exr"
    write_exr(path, np.ones((2, 2, 3), np.float32))
    before = path.read_bytes()
    with pytest.raises(TypeError, match="cannot store attribute"):
        write_exr(path, np.zeros((2, 2, 3), np.float32), {"bad": value})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    assert path.read_bytes() == before


def test_write_into_a_missing_folder_names_the_file(tmp_path):
    path = tmp_path / "nope" / "out.exr"
    with pytest.raises(OutputError, match="does not exist") as error:
        write_exr(path, np.ones((2, 2, 3), np.float32))
    assert str(path) in str(error.value)
    assert list(tmp_path.iterdir()) == []


def test_exr_written_in_bands_with_a_scale_matches_the_input(tmp_path):
    import OpenImageIO as oiio

    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.01, 100.0, (131, 17, 3)).astype(np.float32)  # 3 bands, last short
    before = rgb.copy()
    path = write_exr(tmp_path / "bands.exr", rgb, pixel_type="float", scale=0.25)
    back = oiio.ImageInput.open(str(path)).read_image(0, 0, 0, 3, "float")
    np.testing.assert_array_equal(back, rgb * np.float32(0.25))  # float: exact
    np.testing.assert_array_equal(rgb, before)  # the caller's pixels are not touched
