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
    from hdrio.cms.checks import check_exr, format_report

    for index, path in enumerate(args.files):
        if index:
            print()
        print(format_report(check_exr(Path(path), chart=args.chart, gamut=args.gamut)))
    return 0
