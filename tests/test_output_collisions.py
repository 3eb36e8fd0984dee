"""Outputs planned before any work: two outputs that are one file are refused, both named.

A ``--group`` run whose sets would write the same file (a fixed ``-o`` name, a field two
sets share), two outputs of one chain to one file, and the Python API (``merge_shoot``)
are refused before anything is written; ``--dry-run`` and ``--list-sets`` say so too.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hdrio.batch.shoot import merge_shoot
from hdrio.errors import OutputError
from tests import hostile as h
from tests.conftest import run_cli as run


def _two_sets(folder: Path) -> Path:
    """A shoot of two bracket sets (``a_*`` and ``b_*``, each 4 exposures) in ``folder``."""
    h.ramp_set(folder, stem="a")
    h.ramp_set(folder, stem="b")
    return folder


def _refused(capsys, argv, folder: Path) -> str:
    before = h.snapshot(folder)
    code, _out, err = run(capsys, *argv)
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert h.snapshot(folder) == before  # nothing written, nothing left behind
    return lines[0]


def test_group_with_a_fixed_output_name_is_refused_naming_both_sets(tmp_path, capsys):
    shoot = _two_sets(tmp_path / "shoot")
    line = _refused(capsys, [shoot, "--group", "--merge", "-o", tmp_path / "fixed.exr"],
                    tmp_path)
    assert f"{tmp_path / 'fixed.exr'}: sets 1 (" in line
    assert "a_1_16.png .. a_4_1.png) and 2 (" in line and "b_1_16.png .. b_4_1.png)" in line
    assert "put {index} or {first_stem} in the output name" in line
    assert "fixed_{index}.exr" in line


@pytest.mark.parametrize("flag", ["--dry-run", "--list-sets"])
def test_dry_run_and_list_sets_show_the_collision(tmp_path, capsys, flag):
    shoot = _two_sets(tmp_path / "shoot")
    before = h.snapshot(tmp_path)
    code, _out, err = run(capsys, shoot, flag, "--group", "--merge", "-o",
                          tmp_path / "fixed.exr")
    assert code == 2 and "would both write it" in err, err
    assert h.snapshot(tmp_path) == before


def test_a_pattern_field_two_sets_share_is_refused(tmp_path, capsys):
    """``{folder}``: both sets are in one folder; ``{count}``: both have 4 frames."""
    shoot = _two_sets(tmp_path / "shoot")
    for pattern in ("{folder}/merged.exr", str(tmp_path / "hdr_{count}.exr")):
        line = _refused(capsys, [shoot, "--group", "--merge", "-o", pattern], tmp_path)
        assert "sets 1 (" in line and "would both write it" in line, line


def _day(folder: Path, day: int) -> list[Path]:
    """``IMG_0001.png`` .. ``IMG_0004.png``: a camera's names, EXIF exposure times and
    capture times on day ``day``, 1 s apart."""
    from hdrio.io.write import write_image
    from hdrio.tools.synthetic import render_brackets
    from tests.conftest import DEFAULT_EXPOSURES, ramp_radiance

    folder.mkdir(parents=True)
    codes = render_brackets(ramp_radiance(*h.SIZE), list(DEFAULT_EXPOSURES))
    return [write_image(folder / f"IMG_{k + 1:04d}.png", frame, "uint8",
                        {"ExposureTime": float(t),
                         "Exif:DateTimeOriginal": f"2024:05:{day:02d} 10:00:{k:02d}"})
            for k, (t, frame) in enumerate(zip(DEFAULT_EXPOSURES, codes))]


def test_first_stem_of_two_folders_collides_and_index_does_not(tmp_path, capsys):
    """Two days' folders with the same file names: ``{first_stem}`` names one file for
    both sets; ``{index}`` does not."""
    _day(tmp_path / "day1", 1), _day(tmp_path / "day2", 2)
    argv = [tmp_path / "day1", tmp_path / "day2", "--group", "--merge"]
    line = _refused(capsys, [*argv, "-o", str(tmp_path / "hdr" / "{first_stem}.exr")],
                    tmp_path)
    assert "IMG_0001.exr: sets 1 (4 frames" in line and "and 2 (4 frames" in line, line
    code, out, err = run(capsys, *argv, "-o", str(tmp_path / "hdr" / "{index}.exr"),
                         "--dry-run")
    assert code == 0, err
    assert f"-> {tmp_path / 'hdr' / '1.exr'} (would merge)" in out, out
    assert f"-> {tmp_path / 'hdr' / '2.exr'} (would merge)" in out, out


def test_two_outputs_of_one_set_to_one_file_are_refused(tmp_path, capsys):
    shoot = _two_sets(tmp_path / "shoot")
    pattern = str(tmp_path / "{first_stem}.exr")
    line = _refused(capsys, [shoot, "--group", "--merge", "-o", pattern, "--tonemap",
                             "reinhard-global", "-o", pattern], tmp_path)
    assert "an earlier output of this chain writes this file too" in line, line


@pytest.mark.parametrize("second", ["o.exr", "./o.exr", "sub/../o.exr"])
def test_two_outputs_of_one_chain_to_one_file_are_refused(brackets, tmp_path, capsys,
                                                          monkeypatch, second):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    line = _refused(capsys, [*brackets, "--merge", "-o", "o.exr", "--tonemap",
                             "reinhard-global", "-o", second], tmp_path)
    assert line.startswith(f"hdrio: error: -o {second}: an earlier output of this chain "
                           "writes this file too"), line


def test_a_picture_and_an_output_to_one_file_are_refused(brackets, tmp_path, capsys):
    target = tmp_path / "p.png"
    line = _refused(capsys, [*brackets, "--merge", "--plot-stops", target, "--tonemap",
                             "reinhard-global", "-o", target], tmp_path)
    assert "an earlier output of this chain writes this file too" in line, line


def test_merge_shoot_refuses_a_fixed_name_before_any_work(tmp_path):
    shoot = _two_sets(tmp_path / "shoot")
    before = h.snapshot(tmp_path)
    with pytest.raises(OutputError, match="would both write it"):
        merge_shoot(shoot, str(tmp_path / "fixed.exr"))
    assert h.snapshot(tmp_path) == before


def test_a_pattern_without_group_names_the_output_after_the_brackets(brackets, tmp_path,
                                                                     capsys):
    # Outside --group the brackets given are the one set: {first_stem} is the first's
    # stem in both front ends (the chain wrote "first.exr", its check's stand-in, and
    # hdrio merge a file named "{first_stem}.exr").
    first, last = Path(brackets[0]).stem, Path(brackets[-1]).stem
    code, _, err = run(capsys, *brackets, "--merge", "-o", f"{tmp_path}/c/{{first_stem}}.exr",
                       "--tonemap", "reinhard-global",
                       "-o", f"{tmp_path}/c/{{last_stem}}_{{count}}.jpg")
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == sorted(
        [f"{first}.exr", f"{last}_{len(brackets)}.jpg"])
    code, _, err = run(capsys, "merge", *brackets, "-o", f"{tmp_path}/m/{{first_stem}}.exr",
                       "--preview", f"{tmp_path}/m/{{last_stem}}.jpg", "-q")
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "m").iterdir()) == sorted(
        [f"{first}.exr", f"{last}.jpg"])


def test_a_pattern_that_names_an_input_is_refused_before_any_work(brackets, tmp_path,
                                                                  capsys):
    for argv in (["-v", *brackets, "--merge", "--tonemap", "reinhard-global", "-o",
                  "{folder}/{first_stem}.png"],
                 ["merge", *brackets, "-o", f"{tmp_path}/out.exr", "--preview",
                  "{folder}/{last_stem}.png"]):
        before = {p: Path(p).read_bytes() for p in brackets}
        code, out, err = run(capsys, *argv)
        assert code == 2 and "would overwrite an input" in err, err
        assert "reading" not in out + err  # refused before the brackets were read
        assert {p: Path(p).read_bytes() for p in brackets} == before
