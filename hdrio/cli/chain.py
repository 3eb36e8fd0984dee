"""The oiiotool-style chain: ``hdrio INPUTS... --op ARGS... -o FILE ...``, left to right.

Inputs are read onto a stack: bracket files wait for ``--merge``, float images (EXR,
HDR) go straight onto the image stack; operations act on the top image; ``-o`` writes
it and the chain goes on. Every operation is one registered function (see
:func:`operation`): a name, its arguments, a help line with an example, a converter run
while parsing (so a typo fails before any work) and the step itself. Argument parsing and
printing only: the steps call :mod:`hdrio.pipeline` and the core modules.
"""

from __future__ import annotations

import sys
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from hdrio.cli.progress import Progress
from hdrio.errors import HdrioError

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"})
FLOAT_SUFFIXES = frozenset({".exr", ".hdr"})


class ChainError(HdrioError):
    """A step of the chain failed; the message starts with the operation and argument."""


@dataclass(frozen=True)
class Operation:
    """One chain operation: ``--name ARG...`` (``optional`` is one trailing optional ARG)."""

    name: str
    arguments: tuple[str, ...]
    help: str
    example: str
    run: Callable[[Chain, Any], None]
    convert: Callable[[list[str]], Any] = lambda values: values
    optional: str | None = None
    accepts_optional: Callable[[str], bool] = lambda token: False
    per_set: bool = True  # False: global settings, applied once before any step runs


OPERATIONS: dict[str, Operation] = {}


def one_argument(values: list[str]) -> str:
    """The converter of an operation with one argument kept as text."""
    return values[0]


def operation(name: str, *arguments: str, help: str, example: str,
              convert: Callable[[list[str]], Any] | None = None, optional: str | None = None,
              accepts_optional: Callable[[str], bool] | None = None,
              aliases: Sequence[str] = (), per_set: bool = True):
    """Register ``run(chain, value)`` as the operation ``name`` (and ``aliases``).

    ``convert(list_of_argument_strings)`` turns the arguments into ``value`` while the
    command line is parsed; it raises ``ValueError`` or ``KeyError`` with a message that
    :func:`parse` prefixes with the operation and its arguments.
    """

    def register(run: Callable[[Chain, Any], None]) -> Callable[[Chain, Any], None]:
        op = Operation(name, tuple(arguments), help, example, run,
                       convert or (lambda values: values), optional,
                       accepts_optional or (lambda token: False), per_set)
        for key in (name, *aliases):
            OPERATIONS[key] = op
        return run

    return register


@dataclass(frozen=True)
class Step:
    """A parsed step: an operation name (``read`` for an input file) and its value."""

    name: str
    value: Any
    text: str  # as typed, for messages and the dry-run plan


@dataclass
class Image:
    """An image on the stack: float32 ``(H, W, C)`` pixels and what is known about them."""

    pixels: np.ndarray
    attributes: dict[str, object]
    label: str
    display: bool = False  # True after --tonemap: display-referred, sRGB-encoded [0, 1]
    scale: float = 1.0  # factor applied to the merged radiance (--exposure), for the header


@dataclass
class Chain:
    """The state a chain runs with: pending brackets, the image stack, settings."""

    out: TextIO = field(default_factory=lambda: sys.stdout)
    progress: Progress = field(default_factory=lambda: Progress(quiet=True))
    brackets: list[Path] = field(default_factory=list)
    images: list[Image] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)
    fields: dict[str, str] = field(default_factory=dict)  # for -o patterns: {first_stem}
    last_merge: Any = None  # the latest MergeResult, for pictures
    inputs: list[Path] = field(default_factory=list)
    dry_run: bool = False

    def top(self) -> Image:
        if not self.images:
            hint = ("merge the brackets first (--merge)" if self.brackets
                    else "give an input image first")
            raise ChainError(f"no image to work on: {hint}")
        return self.images[-1]

    def say(self, message: str) -> None:
        print(message, file=self.out)

    def note(self, message: str) -> None:
        """A one-line note on stderr (input repaired, say), shown even when quiet."""
        print(f"hdrio: note: {message}", file=sys.stderr)


def _split(argv: Sequence[str]) -> list[tuple[str, list[str]]]:
    """Tokens into ``(operation or 'read', arguments)``, checking argument counts."""
    tokens = list(argv)
    items: list[tuple[str, list[str]]] = []
    position = 0
    while position < len(tokens):
        token = tokens[position]
        position += 1
        if not token.startswith("-") or token == "-" or _is_number(token):
            items.append(("read", [token]))
            continue
        op = OPERATIONS.get(token)
        if op is None:
            raise ChainError(f"{token}: unknown operation; 'hdrio --help' lists them")
        count = len(op.arguments)
        values = tokens[position: position + count]
        if len(values) < count or any(v.startswith("--") for v in values):
            raise ChainError(f"{token}: needs {' '.join(op.arguments)} (e.g. {op.example})")
        position += count
        if op.optional and position < len(tokens) and op.accepts_optional(tokens[position]):
            values.append(tokens[position])
            position += 1
        items.append((token, values))
    return items


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def parse(argv: Sequence[str]) -> list[Step]:
    """Parse a command line into steps; raises :class:`ChainError` naming the culprit."""
    steps = []
    for name, values in _split(argv):
        text = " ".join([name, *values]) if name != "read" else values[0]
        if name == "read":
            steps.append(Step("read", Path(values[0]), text))
            continue
        try:
            value = OPERATIONS[name].convert(values)
        except (ValueError, KeyError) as error:
            message = error.args[0] if error.args else str(error)
            raise ChainError(f"{text}: {message}") from None
        steps.append(Step(OPERATIONS[name].name, value, text))
    return steps


