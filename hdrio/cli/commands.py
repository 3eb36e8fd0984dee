"""The subcommands ``merge``, ``info`` and ``demo``: options in, a summary out."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from hdrio.align import ALIGN_MODES, DEGHOST_MODES
from hdrio.cli.colour import add_colour_options, colour_fields, display_view_from
from hdrio.cli.progress import Progress
from hdrio.errors import HdrioError
from hdrio.merge.debevec1997 import MERGE_METHODS, SATURATION_POLICIES
from hdrio.merge.weighting import WEIGHTING_METHODS
from hdrio.pipeline import MergeOptions, MergeResult, merge_files
from hdrio.response import RESPONSE_METHODS, SAMPLING_METHODS
from hdrio.skips import SKIPS
from hdrio.tonemap import TONEMAP_METHODS

_WRITABLE = {".exr"}
_PREVIEW = {".jpg", ".jpeg", ".png", ".tif", ".tiff"}


def _colour(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}") from None


def _add_merge_options(parser: argparse.ArgumentParser) -> None:
    defaults = MergeOptions()
    group = parser.add_argument_group("response and merge")
    group.add_argument("--response", default=defaults.response, metavar="METHOD",
                       help=f"response recovery: {', '.join(RESPONSE_METHODS.names())}")
    group.add_argument("--lambda", dest="smoothing", type=float, default=defaults.smoothing,
                       help="smoothness weight lambda (default %(default)g)")
    group.add_argument("--samples", type=int, default=None,
                       help="pixels sampled for the solve (default: 1000; 'tutorial' "
                            "sampling computes its own)")
    group.add_argument("--sampling", default=defaults.sampling,
                       help=f"sample selection: {', '.join(SAMPLING_METHODS.names())} "
                            "(default %(default)s)")
    group.add_argument("--weighting", default=defaults.weighting,
                       help=f"weighting function: {', '.join(WEIGHTING_METHODS.names())} "
                            "(default %(default)s)")
    group.add_argument("--merge", default=defaults.merge, metavar="DOMAIN",
                       help=f"merge domain: {', '.join(MERGE_METHODS.names())} "
                            "(default %(default)s)")
    group.add_argument("--saturation", default=defaults.saturation,
                       choices=SATURATION_POLICIES,
                       help="a code at the top of the range drops that channel ('channel') "
                            "or the whole pixel ('pixel', the tutorial's policy) from its "
                            "bracket and every longer one (default %(default)s)")
    group.add_argument("--exclude-color", type=_colour, default=None, metavar="R,G,B",
                       help="never sample pixels of this code value in any bracket "
                            "(e.g. 0,0,255 for registration borders)")
    group.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    group.add_argument("--response-from", metavar="EXR", default=None,
                       help="use the camera response saved in an EXR written by hdrio "
                            "instead of solving (skips the solve)")
    group.add_argument("--align", default=defaults.align, choices=ALIGN_MODES,
                       help="register the brackets to the best-exposed one: auto (measure; "
                            "warp only if some bracket moved more than 0.1 px), off, or a "
                            "model to warp with (default %(default)s; docs/motion.md)")
    group.add_argument("--deghost", default=defaults.deghost, choices=DEGHOST_MODES,
                       help="drop observations that disagree with the reference bracket "
                            "(moving people, leaves): auto or off (default %(default)s)")
    group.add_argument("--motion-layer", action="store_true",
                       help="also write the deghosting mask as the EXR channel motion.Y "
                            "(1: some bracket dropped for motion)")
    group.add_argument("--no-skip", action="append", default=[], metavar="NAME",
                       choices=[*SKIPS, "all"],
                       help="turn off one of the work skips (repeatable): "
                            f"{', '.join(SKIPS)}, or all (see docs/speed.md)")


def options_from(args: argparse.Namespace) -> MergeOptions:
    # Resolve names now, so a typo fails before any image is read.
    return MergeOptions(
        response=RESPONSE_METHODS.canonical(args.response), smoothing=args.smoothing,
        weighting=WEIGHTING_METHODS.canonical(args.weighting),
        sampling=SAMPLING_METHODS.canonical(args.sampling), samples=args.samples,
        merge=MERGE_METHODS.canonical(args.merge), exclude_colour=args.exclude_color,
        seed=args.seed, saturation=args.saturation, response_from=args.response_from,
        no_skip=tuple(SKIPS) if "all" in args.no_skip else tuple(args.no_skip),
        align=args.align, deghost=args.deghost, motion_layer=args.motion_layer,
        **colour_fields(args),
    )


def add_merge(sub) -> None:
    parser = sub.add_parser(
        "merge", help="merge brackets into a scene-linear EXR",
        description="Merge bracketed exposures into one scene-linear OpenEXR.",
        epilog="example: hdrio merge church_*.png --exposures-from exposures.csv "
               "-o church.exr --preview church.jpg",
    )
    parser.add_argument("images", nargs="+", help="bracketed 8- or 16-bit images")
    parser.add_argument("-o", "--output", required=True, help="output OpenEXR file")
    parser.add_argument("--preview", help="also write a tone-mapped preview (jpg, png, tif)")
    parser.add_argument("--tonemap", default="reinhard-global",
                        help=f"preview operator: {', '.join(TONEMAP_METHODS.names())} "
                             "(default %(default)s)")
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--exposures", help="exposure times in seconds, in image order, "
                                            "comma-separated: 1/8,1,8")
    source.add_argument("--exposures-from", metavar="FILE",
                        help="sidecar list: CSV (file,exposure_time_s) or OpenCV list.txt")
    parser.add_argument("-d", "--data-type", choices=["half", "float"], default="half",
                        help="EXR pixel type (default %(default)s)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    _add_merge_options(parser)
    add_colour_options(parser)
    parser.set_defaults(run=run_merge)


def _check_outputs(output: Path, preview: Path | None, inputs: list[str]) -> None:
    """Refuse bad output paths before any work, so failures never leave partial files."""
    for path, allowed in ((output, _WRITABLE), (preview, _PREVIEW)):
        if path is None:
            continue
        if path.suffix.lower() not in allowed:
            raise HdrioError(f"{path}: unsupported output type; use {', '.join(sorted(allowed))}")
        if path.is_dir():
            raise HdrioError(f"{path}: is a folder, not a file name")
        if not path.parent.is_dir():
            raise HdrioError(f"{path}: folder {path.parent} does not exist")
        if any(Path(i).resolve() == path.resolve() for i in inputs):
            raise HdrioError(f"{path}: output would overwrite an input")


def run_merge(args: argparse.Namespace) -> int:
    output = Path(args.output)
    preview = Path(args.preview) if args.preview else None
    _check_outputs(output, preview, args.images)
    TONEMAP_METHODS.canonical(args.tonemap)
    options = options_from(args)
    display_view = display_view_from(args)
    progress = Progress(quiet=args.quiet)
    result = merge_files(
        args.images, output, preview=preview, tonemap=args.tonemap,
        exposures=args.exposures.split(",") if args.exposures else None,
        exposures_from=args.exposures_from, options=options, pixel_type=args.data_type,
        progress=progress.step, read_progress=progress.bar,
        display_view=display_view,
    )
    label = " / ".join(display_view) if display_view else args.tonemap
    print(summary(result, output, preview, label, args.data_type))
    from hdrio.cms.checks import check_exr, format_report

    print(format_report(check_exr(output)))  # the written file, as a reader will see it
    return 0


def _seconds(t: float) -> str:
    return f"1/{1 / t:.4g} s" if t < 1 else f"{t:.4g} s"


def summary(result: MergeResult, output: Path, preview: Path | None, tonemap: str,
            data_type: str) -> str:
    stack, stats, times = result.stack, result.statistics, result.timings
    height, width, channels = stack.shape
    bits = 8 if stack.code_max == 255 else 16
    full, robust = result.dynamic_range_stops
    params = result.response.parameters
    lines = [
        f"brackets:  {stack.count} x {width}x{height} ({channels} ch, {bits}-bit), "
        f"{_seconds(stack.exposures[0])} .. {_seconds(stack.exposures[-1])} "
        f"(exposures from {stack.exposure_sources[0]}), read in {times['read']:.2f} s",
        f"response:  {result.response.method}, lambda {params.get('smoothing', 0):g}, "
        f"{params['weighting']} weighting, {params['samples']} samples ({params['sampling']}),"
        f" {times['response']:.2f} s",
        f"merge:     {result.options.merge} domain, {times['merge']:.2f} s; clipped in every "
        f"bracket {100 * stats.clipped_everywhere / stats.pixels:.2f} %, black in every "
        f"bracket {100 * stats.black_everywhere / stats.pixels:.2f} %",
        *motion_lines(result),
        *[f"skipped:   {line}" for line in result.skipped.lines(channels)],
        f"range:     {full:.1f} stops (0.1-99.9 percentile: {robust:.1f} stops)",
        f"wrote:     {output} ({data_type}, zip) in {times['write']:.2f} s"
        + ("" if result.exposure_scale == 1.0 else
           f"; scaled by {result.exposure_scale:g} to fit half floats"),
    ]
    if preview is not None:
        lines.append(f"preview:   {preview} ({tonemap}) in {times['preview']:.2f} s")
    return "\n".join(lines)


def motion_lines(result: MergeResult) -> list[str]:
    """The summary's ``align:`` and ``deghost:`` lines."""
    motion, lines = result.motion, []
    if motion.alignment is not None:
        files = tuple(Path(name).name for name in result.stack.files)
        said = "warped" if motion.warped else "not warped"
        lines.append(f"align:     {motion.alignment.model} to "
                     f"{files[motion.alignment.reference]}, {said}, "
                     f"{result.timings.get('align', 0):.2f} s"
                     + (f"; {100 * motion.uncovered:.1f} % of pixels not covered by every "
                        "bracket" if motion.uncovered else ""))
        lines += [f"           {line}" for line in motion.alignment.describe(files)]
    if motion.deghosting is not None:
        lines.append(f"deghost:   {100 * motion.deghosting.fraction:.2f} % of pixels had a "
                     f"bracket dropped for motion, {result.timings.get('deghost', 0):.2f} s")
    return lines


