"""One command language: every merge option gives the same EXR from both front ends,
and argument errors are found before any work or write."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from hdrio.cli.chain_registry import OPERATIONS
from hdrio.cli.merge_arguments import MERGE_OPTIONS, OPTIONS_BY_NAME
from tests.conftest import DEFAULT_EXPOSURES
from tests.conftest import run_cli as run
from tests.test_merge_exclusion import write_masks


@pytest.fixture
def exif_brackets(write_brackets) -> list[Path]:
    """The fixture's ramp brackets with EXIF exposure, aperture and ISO (for --absolute)."""
    return write_brackets(DEFAULT_EXPOSURES, attributes=[
        {"ExposureTime": float(t), "FNumber": 8.0, "Exif:PhotographicSensitivity": 100}
        for t in DEFAULT_EXPOSURES])


def _arguments(option, brackets: list[Path], tmp_path: Path, capsys) -> list[str]:
    values = list(option.example)
    if option.name == "--exposures":
        values = [",".join(str(t) for t in DEFAULT_EXPOSURES)]
    if option.name == "--exposures-from":
        table = tmp_path / "exposures.csv"
        table.write_text("file,exposure_time_s\n" + "".join(
            f"{p.name},{t}\n" for p, t in zip(brackets, DEFAULT_EXPOSURES, strict=True)))
        values = [str(table)]
    if option.name == "--mask":  # a pattern, one mask per bracket
        values = [str(tmp_path / "masks" / "{stem}.png")]
        write_masks(tmp_path / "masks", brackets)
    if option.name == "--nd":  # the longest bracket through a 1-stop filter
        values = [f"1:{brackets[-1].name}"]
    if option.name == "--response-from":
        earlier = tmp_path / "earlier.exr"
        assert run(capsys, "merge", *brackets, "-o", earlier, "-q")[0] == 0
        values = [str(earlier)]
    return [*option.needs, option.name, *values]


def _exr(path: Path) -> tuple[np.ndarray, dict]:
    with OpenEXR.File(str(path)) as file:
        header = dict(file.header())
        return file.channels()["RGB"].pixels.copy(), header


@pytest.mark.parametrize("name", [option.name for option in MERGE_OPTIONS])
def test_both_front_ends_write_the_same_exr(name, exif_brackets, tmp_path, capsys):
    option = OPTIONS_BY_NAME[name]
    extra = _arguments(option, exif_brackets, tmp_path, capsys)
    a, b = tmp_path / "merge.exr", tmp_path / "chain.exr"
    code, _, err = run(capsys, "merge", *exif_brackets, *extra, "-o", a, "-q")
    assert code == 0, err
    if name == "--merge":  # the chain spells the domain as --merge's own argument
        chain = [*exif_brackets, "--merge", *option.example, "-o", b]
    else:
        chain = [*exif_brackets, *extra, "--merge", "-o", b]
    code, _, err = run(capsys, *chain)
    assert code == 0, err
    (pixels_a, header_a), (pixels_b, header_b) = _exr(a), _exr(b)
    # Exactly equal: one definition of the option, one pipeline, one writer.
    np.testing.assert_array_equal(pixels_a, pixels_b)
    assert header_a.keys() == header_b.keys()
    for key in header_a:
        assert str(header_a[key]) == str(header_b[key]), key


def test_every_option_is_a_chain_operation_with_its_aliases():
    for option in MERGE_OPTIONS:
        for spelling in option.spellings:
            assert spelling in OPERATIONS, spelling


def test_old_spellings_are_aliases(brackets, tmp_path, capsys):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    for spelling, output in (("--ocio-config", a), ("--colorconfig", b)):
        code, _, err = run(capsys, "merge", *brackets, spelling, "ocio://cg-config-latest",
                           "--colorspace", "ACEScg", "-o", output, "-q")
        assert code == 0, err
    np.testing.assert_array_equal(_exr(a)[0], _exr(b)[0])


