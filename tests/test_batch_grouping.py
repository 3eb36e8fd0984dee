"""Bracket grouping: splitting a folder into sets, merging each in a pool, skipping done ones."""

from __future__ import annotations

import datetime
from pathlib import Path

import OpenEXR
import pytest

from hdrio.batch.grouping import Frame, format_times, group_brackets, group_frames
from hdrio.cli import main
from tests.conftest import tutorial_name

START = datetime.datetime(2026, 3, 1, 10, 0, 0)
# Three sets with different exposure patterns, shot a minute apart: 3 frames 2 EV apart,
# 5 frames 1 EV apart, 4 frames 2 EV apart.
PATTERNS = ((1 / 64, 1 / 16, 1 / 4),
            (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2),
            (1 / 256, 1 / 64, 1 / 16, 1 / 4))
# File numbers that interleave the sets in name order (as when cards from two bodies, or
# renamed exports, share a folder): set k gets every third number, roughly.
NUMBERS = ((1, 4, 7), (2, 5, 8, 10, 12), (3, 6, 9, 11))


def _frames(timed: bool = True) -> list[Frame]:
    frames = []
    for k, (pattern, numbers) in enumerate(zip(PATTERNS, NUMBERS)):
        for j, (t, n) in enumerate(zip(pattern, numbers)):
            when = START + datetime.timedelta(minutes=k, seconds=j) if timed else None
            frames.append(Frame(Path(f"IMG_{n:04d}.jpg"), t, when, n))
    return frames[::-1]  # any input order


def _names(bracket_set) -> list[str]:
    return [frame.path.name for frame in bracket_set.frames]


def test_interleaved_sets_split_by_capture_time():
    sets = group_frames(_frames())
    assert [_names(s) for s in sets] == [[f"IMG_{n:04d}.jpg" for n in numbers]
                                         for numbers in NUMBERS]
    assert [tuple(f.exposure for f in s.frames) for s in sets] == list(PATTERNS)


def test_without_capture_times_a_repeated_exposure_starts_a_set():
    # Same pattern, no EXIF time, consecutive numbers: 3 sets of 1/60, 1/15, 1/4.
    frames = [Frame(Path(f"P{n:03d}.tif"), t, None, n)
              for n, t in enumerate([1 / 60, 1 / 15, 1 / 4] * 3, start=1)]
    sets = group_frames(frames[::-1])
    assert [_names(s) for s in sets] == [["P001.tif", "P002.tif", "P003.tif"],
                                         ["P004.tif", "P005.tif", "P006.tif"],
                                         ["P007.tif", "P008.tif", "P009.tif"]]


def test_a_repeat_right_after_its_twin_stays_in_the_set():
    # Ladders capped by the shutter, shot shortest first with no capture times: the
    # camera repeated 1/1000 s. Before, the repeat started a set of its own.
    capped = [1 / 1000, 1 / 1000, 1 / 250, 1 / 60]
    frames = [Frame(Path(f"P{n:03d}.tif"), t, None, n)
              for n, t in enumerate(capped * 2, start=1)]
    sets = group_frames(frames[::-1])
    assert [_names(s) for s in sets] == [["P001.tif", "P002.tif", "P003.tif", "P004.tif"],
                                         ["P005.tif", "P006.tif", "P007.tif", "P008.tif"]]


def test_frames_stamped_in_the_same_second_keep_sequence_order():
    # A fast burst: EXIF's one-second resolution gives three frames the same stamp.
    frames = [Frame(Path(f"IMG_{n}.jpg"), t, START, n)
              for n, t in ((3, 1 / 4), (1, 1 / 500), (2, 1 / 60))]
    (only,) = group_frames(frames)
    assert _names(only) == ["IMG_1.jpg", "IMG_2.jpg", "IMG_3.jpg"]


def test_a_long_exposure_is_not_a_gap():
    # A 30 s frame ends 30 s after its stamp: the next frame 31 s later is the same set.
    frames = [Frame(Path("a.jpg"), 1.0, START, 1), Frame(Path("b.jpg"), 30.0, START, 2),
              Frame(Path("c.jpg"), 4.0, START + datetime.timedelta(seconds=31), 3)]
    assert len(group_frames(frames)) == 1


# --------------------------------------------------------------------- a folder, end to end


