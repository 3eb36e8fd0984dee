"""Bracket grouping: splitting a folder into sets, merging each in a pool, skipping done ones."""

from __future__ import annotations

import datetime
from pathlib import Path

import OpenEXR
import pytest

from hdrio.cli import main
from hdrio.batch.grouping import Frame, group_brackets, group_frames

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


def test_sets_merge_in_parallel_and_a_second_run_does_nothing(shoot, tmp_path, capsys):
    out = tmp_path / "hdr"
    out.mkdir()
    argv = ["--threads", "2", str(shoot), "--group", "--merge",
            "-o", f"{out}/{{first_stem}}_hdr.exr", "--tonemap", "reinhard-global",
            "-o", f"{out}/{{first_stem}}.jpg"]
    assert main(argv) == 0, capsys.readouterr().err
    stdout = capsys.readouterr().out
    assert "3 bracket sets; 3 to merge, 0 done, 0 skipped" in stdout
    assert stdout.count("(merged)") == 3
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
