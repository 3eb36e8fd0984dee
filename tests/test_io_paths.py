"""hdrio.io.paths and the writer's temp names: the checks the catalogue relies on."""

from __future__ import annotations

import os

import numpy as np
import pytest

from hdrio.errors import InputError, OutputError
from hdrio.io.paths import check_inputs, check_output, fill_pattern
from hdrio.io.write import NAME_MAX, is_temporary_of, temporary_name, write_exr


@pytest.mark.parametrize("stem", ["o" * 251, "é" * 125 + "x", "short", "a.b" * 60])
def test_temp_names_fit_whenever_the_output_name_does(tmp_path, stem):
    path = tmp_path / f"{stem}.exr"
    assert len(os.fsencode(path.name)) <= NAME_MAX
    temp = temporary_name(path)
    assert len(os.fsencode(temp.name)) <= NAME_MAX
    assert temp.name.startswith(".") and temp.name.endswith(".partial.exr")
    assert temp.parent == path.parent and is_temporary_of(path, temp)
    assert not is_temporary_of(tmp_path / "other.exr", temp)
    write_exr(path, np.ones((2, 2, 3), np.float32))  # the longest legal name is written
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_a_file_given_twice_under_another_name_is_refused(tmp_path):
    first = tmp_path / "a.png"
    first.write_bytes(b"x")
    os.link(first, tmp_path / "hard.png")
    with pytest.raises(InputError, match=r"hard.png: given twice \(as .*a.png\)"):
        check_inputs([first, tmp_path / "hard.png"])


def test_output_checks_leave_nothing_behind(tmp_path):
    check_output(tmp_path / "fine.exr", suffixes={".exr"})
    assert list(tmp_path.iterdir()) == []  # the writability probe is removed again
    with pytest.raises(OutputError, match="name too long"):
        check_output(tmp_path / ("n" * 256 + ".exr"))


@pytest.mark.parametrize("text, fragment", [("{first_stem}{0}.exr", "unknown field {0}"),
                                            ("{first_stem.__class__}.exr", "brace"),
                                            ("{first_stem!r}.exr", "brace"),
                                            ("out}.exr", "brace")])
def test_patterns_take_plain_fields_only(text, fragment):
    with pytest.raises(OutputError, match=fragment.replace("{", r"\{")):
        fill_pattern(text, {"first_stem": "a"})
    assert str(fill_pattern("{first_stem}_hdr.exr", {"first_stem": "a"})) == "a_hdr.exr"


def test_a_name_in_another_letter_case_is_named(tmp_path):
    # Linux tells IMG_0959.JPG from *.jpg; the error says what would match, and a pattern
    # to give only where that pattern matches every such file (case counts).
    from hdrio.io.paths import check_input, expand_patterns

    for name in ("IMG_0959.JPG", "IMG_0960.JPG"):
        (tmp_path / name).write_bytes(b"")
    with pytest.raises(InputError, match=r"matches none \(letter case counts: ignoring it, "
                       r"it matches IMG_0959\.JPG and 1 more; give .*\*\.JPG\)"):
        expand_patterns([str(tmp_path / "*.jpg")])
    # The stem's case is wrong too: no pattern offered that would not match.
    with pytest.raises(InputError) as refused:
        expand_patterns([str(tmp_path / "img_*.jpg")])
    assert "it matches IMG_0959.JPG and 1 more)" in str(refused.value)
    with pytest.raises(InputError, match=r"no such file \(IMG_0960\.JPG is there: letter "
                       r"case counts"):
        check_input(tmp_path / "img_0960.jpg")
    # Nothing like it in any case: the plain message.
    with pytest.raises(InputError) as plain:
        expand_patterns([str(tmp_path / "*.png")])
    assert str(plain.value).endswith("as a pattern it matches none")
