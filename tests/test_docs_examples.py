"""The docs cannot drift: every shell example of README.md and docs/*.md runs, on the data it
names, and prints the figures the page quotes from it.

A shell example is a fenced block marked ``sh``. Each either runs, or says on the line
before it why not: ``<!-- not run: REASON -->`` (its file names stand for the reader's
own, it needs a cluster, it is a timing procedure whose results the page's tables hold).
A fenced ``text`` block right after an example is what it prints: each of its lines must
appear (spacing aside) in what the example's commands printed; a failure shows what they
did print, ready to paste into the page.

README.md's examples run in tests/test_cli_examples.py, in order, on files made from the
demo's brackets and named as the README names them (this module checks that each README
example is one of those or is marked). The docs' examples run here, each in a fresh
folder beside ``../shared/data``; one that reads that data is skipped, saying so, when it
is absent.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from benchmarks.truth.scenes import REPO_ROOT, data_root
from tests.test_cli_examples import readme_commands, segments

PAGES = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
_NOT_RUN = re.compile(r"<!-- not run: (.+?) -->")


@dataclass(frozen=True)
class Example:
    page: Path
    line: int  # of the opening fence, from 1
    commands: tuple[str, ...]  # continuation lines joined
    not_run: str | None
    output: tuple[str, ...]  # the following ``text`` block's lines, if any

    @property
    def id(self) -> str:
        return f"{self.page.relative_to(REPO_ROOT)}:{self.line}"


def examples(page: Path) -> list[Example]:
    """The ``sh`` blocks of ``page``, with their markers and quoted output."""
    lines = page.read_text().splitlines()
    found, index = [], 0
    while index < len(lines):
        if not lines[index].startswith("```"):
            index += 1
            continue
        info, start = lines[index][3:].strip(), index
        end = next(k for k in range(start + 1, len(lines)) if lines[k].startswith("```"))
        index = end + 1
        if info != "sh":
            continue
        before = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
        marker = _NOT_RUN.fullmatch(before.strip())
        after = index
        while after < len(lines) and not lines[after].strip():
            after += 1
        output: list[str] = []
        if after < len(lines) and lines[after].strip() == "```text":
            close = next(k for k in range(after + 1, len(lines)) if lines[k].startswith("```"))
            output = [line for line in lines[after + 1: close] if line.strip()]
        body = "\n".join(lines[start + 1: end]).replace("\\\n", " ")
        commands = tuple(line.strip() for line in body.splitlines() if line.strip()
                         and not line.strip().startswith("#"))
        found.append(Example(page, start + 1, commands, marker and marker.group(1),
                             tuple(output)))
    return found


ALL = [example for page in PAGES for example in examples(page)]
RUN = [example for example in ALL if example.not_run is None
       and example.page.name != "README.md"]


def test_every_example_runs_or_says_why_not():
    assert len(ALL) >= 12, [e.id for e in ALL]  # the pages' blocks were all found
    for example in ALL:
        assert example.not_run is None or len(example.not_run) > 20, example.id
    readme = set(readme_commands((REPO_ROOT / "README.md").read_text()))
    for example in ALL:
        if example.page.name == "README.md" and example.not_run is None:
            missing = [c for c in example.commands if "hdrio" in c and c not in readme]
            assert not missing, (example.id, missing)  # run by test_cli_examples


def _needs_data(example: Example) -> bool:
    text = " ".join(example.commands)
    return "shared/data" in text or "benchmarks.truth" in text


def _run(command: str, env: dict[str, str], capsys) -> str:
    """One line of an example, as a shell would run it; what it printed."""
    from hdrio.cli import main

    words = shlex.split(command, comments=True)
    if words[:2] == ["python", "-m"]:
        process = subprocess.run(
            [sys.executable, *words[1:]], capture_output=True, text=True, timeout=1800,
            env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
        assert process.returncode == 0, f"{command}\n{process.stdout}\n{process.stderr}"
        return process.stdout + process.stderr
    printed = ""
    for argv in segments(command, env):
        code = main(argv)
        captured = capsys.readouterr()
        printed += captured.out + captured.err
        assert code == 0, f"hdrio {shlex.join(argv)}\n{captured.out}\n{captured.err}"
    return printed


def _normal(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.slow
@pytest.mark.parametrize("example", RUN, ids=[example.id for example in RUN])
def test_docs_example_runs_and_prints_what_the_page_quotes(example, tmp_path, capsys,
                                                           monkeypatch):
    if _needs_data(example) and not data_root().is_dir():
        pytest.skip(f"{example.id} reads ../shared/data, which is not here (third-party "
                    "images are read in place, not shipped)")
    work = tmp_path / "work"
    work.mkdir()
    if data_root().is_dir():
        os.symlink(data_root().parent, tmp_path / "shared")
    monkeypatch.chdir(work)
    env = dict(os.environ)
    printed = "".join(_run(command, env, capsys) for command in example.commands)
    lines = [_normal(line) for line in printed.splitlines()]
    missing = [line for line in example.output
               if not any(_normal(line) in printed_line for printed_line in lines)]
    assert not missing, (f"{example.id} quotes lines its commands did not print:\n"
                         + "\n".join(missing) + "\n--- they printed:\n" + printed)