def load_operations() -> None:
    """Import the modules that register operations (each imports this one).

    A new family of operations (colour management, say) adds its module here.
    """
    import importlib

    from hdrio.cli import chain_colour, chain_ops, chain_output, chain_pictures  # noqa: F401

    importlib.import_module("hdrio.cli.chain_batch")  # last: --group's settings end the help


def run_steps(chain: Chain, steps: Sequence[Step]) -> None:
    """Run ``steps`` in order on ``chain``; errors name the step at fault."""
    from hdrio.cli.chain_batch import run_groups
    from hdrio.cli.chain_ops import read_input

    load_operations()
    for index, step in enumerate(steps):
        chain.progress.step(step.text)
        try:
            if step.name == "--group":
                run_groups(chain, step, list(steps[index + 1:]), list(steps))
                return
            if step.name == "read":
                read_input(chain, step.value)
            elif OPERATIONS[step.name].per_set:
                OPERATIONS[step.name].run(chain, step.value)
        except ChainError as error:
            raise ChainError(step_message(step, error)) from None
        except (HdrioError, ValueError, KeyError) as error:
            message = error.args[0] if isinstance(error, KeyError) and error.args else error
            raise ChainError(step_message(step, message)) from None


def step_message(step: Step, message: object) -> str:
    """``step.text: message``, without naming the step's file twice when the message
    already starts with it (``-o x.exr: folder ... does not exist``)."""
    message, value = str(message), str(step.value)
    if step.text.endswith(value) and message.startswith(f"{value}: "):
        head = step.text[: len(step.text) - len(value)].strip()  # "-o", or "" for a read
        return f"{head} {message}" if head else message
    return f"{step.text}: {message}"


def help_text() -> str:
    """``hdrio --help``: usage, every operation with an example, the subcommands."""
    lines = [
        "usage: hdrio INPUT... [OPERATION [ARG...]]... -o OUTPUT [OPERATION...]",
        "       hdrio {merge,info,demo} ...   (hdrio COMMAND --help for each)",
        "",
        "A chain in the manner of oiiotool, run left to right. Bracket files (8/16-bit",
        "JPEG, PNG, TIFF, or camera RAW) wait for --merge; EXR and HDR files are read as",
        "images; a folder stands for the images in it. Operations act on the top image;",
        "-o writes it and the chain goes on.",
        "",
        "example: hdrio a.jpg b.jpg c.jpg --exposures 1/8,1,8 --merge -o out.exr \\",
        "             --tonemap reinhard-local -o preview.jpg",
        "",
        "operations:",
    ]
    seen = set()
    for op in OPERATIONS.values():
        if op.name in seen:
            continue
        seen.add(op.name)
        aliases = [key for key, other in OPERATIONS.items() if other is op and key != op.name]
        usage = " ".join([", ".join([op.name, *aliases]), *op.arguments]
                         + ([f"[{op.optional}]"] if op.optional else []))
        lines.append(f"  {usage}")
        lines.append(textwrap.fill(op.help, 88, initial_indent=" " * 6,
                                   subsequent_indent=" " * 6))
        lines.append(f"      e.g. {op.example}")
    lines += ["", "Errors exit with code 2 and one line naming the operation and argument."]
    return "\n".join(lines)


def main(argv: Sequence[str]) -> int:
    """Run a chain; returns the exit code (2 with one line on stderr for bad input)."""
    load_operations()  # first, so that --help lists operations in the modules' order
    from hdrio.cli.chain_batch import check_batch_options, print_plan
    from hdrio.cli.chain_output import check_outputs

    if not argv or argv[0] in ("-h", "--help"):
        print(help_text(), file=sys.stdout if argv else sys.stderr)
        return 0 if argv else 2
    try:
        steps = parse(argv)
        chain = Chain()
        for step in steps:  # global settings (-v, --threads, --dry-run) first
            if step.name != "read" and not OPERATIONS[step.name].per_set:
                OPERATIONS[step.name].run(chain, step.value)
        check_outputs(steps)
        check_batch_options(steps)
        if chain.dry_run:
            print_plan(chain, steps)
            return 0
        run_steps(chain, steps)
    except HdrioError as error:
        print(f"hdrio: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hdrio: interrupted; outputs written so far are complete", file=sys.stderr)
        return 130
    return 0
