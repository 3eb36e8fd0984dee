"""The ``hdrio`` command, run through ``hdrio.cli.main([...])``."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenEXR  # the test extra: proves our EXRs are readable by OpenEXR itself
import OpenImageIO as oiio
import pytest

from hdrio.radiometry.weighting import WEIGHTING_METHODS
from tests.conftest import DEFAULT_EXPOSURES
from tests.conftest import run_cli as run

EXPOSURES = DEFAULT_EXPOSURES  # what the fixture's file names say




def assert_rejected(capsys, argv: list[object], out_dir: Path, *needles: str) -> str:
    """Exit code 2, nothing on stdout, one stderr line naming each needle, no output left."""
    code, out, err = run(capsys, *argv)
    lines = err.strip().splitlines()
    assert code == 2, err
    assert out == ""
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert sorted(p.name for p in out_dir.iterdir()) == []  # no EXR, preview or temp file
    return lines[0]


def merge_args(images, out_dir: Path, *extra: object) -> list[object]:
    return ["merge", *images, "-o", out_dir / "out.exr", "--preview", out_dir / "out.jpg",
            "-q", *extra]


# ------------------------------------------------------------------------------ merge, info


def test_merge_writes_exr_and_preview_then_info_shows_provenance(brackets, out_dir, capsys):
    exr, preview = out_dir / "ramp.exr", out_dir / "ramp.jpg"
    code, out, err = run(capsys, "merge", *brackets, "-o", exr, "--preview", preview, "-q")
    assert code == 0, err
    # -q: no progress, no summary, no check; the files written, warnings and errors.
    assert err == ""
    assert [line.split()[:2] for line in out.splitlines()] == [["wrote:", str(exr)],
                                                               ["preview:", str(preview)]]
    assert sorted(p.name for p in out_dir.iterdir()) == ["ramp.exr", "ramp.jpg"]

    preview_spec = oiio.ImageInput.open(str(preview))
    assert (preview_spec.spec().width, preview_spec.spec().height) == (64, 48)
    preview_spec.close()

    rgb = OpenEXR.File(str(exr)).channels()["RGB"].pixels.astype(np.float64)
    assert rgb.shape == (48, 64, 3)
    assert np.all(np.isfinite(rgb)) and np.all(rgb > 0)
    # The scene is a ramp rising about 12 % per column, far above the noise once averaged
    # over 48 rows: a working merge keeps every column brighter than the one before.
    assert np.all(np.diff(rgb[..., 1].mean(axis=0)) > 0)

    code, out, err = run(capsys, "info", exr)
    assert code == 0, err
    assert out.startswith(f"{exr}: 64x48, R,G,B (half)")
    for name in ("chromaticities", "hdrio:lambda", "hdrio:responseR", "hdrio:responseG",
                 "hdrio:responseB", "hdrio:exposures", "hdrio:sourceFiles",
                 "hdrio:weighting", "hdrio:version"):
        assert re.search(rf"^  {re.escape(name)}\s", out, re.MULTILINE), name
    assert re.search(r"^  hdrio:lambda\s+50$", out, re.MULTILINE)
    assert re.search(r"^  hdrio:exposureSource\s+filename$", out, re.MULTILINE)
    assert re.search(r"^  hdrio:responseR\s+\[256 values: ", out, re.MULTILINE)
    assert re.search(r"^  hdrio:responseSupport\s+R \d+-\d+, G \d+-\d+, B \d+-\d+$", out,
                     re.MULTILINE)

    header = OpenEXR.File(str(exr)).header()
    assert header["hdrio:lambda"] == 50.0  # exact: 50 is a float32
    assert len(header["hdrio:responseR"]) == 256
    # Exact decimal text (see docs/metadata.md): parsing gives back the very same floats.
    assert [float(t) for t in header["hdrio:exposures"]] == list(EXPOSURES)


def test_merge_prints_progress_on_stderr_unless_quiet(brackets, out_dir, capsys):
    code, out, err = run(capsys, "merge", *brackets, "-o", out_dir / "ramp.exr")
    assert code == 0, err
    assert "reading 4 brackets" in err and "writing" in err
    assert "stops" in out and "stops" not in err


def test_merge_with_explicit_exposures_and_float_output(brackets, out_dir, capsys):
    code, out, err = run(capsys, "merge", *brackets, "-o", out_dir / "f.exr",
                         "--exposures", ",".join(["1/16", "1/4", "1", "4"]), "-d", "float")
    assert code == 0, err
    assert "exposures from explicit" in out
    assert OpenEXR.File(str(out_dir / "f.exr")).channels()["RGB"].pixels.dtype == np.float32


def test_merge_compression_is_the_chains(brackets, out_dir, capsys):
    """``hdrio merge --compression`` takes the chain's names (any case, ``dwaa:LEVEL``),
    writes them and says them in the summary; a name OpenEXR does not have is refused
    before any bracket is read, listing the choices (the command had no such option:
    'did you mean --response?'). Pixels are the zip file's where the compression is
    lossless."""
    code, out, err = run(capsys, "merge", *brackets, "-o", out_dir / "piz.exr",
                         "--compression", "PIZ")
    assert code == 0 and f"wrote:     {out_dir / 'piz.exr'} (half, piz) in" in out, err
    code, out, err = run(capsys, "merge", *brackets, "-o", out_dir / "zip.exr")
    assert code == 0 and "(half, zip) in" in out, err
    assert "lossy compression" not in out
    code, out, err = run(capsys, "merge", *brackets, "-o", out_dir / "dwaa.exr", "-d",
                         "float", "--compression", "dwaa:45")
    assert code == 0 and "(float, dwaa:45) in" in out, err
    # The report after the merge counts the pixels as converted, before a lossy codec.
    assert "note:         counted before dwaa:45's lossy compression; hdrio check " \
        "dwaa.exr reads the pixels it kept" in out
    images = {name: oiio.ImageInput.open(str(out_dir / f"{name}.exr"))
              for name in ("piz", "zip", "dwaa")}
    specs = {name: image.spec() for name, image in images.items()}
    assert specs["piz"].getattribute("compression") == "piz"
    assert specs["dwaa"].getattribute("compression") == "dwaa"
    assert specs["dwaa"].getattribute("openexr:dwaCompressionLevel") == 45
    assert np.array_equal(images["piz"].read_image(), images["zip"].read_image())
    for image in images.values():
        image.close()
    code, _, err = run(capsys, "merge", *brackets, "-o", out_dir / "lzw.exr",
                       "--compression", "lzw")
    assert code == 2 and "--compression 'lzw': choose from none, rle, zips, zip, piz" in err
    assert not (out_dir / "lzw.exr").exists()


def test_info_on_several_files(brackets, capsys):
    code, out, err = run(capsys, "info", *brackets[:2])
    assert code == 0, err
    assert out.count("64x48, R,G,B (uint8)") == 2


def test_info_on_a_missing_file(tmp_path, capsys):
    missing = tmp_path / "nothere.exr"
    code, out, err = run(capsys, "info", missing)
    assert code == 2
    assert err.strip().splitlines() == [f"hdrio info: error: {missing}: no such file"]


# ------------------------------------------------------------------------------- bad input


def test_images_of_different_sizes(write_brackets, tmp_path, out_dir, capsys):
    big = write_brackets(EXPOSURES[:3])
    small = write_brackets(EXPOSURES[3:], size=(24, 32), folder=tmp_path / "small")
    assert_rejected(capsys, merge_args([*big, *small], out_dir), out_dir,
                    str(small[0]), "32x24", "64x48", "must match")


def test_exposures_are_typed_with_commas_or_spaces_and_a_unit(brackets, out_dir, capsys):
    # As Blender's Exposures field reads them (hdrio.io.exposure.split_exposures).
    typed = ("1/16,1/4,1,4", "1/16 1/4 1 4", "1/16 s, 1/4 s, 1 s, 4 s", '1/16,1/4,1,4"')
    headers = []
    for k, exposures in enumerate(typed):
        exr = out_dir / f"typed{k}.exr"
        code, _, err = run(capsys, "merge", *brackets, "-o", exr, "-q", "--exposures",
                           exposures)
        assert code == 0, err
        headers.append(OpenEXR.File(str(exr)).header()["hdrio:exposures"])
    assert all(header == headers[0] for header in headers)


def exr_rgb(path: Path) -> np.ndarray:
    return OpenEXR.File(str(path)).channels()["RGB"].pixels


def test_exposures_typed_in_ev_merge_as_the_seconds_they_stand_for(brackets, out_dir,
                                                                   capsys):
    # Four brackets 2 EV apart, 1/16 .. 4 s. Typed as steps in EV (a leading minus sign
    # too: argparse would take '-4EV,...' for an option), they are relative exposures,
    # 0 EV's 1: the same ratios, so the same pixels, and the summary says relative.
    seconds = out_dir / "seconds.exr"
    code, _, err = run(capsys, "merge", *brackets, "-o", seconds, "-q", "--exposures",
                       "1/16,1/4,1,4")
    assert code == 0, err
    for k, typed in enumerate(("-4EV,-2EV,0EV,+2EV", "-4 EV, -2 EV, 0 EV, 2 EV")):
        exr = out_dir / f"ev{k}.exr"
        code, out, err = run(capsys, "merge", *brackets, "-o", exr, "--exposures", typed)
        assert code == 0, err
        assert "relative exposures 0.0625 .. 4 (exposures from EV steps)" in out
        header = OpenEXR.File(str(exr)).header()
        assert header["hdrio:exposureSource"] == "EV steps"
        assert np.array_equal(exr_rgb(exr), exr_rgb(seconds))  # exact: same ratios
    chain = out_dir / "chain.exr"
    code, _, err = run(capsys, *brackets, "--exposures", "-4EV,-2EV,0EV,+2EV", "--merge",
                       "-o", chain)
    assert code == 0, err
    assert np.array_equal(exr_rgb(chain), exr_rgb(seconds))


def test_an_exposure_in_ev_the_data_contradict_is_named_in_ev(brackets, out_dir, capsys):
    # The 4 s bracket typed as +1 EV (2 s): the warning speaks the unit it was typed in.
    code, _, err = run(capsys, "merge", *brackets, "-o", out_dir / "off.exr", "-q",
                       "--exposures", "-4EV,-2EV,0EV,+1EV")
    assert code == 0, err
    assert re.search(r"exposure [+-]?\d+ EV given by --exposures \(in EV\), the data say "
                     r"[+-]?[\d.]+ EV \([+-][\d.]+ stop\)", err), err


def test_exposures_in_ev_and_seconds_mixed_are_refused(brackets, out_dir, capsys):
    assert_rejected(capsys, merge_args(brackets[:3], out_dir, "--exposures", "-2EV,1,2EV"),
                    out_dir, "--exposures -2EV,1,2EV", "'1' beside '-2EV'")


def test_duplicate_exposure_times(brackets, out_dir, capsys):
    assert_rejected(capsys, merge_args(brackets[:3], out_dir, "--exposures", "1/8,1/8,1"),
                    out_dir, str(brackets[1]), "same exposure", "not the same picture")


def test_wrong_number_of_exposures(brackets, out_dir, capsys):
    assert_rejected(capsys, merge_args(brackets, out_dir, "--exposures", "1/8,1"), out_dir,
                    str(brackets[2]), "2 exposures given for 4 images")


def test_unparsable_exposure(brackets, out_dir, capsys):
    # Found while the options are parsed, before any image is read: the option is named.
    assert_rejected(capsys, merge_args(brackets[:3], out_dir, "--exposures", "1/8,fast,1"),
                    out_dir, "--exposures 1/8,fast,1", "'fast'")


def test_exposure_too_large_for_a_float(brackets, out_dir, capsys):
    assert_rejected(capsys, merge_args(brackets[:3], out_dir, "--exposures", "1/8,1e400,1"),
                    out_dir, "--exposures 1/8,1e400,1")


def test_unreadable_file(brackets, tmp_path, out_dir, capsys):
    garbage = tmp_path / "garbage_8_1.jpg"
    garbage.write_bytes(bytes(range(256)) * 16)
    assert_rejected(capsys, merge_args([*brackets[:3], garbage], out_dir), out_dir,
                    str(garbage), "cannot read image")


def test_truncated_file(brackets, tmp_path, out_dir, capsys):
    whole = brackets[3].read_bytes()
    truncated = tmp_path / "truncated_8_1.png"
    truncated.write_bytes(whole[: len(whole) // 2])
    assert_rejected(capsys, merge_args([*brackets[:3], truncated], out_dir), out_dir,
                    str(truncated), "cannot decode image")


def test_single_image(brackets, out_dir, capsys):
    assert_rejected(capsys, merge_args(brackets[:1], out_dir), out_dir,
                    str(brackets[0]), "at least 2")


def test_missing_exposure(write_brackets, out_dir, capsys):
    paths = write_brackets(EXPOSURES[:3], names=["dark.png", "mid.png", "bright.png"])
    assert_rejected(capsys, merge_args(paths, out_dir), out_dir,
                    str(paths[0]), "no exposure time", "--exposures")


def test_nonexistent_input(brackets, tmp_path, out_dir, capsys):
    missing = tmp_path / "nothere_8_1.png"
    assert_rejected(capsys, merge_args([*brackets[:3], missing], out_dir), out_dir,
                    str(missing), "no such file")


def test_sidecar_missing_a_file(brackets, tmp_path, out_dir, capsys):
    sidecar = tmp_path / "exposures.csv"
    listed = [(brackets[0], "1/16"), (brackets[1], "1/4"), (brackets[3], "4")]
    sidecar.write_text("file,exposure_time_s\n"
                       + "".join(f"{path.name},{t}\n" for path, t in listed))
    assert_rejected(capsys, merge_args(brackets, out_dir, "--exposures-from", sidecar),
                    out_dir, str(brackets[2]), "no exposure for this file", str(sidecar))


def test_malformed_sidecar(brackets, tmp_path, out_dir, capsys):
    sidecar = tmp_path / "list.txt"
    sidecar.write_text("bracket_1_16.png 16\nbracket_1_4.png four\n")
    assert_rejected(capsys, merge_args(brackets[:2], out_dir, "--exposures-from", sidecar),
                    out_dir, str(sidecar), "line 2")


def test_outputs_in_missing_folders_make_them(brackets, tmp_path, capsys):
    output, preview = tmp_path / "new" / "deeper" / "out.exr", tmp_path / "p" / "out.jpg"
    code, _, err = run(capsys, "merge", *brackets, "-o", output, "--preview", preview, "-q")
    assert code == 0, err
    assert output.is_file() and preview.is_file()


def test_output_under_a_file_is_refused_before_work(brackets, tmp_path, out_dir, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    output = blocker / "sub" / "out.exr"
    assert_rejected(capsys, ["merge", *brackets, "-o", output, "-q"], out_dir,
                    str(output), "is a file, not a folder")
    assert blocker.read_text() == "x"


@pytest.mark.parametrize("output", ["out.png", "out.hdr", "out"])
def test_unsupported_output_type(brackets, out_dir, capsys, output):
    assert_rejected(capsys, ["merge", *brackets, "-o", out_dir / output, "-q"], out_dir,
                    str(out_dir / output), "unsupported output type", ".exr")


def test_output_path_that_is_a_folder(brackets, out_dir, capsys):
    folder = out_dir / "taken.exr"
    folder.mkdir()
    assert_rejected(capsys, ["merge", *brackets, "-o", folder, "-q"], folder, str(folder))


def test_unknown_weighting_lists_the_choices(brackets, out_dir, capsys):
    line = assert_rejected(capsys, merge_args(brackets, out_dir, "--weighting", "bogus"),
                           out_dir, "'bogus'", "choose from")
    for name in WEIGHTING_METHODS.names():
        assert name in line


@pytest.mark.parametrize(("option", "kind"), [("--response", "response"),
                                              ("--tonemap", "tone"), ("--merge", "merge"),
                                              ("--sampling", "sampl")])
def test_other_unknown_method_names(brackets, out_dir, capsys, option, kind):
    line = assert_rejected(capsys, merge_args(brackets, out_dir, option, "bogus"), out_dir,
                           "'bogus'", "choose from")
    assert kind in line


@pytest.mark.parametrize(
    "bad",
    [pytest.param("garbage", id="garbage-jpg"), pytest.param("truncated", id="truncated-jpg")],
)
def test_native_decoder_chatter_stays_off_the_terminal(write_brackets, tmp_path, bad):
    """A real process, so what libjpeg prints on file descriptor 2 is seen too."""
    paths = write_brackets(EXPOSURES[:3], suffix=".jpg")
    broken = tmp_path / "broken_8_1.jpg"
    if bad == "garbage":
        broken.write_bytes(b"\xff\xd8\xff\xe0" + bytes(range(256)) * 8)
    else:
        whole = paths[0].read_bytes()
        broken.write_bytes(whole[: len(whole) // 2])
    output = tmp_path / "out" / "out.exr"
    output.parent.mkdir()
    process = subprocess.run(
        [sys.executable, "-m", "hdrio", "merge", *map(str, [*paths, broken]),
         "-o", str(output), "-q"],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert process.returncode == 2, process.stderr
    lines = process.stderr.strip().splitlines()
    assert len(lines) == 1, process.stderr
    assert str(broken) in lines[0]
    assert list(output.parent.iterdir()) == []


def test_every_merge_option_is_recorded(brackets, out_dir, capsys):
    exr = out_dir / "ramp.exr"
    code, _, err = run(capsys, "merge", *brackets, "-o", exr, "-q", "--seed", "7",
                       "--exclude-color", "0,0,255")
    assert code == 0, err
    header = OpenEXR.File(str(exr)).header()
    assert header.get("hdrio:seed") == 7
    assert any("exclu" in name.lower() for name in header)


# ------------------------------------------------------------------------------------- demo


def test_demo_writes_exr_preview_and_reports_error_against_truth(tmp_path, capsys):
    folder = tmp_path / "demo"
    code, out, err = run(capsys, "demo", "-o", folder, "-q")
    assert code == 0, err
    assert (folder / "demo.exr").is_file() and (folder / "demo_preview.jpg").is_file()
    assert not [p.name for p in folder.iterdir() if ".partial" in p.name]
    truth = [line for line in out.splitlines() if line.startswith("truth:")]
    assert len(truth) == 1, out
    median = re.search(r"median ([0-9.]+) %", truth[0])
    assert median, truth[0]
    # < 10 %: 8-bit codes with sensor noise, merged from a recovered response, land at a
    # few percent (3.6 % today); a broken response or merge is off by tens of percent.
    assert float(median.group(1)) < 10.0


# ----------------------------------------------------------------------------- import hygiene


def test_importing_hdrio_pulls_in_no_front_end():
    code = (
        "import json, sys\n"
        "import hdrio\n"
        "print(json.dumps(sorted(m for m in sys.modules if m == 'bpy' or m == 'plugins'\n"
        "    or m.startswith(('bpy.', 'plugins.', 'hdrio.cli')))))\n"
    )
    process = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=120, check=True)
    assert json.loads(process.stdout) == []


def test_every_subcommand_is_routed_to_its_parser_not_to_the_chain():
    import argparse

    from hdrio.cli import SUBCOMMANDS, build_parser

    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(action.choices) == SUBCOMMANDS


def test_one_bracket_is_counted_in_the_singular(brackets, out_dir, capsys):
    code, _, err = run(capsys, "merge", brackets[0], "-o", out_dir / "one.exr")
    assert code == 2 and "reading 1 bracket\n" in err and "1 brackets" not in err, err


def test_camera_raw_without_rawpy_names_the_extra(tmp_path, out_dir, capsys, monkeypatch):
    # The plain install has no rawpy (the 'raw' extra): RAW brackets are refused naming
    # the first file and the install that reads them, with exit 2, where an internal
    # error (ModuleNotFoundError) was reported before. Both front ends, as on that install.
    monkeypatch.setitem(sys.modules, "rawpy", None)  # import rawpy raises ImportError
    raws = []
    for name in ("a.CR2", "b.CR2", "c.CR2"):
        (tmp_path / name).write_bytes(b"II*\x00" + bytes(64))
        raws.append(tmp_path / name)
    for argv in (["merge", *raws, "-o", out_dir / "raw.exr"],
                 [*raws, "--merge", "-o", out_dir / "raw.exr"]):
        code, _, err = run(capsys, *argv)
        assert code == 2, err
        assert "a.CR2: camera RAW needs rawpy" in err and "pip install 'hdrio[raw]'" in err
        assert "internal error" not in err
    assert not list(out_dir.iterdir())
