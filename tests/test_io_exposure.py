"""Exposure times: parsing, the file-name convention, sidecar lists and EXIF scaling."""

from __future__ import annotations

from pathlib import Path

import pytest

from hdrio.errors import InputError
from hdrio.io.exposure import (
    exposure_from_filename,
    parse_exposure,
    read_exposure_table,
    relative_exif_exposures,
)

# Exposure times are parsed as exact fractions and converted once to float, so they must
# equal Python's own correctly rounded division: comparisons below are exact (==) unless
# the value is the product of several roundings, where rel=1e-12 allows a few ulps.


# --------------------------------------------------------------------------- parse_exposure


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("1/60", 1 / 60),
        ("0.5", 0.5),
        ("30", 30.0),
        (" 1/8 ", 1 / 8),
        ("1/3.75", 1 / 3.75),  # what some cameras' EXIF and sidecars print
        ("2.5/10", 0.25),
        ("1e-3", 0.001),
        (0.25, 0.25),
        (2, 2.0),
        ("1/60s", 1 / 60),  # a unit, as a camera's or an editor's list prints it
        ("1/60 s", 1 / 60),
        ('30"', 30.0),  # a camera's display: 30" is 30 s
    ],
)
def test_parse_exposure_accepts_fractions_decimals_and_numbers(text, seconds):
    assert parse_exposure(text) == seconds  # exact: one correctly rounded conversion


@pytest.mark.parametrize(
    "text",
    ["", "abc", "1/", "/60", "1//60", "1/2/3", "1/inf", "1/nan", "s", "1/60 ss", "1,5", "inf",
     "nan", "1/0", "0", "0/1", "0.0", "-1/60", "-2", -0.5, 0, 0.0, float("inf"), float("nan")],
)
def test_parse_exposure_rejects_bad_zero_and_negative_values(text):
    with pytest.raises(ValueError):
        parse_exposure(text)


@pytest.mark.parametrize(
    ("text", "times"),
    [
        ("1/8,1,8", ["1/8", "1", "8"]),
        ("1/8 1 8", ["1/8", "1", "8"]),
        (" 1/8  1\t8 ", ["1/8", "1", "8"]),
        ("1/4, 1 4", ["1/4", "1", "4"]),
        ("1/8 s, 1 s, 8 s", ["1/8 s", "1 s", "8 s"]),  # a unit alone is the time's before it
        ('1/8 1 8 "', ["1/8", "1", '8 "']),
        ("1/8,1,", ["1/8", "1", ""]),  # an empty item is the parser's to refuse
    ],
)
def test_a_list_of_exposures_is_split_at_commas_and_spaces(text, times):
    # hdrio merge --exposures and Blender's Exposures field read a list the same way.
    from hdrio.io.exposure import split_exposures

    assert split_exposures(text) == times


def test_parse_exposure_rejects_values_too_large_for_a_float():
    with pytest.raises(ValueError):
        parse_exposure("1e400")


# ----------------------------------------------------------------------- exposures in EV


@pytest.mark.parametrize(
    ("texts", "exposures", "in_ev"),
    [
        (["-2EV", "0EV", "+2EV"], [0.25, 1.0, 4.0], True),
        (["-2 EV", "0 ev", "2Ev"], [0.25, 1.0, 4.0], True),
        (["-1/3EV", "+1/3EV"], [2 ** (-1 / 3), 2 ** (1 / 3)], True),
        (["0.5EV"], [2**0.5], True),
        (["1/8", "1", "8 s"], [0.125, 1.0, 8.0], False),
    ],
)
def test_a_list_in_ev_is_relative_exposures(texts, exposures, in_ev):
    from hdrio.io.exposure import explicit_exposures

    values, ev = explicit_exposures(texts)
    assert ev is in_ev
    assert values == pytest.approx(exposures, rel=1e-15)  # 2**x: one rounding each


@pytest.mark.parametrize(
    ("texts", "problem"),
    [
        (["-2EV", "1", "4"], "'1' beside '-2EV'"),  # mixed units: the bare ones are a guess
        (["-2EV", "xEV"], "not an exposure step: 'xEV'"),
        (["EV"], "not an exposure step"),
        (["1/0EV"], "not an exposure step"),
        (["100EV"], "not an exposure step"),  # 2^100: no camera's step
    ],
)
def test_a_bad_list_in_ev_says_why(texts, problem):
    from hdrio.io.exposure import explicit_exposures

    with pytest.raises(ValueError, match=problem.replace("(", r"\(")):
        explicit_exposures(texts)


