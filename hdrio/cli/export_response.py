"""The ``export-response`` command: a merge's camera response as a 1D LUT plus an OCIO
config (the work is :mod:`hdrio.cms.lut`'s)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hdrio.errors import HdrioError


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
    from hdrio.radiometry.saved_response import read_response

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
