"""Every ``hdrio`` command of the README and every ``--help`` example runs, as written,
on the demo brackets, in a fresh folder.

The folder holds the files the examples name (``a.jpg b.jpg c.jpg``, ``IMG_2600.jpg``...,
``church_*.png`` with ``exposures.csv``, ``mask.png``, a ``shoot/`` of two bracket sets),
each one of the demo's brackets with EXIF exposure, aperture, ISO and capture time. Commands run in
order (later ones read what earlier ones wrote, as a reader following the README would),
split and expanded as a shell would (quotes, globs, ``$D``, ``&&`` and ``;``), through
``hdrio.cli.main``. Segments that are not ``hdrio`` (pip, oiiotool) are not run.
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from benchmarks.truth.scenes import REPO_ROOT, data_root
from hdrio.io.write import write_image

README = REPO_ROOT / "README.md"
_SETS = {  # file names -> demo bracket indices (1/1024 s .. 4 s, 2 EV apart)
    ("a.jpg", "b.jpg", "c.jpg"): (2, 3, 4),
    ("d.jpg", "e.jpg", "f.jpg"): (2, 3, 4),
    ("IMG_2600.jpg", "IMG_2601.jpg", "IMG_2602.jpg"): (2, 4, 6),
    ("next_1.jpg", "next_2.jpg", "next_3.jpg"): (2, 4, 6),
    ("church_1.png", "church_2.png", "church_3.png"): (1, 3, 5),
    ("shoot/IMG_0001.jpg", "shoot/IMG_0002.jpg", "shoot/IMG_0003.jpg"): (2, 4, 6),
    ("shoot/IMG_0004.jpg", "shoot/IMG_0005.jpg", "shoot/IMG_0006.jpg"): (1, 3, 5),
}


def readme_commands(text: str) -> list[str]:
    """``hdrio`` command lines of the README's ``sh`` blocks (continuations joined) and of
    its inline spans that chain commands (``hdrio demo -o demo && hdrio ...``)."""
    commands = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        commands += [line.strip() for line in block.replace("\\\n", " ").splitlines()
                     if line.strip()]
    commands += [span for span in re.findall(r"`([^`\n]+)`", text.replace("\n", " "))
                 if span.startswith("hdrio ") and "&&" in span]
    return commands


def help_commands() -> list[str]:
    """Every example of ``hdrio --help`` and of each ``hdrio COMMAND --help``."""
    from hdrio.cli import build_parser
    from hdrio.cli.chain import help_text

    text = help_text()
    examples = [line.split("e.g. ", 1)[1] for line in text.splitlines() if "e.g. hdrio" in line]
    joined = text.replace("\\\n", " ")  # the usage example's continuation line
    examples.append(next(line for line in joined.splitlines() if line.startswith("example:"))
                    .split(": ", 1)[1])
    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for sub in subparsers.choices.values():
        examples += [sub.epilog.split("example: ", 1)[1]] if sub.epilog else []
    return examples


def segments(command: str, env: dict[str, str]) -> list[list[str]]:
    """``command`` as a shell would run it: ``VAR=value`` set, ``&&``/``;`` split, quotes,
    ``$VAR`` and globs expanded. Non-``hdrio`` segments are dropped."""
    runs = []
    for part in re.split(r"&&|;", command):
        words = shlex.split(part, comments=True)
        while words and re.fullmatch(r"\w+=.*", words[0]):
            name, _, value = words.pop(0).partition("=")
            env[name] = value
        if not words or not words[0].endswith("hdrio"):
            continue
        expanded: list[str] = []
        for word in words[1:]:
            word = re.sub(r"\$(\w+)", lambda m: env.get(m.group(1), m.group(0)), word)
            matches = sorted(glob.glob(word)) if any(c in word for c in "*?[") else []
            expanded += matches or [word]
        runs.append(expanded)
    return runs


@pytest.fixture
def fresh_folder(tmp_path: Path, monkeypatch) -> Path:
    """A folder holding the example files, made from the demo's brackets; beside it,
    ``../shared/data`` is the real data when present (the README's memorial example)."""
    from hdrio.tools.demo import DEMO_EXPOSURES, write_demo_brackets

    work = tmp_path / "work"
    (work / "shoot").mkdir(parents=True)
    _, demo = write_demo_brackets(work / "shoot")  # temporary: removed below
    import OpenImageIO as oiio

    frames = []
    for path in demo:
        image = oiio.ImageInput.open(str(path))
        frames.append(image.read_image("uint8"))
        image.close()
        path.unlink()
    times = [n / d for n, d in DEMO_EXPOSURES]
    rows = ["file,exposure_time_s"]
    for set_index, (names, brackets) in enumerate(_SETS.items()):
        for k, (name, j) in enumerate(zip(names, brackets, strict=True)):
            exif = {"ExposureTime": times[j], "FNumber": 8.0, "Exif:PhotographicSensitivity": 100,
                    "Exif:DateTimeOriginal": f"2024:05:06 10:{set_index:02d}:{k:02d}"}
            write_image(work / name, frames[j], "uint8", exif if name.endswith(".jpg") else None)
            rows.append(f"{name},{times[j]!r}")
    (work / "exposures.csv").write_text("\n".join(rows) + "\n")
    mask = np.full((*frames[0].shape[:2], 1), 255, np.uint8)  # --mask's example
    mask[:8, :8] = 0
    write_image(work / "mask.png", mask, "uint8")
    shared = data_root()
    if shared.is_dir():
        os.symlink(shared.parent, tmp_path / "shared")
    monkeypatch.chdir(work)
    return work


def _run_all(commands: list[str], capsys) -> None:
    from hdrio.cli import main

    env = dict(os.environ)
    for command in commands:
        if "shared/data" in command or "$D" in command:
            if not Path(env.get("D", "../shared/data")).exists() and "D=" not in command:
                continue
        for argv in segments(command, env):
            if any(word.startswith("$") for word in argv):
                continue
            if "../shared/data" in " ".join(argv) and not Path("../shared/data").exists():
                continue  # the third-party data is not here: that example cannot run
            code = main(argv)
            captured = capsys.readouterr()
            assert code == 0, f"hdrio {shlex.join(argv)}\n{captured.err}"


@pytest.mark.slow
def test_readme_then_help_examples_run_as_written(fresh_folder, capsys):
    """One test (the README's commands take a while): the help's examples read the
    out.exr and room.exr that the README's wrote, as a reader would have them."""
    commands = readme_commands(README.read_text())
    assert len(commands) >= 15, commands  # the README's examples were all found
    _run_all(commands, capsys)
    assert (fresh_folder / "room.exr").is_file() and (fresh_folder / "room_ocio").is_dir()
    assert len(list((fresh_folder / "hdr").glob("*_hdr.exr"))) == 2  # two sets grouped
    commands = help_commands()
    assert len(commands) >= 30, commands
    _run_all(commands, capsys)
