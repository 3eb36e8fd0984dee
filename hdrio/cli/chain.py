"""The oiiotool-style chain: ``hdrio INPUTS... --op ARGS... -o FILE ...``, left to right.

Inputs are read onto a stack: bracket files wait for ``--merge``, float images (EXR,
HDR) go straight onto the image stack; operations act on the top image; ``-o`` writes
it and the chain goes on. This module assembles the chain: it imports the operation
modules (each registers its operations in :mod:`hdrio.cli.chain_registry`, which they import
and which imports none of them), checks the whole command line before any work
(:func:`hdrio.cli.chain_registry.validate`) and runs it. Argument parsing and printing only:
the steps call :mod:`hdrio.job.run` and the core modules.
"""

from __future__ import annotations

import sys
import textwrap
from collections.abc import Sequence
from typing import Any

# The operation modules, in the order --help lists them (importing registers them).
from hdrio.cli import (  # noqa: F401  (inputs, merge, image steps)  # noqa: F401
    chain_batch,
    chain_colour,
    chain_merge,
    chain_ops,
    chain_output,
    chain_pictures,
)
from hdrio.cli.chain_merge import PENDING
from hdrio.cli.chain_registry import OPERATIONS, Chain, ChainError, Step, parse, run_steps, validate
from hdrio.cli.progress import Progress
from hdrio.errors import HdrioError


def run_set(steps: list[Step], settings: dict[str, Any], verbose: bool,
            task: Any) -> tuple[bool, str]:
    """One bracket set of ``--group``, in a worker process (this module registers every
    operation on import, so the worker knows them all)."""
    return chain_batch.run_set(steps, settings, verbose, task)


def help_text() -> str:
    """``hdrio --help``: usage, every operation with an example, the subcommands."""
    lines = [
        "usage: hdrio INPUT... [OPERATION [ARG...]]... -o OUTPUT [OPERATION...]",
        "       hdrio {merge,info,demo,check,export-response} ...   (hdrio COMMAND --help)",
        "",
        "A chain in the manner of oiiotool, run left to right. Bracket files (8/16-bit",
        "JPEG, PNG, TIFF, or camera RAW) wait for --merge; EXR and HDR files are read as",
        "images; a folder stands for the images in it. Options of 'hdrio merge' (same",
        "names, same meaning) set up the next --merge; operations act on the top image;",
        "-o writes it and the chain goes on. The whole line is checked before any work.",
        "",
        "example: hdrio a.jpg b.jpg c.jpg --exposures 1/8,1,8 --merge -o out.exr \\",
        "             --tonemap reinhard-local -o preview.jpg",
        "",
        "operations:",
    ]
    seen = set()
    for op in OPERATIONS.values():
        if op.name in seen or op.hidden:
            continue
        seen.add(op.name)
        aliases = [key for key, other in OPERATIONS.items() if other is op and key != op.name]
        usage = " ".join([", ".join([op.name, *aliases]), *op.arguments]
                         + ([f"[{op.optional}]"] if op.optional else []))
        lines.append(f"  {usage}")
        lines.append(textwrap.fill(op.help, 88, initial_indent=" " * 6,
                                   subsequent_indent=" " * 6))
        lines.append(f"      e.g. hdrio {op.example}")
    lines += ["", "Errors exit with code 2 and one line naming the operation and argument."]
    return "\n".join(lines)


def _global_settings(chain: Chain, steps: Sequence[Step]) -> None:
    """Apply the settings that hold for the whole line (-v, --threads, --colorconfig...)."""
    for step in steps:
        op = OPERATIONS[step.name]
        if not op.per_set:
            op.run(chain, step.value)


def check_chain(steps: Sequence[Step], settings: dict[str, Any]) -> None:
    """Everything a run would find wrong with ``steps``, found before any work."""
    probe = Chain(settings={key: value for key, value in settings.items()
                            if key not in ("report",)})
    validate(probe, steps)
    pending = probe.settings.get(PENDING)
    if pending:
        raise ChainError(f"{', '.join(dict.fromkeys(pending))}: no --merge follows; merge "
                         "options go before the --merge they set up")
    if probe.brackets and not any(step.name == "--group" for step in steps):
        raise ChainError(f"{len(probe.brackets)} bracket files but no --merge after them "
                         "(e.g. hdrio a.jpg b.jpg c.jpg --merge -o out.exr)")
    if not any(step.name in ("-o", "--info", "--stats") or step.name.startswith("--plot")
               or step.name == "--contact-sheet" for step in steps):
        raise ChainError("nothing would be written or printed: add -o FILE")


def main(argv: Sequence[str]) -> int:
    """Run a chain; returns the exit code (2 with one line on stderr for bad input)."""
    if not argv or argv[0] in ("-h", "--help"):
        print(help_text(), file=sys.stdout if argv else sys.stderr)
        return 0 if argv else 2
    try:
        steps = parse(argv)
        chain = Chain(progress=Progress(quiet=True), run_set=run_set)
        _global_settings(chain, steps)
        chain_batch.check_batch_options(steps)
        check_chain(steps, chain.settings)
        if chain.dry_run:
            chain_batch.print_plan(chain, steps)
            return 0
        run_steps(chain, steps)
    except HdrioError as error:
        print(f"hdrio: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hdrio: interrupted; outputs written so far are complete", file=sys.stderr)
        return 130
    return 0
