"""The subcommands ``merge``, ``info`` and ``demo``: options in, a summary out."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from hdrio.align import REFERENCE_RULE
from hdrio.cli.merge_arguments import (
    add_arguments,
    merge_options,
    settings_from_namespace,
    tonemap_arguments,
)
from hdrio.cli.outputs import EXR_SUFFIXES, PREVIEW_SUFFIXES, lossy_note, make_parent
from hdrio.cli.progress import Progress
from hdrio.cms.checks import CheckReport, StreamingCheck, format_report
from hdrio.errors import HdrioError
from hdrio.io.exposure import EV_STEPS
from hdrio.io.orientation import turned_text
from hdrio.io.write import EXR_COMPRESSIONS, exr_compression
from hdrio.job.options import MergeOptions
from hdrio.job.output import saturation_rule
from hdrio.job.result import MergeResult
from hdrio.job.run import merge_files
from hdrio.radiometry.curve import CameraResponse, linear_deviation
from hdrio.stack import ExposureStack, repeated_exposures
from hdrio.tonemap import TONEMAP_METHODS


def add_merge(sub) -> None:
    parser = sub.add_parser(
        "merge", help="merge brackets into a scene-linear EXR",
        description="Merge bracketed exposures into one scene-linear OpenEXR. Every "
                    "option below means the same in a chain's --merge (hdrio --help).",
        epilog="example: hdrio merge church_*.png --exposures-from exposures.csv "
               "-o church.exr --preview church.jpg",
    )
    parser.add_argument("images", nargs="+", help="bracketed 8- or 16-bit images")
    parser.add_argument("-o", "--output", required=True,
                        help="output OpenEXR file (missing folders are made); {first_stem}, "
                             "{last_stem}, {count} and {folder} are the brackets' (e.g. "
                             "'{first_stem}_hdr.exr')")
    parser.add_argument("-d", "--data-type", choices=["half", "float"], default="half",
                        help="EXR pixel type (default %(default)s)")
    parser.add_argument("--compression", metavar="NAME", default="zip",
                        help=f"EXR compression: {', '.join(EXR_COMPRESSIONS)} (default zip; "
                             "dwaa:45 sets a level), as the chain's --compression")
    parser.add_argument("-q", "--quiet", action="store_true", help=QUIET_HELP)
    preview = parser.add_argument_group("preview")
    preview.add_argument("--preview", help="also write a tone-mapped preview (jpg, png, tif)")
    preview.add_argument("--tonemap", nargs="+", default=["reinhard-global"],
                         metavar=("OPERATOR", "NAME=VALUE,"),
                         help=f"preview operator ({', '.join(TONEMAP_METHODS.names())}; "
                              "default reinhard-global) and its parameters, e.g. "
                              "--tonemap reinhard-global key=0.18,white=8")
    preview.add_argument("--ociodisplay", nargs=2, metavar=("DISPLAY", "VIEW"),
                         help="render the preview through this OpenColorIO display and view "
                              "instead of --tonemap, e.g. 'sRGB - Display' 'ACES 2.0 - SDR "
                              "100 nits (Rec.709)'")
    preview.add_argument("--ocio-display", help=argparse.SUPPRESS)  # older spelling
    preview.add_argument("--ocio-view", help=argparse.SUPPRESS)  # older spelling
    add_arguments(parser)
    parser.set_defaults(run=run_merge)


def display_view_from(args: argparse.Namespace, config: str | None
                      ) -> tuple[str, str] | None:
    """``(display, view)`` for the preview, checked against the config, or ``None``."""
    from hdrio.cms.spaces import display_view_names

    display, view = args.ociodisplay or (None, None)
    display, view = args.ocio_display or display, args.ocio_view or view
    if not display:
        if view:
            raise HdrioError("--ocio-view needs --ociodisplay DISPLAY VIEW")
        return None
    return display_view_names(display, view, config)


def _filled(text: str, option: str, images: list) -> Path:
    """An output name with its pattern fields (``{first_stem}``...) filled in from the
    brackets as given, as the chain fills them (:func:`hdrio.io.paths.set_fields`)."""
    from hdrio.io.paths import fill_pattern, is_pattern, set_fields

    if not is_pattern(text) or not images:
        return Path(text)
    try:
        return fill_pattern(text, set_fields(images))
    except HdrioError as error:
        raise HdrioError(f"{option} {text}: {error}") from None


def run_merge(args: argparse.Namespace) -> int:
    # Everything is checked before any image is read: names, values, colour spaces,
    # displays, output folders.
    from hdrio.io.paths import check_outputs, expand_patterns

    args.images = expand_patterns(args.images)
    output = _filled(args.output, "-o", args.images)
    preview = _filled(args.preview, "--preview", args.images) if args.preview else None

    check_outputs([(path, allowed) for path, allowed in ((output, EXR_SUFFIXES),
                                                         (preview, PREVIEW_SUFFIXES))
                   if path is not None], args.images)
    try:
        compression = exr_compression(args.compression)
    except ValueError as error:
        raise HdrioError(f"--compression {error}") from None
    if len(args.tonemap) > 2:
        raise HdrioError(f"--tonemap {' '.join(args.tonemap)}: expected OPERATOR "
                         "[NAME=VALUE,...]")
    try:
        tonemap, parameters = tonemap_arguments(args.tonemap)
    except (ValueError, KeyError) as error:
        message = error.args[0] if error.args else error
        raise HdrioError(f"--tonemap {' '.join(args.tonemap)}: {message}") from None
    settings = settings_from_namespace(args)
    options = merge_options(settings)
    display_view = display_view_from(args, options.ocio_config)
    from hdrio.io.paths import check_inputs

    check_inputs(args.images)
    for path in (output, preview):
        if path is not None:
            make_parent(path)
    progress = Progress(quiet=args.quiet)
    check = merge_check(options)
    result = merge_files(
        args.images, output, preview=preview, tonemap=tonemap,
        tonemap_parameters=parameters, exposures=settings.get("exposures"),
        exposures_from=settings.get("exposures_from"), options=options,
        pixel_type=args.data_type, compression=compression, progress=progress.step,
        read_progress=progress.bar, display_view=display_view, observe=check.add,
        compile_ahead=True,
    )
    source = result.stack.exposure_sources[0]
    for line in result.exposures.warnings(source) if result.exposures is not None else ():
        print(f"hdrio merge: warning: {line}", file=sys.stderr)
    label = " / ".join(display_view) if display_view else tonemap
    report = merge_report(check, result, output)
    lossy = lossy_note(compression, args.data_type, output)
    if lossy:
        report.notes.append(lossy)
    text = summary(result, output, preview, label, f"{args.data_type}, {compression}",
                   report)
    if args.quiet:
        print(written_lines(text))
        return 0
    print(text)
    # The written file as 'hdrio check' reads it: counted from its bands as they were
    # written, not read back.
    print(format_report(report))
    return 0


QUIET_HELP = ("quiet: no progress, summary or check; only the lines naming the files "
              "written, warnings and errors")


def written_lines(summary_text: str) -> str:
    """The ``wrote:`` and ``preview:`` lines of a summary: all that ``-q`` prints."""
    return "\n".join(line for line in summary_text.splitlines()
                     if line.startswith(("wrote:", "preview:")))


def merge_check(options) -> StreamingCheck:
    """The check to feed with a merge's EXR bands as they are written (counted by numba's
    kernel, on the threads that convert them)."""
    from hdrio.cms.spaces import chromaticities

    return StreamingCheck(chromaticities(options.output_space, options.ocio_config),
                          units="cd/m^2" if options.calibration is not None else "relative",
                          compiled=True)


def merge_report(check: StreamingCheck, result: MergeResult, output: Path) -> CheckReport:
    stats = result.statistics
    return check.report(str(output), clipped_fraction=stats.clipped_fraction,
                        masked_fraction=stats.masked_everywhere / stats.pixels)


def _linear_hint(response: CameraResponse) -> list[str]:
    """The summary's line when a solved response is a linear sensor's
    (:func:`hdrio.radiometry.curve.linear_deviation`), else none."""
    if response.method == "linear":
        return []
    deviation = linear_deviation(response)
    if deviation is None:
        return []
    return [f"           the solved curve is ln z within {deviation:.3f} from 1 to 95 % of "
            "the codes: linear codes, which --response linear merges without a solve "
            "(and closer: docs/method.md)"]


def _seconds(t: float) -> str:
    return f"1/{1 / t:.4g} s" if t < 1 else f"{t:.4g} s"


def summary(result: MergeResult, output: Path, preview: Path | None, tonemap: str,
            layout: str, report: CheckReport) -> str:
    """What the merge did, from its own statistics and ``report`` (the EXR's check);
    ``layout``: the EXR's pixel type and compression, e.g. ``half, zip``."""
    stack, stats, times = result.stack, result.statistics, result.timings
    height, width, channels = stack.shape
    bits = 8 if stack.code_max == 255 else 16
    full, robust = report.dynamic_range_stops, report.robust_range_stops
    params = result.response.parameters
    inferred = result.exposures.line() if result.exposures is not None else ""
    relative = (inferred and result.exposures.exif is None) or (
        stack.exposure_sources[0] == EV_STEPS)
    span = (f"relative exposures {stack.exposures[0]:.4g} .. {stack.exposures[-1]:.4g}"
            if relative else f"{_seconds(stack.exposures[0])} .. {_seconds(stack.exposures[-1])}")
    upright = turned_text(stack.files, stack.metadata)
    lines = [
        f"brackets:  {stack.count} x {width}x{height} ({channels} ch, {bits}-bit), {span} "
        f"(exposures from {stack.exposure_sources[0]}"
        + (", then from the data" if result.exposures and result.exposures.used
           and not inferred else "")
        + f"), read in {times['read']:.2f} s",
        *[f"repeated:  {line}" for line in repeat_lines(stack)],
        *([f"upright:   as the EXIF says, {upright}"] if upright else []),
        *([f"exposures: {inferred}"] if inferred else []),
        f"response:  {result.response.method}, lambda {params.get('smoothing', 0):g}, "
        f"{params['weighting']} weighting, {params['samples']} samples ({params['sampling']}),"
        + (" observations at or reaching the clip left out (the channels mix after it),"
           if params.get("dropped") else "")
        + f" {times['response']:.2f} s",
        *_linear_hint(result.response),
        f"merge:     {result.options.merge}, {times['merge']:.2f} s; clipped in every "
        f"bracket {100 * stats.clipped_fraction:.2f} % ("
        + ("reconstructed" if result.highlights else "a neutral lower bound")
        + f"{', layer clipped.Y' if result.options.clip_mask else ''}), black in every "
        f"bracket {100 * stats.black_everywhere / stats.pixels:.2f} %"
        + (f"; masked in every bracket {100 * stats.masked_everywhere / stats.pixels:.2f} "
           "% (alpha 0, not counted)" if stats.masked_everywhere else ""),
        f"clipping:  --saturation {result.options.saturation}, {saturation_rule(stats)}"
        + (f" (limits {', '.join(str(v) for v in stats.limits)})" if stats.limits else ""),
        *([f"highlight: {result.highlights.text()}, {times['highlights']:.2f} s"]
          if result.highlights else []),
        *motion_lines(result),
        *[f"nd:        {line}" for line in (result.nd.lines() if result.nd else [])],
        *[f"skipped:   {line}" for line in result.skipped.lines(channels)],
        f"range:     {full:.1f} stops (0.1-99.9 percentile: {robust:.1f} stops)",
        f"wrote:     {output} ({layout}) in {times['write']:.2f} s"
        + ("" if result.exposure_scale == 1.0 else
           f"; scaled by {result.exposure_scale:g} to fit half floats"),
    ]
    if preview is not None:
        lines.append(f"preview:   {preview} ({tonemap}) in {times['preview']:.2f} s")
    return "\n".join(lines)


def repeat_lines(stack: ExposureStack) -> list[str]:
    """The summary's ``repeated:`` lines: frames that share an exposure
    (:func:`hdrio.stack.repeated_exposures`), each merged as an observation of it."""
    return [f"{', '.join(Path(stack.files[j]).name for j in group)} at "
            f"{_seconds(stack.exposures[group[0]])}: the same exposure, each frame merged"
            for group in repeated_exposures(stack.exposures)]


def motion_lines(result: MergeResult) -> list[str]:
    """The summary's ``align:`` and ``deghost:`` lines."""
    motion, lines = result.motion, []
    if motion.too_small:
        lines.append(f"align:     none: {motion.too_small}")
    if motion.alignment is not None:
        files = tuple(Path(name).name for name in result.stack.files)
        said = "warped" if motion.warped else "not warped"
        resample = result.timings.get("resample", 0.0)
        lines.append(f"align:     {motion.alignment.model} to "
                     f"{files[motion.alignment.reference]} ({REFERENCE_RULE}), {said}, "
                     f"{result.timings.get('align', 0) + resample:.2f} s"
                     + (f" (re-merging with resampling weights {resample:.2f} s)"
                        if resample else "")
                     + (f"; {100 * motion.uncovered:.1f} % of pixels not covered by every "
                        "bracket" if motion.uncovered else ""))
        lines += [f"           {line}" for line in motion.alignment.describe(files)]
    if motion.deghosting is not None:
        lines.append(f"deghost:   {100 * motion.deghosting.fraction:.2f} % of pixels had a "
                     f"bracket dropped for motion, {result.timings.get('deghost', 0):.2f} s"
                     + ("" if result.motion_test_exposures is None else
                        "; tested with the exposures the data say (the merge's are off by "
                        f"up to {result.exposures.spread():.2f} stop)"))
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
    from hdrio.io.paths import expand_patterns

    for index, path in enumerate(expand_patterns(args.files)):
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
        epilog="example: hdrio demo -o hdrio_demo",
    )
    parser.add_argument("-o", "--output-dir", default="hdrio_demo",
                        help="folder for brackets, EXR and preview (default %(default)s)")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="quiet: no progress or summary; only the lines naming the "
                             "files written, the comparison with the truth (truth, bound, "
                             "verdict), warnings and errors")
    parser.set_defaults(run=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    from hdrio import jit
    from hdrio.tools.demo import DEMO_EXPOSURES, oracle_radiance, write_demo_brackets
    from hdrio.tools.synthetic import radiance_error, well_exposed

    folder = Path(args.output_dir)
    folder.mkdir(parents=True, exist_ok=True)
    progress = Progress(quiet=args.quiet)
    # A first run compiles ahead while the brackets (8-bit RGB) are rendered, too.
    jit.compile_ahead("reinhard-global", merge=lambda: True, motion=True)
    progress.step(f"rendering {len(DEMO_EXPOSURES)} synthetic brackets into {folder}")
    truth, files = write_demo_brackets(folder)
    output, preview = folder / "demo.exr", folder / "demo_preview.jpg"
    options = MergeOptions()
    check = merge_check(options)
    result = merge_files(files, output, preview=preview, progress=progress.step,
                         read_progress=progress.bar, options=options, observe=check.add,
                         compile_ahead=True)
    text = summary(result, output, preview, "reinhard-global", "half, zip",
                   merge_report(check, result, output))
    print(written_lines(text) if args.quiet else text)
    mask = well_exposed(result.stack.codes, result.stack.code_max)
    error = radiance_error(result.radiance, truth, mask)
    print(f"truth:     relative radiance error after one global scale, on the "
          f"{100 * mask.mean():.1f} % of pixels well exposed in some bracket: median "
          f"{100 * error['median']:.2f} %, p95 {100 * error['p95']:.2f} %, "
          f"p99 {100 * error['p99']:.2f} %")
    bound = radiance_error(oracle_radiance(result.stack), truth, mask)
    print(f"bound:     the noise-aware oracle (true curve, true noise, inverse-variance "
          f"weights): median {100 * bound['median']:.2f} %, p95 {100 * bound['p95']:.2f} %, "
          f"p99 {100 * bound['p99']:.2f} %")
    ratio = max(error["median"] / bound["median"], error["p99"] / bound["p99"])
    verdict = ("within 10 % of the bound" if ratio <= 1.1 else
               f"{ratio:.2f}x the bound (a calibrated curve or --merge inverse-variance "
               "closes the gap)")
    print(f"verdict:   {verdict}")
    return 0
