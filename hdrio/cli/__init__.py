"""The ``hdrio`` command: argument parsing and printing only; the work is in the pipeline."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence

from hdrio import __version__
from hdrio.cli import colour, commands
from hdrio.errors import HdrioError

# colour-science warns at import when Matplotlib is absent; only its plotting needs it
# (hdrio's --plot-* say so themselves), so it is not the user's business on every run.
warnings.filterwarnings("ignore", message='"Matplotlib" related API features')

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
# Must list every subcommand build_parser() adds; anything else is a chain.
SUBCOMMANDS = frozenset({"merge", "info", "demo", "check", "export-response"})


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hdrio",
        description="Merge bracketed exposures into scene-linear OpenEXR, with previews.",
    )
    parser.add_argument("--version", action="version", version=f"hdrio {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands.add_merge(sub)
    commands.add_info(sub)
    commands.add_demo(sub)
    colour.add_check(sub)
    colour.add_export_response(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``hdrio``; returns the exit code (2 for bad input, with one line on stderr).

    ``hdrio COMMAND ...`` runs a subcommand; anything else is an oiiotool-style chain
    (:mod:`hdrio.cli.chain`).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in SUBCOMMANDS | {"--version"}:
        from hdrio.cli import chain

        return chain.main(argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    try:
        return args.run(args)
    except (HdrioError, ValueError, KeyError) as error:
        message = error.args[0] if isinstance(error, KeyError) and error.args else error
        print(f"hdrio {args.command}: error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("hdrio: interrupted; no output written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
