"""Camera RAW brackets: synthetic DNGs of known radiance, decoded by rawpy and merged."""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

pytest.importorskip("rawpy", reason="camera RAW needs rawpy (the 'raw' extra)")
pytest.importorskip("tifffile", reason="synthetic DNGs are written with tifffile ('test' extra)")

import hdrio  # noqa: E402
from hdrio.cli import main  # noqa: E402
from hdrio.errors import InputError  # noqa: E402
from hdrio.io.raw import RAW_CODE_MAX, read_raw  # noqa: E402
from hdrio.tools.synthetic import radiance_error  # noqa: E402
from tests.conftest import ramp_radiance  # noqa: E402
from tests.synthetic_dng import BLACK, NEUTRAL, WHITE, mosaic_of, write_dng  # noqa: E402

EXPOSURES = (1 / 64, 1 / 16, 1 / 4, 1.0)
SIZE = (48, 64)


# Slow (camera RAW brackets through rawpy, end to end): deselected by default, run by
# `pytest -m slow` (CI runs both).
pytestmark = pytest.mark.slow


@pytest.fixture
def truth() -> np.ndarray:
    """The conftest ramp: 0.01 .. 12.6, so the 1 s and 1/4 s frames clip its bright end."""
    return ramp_radiance(*SIZE)


@pytest.fixture
def dngs(tmp_path, truth) -> list[Path]:
    start = datetime.datetime(2026, 3, 1, 10, 0, 0)
    return [write_dng(tmp_path / f"IMG_{j:04d}.dng", mosaic_of(truth, t), t,
                      captured=start + datetime.timedelta(seconds=j))
            for j, t in enumerate(EXPOSURES)]


def test_rawpy_reads_the_synthetic_dng_as_written(dngs):
    import rawpy

    with rawpy.imread(str(dngs[0])) as raw:
        assert raw.raw_pattern.tolist() == [[0, 1], [3, 2]]  # R G / G2 B
        assert raw.black_level_per_channel == [BLACK] * 4
        assert raw.white_level == WHITE
        assert raw.other.shutter_speed == pytest.approx(1 / 64)
        # As-shot multipliers are 1 / AsShotNeutral, normalised to green.
        np.testing.assert_allclose(raw.camera_whitebalance[:3], 1 / NEUTRAL, rtol=1e-5)


def test_raw_brackets_merge_to_the_truth_without_a_response_solve(dngs, truth, monkeypatch):
    from hdrio.response import debevec1997

    def no_solve(*args, **kwargs):
        raise AssertionError("a RAW merge must not solve a response")

    monkeypatch.setattr(debevec1997, "g_solve_Debevec1997", no_solve)
    result = hdrio.merge_files(dngs, dngs[0].parent / "raw.exr")
    assert result.response.method == "linear"
    assert result.stack.exposure_sources[0] == "exif"
    np.testing.assert_allclose(result.stack.exposures, EXPOSURES)
    # Acceptance: median within 1 % of the truth (after one global scale). The data are
    # noiseless 14-bit codes, so what is left is demosaic interpolation on a smooth ramp
    # and 16-bit rounding: 0.05 % today.
    error = radiance_error(result.radiance, truth)
    assert error["median"] < 0.01, error
    # Colour survives white balance and camera matrix: each channel on its own, too.
    for c in range(3):
        assert radiance_error(result.radiance[..., c], truth[..., c])["median"] < 0.01


def test_raw_chain_through_the_command_line(dngs, truth, tmp_path, capsys):
    exr = tmp_path / "raw.exr"
    code = main([*map(str, dngs), "--merge", "-d", "float", "-o", str(exr)])
    assert code == 0, capsys.readouterr().err
    header = OpenEXR.File(str(exr)).header()
    assert header["hdrio:responseMethod"] == "linear"
    assert header["hdrio:codeMax"] == RAW_CODE_MAX
    pixels = OpenEXR.File(str(exr)).channels()["RGB"].pixels.astype(np.float64)
    assert radiance_error(pixels, truth)["median"] < 0.01  # as above