def test_a_list_in_ev_splits_as_typed():
    from hdrio.io.exposure import split_exposures

    assert split_exposures("-2 EV, 0 EV, +2 EV") == ["-2 EV", "0 EV", "+2 EV"]
    assert split_exposures("-2EV 0EV +2EV") == ["-2EV", "0EV", "+2EV"]


# -------------------------------------------------------------------- exposure_from_filename


@pytest.mark.parametrize(
    ("name", "seconds"),
    [
        ("church_30_1.jpg", 30.0),
        ("window exp 1 60.jpg", 1 / 60),
        ("bracket_1_1024.png", 1 / 1024),
        ("/photos/2024/12/shot_1_8.tif", 1 / 8),  # digits in folders do not count
        (Path("church_2_1.png"), 2.0),
    ],
)
def test_exposure_from_filename_reads_numerator_and_denominator(name, seconds):
    assert exposure_from_filename(name) == seconds  # exact: one correctly rounded division


@pytest.mark.parametrize(
    "name",
    ["IMG_2600.jpg", "church.jpg", "shot_1_60_2.jpg", "2024_01_02_1_60.jpg",
     "church_0_1.jpg", "church_1_0.jpg"],
)
def test_exposure_from_filename_refuses_to_guess(name):
    assert exposure_from_filename(name) is None


# ------------------------------------------------------------------------ read_exposure_table


def test_csv_table_ignores_extra_columns_and_column_order(tmp_path):
    sidecar = tmp_path / "exposures.csv"
    sidecar.write_text(
        "note,exposure_time_s,camera,file\n"
        "long,30,EOS,church_a.png\n"
        "short,1/60,EOS,church_b.png\n"
        "mid,0.5,EOS,sub/church_c.png\n",
        encoding="utf-8",
    )
    assert read_exposure_table(sidecar) == {
        "church_a.png": 30.0, "church_b.png": 1 / 60, "sub/church_c.png": 0.5,
    }  # exact: one correctly rounded conversion each


def test_csv_table_header_names_ignore_case_spaces_and_bom(tmp_path):
    sidecar = tmp_path / "exposures.csv"
    sidecar.write_text("\ufeffFile, Exposure_Time_S\na.png, 1/4\n", encoding="utf-8")
    assert read_exposure_table(sidecar) == {"a.png": 0.25}  # exact: 1/4 is a binary fraction


def test_csv_table_without_the_required_columns_names_the_file(tmp_path):
    sidecar = tmp_path / "exposures.csv"
    sidecar.write_text("frame,value\na.png,1\n", encoding="utf-8")
    with pytest.raises(InputError) as error:
        read_exposure_table(sidecar)
    assert error.value.path == str(sidecar)
    assert "exposure_time_s" in error.value.problem
    assert "'frame,value'" in error.value.problem  # the header it found


@pytest.mark.parametrize("text", [
    "filename,shutter\r\na.png,1/8\r\nb.png,2\r\n",  # other names, Windows line ends
    "Name;Exposure\na.png;0,125\nb.png;2\n",  # a spreadsheet with a decimal comma
    "image\texposure time\na.png\t1/8 s\nb.png\t2\n",  # tab-separated, a unit
])
def test_csv_table_as_spreadsheets_and_scripts_write_it(tmp_path, text):
    sidecar = tmp_path / "exposures.csv"
    sidecar.write_bytes(text.encode("utf-8"))
    assert read_exposure_table(sidecar) == {"a.png": 0.125, "b.png": 2.0}  # exact: binary


def test_opencv_list_separated_by_tabs_is_still_opencvs(tmp_path):
    sidecar = tmp_path / "list.txt"
    sidecar.write_text("a.png\t32\nb.png\t2\n", encoding="utf-8")
    assert read_exposure_table(sidecar) == {"a.png": 1 / 32, "b.png": 0.5}  # exact


def test_memorial_csv_from_shared_data(shared_data):
    table = read_exposure_table(shared_data("memorial_debevec") / "exposures.csv")
    assert len(table) == 16
    # exact: powers of two are represented exactly
    assert table["memorial0061.png"] == 32.0
    assert table["memorial0076.png"] == 1 / 1024


