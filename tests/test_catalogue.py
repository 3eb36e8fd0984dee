"""The catalogue of hostile inputs and faults: one case per row, run through ``hdrio``.

Each row: an id, a builder (a fresh folder in, the command's arguments out), the exit code
expected and a fragment of the message. For a refusal (exit 2) the test also asserts:
one line on stderr, nothing on stdout, no traceback, and the folder afterwards holds
exactly what it held before (no output, no temp file, inputs unchanged, byte for byte).
For a success (exit 0) the fragment is looked for in stdout and stderr together.

Cases run in-process (``hdrio.cli.main``) to keep the catalogue within seconds; the exit
code and traceback policy of the process itself is tested in tests/test_exit_codes.py.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests import hostile as h
from tests.conftest import run_cli


@dataclass(frozen=True)
class Case:
    id: str
    build: Callable[[Path], list[object]]
    exit: int
    fragment: str
    report: bool = False  # a refusal that prints its report on stdout first (hdrio check)
    verify: Callable[[Path, str], None] | None = None  # more checks (case folder, output)


def _rgb(d: Path) -> list[Path]:
    return h.ramp_set(d / "in")


def _grey(d: Path) -> list[Path]:
    return h.ramp_set(d / "in", channels=1)


def _long_input(d: Path) -> list[object]:
    images = _rgb(d)
    return h.merge(d, [*images[:3], d / "in" / ("x" * 300 + ".png")])


def _heic(d: Path, name: str) -> Path:
    """A file as an iPhone writes it: an ISO box of brand 'heic' (no HEIF reader here)."""
    (d / "in").mkdir(exist_ok=True)
    path = d / "in" / f"{name}.heic"
    path.write_bytes(b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00mif1heic" + bytes(64))
    return path


def _upper_case(d: Path) -> list[Path]:
    """The ramp set as a camera names its files: ``.PNG``."""
    return [path.rename(path.with_suffix(".PNG")) for path in _rgb(d)]


def _twice(d: Path) -> list[object]:
    images = _rgb(d)
    return h.merge(d, [images[0], *images])


def _same_via_link(d: Path) -> list[object]:
    images = _rgb(d)
    (d / "in" / "alias_1_16.png").symlink_to(images[0].name)
    return h.merge(d, [*images, d / "in" / "alias_1_16.png"])


def _mismatched(d: Path) -> list[object]:
    images = _rgb(d)
    other = h.ramp_set(d / "big", size=(30, 32), exposures=(16.0,))
    return h.merge(d, [*images, *other])


def _truncated(d: Path) -> list[object]:
    images = _rgb(d)
    h.truncated(images[1])
    return h.merge(d, images)


def _fake(d: Path) -> list[object]:
    images = _rgb(d)
    h.text_file(images[2], "this is not a PNG\n")
    return h.merge(d, images)


def _float_tiff(d: Path) -> list[object]:
    import numpy as np

    from hdrio.io.write import write_image

    (d / "in").mkdir(parents=True)
    files = [write_image(d / "in" / f"f_1_{k}.tif", np.ones((8, 8, 3), np.float32), "float")
             for k in (1, 2)]
    return h.merge(d, files)


def _sidecar(d: Path, text: bytes | str) -> list[object]:
    images = _rgb(d)
    sidecar = h.text_file(d / "in" / "exposures.csv", text)
    return h.merge(d, images, "--exposures-from", sidecar)


def _response(d: Path, channels: int = 3, images=None, **changes) -> list[object]:
    images = images if images is not None else _rgb(d)
    saved = h.saved_response(d / "in", channels=channels, **changes)
    return h.merge(d, images, "--response-from", saved)


def _huge_declared(d: Path) -> list[object]:
    """A PNG header declaring 100000 x 100000 pixels, and no pixel data."""
    import struct
    import zlib

    images = _rgb(d)
    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 2, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    data = (b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(ihdr)) + chunk
            + struct.pack(">I", zlib.crc32(chunk)))
    h.text_file(images[0], data)
    return h.merge(d, images)


def _group_names_input(d: Path) -> list[object]:
    _rgb(d)
    return [d / "in", "--group", "--merge", "--tonemap", "reinhard-global",
            "-o", str(d / "in" / "{first_stem}.png")]


def _grey_check(d: Path) -> list[object]:
    return ["check", h.grey_exr(d / "in")]


def _strip(d: Path, size: tuple[int, int], *extra: object) -> list[object]:
    return h.merge(d, h.ramp_set(d / "in", size=size), *extra, quiet=False)


def _nan_exr(d: Path) -> list[object]:
    return ["check", h.float_image(d / "in", nan_rows=2, inf_pixels=3)]


def _check_of(d: Path, name: str, data: bytes | str) -> list[object]:
    return ["check", h.text_file(d / "in" / name, data)]


def _truncated_exr(d: Path) -> list[object]:
    return ["check", h.truncated(h.float_image(d / "in"))]


def _jpeg(d: Path) -> list[object]:
    import numpy as np

    from hdrio.io.write import write_image

    (d / "in").mkdir(parents=True)
    return ["check", write_image(d / "in" / "preview.jpg", np.zeros((8, 8, 3), np.uint8),
                                 "uint8")]


def _two_sets(d: Path) -> Path:
    h.ramp_set(d / "shoot", stem="a")
    h.ramp_set(d / "shoot", stem="b")
    return d / "shoot"


def _negative_exr(d: Path) -> list[object]:
    import numpy as np

    from hdrio.io.write import write_exr

    pixels = h.ramp_radiance(48, 64).astype(np.float32)
    pixels[4:8, 4:8] = -0.5
    (d / "in").mkdir(parents=True)
    exr = write_exr(d / "in" / "negative.exr", pixels, pixel_type="float")
    return [exr, "--tonemap", "reinhard-global-tutorial", "-o", h.out(d, "o.png")]


def _not_black(d: Path, _text: str) -> None:
    import numpy as np
    import OpenImageIO as oiio

    pixels = oiio.ImageBuf(str(h.out(d, "o.png"))).get_pixels(oiio.FLOAT)
    assert np.mean(pixels) > 0.2, np.mean(pixels)  # the clean ramp's preview: about 0.5


def _relative_sources(d: Path) -> list[object]:
    images = _rgb(d)
    return ["merge", *(Path("in") / p.name for p in images), "-o", Path("out") / "o.exr",
            "-q"]


def _sources_resolved(d: Path, _text: str) -> None:
    from hdrio.io.header import read_header

    header = read_header(d / "out" / "o.exr")
    assert all(Path(p).is_absolute() and Path(p).is_file()
               for p in header["hdrio:sourceFiles"])
    assert all(p.startswith("../in/") for p in header["hdrio:sourceFilesRelative"])


def _only_written(d: Path, text: str) -> None:
    assert [line.split()[0] for line in text.splitlines()] == ["wrote:", "preview:"], text


CASES = [
    # ---- paths: one validator (hdrio.io.paths) for inputs and outputs
    Case("missing input", lambda d: h.merge(d, [*_rgb(d), d / "in" / "nope_1_1.png"]), 2,
         "nope_1_1.png: no such file"),
    Case("folder as image", lambda d: h.merge(d, [*_rgb(d), d / "in"]), 2,
         "is a folder, not an image file: name its files (e.g. '"),
    # A pattern no shell expanded (quoted; Windows' cmd): read as a shell would have.
    Case("pattern unexpanded", lambda d: _rgb(d) and h.merge(d, [d / "in" / "*.png"],
                                                             quiet=False), 0,
         "brackets:  4 x"),
    Case("pattern unexpanded in a chain",
         lambda d: _rgb(d) and [d / "in" / "bracket_*.png", "--merge", "-o", h.out(d)], 0,
         "wrote"),
    Case("pattern unexpanded in hdrio info",
         lambda d: _rgb(d) and ["info", d / "in" / "bracket_1_1*.png"], 0, "bracket_1_16.png"),
    Case("HEIC from a phone", lambda d: h.merge(d, [_heic(d, name) for name in "abc"]), 2,
         "a.heic: HEIC (HEIF) is not a format hdrio reads: export the brackets as TIFF"),
    Case("pattern matching nothing", lambda d: h.merge(d, [*_rgb(d), d / "in" / "*.tif"]),
         2, "*.tif: no such file, and as a pattern it matches none"),
    Case("pattern in the other letter case",
         lambda d: _upper_case(d) and h.merge(d, [d / "in" / "*.png"]), 2,
         "as a pattern it matches none (letter case counts: ignoring it, it matches "
         "bracket_1_1.PNG and 3 more; give "),
    Case("name in the other letter case",
         lambda d: h.merge(d, [*(p.with_suffix(".png") for p in _upper_case(d))]), 2,
         "PNG is there: letter case counts in file names here"),
    Case("symlink loop input", lambda d: h.merge(d, [*_rgb(d), h.symlink_loop(d / "in")]), 2,
         "symbolic links"),
    Case("input name over 255 bytes", _long_input, 2, "name too long"),
    Case("output name over 255 bytes",
         lambda d: ["merge", *_rgb(d), "-o", h.out(d, "o" * 300 + ".exr"), "-q"], 2,
         "name too long"),
    Case("output name 250 bytes is fine",
         lambda d: ["merge", *_rgb(d), "-o", h.out(d, "o" * 246 + ".exr"), "-q"], 0,
         "wrote:"),
    Case("same file twice", _twice, 2, "given twice"),
    Case("same file through a link", _same_via_link, 2, "given twice"),
    Case("output is an input", lambda d: ["merge", *_rgb(d), "-o", d / "in" / "x.exr",
                                          "--preview", _rgb(d)[0], "-q"], 2,
         "would overwrite an input"),
    Case("output folder missing: made",
         lambda d: ["merge", *_rgb(d), "-o", d / "nowhere" / "o.exr", "-q"], 0, "wrote:"),
    Case("output folder under a file",
         lambda d: ["merge", *_rgb(d), "-o", Path(_rgb(d)[0]) / "sub" / "o.exr", "-q"], 2,
         "is a file, not a folder"),
    Case("output is a folder", lambda d: ["merge", *_rgb(d), "-o", h.out(d, "x.exr"),
                                          "--preview", d / "in", "-q"], 2, "folder"),
    Case("output type unsupported",
         lambda d: ["merge", *_rgb(d), "-o", h.out(d, "o.bmp"), "-q"], 2, "unsupported"),
    Case("output folder not writable",
         lambda d: ["merge", *_rgb(d), "-o", h.unwritable_folder(d) / "o.exr", "-q"], 2,
         "permission denied"),
    Case("preview folder not writable",
         lambda d: ["merge", *_rgb(d), "-o", h.out(d), "--preview",
                    h.unwritable_folder(d) / "p.jpg", "-q"], 2, "permission denied"),
    Case("output pattern bad field (chain)",
         lambda d: [*_rgb(d), "--merge", "-o", str(h.out(d, "out{1}.exr"))], 2,
         "unknown field"),
    Case("output pattern lone brace (chain)",
         lambda d: [*_rgb(d), "--merge", "-o", str(h.out(d, "out{.exr"))], 2, "brace"),
    Case("group output names an input", _group_names_input, 2, "input"),
    # ---- files: decoded only after every header is read
    Case("truncated bracket", _truncated, 2, "cannot"),
    Case("fake bracket", _fake, 2, "cannot read image"),
    Case("float TIFF as bracket", _float_tiff, 2, "not bracket code values"),
    Case("different sizes", _mismatched, 2, "brackets must match"),
    Case("huge declared size", _huge_declared, 2, "bracket_1_16.png"),
    Case("single image", lambda d: h.merge(d, _rgb(d)[:1]), 2, "at least 2"),
    # ---- exposures and sidecars
    Case("no exposure anywhere",
         lambda d: h.merge(d, [p.rename(p.with_name(f"shot{'abcd'[k]}.png"))
                               for k, p in enumerate(_rgb(d))]), 2, "no exposure time"),
    Case("RAW and PNG mixed",
         lambda d: h.merge(d, [*_rgb(d), h.text_file(d / "in" / "IMG_1.dng", b"II*\0")]),
         2, "camera RAW and other images"),
    Case("exposure count", lambda d: h.merge(d, _rgb(d), "--exposures", "1,2"), 2,
         "2 exposures given for 4 images"),
    Case("exposure not a number", lambda d: h.merge(d, _rgb(d), "--exposures", "a,b,c,d"),
         2, "not an exposure time"),
    Case("exposure negative", lambda d: h.merge(d, _rgb(d), "--exposures=-1,1,2,3"), 2,
         "positive"),
    Case("duplicate exposures", lambda d: h.merge(d, _rgb(d), "--exposures", "1,1,2,3"), 2,
         "duplicate"),
    Case("sidecar not UTF-8",
         lambda d: _sidecar(d, b"file,exposure_time_s\nbracket_1_16.png,\x80\x81\n"), 2,
         "exposures.csv: not UTF-8 text"),
    Case("sidecar empty", lambda d: _sidecar(d, ""), 2, "exposure list is empty"),
    Case("sidecar bad value",
         lambda d: _sidecar(d, "file,exposure_time_s\nbracket_1_16.png,abc\n"), 2, "line 2"),
    Case("sidecar lacks a file",
         lambda d: _sidecar(d, "file,exposure_time_s\nbracket_1_16.png,0.0625\n"), 2,
         "no exposure for this file"),
    Case("sidecar missing", lambda d: h.merge(d, _rgb(d), "--exposures-from",
                                              d / "none.csv"), 2, "none.csv: no such file"),
    Case("sidecar is a folder", lambda d: h.merge(d, _rgb(d), "--exposures-from", d / "in"),
         2, "is a folder, not an exposure list"),
    # ---- numbers: one validator (hdrio.numbers)
    *[Case(f"--lambda {v}", lambda d, v=v: h.merge(d, _rgb(d), "--lambda", v), 2, "--lambda")
      for v in ("-1", "0", "nan", "inf")],
    *[Case(f"--samples {v}", lambda d, v=v: h.merge(d, _rgb(d), "--samples", v), 2,
           "--samples") for v in ("0", "-5")],
    Case("--seed negative", lambda d: h.merge(d, _rgb(d), "--seed", "-1"), 2, "--seed"),
    Case("--meter-k inf", lambda d: h.merge(d, _rgb(d), "--absolute", "exif", "--meter-k",
                                            "inf"), 2, "--meter-k"),
    Case("--reference-reflectance 2",
         lambda d: h.merge(d, _rgb(d), "--absolute", "illuminance", "--reference-region",
                           "0,0,4,4", "--reference-illuminance", "100",
                           "--reference-reflectance", "2"), 2, "at most 1"),
    Case("--white-balance nan (chain)",
         lambda d: [*_rgb(d), "--white-balance", "nan,1,1", "--merge", "-o", h.out(d)], 2,
         "--white-balance"),
    Case("--exposure nan (chain)", lambda d: [h.float_image(d / "in"), "--exposure", "nan",
                                              "-o", h.out(d)], 2, "--exposure"),
    Case("--tonemap key=-1 (chain)",
         lambda d: [h.float_image(d / "in"), "--tonemap", "reinhard-global", "key=-1",
                    "-o", h.out(d, "o.jpg")], 2, "key"),
    # ---- saved responses
    Case("response codeMax 0", lambda d: _response(d, code_max=0), 2, "hdrio:codeMax"),
    Case("response 16-bit for 8-bit brackets", lambda d: _response(d, code_max=65535), 2,
         "response.exr"),
    Case("response grey for RGB brackets", lambda d: _response(d, channels=1), 2,
         "response.exr"),
    Case("response curve text", lambda d: _response(d, **{"hdrio:responseR": "abc"}), 2,
         "hdrio:responseR"),
    Case("response curve NaN",
         lambda d: _response(d, **{"hdrio:responseG": [float("nan")] * 256}), 2,
         "hdrio:responseG"),
    Case("response missing", lambda d: h.merge(d, _rgb(d), "--response-from",
                                               d / "no.exr"), 2, "no.exr: no such file"),
    Case("response from a plain EXR",
         lambda d: h.merge(d, _rgb(d), "--response-from", h.float_image(d / "in")), 2,
         "holds no hdrio response"),
    # ---- scenes that cannot give a response: say which files and what to do
    Case("all black", lambda d: h.merge(d, h.flat_set(d / "in", 0)), 2, "--response-from"),
    Case("all white", lambda d: h.merge(d, h.flat_set(d / "in", 255)), 2, "--response-from"),
    Case("uniform grey", lambda d: h.merge(d, h.flat_set(d / "in", 128)), 2,
         "--response-from"),
    Case("identical brackets", lambda d: h.merge(d, h.identical_set(d / "in")), 2,
         "--response-from"),
    Case("1x1 brackets", lambda d: h.merge(d, h.ramp_set(d / "in", size=(1, 1))), 2,
         "--response-from"),
    Case("2x2 brackets", lambda d: h.merge(d, h.ramp_set(d / "in", size=(2, 2))), 2,
         "--response-from"),
    # ---- greyscale brackets: first class
    Case("grey merge", lambda d: h.merge(d, _grey(d), quiet=False), 0, "1 ch"),
    Case("grey 16-bit merge", lambda d: h.merge(d, h.ramp_set(d / "in", channels=1,
                                                               bit_depth=16), quiet=False),
         0, "16-bit"),
    Case("grey and colour mixed", lambda d: h.merge(d, [*_rgb(d)[:2],
                                                       *h.ramp_set(d / "grey", 1)[2:]]), 2,
         "brackets must match"),
    Case("grey chain", lambda d: [*_grey(d), "--merge", "-o", h.out(d), "--tonemap",
                                  "reinhard-local", "-o", h.out(d, "o.jpg")], 0, "wrote"),
    Case("grey check", _grey_check, 0, "range:"),
    Case("grey with RGB response", lambda d: _response(d, images=_grey(d)), 2,
         "response.exr"),
    # ---- float inputs with non-finite values: replaced by a stated rule, said once
    Case("NaN rows in a float input",
         lambda d: [h.float_image(d / "in", nan_rows=4), "--tonemap", "reinhard-global",
                    "-o", h.out(d, "o.jpg")], 0, "replaced"),
    Case("Inf pixels in a float input",
         lambda d: [h.float_image(d / "in", inf_pixels=7), "--stats"], 0, "7 +Inf"),
    # ---- options and operations
    Case("unknown tonemap", lambda d: h.merge(d, _rgb(d), "--tonemap", "drago"), 2, "drago"),
    Case("unknown response", lambda d: h.merge(d, _rgb(d), "--response", "mitsunaga"), 2,
         "mitsunaga"),
    Case("unknown chain operation", lambda d: [*_rgb(d), "--sharpen"], 2, "--sharpen"),
    Case("chain needs a merge", lambda d: [*_rgb(d), "-o", h.out(d)], 2, "--merge"),
    Case("chain scene-linear to jpg",
         lambda d: [h.float_image(d / "in"), "-o", h.out(d, "o.jpg")], 2, "tone-map it"),
    # ---- issue 31: nothing lost, nothing broken
    # hdrio check on what is not a whole, finite EXR: the file named, exit 2
    Case("check a JPEG", _jpeg, 2, "preview.jpg: a JPEG image, not OpenEXR"),
    Case("check a PNG bracket", lambda d: ["check", _rgb(d)[0]], 2,
         "a PNG image, not OpenEXR"),
    Case("check a text file", lambda d: _check_of(d, "notes.exr", "hello\n"), 2,
         "notes.exr: not an OpenEXR file"),
    Case("check an empty file", lambda d: _check_of(d, "empty.exr", b""), 2,
         "empty.exr: not an OpenEXR file"),
    Case("check a truncated EXR", _truncated_exr, 2, "scene.exr: "),
    Case("check NaN and Inf pixels", _nan_exr, 2, "scene.exr: 131 of 3072 pixels hold NaN",
         report=True),
    Case("check a folder", lambda d: ["check", (d / "in").mkdir() or d / "in"], 2,
         "is a folder"),
    # outputs planned before any work
    Case("group with a fixed output",
         lambda d: [_two_sets(d), "--group", "--merge", "-o", h.out(d, "fixed.exr")], 2,
         "would both write it; put {index} or {first_stem}"),
    Case("group dry run with a fixed output",
         lambda d: [_two_sets(d), "--dry-run", "--group", "--merge", "-o",
                    h.out(d, "fixed.exr")], 2, "would both write it", report=True),
    Case("group pattern {folder} shared",
         lambda d: [_two_sets(d), "--group", "--merge", "-o", "{folder}/o.exr"], 2,
         "sets 1 ("),
    Case("group pattern written twice per set",
         lambda d: [_two_sets(d), "--group", "--merge", "-o", str(h.out(d, "{index}.exr")),
                    "--tonemap", "reinhard-global", "-o", str(h.out(d, "{index}.exr"))],
         2, "an earlier output of this chain writes this file too"),
    Case("chain two outputs to one file",
         lambda d: [*_rgb(d), "--merge", "-o", h.out(d), "--tonemap", "reinhard-global",
                    "-o", h.out(d)], 2, "an earlier output of this chain writes this file"),
    # every error in hdrio's words, naming the file or option
    Case("1x1000 strip", lambda d: _strip(d, (1, 1000)), 0, "too small to register"),
    Case("1000x1 strip", lambda d: _strip(d, (1000, 1)), 0, "too small to register"),
    Case("5x5 thumbnail", lambda d: _strip(d, (5, 5)), 0, "too small to register"),
    Case("1x1000 strip --align translation",
         lambda d: [*h.merge(d, h.ramp_set(d / "in", size=(1, 1000))), "--align",
                    "translation"], 2, "--align translation: the brackets are 1000x1"),
    Case("merge option typo", lambda d: h.merge(d, _rgb(d), "--exposure", "1"), 2,
         "--exposure: unknown option (did you mean --exposures?); usage: hdrio merge"),
    Case("merge option abbreviated", lambda d: h.merge(d, _rgb(d), "--merg", "log"), 2,
         "did you mean --merge?"),
    Case("merge missing -o", lambda d: ["merge", *_rgb(d)], 2,
         "missing -o/--output; usage: hdrio merge"),
    Case("merge bad choice", lambda d: h.merge(d, _rgb(d), "-d", "halff"), 2,
         "--data-type halff: not one of half, float (did you mean half?)"),
    Case("chain operation typo", lambda d: [*_rgb(d), "--merg", "-o", h.out(d)], 2,
         "--merg: unknown operation (did you mean --merge?)"),
    Case("chain given a merge option", lambda d: [*_rgb(d), "--merge", "--preview",
                                                  h.out(d, "p.jpg")], 2,
         "--tonemap reinhard-global -o preview.jpg"),
    # tone mapping: non-finite and negative pixels as every operator treats them
    Case("tutorial global on negative pixels", _negative_exr, 0, "wrote",
         verify=_not_black),
    Case("tutorial global on NaN and Inf pixels",
         lambda d: [h.float_image(d / "in", nan_rows=4, inf_pixels=7), "--tonemap",
                    "reinhard-global-tutorial", "-o", h.out(d, "o.png")], 0, "replaced",
         verify=_not_black),
    # provenance: sources resolved, and relative to the EXR
    Case("relative source paths", _relative_sources, 0, "wrote:",
         verify=_sources_resolved),
    Case("-q prints only what was written", lambda d: h.merge(d, _rgb(d)), 0, "wrote:",
         verify=_only_written),
]


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
def test_catalogue(case: Case, tmp_path: Path, capsys) -> None:
    argv = case.build(tmp_path)
    before = h.snapshot(tmp_path)
    code, out, err = run_cli(capsys, *argv)
    text = out + err
    assert "Traceback" not in text
    assert code == case.exit, text
    if case.exit == 0:
        assert case.fragment in text, text
        if case.verify is not None:
            case.verify(tmp_path, out)
        return
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert case.fragment.lower() in lines[0].lower(), lines[0]
    assert (out != "") if case.report else (out == "")
    assert h.snapshot(tmp_path) == before  # nothing written, nothing left, inputs unchanged


def test_catalogue_is_at_least_the_issue() -> None:
    """Every kind the issue lists has a row (names kept stable for the report)."""
    assert len(CASES) >= 60
    assert len({case.id for case in CASES}) == len(CASES)


@pytest.fixture(autouse=True)
def _in_case_folder(tmp_path, monkeypatch):
    """Run each case from its own folder, so a stray relative output shows in the snapshot."""
    monkeypatch.chdir(tmp_path)
