"""The ``hdrio`` command: argument parsing and printing only; the work is in the pipeline.

Exit codes: 0 done; 2 the user's input or options are at fault (one line naming the file
or option); 1 hdrio's own fault (one line asking for a report; ``HDRIO_DEBUG=1`` shows
the traceback instead); 130 interrupted; 141 the reader of the output went away (a
closed pipe, ``hdrio info x.exr | head -1``).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import warnings
from collections.abc import Sequence

from hdrio import __version__
from hdrio.cli import check, export_response
from hdrio.cli.usage import Parser, UsageError
from hdrio.errors import HdrioError
from hdrio.parallel import limit_heap_arenas

# colour-science warns at import when Matplotlib is absent; only its plotting needs it
# (hdrio's --plot-* say so themselves), so it is not the user's business on every run.
warnings.filterwarnings("ignore", message='"Matplotlib" related API features')

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 130, 141
# Must list every subcommand build_parser() adds; anything else is a chain.
SUBCOMMANDS = frozenset({"merge", "info", "demo", "check", "export-response"})


# Commands whose parser and work need no merge machinery (imported only when used).
_LIGHT_COMMANDS = frozenset({"check", "export-response"})


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand; of ``command``'s alone when it is one of
    :data:`_LIGHT_COMMANDS` (``hdrio check`` then never imports the merge)."""
    parser = Parser(
        prog="hdrio",
        description="Merge bracketed exposures into scene-linear OpenEXR, with previews.",
    )
    parser.add_argument("--version", action="version", version=f"hdrio {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    if command not in _LIGHT_COMMANDS:
        from hdrio.cli import commands

        commands.add_merge(sub)
        commands.add_info(sub)
        commands.add_demo(sub)
    check.add_check(sub)
    export_response.add_export_response(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``hdrio``; returns the exit code (see the module's docstring).

    ``hdrio COMMAND ...`` runs a subcommand; anything else is an oiiotool-style chain
    (:mod:`hdrio.cli.chain`). Nothing escapes as a traceback unless ``HDRIO_DEBUG=1``.
    """
    try:
        code = _run(list(sys.argv[1:] if argv is None else argv))
        sys.stdout.flush()  # here, so a closed pipe is caught below, not at exit
        return code
    except BrokenPipeError:
        # Whoever read our output has gone; say nothing more (stdout to /dev/null, so
        # the interpreter's final flush cannot fail again).
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except KeyboardInterrupt:
        print("hdrio: interrupted; outputs written so far are complete", file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError as error:
        if error.filename is None or _debugging():
            return _internal_error(error)
        # The system refused a file (disk full, I/O error): the environment, not hdrio.
        print(f"hdrio: error: {error.filename}: {(error.strerror or str(error)).lower()}",
              file=sys.stderr)
        return EXIT_USAGE
    except Exception as error:  # noqa: BLE001 - the last line of defence
        return _internal_error(error)


def run() -> None:
    """The ``hdrio`` command as installed (the console script, ``python -m hdrio``):
    :func:`main`, then the process ends with its exit code, its output flushed, without
    tearing the interpreter down. The operating system frees its memory and closes its
    files at once, where the interpreter's own teardown, destroying every object and
    numba's compiled kernels one by one, took 0.8-2 s of CPU after the last line was
    printed (2 cores; docs/speed.md). Everything hdrio opens is closed before
    :func:`main` returns: outputs are renamed into place, staged brackets are in an
    unlinked file, process pools and Dask clusters are shut down, compile-ahead
    helpers end with their parent. glibc's heap arenas are held to a few first
    (:func:`hdrio.parallel.limit_heap_arenas`)."""
    limit_heap_arenas()
    code = main()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(code)


def _debugging() -> bool:
    return os.environ.get("HDRIO_DEBUG", "").strip() not in ("", "0")


def _internal_error(error: BaseException) -> int:
    """hdrio's own fault: one line asking for a report (the traceback with HDRIO_DEBUG=1)."""
    if _debugging():
        raise error
    detail = str(error).strip().splitlines()
    print(f"hdrio: internal error ({type(error).__name__}"
          f"{': ' + detail[0] if detail else ''}); this is a bug in hdrio, not a problem "
          f"with your input: please report it to hdrio's issue tracker with the command "
          "line and the traceback HDRIO_DEBUG=1 shows", file=sys.stderr)
    return EXIT_FAILURE


def _run(argv: list[str]) -> int:
    if not argv or argv[0] not in SUBCOMMANDS | {"--version"}:
        from hdrio.cli import chain

        return chain.main(argv)
    parser = build_parser(argv[0])
    try:
        args, extras = parser.parse_known_args(negative_values(argv))
        if extras:
            raise _subparser(parser, argv[0]).unknown(extras)
    except SystemExit as exit_:  # --help, --version
        return int(exit_.code or 0)
    except UsageError as error:
        print(f"{error.prog}: error: {error}", file=sys.stderr)
        return EXIT_USAGE
    try:
        return args.run(args)
    except (HdrioError, ValueError, KeyError) as error:
        message = error.args[0] if isinstance(error, KeyError) and error.args else error
        print(f"hdrio {args.command}: error: {message}", file=sys.stderr)
        return EXIT_USAGE


TAKES_NEGATIVE = ("--exposures",)
"""Options whose value may start with a minus sign (``--exposures -2EV,0,+2EV``)."""


def negative_values(argv: list[str]) -> list[str]:
    """``argv`` with each of :data:`TAKES_NEGATIVE` joined to a following value that starts
    with a minus sign and a digit (``--exposures=-2EV,...``): argparse would take the
    value for an option of its own and say the option has no value."""
    joined: list[str] = []
    position = 0
    while position < len(argv):
        token = argv[position]
        following = argv[position + 1] if position + 1 < len(argv) else ""
        if token in TAKES_NEGATIVE and following[:1] == "-" and following[1:2].isdigit():
            joined.append(f"{token}={following}")
            position += 2
            continue
        joined.append(token)
        position += 1
    return joined


def _subparser(parser: argparse.ArgumentParser, command: str) -> Parser:
    """The parser of ``command`` among ``parser``'s subcommands."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return actions[0].choices[command]


if __name__ == "__main__":
    sys.exit(main())