def add_info(sub) -> None:
    parser = sub.add_parser("info", help="print an EXR header, hdrio's attributes included",
                            epilog="example: hdrio info church.exr")
    parser.add_argument("files", nargs="+", help="OpenEXR (or any image) files")
    parser.add_argument("--full", action="store_true", help="print arrays in full")
    parser.set_defaults(run=run_info)


def _format_value(value, full: bool) -> str:
    if isinstance(value, np.ndarray):
        value = value.reshape(-1).tolist()
    if isinstance(value, tuple | list) and len(value) > 8 and not full:
        head = ", ".join(_short(v) for v in value[:3])
        tail = ", ".join(_short(v) for v in value[-2:])
        return f"[{len(value)} values: {head}, ..., {tail}]"
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_short(v) for v in value) + "]"
    return _short(value)


def _short(value) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def run_info(args: argparse.Namespace) -> int:
    from hdrio.io.header import read_header

    for index, path in enumerate(args.files):
        header = read_header(path)
        if index:
            print()
        print(f"{path}: {header.pop('.resolution')}, {header.pop('.channels')} "
              f"({header.pop('.format')})")
        for name in sorted(header, key=lambda n: (n.startswith("hdrio:"), n.lower())):
            print(f"  {name:28s} {_format_value(header[name], args.full)}")
    return 0


