"""Exit codes and what reaches stderr: 2 for the user's input, 1 for hdrio's own fault
(one line asking for a report), a traceback only with ``HDRIO_DEBUG=1``; the process
itself, where that is what a user runs."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from hdrio.cli import EXIT_BROKEN_PIPE, main
from tests import hostile as h


def _hdrio(*argv: object, env: dict | None = None, code: str | None = None
           ) -> subprocess.CompletedProcess:
    """``hdrio ARGV`` as a process (``python -c CODE`` first when given)."""
    prelude = code or ""
    script = f"{prelude}\nimport sys\nfrom hdrio.cli import main\nsys.exit(main())"
    return subprocess.run([sys.executable, "-c", script, *map(str, argv)],
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})})


def _break_merge(monkeypatch) -> None:
    def broken(*args, **kwargs):
        return 1 / 0

    monkeypatch.setattr("hdrio.cli.commands.merge_files", broken)


def test_a_fault_of_hdrio_exits_1_with_one_line_asking_for_a_report(
        tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("HDRIO_DEBUG", raising=False)
    _break_merge(monkeypatch)
    images = h.ramp_set(tmp_path / "in")
    code = main(["merge", *map(str, images), "-o", str(h.out(tmp_path)), "-q"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "internal error (ZeroDivisionError: division by zero)" in err
    assert "report" in err and "HDRIO_DEBUG=1" in err


def test_hdrio_debug_shows_the_traceback(tmp_path, monkeypatch):
    monkeypatch.setenv("HDRIO_DEBUG", "1")
    _break_merge(monkeypatch)
    images = h.ramp_set(tmp_path / "in")
    with pytest.raises(ZeroDivisionError):
        main(["merge", *map(str, images), "-o", str(h.out(tmp_path)), "-q"])


def test_bad_input_as_a_process_exits_2_with_one_line_and_leaves_nothing(tmp_path):
    images = h.ramp_set(tmp_path / "in")
    output = h.out(tmp_path)
    result = _hdrio("merge", *images, images[0], "-o", output, "-q")
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1 and "given twice" in result.stderr
    assert list(output.parent.iterdir()) == []


def test_no_matplotlib_warning_when_matplotlib_is_absent(tmp_path):
    """colour-science warns on import without matplotlib; hdrio's users see none of it."""
    images = h.ramp_set(tmp_path / "in")
    result = _hdrio("merge", *images, "-o", h.out(tmp_path),
                    code="import sys; sys.modules['matplotlib'] = None")
    assert result.returncode == 0, result.stderr
    # Progress lines only ("[  0.01 s] reading 4 brackets").
    assert all(line.startswith("[") for line in result.stderr.splitlines()), result.stderr
    assert "range:" in result.stdout  # colour-science was reached (the check report)


def test_a_closed_pipe_ends_quietly(tmp_path):
    exr = h.float_image(tmp_path)
    reader, writer = os.pipe()
    os.close(reader)  # nobody will read hdrio's output
    script = "import sys\nfrom hdrio.cli import main\nsys.exit(main())"
    result = subprocess.run([sys.executable, "-c", script, "info", "--full", str(exr)],
                            stdout=writer, stderr=subprocess.PIPE, text=True, timeout=60)
    os.close(writer)
    assert result.returncode == EXIT_BROKEN_PIPE
    assert result.stderr == ""
