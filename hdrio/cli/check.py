"""The ``check`` command: what a compositor should know about an EXR before trusting it
(the work is :mod:`hdrio.cms.checks`'s)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hdrio.cms.calibration import Region


def _region(text: str) -> Region:
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4:
        raise argparse.ArgumentTypeError(f"expected a region x,y,width,height, got {text!r}")
    return values  # type: ignore[return-value]


def add_check(sub) -> None:
    parser = sub.add_parser(
        "check", help="colour and range checks of an EXR (colour-science)",
        description="Dynamic range, negative and non-finite pixels, out-of-gamut fraction, "
                    "luminance from the file's own chromaticities, clipping per bracket "
                    "(from hdrio's header), and ColorChecker Delta E 2000 for a chart region.",
        epilog="example: hdrio check room.exr --chart 120,200,180,120")
    parser.add_argument("files", nargs="+", help="OpenEXR files")
    parser.add_argument("--chart", type=_region, metavar="X,Y,W,H",
                        help="region of a ColorChecker 24 (4 rows of 6, dark row at the "
                             "bottom) for Delta E 2000 against its reference values")
    parser.add_argument("--gamut", metavar="NAME",
                        help="colour-science space for the out-of-gamut fraction (default: "
                             "the file's own primaries)")
    parser.set_defaults(run=run_check)


def run_check(args: argparse.Namespace) -> int:
    """Print each file's report; exit 2 (one line on stderr for each) when a file holds
    NaN or infinite values, which a compositor's blur or grade spreads."""
    import sys

    from hdrio.cms.checks import check_exr, format_report
    from hdrio.io.paths import expand_patterns

    faulty = []
    for index, path in enumerate(expand_patterns(args.files)):
        if index:
            print()
        report = check_exr(Path(path), chart=args.chart, gamut=args.gamut)
        print(format_report(report))
        if report.non_finite:
            faulty.append(f"{path}: {report.non_finite} of {report.pixels} pixels hold NaN "
                          "or infinite values (hdrio reads such a file with them replaced, "
                          "and says so)")
    for line in faulty:
        print(f"hdrio check: error: {line}", file=sys.stderr)
    return 2 if faulty else 0