def test_opencv_list_values_are_reciprocal_times(tmp_path):
    sidecar = tmp_path / "list.txt"
    sidecar.write_text(
        "# OpenCV loadExposureSeq: file 1/t\n"
        "memorial00.png 0.03125\n"
        "memorial01.png 1   # one second\n"
        "\n"
        "   memorial02.png   1024\n",
        encoding="utf-8",
    )
    assert read_exposure_table(sidecar) == {
        "memorial00.png": 32.0, "memorial01.png": 1.0, "memorial02.png": 1 / 1024,
    }  # exact: reciprocals of powers of two are exact


def test_empty_or_missing_list_names_the_file(tmp_path):
    empty = tmp_path / "list.txt"
    empty.write_text("\n  \n", encoding="utf-8")
    with pytest.raises(InputError, match="empty") as error:
        read_exposure_table(empty)
    assert error.value.path == str(empty)
    missing = tmp_path / "nothere.csv"
    with pytest.raises(InputError) as error:
        read_exposure_table(missing)
    assert error.value.path == str(missing)


@pytest.mark.parametrize(
    ("name", "text", "line"),
    [
        ("list.txt", "a.png 32\nb.png 16 extra\n", 2),  # three fields
        ("list.txt", "a.png 32\nb.png\n", 2),  # no value
        ("list.txt", "a.png 32\nb.png 16\nc.png zero\n", 3),  # not a number
        ("list.txt", "a.png 0\n", 1),  # 1/t = 0 is no exposure
        ("list.txt", "a.png -4\n", 1),
        ("list.txt", "a.png 32\n\nb.png x\n", 3),  # numbering counts the blank line
        ("exposures.csv", "file,exposure_time_s\na.png,1/60\nb.png,fast\n", 3),
        ("exposures.csv", "file,exposure_time_s\na.png,0\n", 2),
        ("exposures.csv", "file,exposure_time_s\na.png\n", 2),  # short row: no value
        ("exposures.csv", "file,exposure_time_s\n# camera A\na.png,1\n\nb.png,x\n", 5),
    ],
)
def test_malformed_sidecar_line_names_file_and_line(tmp_path, name, text, line):
    sidecar = tmp_path / name
    sidecar.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as error:
        read_exposure_table(sidecar)
    assert error.value.path == str(sidecar)
    assert f"line {line}:" in error.value.problem


def test_opencv_list_with_a_leading_comment_containing_a_comma(tmp_path):
    sidecar = tmp_path / "list.txt"
    sidecar.write_text("# file, 1/t\na.png 32\nb.png 2\n", encoding="utf-8")
    assert read_exposure_table(sidecar) == {"a.png": 1 / 32, "b.png": 0.5}  # exact


# ------------------------------------------------------------------- relative_exif_exposures


def test_constant_aperture_and_iso_keep_plain_times():
    readings = [(1 / 8, 8.0, 100.0), (1.0, 8.0, 100.0), (8.0, 8.0, 100.0)]
    assert relative_exif_exposures(readings) == [1 / 8, 1.0, 8.0]  # exact: passed through


def test_constant_but_missing_aperture_and_iso_keep_plain_times():
    readings = [(1 / 8, 0.0, 0.0), (1.0, 0.0, 0.0)]
    assert relative_exif_exposures(readings) == [1 / 8, 1.0]  # exact: passed through


@pytest.mark.parametrize(
    "readings",
    [
        [(1 / 4, 4.0, 100.0), (1 / 4, 4.0, 400.0), (1 / 4, 4.0, 1600.0)],  # ISO varies
        [(1.0, 2.8, 200.0), (1.0, 5.6, 200.0), (2.0, 11.0, 200.0)],  # aperture varies
    ],
)
def test_varying_aperture_or_iso_scales_by_iso_over_n_squared(readings):
    expected = [t * iso / 100.0 / n**2 for t, n, iso in readings]
    # rel=1e-12: a few float roundings in a product, nothing more
    assert relative_exif_exposures(readings) == pytest.approx(expected, rel=1e-12)


def test_iso_bracketing_gives_distinct_relative_exposures():
    relative = relative_exif_exposures([(1 / 4, 4.0, 100.0), (1 / 4, 4.0, 400.0)])
    assert relative[1] / relative[0] == pytest.approx(4.0, rel=1e-12)  # two stops of ISO


def test_varying_settings_with_missing_values_raise():
    with pytest.raises(ValueError, match="vary"):
        relative_exif_exposures([(1.0, 4.0, 100.0), (1.0, 8.0, 0.0)])
