"""The chain's operation registry and state: what every operation module imports.

An operation is one registered function (see :func:`operation`): a name, its
arguments, a help line with an example, a converter run while parsing (so a typo fails
before any work) and the step itself. Operation modules (``chain_*.py``) import this
module and never :mod:`hdrio.cli.chain`, which imports them all and runs the chain:
imports go one way, with no circle.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from hdrio.cli.progress import Progress
from hdrio.errors import HdrioError
from hdrio.io.paths import expand_patterns

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"})
FLOAT_SUFFIXES = frozenset({".exr", ".hdr"})


class ChainError(HdrioError):
    """A step of the chain failed; the message starts with the operation and argument."""


@dataclass(frozen=True)
class Operation:
    """One chain operation: ``--name ARG...`` (``optional`` is one trailing optional ARG).

    ``check(chain, value)``, when given, is run for each step by :func:`validate` before
    any work: it checks what the converter alone cannot (a colour space against the
    config, a setting that needs a later ``--merge``) and records settings on ``chain``
    as the step would. ``rest``: the operation takes the rest of the chain (``--group``):
    ``run(chain, value, rest_of_steps, all_steps)``.
    """

    name: str
    arguments: tuple[str, ...]
    help: str
    example: str
    run: Callable[..., None]
    convert: Callable[[list[str]], Any] = lambda values: values
    optional: str | None = None
    accepts_optional: Callable[[str], bool] = lambda token: False
    per_set: bool = True  # False: global settings, applied once before any step runs
    check: Callable[[Chain, Any], None] | None = None
    rest: bool = False
    hidden: bool = False  # not an option the user types ("read": a positional input)


OPERATIONS: dict[str, Operation] = {}


def one_argument(values: list[str]) -> str:
    """The converter of an operation with one argument kept as text."""
    return values[0]


def operation(name: str, *arguments: str, help: str, example: str,
              convert: Callable[[list[str]], Any] | None = None, optional: str | None = None,
              accepts_optional: Callable[[str], bool] | None = None,
              aliases: Sequence[str] = (), per_set: bool = True,
              check: Callable[[Chain, Any], None] | None = None, rest: bool = False,
              hidden: bool = False):
    """Register ``run(chain, value)`` as the operation ``name`` (and ``aliases``).

    ``convert(list_of_argument_strings)`` turns the arguments into ``value`` while the
    command line is parsed; it raises ``ValueError`` or ``KeyError`` with a message that
    :func:`parse` prefixes with the operation and its arguments.
    """

    def register(run: Callable[..., None]) -> Callable[..., None]:
        op = Operation(name, tuple(arguments), help, example, run,
                       convert or (lambda values: values), optional,
                       accepts_optional or (lambda token: False), per_set, check, rest,
                       hidden)
        for key in (name, *aliases):
            if key in OPERATIONS and OPERATIONS[key].name != name:
                raise AssertionError(f"{key} is registered twice")
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
    statistics: Any = None  # the merge's MergeResult while the pixels are still its own
    alpha: np.ndarray | None = None  # (H, W, 1) alpha of an input image, carried along
    layers: dict[str, np.ndarray] = field(default_factory=dict)  # e.g. the merge's
    # "uncertainty": written beside the pixels, resized with them
    channels: dict[str, np.ndarray] = field(default_factory=dict)  # an input's other
    # channels by name ("Z", "motion.Y"...), (H, W, 1): carried along, resized, written
    window: Any = None  # an input's place in its frame (hdrio.io.write.Window), or None
    pixel_type: str = "half"  # what -o writes without -d: an input's own (float stays float)

    def attribute(self, name: str, default: object = None) -> object:
        """The header attribute ``name`` as a plain value (a foreign file's are typed)."""
        value = self.attributes.get(name, default)
        return getattr(value, "value", value)


@dataclass
class Chain:
    """The state a chain runs with: pending brackets, the image stack, settings.

    ``checking`` is true while :func:`validate` walks the steps (nothing is read or
    written then); ``run_set`` is the function ``--group`` runs in each worker process
    (set by :mod:`hdrio.cli.chain`, so that the batch module need not import it).
    """

    out: TextIO = field(default_factory=lambda: sys.stdout)
    progress: Progress = field(default_factory=lambda: Progress(quiet=True))
    brackets: list[Path] = field(default_factory=list)
    images: list[Image] = field(default_factory=list)
    settings: dict[str, Any] = field(default_factory=dict)
    fields: dict[str, str] = field(default_factory=dict)  # for -o patterns: {first_stem}
    last_merge: Any = None  # the latest MergeResult, for pictures
    inputs: list[Path] = field(default_factory=list)
    dry_run: bool = False
    checking: bool = False
    run_set: Callable[..., tuple[bool, str]] | None = None

    def top(self) -> Image:
        """The image operations act on; raises :class:`ChainError` when there is none."""
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


# Options of 'hdrio merge' that a chain spells otherwise.
_MERGE_ONLY = {
    "--preview": " (in a chain, tone-map and write it: --tonemap reinhard-global -o "
                 "preview.jpg)",
    "--output": " (in a chain: -o FILE)",
    "--data-type": " (in a chain: -d TYPE)",
    "--quiet": " (a chain is quiet unless -v is given)",
    "-q": " (a chain is quiet unless -v is given)",
}


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
        if op is None or op.hidden:
            from hdrio.cli.usage import nearest

            known = [name for name, other in OPERATIONS.items() if not other.hidden]
            hint = _MERGE_ONLY.get(token.split("=", 1)[0]) or nearest(token, known)
            raise ChainError(f"{token}: unknown operation{hint}; 'hdrio --help' lists them")
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
        if name == "read":
            steps.extend(Step("read", Path(path), str(path))
                         for path in expand_patterns(values[:1]))
            continue
        text = " ".join([name, *values])
        try:
            value = OPERATIONS[name].convert(values)
        except (ValueError, KeyError) as error:
            message = error.args[0] if error.args else str(error)
            raise ChainError(f"{text}: {message}") from None
        steps.append(Step(OPERATIONS[name].name, value, text))
    return steps


def _culprit(step: Step, error: Exception) -> ChainError:
    """``step.text: message``, without naming the step's file twice when the message
    already starts with it (``-o x.exr: folder ... does not exist``)."""
    message = str(error.args[0] if isinstance(error, KeyError) and error.args else error)
    value = str(step.value)
    if step.text.endswith(value) and message.startswith(f"{value}: "):
        head = step.text[: len(step.text) - len(value)].strip()  # "-o", or "" for a read
        return ChainError(f"{head} {message}" if head else message)
    if step.name == "read" and message.startswith(step.text):
        return ChainError(message)  # already names the file
    return ChainError(f"{step.text}: {message}")


def run_steps(chain: Chain, steps: Sequence[Step]) -> None:
    """Run ``steps`` in order on ``chain``; errors name the step at fault."""
    for index, step in enumerate(steps):
        chain.progress.step(step.text)
        op = OPERATIONS[step.name]
        try:
            if op.rest:
                op.run(chain, step.value, list(steps[index + 1:]), list(steps))
                return
            if op.per_set:
                op.run(chain, step.value)
        except (HdrioError, ValueError, KeyError) as error:
            raise _culprit(step, error) from None


def validate(chain: Chain, steps: Sequence[Step]) -> None:
    """Check every step before any work: names, values, inputs, outputs, order.

    Walks the chain as a run would, calling each operation's ``check`` (which reads no
    pixels and writes nothing); raises :class:`ChainError` naming the step at fault.
    ``chain`` should be a throw-away copy: checks record settings on it.
    """
    chain.checking = True
    for step in steps:
        op = OPERATIONS[step.name]
        if op.check is None:
            continue
        try:
            op.check(chain, step.value)
        except (HdrioError, ValueError, KeyError) as error:
            raise _culprit(step, error) from None
