"""Errors that hdrio raises on purpose, each carrying a message fit for a user."""

from __future__ import annotations

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