@pytest.fixture
def shoot(write_brackets, tmp_path) -> Path:
    """A folder of 12 JPEGs with EXIF exposure and capture time: the three sets above."""
    folder = tmp_path / "shoot"
    for k, (pattern, numbers) in enumerate(zip(PATTERNS, NUMBERS)):
        stamps = [(START + datetime.timedelta(minutes=k, seconds=j)).strftime(
            "%Y:%m:%d %H:%M:%S") for j in range(len(pattern))]
        write_brackets(pattern, names=[f"IMG_{n:04d}.jpg" for n in numbers], folder=folder,
                       suffix=".jpg",
                       attributes=[{"ExposureTime": float(t), "Exif:DateTimeOriginal": s}
                                   for t, s in zip(pattern, stamps)])
    return folder


def test_folder_grouping_from_file_headers(shoot):
    sets = group_brackets(sorted(shoot.iterdir()))
    assert [_names(s) for s in sets] == [[f"IMG_{n:04d}.jpg" for n in numbers]
                                         for numbers in NUMBERS]


def test_dry_run_shows_the_grouping_and_writes_nothing(shoot, tmp_path, capsys):
    out = tmp_path / "hdr"
    out.mkdir()
    code = main([str(shoot), "--group", "--merge", "-o", f"{out}/{{first_stem}}_hdr.exr",
                 "--dry-run"])
    stdout = capsys.readouterr().out
    assert code == 0
    for k, numbers in enumerate(NUMBERS, start=1):
        line = next(line for line in stdout.splitlines() if f"set {k}:" in line)
        assert f"{len(numbers)} frames" in line
        assert f"IMG_{numbers[0]:04d}_hdr.exr" in line and "would merge" in line
    assert list(out.iterdir()) == []


@pytest.mark.slow
def test_sets_merge_in_parallel_and_a_second_run_does_nothing(shoot, tmp_path, capsys):
    out = tmp_path / "hdr"
    out.mkdir()
    argv = ["--threads", "2", str(shoot), "--group", "--merge",
            "-o", f"{out}/{{first_stem}}_hdr.exr", "--tonemap", "reinhard-global",
            "-o", f"{out}/{{first_stem}}.jpg"]
    assert main(argv) == 0, capsys.readouterr().err
    stdout = capsys.readouterr().out
    assert "3 bracket sets; 3 to merge, 0 done, 0 skipped" in stdout
    assert stdout.count("(merged in ") == 3
    for numbers in NUMBERS:
        exr = out / f"IMG_{numbers[0]:04d}_hdr.exr"
        sources = OpenEXR.File(str(exr)).header()["hdrio:sourceFiles"]
        assert sorted(Path(s).name for s in sources) == [f"IMG_{n:04d}.jpg" for n in numbers]
        assert (out / f"IMG_{numbers[0]:04d}.jpg").is_file()
    written = {p: p.stat().st_mtime_ns for p in out.iterdir()}

    assert main(argv) == 0
    stdout = capsys.readouterr().out
    assert "3 bracket sets; 0 to merge, 3 done, 0 skipped" in stdout
    assert "nothing to do" in stdout
    assert {p: p.stat().st_mtime_ns for p in out.iterdir()} == written  # nothing rewritten


@pytest.mark.slow
def test_a_failing_set_is_reported_and_the_others_still_merge(shoot, tmp_path, capsys,
                                                             write_brackets):
    out = tmp_path / "hdr"
    out.mkdir()
    # Replace the last frame of set 3 by one of another size (same EXIF): that set fails.
    last = START + datetime.timedelta(minutes=2, seconds=3)
    write_brackets([1 / 4], names=["IMG_0011.jpg"], folder=shoot, suffix=".jpg", size=(24, 32),
                   attributes=[{"ExposureTime": 0.25,
                                "Exif:DateTimeOriginal": last.strftime("%Y:%m:%d %H:%M:%S")}])
    code = main([str(shoot), "--group", "--merge", "-o", f"{out}/{{first_stem}}.exr"])
    captured = capsys.readouterr()
    assert code == 2
    assert "1 of 3 sets failed (sets 3)" in captured.err
    assert "IMG_0011.jpg" in captured.out and "brackets must match" in captured.out
    assert sorted(p.name for p in out.glob("*.exr")) == ["IMG_0001.exr", "IMG_0002.exr"]


