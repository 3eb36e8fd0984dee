"""Argument errors: one line, the subcommand's usage, the nearest option; no abbreviations."""

from __future__ import annotations

import pytest

from tests.conftest import run_cli as run


def _one_line_refusal(code: int, out: str, err: str) -> str:
    assert code == 2, err
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("typo, nearest", [("--exposure", "--exposures"),
                                           ("--merg", "--merge"), ("--lamda", "--lambda"),
                                           ("--colourspace", "--colorspace")])
def test_a_typo_in_a_merge_option_names_the_nearest_and_the_merge_usage(
        brackets, tmp_path, capsys, typo, nearest):
    line = _one_line_refusal(*run(capsys, "merge", *brackets, typo, "1", "-o",
                                  tmp_path / "o.exr"))
    assert line.startswith(f"hdrio merge: error: {typo}: unknown option"), line
    assert f"did you mean {nearest}?" in line
    assert "usage: hdrio merge [OPTIONS] IMAGES... -o OUTPUT (hdrio merge --help)" in line
    assert not (tmp_path / "o.exr").exists()


def test_an_abbreviated_option_is_not_taken_for_the_whole_name(brackets, tmp_path, capsys):
    """``--merg log`` was read as ``--merge log``: the chain takes no abbreviation, and
    the two front ends mean the same by the same words."""
    line = _one_line_refusal(*run(capsys, "merge", *brackets, "--merg", "log", "-o",
                                  tmp_path / "o.exr"))
    assert "--merg: unknown option (did you mean --merge?)" in line


@pytest.mark.parametrize("argv, fragment", [
    (["merge", "a.png", "b.png"], "hdrio merge: error: missing -o/--output; usage: hdrio merge"),
    (["check"], "hdrio check: error: missing files; usage: hdrio check [OPTIONS] FILES..."),
    (["export-response", "x.exr"], "missing -o/--output-dir; usage: hdrio export-response"),
    (["merge", "a.png", "-o", "o.exr", "-d", "halff"],
     "--data-type halff: not one of half, float (did you mean half?)"),
    (["check", "x.exr", "--chart", "1,2"],
     "hdrio check: error: --chart: expected a region x,y,width,height, got '1,2'"),
])
def test_argument_errors_are_one_line(capsys, argv, fragment):
    line = _one_line_refusal(*run(capsys, *argv))
    assert fragment in line, line


@pytest.mark.parametrize("typo, hint", [
    ("--tonemapp", "did you mean --tonemap?"),
    ("--preview", "in a chain, tone-map and write it: --tonemap reinhard-global -o"),
    ("-q", "a chain is quiet unless -v is given"),
])
def test_a_typo_in_a_chain_names_the_nearest_operation(brackets, tmp_path, capsys, typo,
                                                        hint):
    line = _one_line_refusal(*run(capsys, *brackets, "--merge", typo, "x.jpg", "-o",
                                  tmp_path / "o.exr"))
    assert line.startswith(f"hdrio: error: {typo}: unknown operation"), line
    assert hint in line, line