def add_demo(sub) -> None:
    parser = sub.add_parser(
        "demo", help="merge a built-in synthetic bracket set and check it against truth",
        description="Render a procedural HDR scene through a known camera response (with "
                    "sensor noise and 8-bit quantisation), merge it, write the EXR and a "
                    "preview, and print the error against the ground truth.",
        epilog="example: hdrio demo -o demo_out",
    )
    parser.add_argument("-o", "--output-dir", default="hdrio_demo",
                        help="folder for brackets, EXR and preview (default %(default)s)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(run=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    from hdrio.demo import DEMO_EXPOSURES, write_demo_brackets
    from hdrio.synthetic import radiance_error, well_exposed

    folder = Path(args.output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    progress = Progress(quiet=args.quiet)
    progress.step(f"rendering {len(DEMO_EXPOSURES)} synthetic brackets into {folder}")
    truth, files = write_demo_brackets(folder)
    output, preview = folder / "demo.exr", folder / "demo_preview.jpg"
    result = merge_files(files, output, preview=preview, progress=progress.step,
                         read_progress=progress.bar)
    print(summary(result, output, preview, "reinhard-global", "half"))
    mask = well_exposed(result.stack.codes, result.stack.code_max)
    error = radiance_error(result.radiance, truth, mask)
    print(f"truth:     relative radiance error after one global scale, on the "
          f"{100 * mask.mean():.1f} % of pixels well exposed in some bracket: median "
          f"{100 * error['median']:.2f} %, p95 {100 * error['p95']:.2f} %, "
          f"p99 {100 * error['p99']:.2f} %")
    return 0