def test_clipped_sensels_saturate_the_pixel_in_every_channel(tmp_path, truth):
    # At 1 s the right half of the ramp is far above full well.
    path = write_dng(tmp_path / "long.dng", mosaic_of(truth, 1.0), 1.0)
    codes, code_max, exif = read_raw(path)
    assert code_max == RAW_CODE_MAX and codes.dtype == np.uint16
    assert exif["ExposureTime"] == 1.0 and exif["DateTimeOriginal"] == "2026:01:01 12:00:00"
    assert np.all(codes[:, -8:] == RAW_CODE_MAX)  # clipped: every channel at the top
    assert np.all(codes[:, :8] < RAW_CODE_MAX // 2)  # the dark end is far from it


def test_one_white_balance_for_the_whole_set(tmp_path, truth):
    # A camera on auto white balance may tag each frame differently; the set must share
    # one, or the frames would not be linear in one another.
    first = write_dng(tmp_path / "a.dng", mosaic_of(truth, 1 / 16), 1 / 16)
    second = write_dng(tmp_path / "b.dng", mosaic_of(truth, 1 / 4), 1 / 4,
                       neutral=(0.6, 1.0, 0.5))
    stack = hdrio.read_brackets([first, second])
    balances = {m["WhiteBalance"] for m in stack.metadata}
    assert len(balances) == 1
    np.testing.assert_allclose(next(iter(balances))[:3], 1 / NEUTRAL, rtol=1e-5)


def test_damaged_raw_is_named(tmp_path, dngs):
    broken = tmp_path / "broken.dng"
    broken.write_bytes(dngs[0].read_bytes()[:200])
    with pytest.raises(InputError, match="broken.dng: cannot read camera RAW"):
        hdrio.read_brackets([dngs[1], broken])


def test_raw_and_other_images_are_not_mixed(dngs, write_brackets):
    png = write_brackets([1.0, 4.0])[0]
    with pytest.raises(InputError, match="RAW and other images"):
        hdrio.read_brackets([dngs[0], png])


def test_given_white_balance_through_the_chain(dngs, truth, tmp_path, capsys):
    # Multipliers twice the as-shot red one: red comes out twice as strong relative to
    # green as in the truth (after white balance, the matrix is the identity here).
    exr = tmp_path / "wb.exr"
    red, green, blue = 2 / NEUTRAL
    red *= 2
    code = main([*map(str, dngs), "--white-balance", f"{red},{green},{blue}", "--merge",
                 "-d", "float", "-o", str(exr)])
    assert code == 0, capsys.readouterr().err
    pixels = OpenEXR.File(str(exr)).channels()["RGB"].pixels.astype(np.float64)
    ratio = np.median(pixels[..., 0] / pixels[..., 1]) / np.median(truth[..., 0] / truth[..., 1])
    # 2 within 2 %: the merge is within 0.1 % per channel (test above); the margin covers
    # LibRaw's clipping of the now brighter red in the longer frames.
    assert ratio == pytest.approx(2.0, rel=0.02)


def test_raw_frames_group_by_their_own_capture_times(dngs, truth, tmp_path):
    from hdrio.batch.grouping import group_brackets

    later = datetime.datetime(2026, 3, 1, 10, 5, 0)  # five minutes on: another position
    more = [write_dng(tmp_path / f"IMG_{9 + j:04d}.dng", mosaic_of(truth, t), t,
                      captured=later + datetime.timedelta(seconds=j))
            for j, t in enumerate(EXPOSURES[:2])]
    sets = group_brackets([*more, *dngs])
    assert [[f.path.name for f in s.frames] for s in sets] == [
        [p.name for p in dngs], [p.name for p in more]]
    assert [f.exposure for f in sets[0].frames] == pytest.approx(EXPOSURES)