@pytest.mark.parametrize(("argv", "needle"), [
    (["--merge", "-o", "{out}/a.exr", "--colorspace", "ACEScgg", "-o", "{out}/b.exr"],
     "--colorspace ACEScgg"),
    (["--merge", "-o", "{out}/a.exr", "--tonemap", "reinhard-local", "white=8",
      "-o", "{out}/b.jpg"], "no parameter 'white'"),
    (["--merge", "-o", "{out}/a.exr", "--ociodisplay", "sRGB - Display", "Nope",
      "-o", "{out}/b.jpg"], "has no view 'Nope'"),
    (["--merge", "-o", "{out}/a.exr", "--exposure", "1"], "--exposure 1"),
    (["--merge", "-o", "{out}/a.exr", "--lambda", "10"], "no --merge follows"),
    (["--lambda", "-3", "--merge", "-o", "{out}/a.exr"], "positive number"),
    (["--absolute", "luminance", "--merge", "-o", "{out}/a.exr"], "needs a region"),
    (["--reference-luminance", "100", "--merge", "-o", "{out}/a.exr"], "needs --absolute"),
    (["--merge", "-o", "{out}/a.exr", "{out}/missing.exr", "-o", "{out}/c.exr"],
     "missing.exr: no such file"),
])
def test_argument_errors_are_found_before_any_write(argv, needle, brackets, out_dir, capsys):
    """The first -o comes before the error: nothing at all may be written."""
    argv = [a.replace("{out}", str(out_dir)) for a in argv]
    if argv[3:5] == ["--exposure", "1"]:  # --exposure on a tone-mapped image
        argv = argv[:3] + ["--tonemap", "reinhard-global", *argv[3:]]
    code, stdout, err = run(capsys, *brackets, *argv)
    assert code == 2, err
    assert needle in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert list(out_dir.iterdir()) == []


def test_brackets_without_merge_are_an_error(brackets, capsys):
    code, _, err = run(capsys, *brackets)
    assert code == 2 and "no --merge" in err, err


def test_missing_brackets_without_merge_are_named(tmp_path, capsys):
    code, _, err = run(capsys, tmp_path / "foo.jpg", tmp_path / "bar.jpg")
    assert code == 2 and "foo.jpg: no such file" in err, err


def test_merge_subcommand_finds_colour_errors_before_work(brackets, out_dir, capsys):
    code, _, err = run(capsys, "merge", *brackets, "-o", out_dir / "a.exr", "--preview",
                       out_dir / "a.jpg", "--colorspace", "ACEScgg")
    assert code == 2 and "--colorspace ACEScgg" in err, err
    assert list(out_dir.iterdir()) == []


def test_merge_subcommand_takes_tonemap_parameters(brackets, out_dir, capsys):
    code, _, err = run(capsys, "merge", *brackets, "-o", out_dir / "a.exr", "--preview",
                       out_dir / "a.jpg", "--tonemap", "reinhard-local", "white=8")
    assert code == 2 and "no parameter 'white'" in err, err
    code, _, err = run(capsys, "merge", *brackets, "-o", out_dir / "a.exr", "--preview",
                       out_dir / "a.jpg", "--tonemap", "reinhard-global", "white=8", "-q")
    assert code == 0, err


def test_dry_run_checks_what_a_run_would(brackets, out_dir, capsys):
    code, _, err = run(capsys, *brackets, "--merge", "-o", out_dir / "a.exr",
                       "--colorspace", "nope", "-o", out_dir / "b.exr", "--dry-run")
    assert code == 2 and "--colorspace nope" in err, err


