"""Errors that hdrio raises on purpose, each carrying a message fit for a user."""

from __future__ import annotations

from collections.abc import Callable
from os import PathLike


class HdrioError(Exception):
    """Base class: a problem hdrio diagnosed and can explain in one line."""


class InputError(HdrioError):
    """An input file (or a set of them) cannot be used; names the file and the problem."""

    def __init__(self, path: str | PathLike[str], problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class ResponseSolveError(HdrioError):
    """The samples do not determine a camera response (say why and what to do)."""


class OutputError(HdrioError):
    """An output cannot be written (the message names the file and the reason)."""


def library_message(get: Callable[[], str]) -> str:
    """The first line of a library's error message (``oiio.geterror``, say), for ours.

    A corrupt file can put bytes that are not UTF-8 into the message; then the message
    cannot be shown and says so rather than failing.
    """
    try:
        text = get()
    except UnicodeDecodeError:
        return "the library's message about it is not readable text"
    lines = [line.strip() for line in str(text).splitlines() if line.strip()]
    return lines[0] if lines else ""
