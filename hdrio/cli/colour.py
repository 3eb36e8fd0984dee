"""Colour options of ``hdrio merge`` and the ``check`` and ``export-response`` commands."""

from __future__ import annotations

import argparse
from pathlib import Path

from hdrio.cms.calibration import DEFAULT_K, Calibration, Region
from hdrio.cms.spaces import DEFAULT_WORKING_SPACE


def _region(text: str) -> Region:
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4:
        raise argparse.ArgumentTypeError(f"expected a region x,y,width,height, got {text!r}")
    return values  # type: ignore[return-value]


def add_colour_options(parser: argparse.ArgumentParser) -> None:
    """``--colorspace``, ``--ocio-config``, encoding, calibration and white balance."""
    group = parser.add_argument_group("colour (see docs/colour.md)")
    group.add_argument("--colorspace", default=DEFAULT_WORKING_SPACE, metavar="NAME",
                       help="OpenColorIO scene-linear space of the EXR, e.g. ACEScg, "
                            "ACES2065-1 (default %(default)s: linear Rec.709)")
    group.add_argument("--ocio-config", metavar="CONFIG",
                       help="OCIO config file or ocio:// URI (default: $OCIO, else "
                            "ocio://cg-config-latest)")
    group.add_argument("--input-encoding", metavar="NAME",
                       help="encoding of the brackets when their ICC profile and EXIF do "
                            "not say: sRGB (default), 'Adobe RGB (1998)', 'Display P3'")
    group.add_argument("--white-balance", type=_region, metavar="X,Y,W,H",
                       help="make this neutral region grey (default: keep the camera's)")
    group.add_argument("--absolute", choices=["exif", "luminance", "illuminance"],
                       help="write cd/m^2: from EXIF (t, N, ISO and --meter-k), or from a "
                            "--reference-region of known --reference-luminance, or a grey "
                            "card of --reference-reflectance under --reference-illuminance")
    group.add_argument("--meter-k", type=float, default=DEFAULT_K, metavar="K",
                       help="reflected-light meter calibration constant (default %(default)g)")
    group.add_argument("--reference-region", type=_region, metavar="X,Y,W,H")
    group.add_argument("--reference-luminance", type=float, metavar="CD_M2")
    group.add_argument("--reference-illuminance", type=float, metavar="LUX")
    group.add_argument("--reference-reflectance", type=float, default=0.18, metavar="R",
                       help="grey card reflectance (default %(default)g)")
    group.add_argument("--ocio-display", metavar="DISPLAY",
                       help="render the preview through this OCIO display (e.g. 'sRGB - "
                            "Display') instead of --tonemap")
    group.add_argument("--ocio-view", metavar="VIEW",
                       help="view of --ocio-display (default: the display's first view, "
                            "e.g. 'ACES 2.0 - SDR 100 nits (Rec.709)')")


def display_view_from(args: argparse.Namespace) -> tuple[str, str] | None:
    """``(display, view)`` for the preview, checked against the config, or ``None``."""
    from hdrio.cms.spaces import config_source, load_config
    from hdrio.errors import HdrioError

    if not args.ocio_display:
        if args.ocio_view:
            raise HdrioError("--ocio-view needs --ocio-display")
        return None
    config = load_config(args.ocio_config)
    displays = list(config.getDisplays())
    if args.ocio_display not in displays:
        raise HdrioError(f"{config_source(args.ocio_config)}: no display "
                         f"{args.ocio_display!r}; choose from {', '.join(displays)}")
    views = list(config.getViews(args.ocio_display))
    view = args.ocio_view or config.getDefaultView(args.ocio_display)
    if view not in views:
        raise HdrioError(f"display {args.ocio_display!r} has no view {view!r}; choose from "
                         f"{', '.join(views)}")
    return args.ocio_display, view


def colour_fields(args: argparse.Namespace) -> dict[str, object]:
    """The :class:`~hdrio.pipeline.MergeOptions` colour fields, validated now."""
    from hdrio.cms.spaces import require_scene_linear

    calibration = None
    if args.absolute:
        calibration = Calibration(
            method=args.absolute, K=args.meter_k, region=args.reference_region,
            luminance=args.reference_luminance, illuminance=args.reference_illuminance,
            reflectance=args.reference_reflectance)
    if args.input_encoding:
        from hdrio.cms.encoding import encoding

        encoding(args.input_encoding)
    return {
        "output_space": require_scene_linear(args.colorspace, args.ocio_config),
        "ocio_config": args.ocio_config,
        "input_encoding": args.input_encoding,
        "white_balance": args.white_balance,
        "calibration": calibration,
    }


def add_check(sub) -> None:
    parser = sub.add_parser(
        "check", help="colour and range checks of an EXR (colour-science)",
        description="Dynamic range, negative and non-finite pixels, out-of-gamut fraction, "
                    "luminance from the file's own chromaticities, clipping per bracket "
                    "(from hdrio's header), and ColorChecker Delta E 2000 for a chart region.",
        epilog="example: hdrio check room.exr --chart 120,300,180,120")
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


def add_export_response(sub) -> None:
    parser = sub.add_parser(
        "export-response",
        help="export a merge's camera response as a 1D LUT plus an OCIO config",
        description="Write the response recorded in an hdrio EXR as a 1D LUT (SPI1D or "
                    "CLF) and an OCIO config (the project's, plus the camera's colour "
                    "space), so oiiotool, Nuke or Blender linearise that camera's images "
                    "as hdrio does.",
        epilog="example: hdrio export-response memorial.exr -o memorial_ocio --name "
               "memorial; oiiotool --colorconfig memorial_ocio/config.ocio in.png "
               "--colorconvert memorial lin_rec709 -o linear.exr")
    parser.add_argument("exr", help="an EXR written by hdrio merge")
    parser.add_argument("-o", "--output-dir", required=True, help="folder for LUT and config")
    parser.add_argument("--name", default="camera", help="colour space name (default %(default)s)")
    parser.add_argument("--format", choices=["spi1d", "clf"], default="spi1d",
                        help="LUT format (default %(default)s)")
    parser.set_defaults(run=run_export_response)


def run_export_response(args: argparse.Namespace) -> int:
    from hdrio.cms.lut import export_response

    written = export_response(args.exr, args.output_dir, name=args.name, lut_format=args.format)
    for path in written:
        print(f"wrote: {path}")
    return 0
