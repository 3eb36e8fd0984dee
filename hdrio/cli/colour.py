"""The ``check`` and ``export-response`` commands."""

from __future__ import annotations

import argparse
from pathlib import Path

from hdrio.cms.calibration import Region
from hdrio.errors import HdrioError


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

    faulty = []
    for index, path in enumerate(args.files):
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


def add_export_response(sub) -> None:
    parser = sub.add_parser(
        "export-response",
        help="export a merge's camera response as a 1D LUT plus an OCIO config",
        description="Write the response recorded in an hdrio EXR as a 1D LUT (SPI1D or "
                    "CLF) and an OCIO config (the project's, plus the camera's colour "
                    "space), so oiiotool, Nuke or Blender linearise that camera's images "
                    "as hdrio does.",
        epilog="example: hdrio export-response room.exr -o room_ocio --name mycam; "
               "oiiotool --colorconfig room_ocio/config.ocio in.png --colorconvert mycam "
               "lin_rec709 -o linear.exr")
    parser.add_argument("exr", help="an EXR written by hdrio merge")
    parser.add_argument("-o", "--output-dir", required=True,
                        help="folder for LUT and config (made if missing)")
    parser.add_argument("--name", default="camera", help="colour space name (default %(default)s)")
    parser.add_argument("--format", choices=["spi1d", "clf"], default="spi1d",
                        help="LUT format (default %(default)s)")
    parser.set_defaults(run=run_export_response)


def run_export_response(args: argparse.Namespace) -> int:
    from hdrio.cms.lut import export_response
    from hdrio.response.stored import read_response

    read_response(args.exr)  # an EXR without a response fails before any folder is made
    try:
        Path(args.output_dir).mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise HdrioError(f"{args.output_dir}: cannot make the folder ({error.strerror})"
                         ) from None
    written = export_response(args.exr, args.output_dir, name=args.name, lut_format=args.format)
    for path in written:
        print(f"wrote: {path}")
    return 0
