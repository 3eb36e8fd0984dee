"""Argument errors in one line: the subcommand's usage, and the nearest option name.

argparse prints a subcommand's whole usage (20 lines for ``hdrio merge``) before the
error, reports an option it does not know against the top-level parser (``usage: hdrio
[-h] [--version] COMMAND ...``) and takes ``--merg`` for ``--merge``. :class:`Parser`
does none of that: an error raises :class:`UsageError`, which :mod:`hdrio.cli` prints as
one line naming the subcommand, the option at fault, the nearest known spelling and a
one-line usage; an option is spelled out in full, as in the chain.
"""

from __future__ import annotations

import argparse
import difflib
import re
from collections.abc import Iterable

from hdrio.errors import HdrioError


class UsageError(HdrioError):
    """An argument error of ``prog`` (``hdrio merge``): the message, then the usage."""

    def __init__(self, prog: str, message: str, usage: str) -> None:
        self.prog = prog
        super().__init__(f"{message}; usage: {usage} ({prog} --help)")


def nearest(word: str, known: Iterable[str]) -> str:
    """``" (did you mean --merge?)"`` for the known spelling nearest ``word``, or ``""``."""
    name = word.split("=", 1)[0]
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are :class:`UsageError` (one line, with the
    nearest option) and which takes no abbreviated option."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def option_names(self) -> list[str]:
        """Every option spelling this parser knows (``--merge``, ``-o``...)."""
        return [name for action in self._actions for name in action.option_strings]

    def one_line_usage(self) -> str:
        """``hdrio merge [OPTIONS] -o OUTPUT IMAGES...``: the required arguments only."""
        words = [self.prog]
        if any(not action.required for action in self._actions if action.option_strings):
            words.append("[OPTIONS]")
        for action in self._actions:
            if action.option_strings and action.required:
                words += [action.option_strings[0], action.metavar or action.dest.upper()]
            elif not action.option_strings and not isinstance(
                    action, argparse._SubParsersAction):
                name = (action.metavar or action.dest).upper()
                words.append(f"{name}..." if action.nargs in ("+", "*") else name)
        return " ".join(words)

    def error(self, message: str):  # noqa: D102 - argparse's hook
        raise UsageError(self.prog, self._with_suggestion(message), self.one_line_usage())

    def unknown(self, extras: list[str]) -> UsageError:
        """The error for arguments no option took (``parse_known_args``' leftovers)."""
        options = [word for word in extras if word.startswith("-")]
        if options:
            word = options[0]
            message = f"{word}: unknown option{nearest(word, self.option_names())}"
        else:
            message = f"unexpected argument {extras[0]!r}"
        return UsageError(self.prog, message, self.one_line_usage())

    def _with_suggestion(self, message: str) -> str:
        """argparse's message, with the nearest choice where a value was refused."""
        match = re.match(r"argument (\S+): invalid choice: '([^']*)' \(choose from (.*)\)$",
                         message)
        if match:
            option, value, choices = match.groups()
            known = [c.strip(" '\"") for c in choices.split(",")]
            return (f"{option.split('/')[-1]} {value}: not one of {', '.join(known)}"
                    f"{nearest(value, known)}")
        match = re.match(r"the following arguments are required: (.*)$", message)
        if match:
            return f"missing {match.group(1)}"
        match = re.match(r"argument (\S+): (.*)$", message)
        if match:
            return f"{match.group(1).split('/')[-1]}: {match.group(2)}"
        return message