def test_an_unreadable_file_in_the_folder_is_named(shoot, tmp_path, capsys):
    (shoot / "IMG_0099.jpg").write_bytes(b"not a jpeg")
    code = main([str(shoot), "--group", "--merge", "-o", f"{tmp_path}/{{first_stem}}.exr"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--group" in err and "IMG_0099.jpg" in err


# ------------------------------------------------------------------ grouping real shoots


def test_three_file_name_ladders_in_one_folder_are_three_sets(write_brackets, tmp_path):
    # Three positions of one 7-frame ladder, exposures in the names (north_1_64.png ...),
    # no EXIF: before, one 21-frame set with repeated exposures.
    ladder = [1 / 64, 1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0]
    folder = tmp_path / "ladders"
    for stem in ("north", "east", "south"):
        write_brackets(ladder, folder=folder, size=(8, 8),
                       names=[tutorial_name(t, stem=stem) for t in ladder])
    sets = group_brackets(sorted(folder.iterdir()))
    assert len(sets) == 3
    for bracket_set in sets:
        stems = {frame.path.name.split("_")[0] for frame in bracket_set.frames}
        assert len(stems) == 1 and len(bracket_set.frames) == 7
        assert sorted(bracket_set.times_s) == pytest.approx(ladder, rel=1e-9)


def test_auto_exposure_bracketing_order_0_minus2_plus2():
    # AEB shoots the metered exposure first, then -2 EV and +2 EV; no capture times.
    pattern = [1 / 60, 1 / 240, 1 / 15]
    frames = [Frame(Path(f"DSC{n:05d}.ARW"), t, None, n)
              for n, t in enumerate(pattern * 3, start=101)]
    sets = group_frames(frames[::-1])
    assert [[f.sequence for f in s.frames] for s in sets] == [[101, 102, 103],
                                                              [104, 105, 106],
                                                              [107, 108, 109]]
    assert all([f.exposure for f in s.frames] == pattern for s in sets)


def test_a_fixed_group_size_overrides_the_exposure_rules():
    # Five frames of one exposure each set (a bracket mode that repeats the base frame):
    # the repeat rule alone would split them; --group-size 5 keeps every five together.
    pattern = [1 / 60, 1 / 240, 1 / 15, 1 / 60, 1 / 4]
    frames = [Frame(Path(f"IMG_{n:04d}.jpg"), t, START, n)
              for n, t in enumerate(pattern * 2 + [1 / 60], start=1)]
    sets = group_frames(frames, size=5)
    assert [len(s.frames) for s in sets] == [5, 5, 1]
    assert [f.sequence for f in sets[1].frames] == [6, 7, 8, 9, 10]


def test_a_time_gap_splits_sets_without_repeated_exposures():
    # Two different patterns 10 s apart: the gap splits them; --group-gap 20 joins them.
    frames = [Frame(Path(f"IMG_{n}.jpg"), t, START + datetime.timedelta(seconds=s), n, t)
              for n, (t, s) in enumerate([(1 / 100, 0), (1 / 25, 1), (1 / 6, 11),
                                          (2 / 3, 12)], start=1)]
    assert [len(s.frames) for s in group_frames(frames)] == [2, 2]
    assert [len(s.frames) for s in group_frames(frames, max_gap_s=20)] == [4]


def test_listing_prints_real_exposure_times_not_relative_exposure(write_brackets, tmp_path,
                                                                 capsys):
    # ISO 400 and f/8: t * ISO/100 / N^2 = t / 16; the listing must say 1/64 s, not 1/1024.
    folder = tmp_path / "iso"
    times = (1 / 64, 1 / 16, 1 / 4)
    write_brackets(times, folder=folder, suffix=".jpg", size=(8, 8),
                   names=[f"IMG_{n}.jpg" for n in (1, 2, 3)],
                   attributes=[{"ExposureTime": t, "FNumber": 8.0,
                                "Exif:PhotographicSensitivity": 400} for t in times])
    assert main([str(folder), "--group", "--merge", "-o", f"{tmp_path}/{{index}}.exr",
                 "--dry-run"]) == 0
    line = next(li for li in capsys.readouterr().out.splitlines() if "set 1:" in li)
    assert "3 frames, 1/64 1/16 1/4 s:" in line


def test_format_times():
    assert format_times([1 / 8000, 1 / 3, 0.5, 1.0, 30.0, None]) == "1/8000 1/3 1/2 1 30 ? s"