def test_cli_modules_import_one_way():
    """No import circle in hdrio/cli (imports inside functions count too): the operation
    modules import the registry and the option table, never the chain that runs them."""
    import ast

    from benchmarks.truth.scenes import REPO_ROOT

    folder = REPO_ROOT / "hdrio" / "cli"
    graph: dict[str, set[str]] = {}
    for path in folder.glob("*.py"):
        name = f"hdrio.cli.{path.stem}" if path.stem != "__init__" else "hdrio.cli"
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                if node.module == "hdrio.cli":
                    imported |= {f"hdrio.cli.{alias.name}" for alias in node.names}
                elif node.module.startswith("hdrio.cli."):
                    imported.add(node.module)
        graph[name] = imported - {name}

    def visit(name: str, path: tuple[str, ...]) -> None:
        assert name not in path, " -> ".join((*path, name))
        for other in graph.get(name, ()):
            visit(other, (*path, name))

    for name in graph:
        if name != "hdrio.cli":  # the entry point imports the chain lazily, nothing back
            visit(name, ())
    for name in ("chain_merge", "chain_ops", "chain_colour", "chain_output",
                 "chain_pictures", "chain_batch", "merge_arguments", "chain_registry"):
        assert "hdrio.cli.chain" not in graph[f"hdrio.cli.{name}"], name


def test_no_library_warning_without_matplotlib(brackets, tmp_path):
    """colour-science's Matplotlib warning is not printed on every run."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['matplotlib'] = None\n"
            "from hdrio.cli import main\n"
            f"sys.exit(main(['merge', *{[str(b) for b in brackets]!r}, '-o', "
            f"{str(tmp_path / 'x.exr')!r}, '-q']))")
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert completed.returncode == 0, completed.stderr
    assert "Warning" not in completed.stderr, completed.stderr


def test_a_flag_and_a_repeatable_option_in_the_table_work_in_argparse():
    """How a new entry behaves (the lead ports options in as entries): a flag gives True,
    a repeatable option a tuple, a bad value one line naming the option."""
    import argparse

    from hdrio.cli.merge_arguments import Option, add_arguments, settings_from_namespace
    from hdrio.cli.values import flag, positive_whole
    from hdrio.errors import HdrioError

    table = (Option("--deghost", (), "deghost", flag, help="h", example=()),
             Option("--level", ("N",), "levels", positive_whole, help="h", example=("2",),
                    repeat=True))
    parser = argparse.ArgumentParser()
    add_arguments(parser, options=table)
    settings = settings_from_namespace(
        parser.parse_args(["--deghost", "--level", "2", "--level", "3"]), table)
    assert settings == {"deghost": True, "levels": (2, 3)}
    assert settings_from_namespace(parser.parse_args([]), table) == {}
    with pytest.raises(HdrioError, match="--level 0: expected a positive whole number"):
        settings_from_namespace(parser.parse_args(["--level", "0"]), table)


def test_chain_refuses_to_overwrite_an_exr_input_before_work(brackets, tmp_path, capsys):
    exr = tmp_path / "in.exr"
    assert run(capsys, *brackets, "--merge", "-o", exr)[0] == 0
    before = exr.read_bytes()
    code, _, err = run(capsys, exr, "--exposure", "1", "-o", tmp_path / "x.exr",
                       "-o", exr)
    assert code == 2 and "would overwrite an input" in err, err
    assert exr.read_bytes() == before and not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("name, modes", [
    ("--align", "ALIGN_MODES"), ("--deghost", "DEGHOST_MODES"),
    ("--saturation", "SATURATION_POLICIES"), ("--highlights", "HIGHLIGHT_MODES")])
def test_help_of_a_choice_lists_every_value_and_the_real_default(name, modes):
    """The help cannot drift from the code: every value is named, and the one marked
    default is MergeOptions' default (the --saturation help said 'safe' while the
    default was 'auto')."""
    import re
    from dataclasses import fields

    import hdrio.align
    import hdrio.merge.highlights
    import hdrio.merge.saturation
    from hdrio.job.options import MergeOptions

    values = next(getattr(module, modes) for module in
                  (hdrio.align, hdrio.merge.highlights, hdrio.merge.saturation)
                  if hasattr(module, modes))
    option = OPTIONS_BY_NAME[name]
    default = {f.name: f.default for f in fields(MergeOptions)}[option.key]
    assert all(re.search(rf"\b{value}\b", option.help) for value in values), option.help
    marked = re.findall(r"'(\w+)' \(default|\(default (\w+)\)", option.help)
    assert [a or b for a, b in marked] == [default], option.help
