"""The one place that chains the steps: brackets -> response -> radiance -> EXR (+ preview).

Every front end (the command line, the Blender add-on) calls these functions. The job's
options and result are :mod:`hdrio.merge_job`'s; what the EXR holds (pixels, layers,
header) is :mod:`hdrio.merge_output`'s; the preview is :mod:`hdrio.tonemap.preview`'s.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from hdrio import jit
from hdrio.align.deghost import CELL
from hdrio.align.registration import align_masks
from hdrio.align.stage import align_step, check_modes, deghost_step, remerge_step
from hdrio.cms.encoding import resolve_encoding
from hdrio.cms.spaces import require_scene_linear
from hdrio.cms.stage import colour_stage
from hdrio.errors import HdrioError, ResponseSolveError
from hdrio.io.brackets import read_brackets
from hdrio.io.brackets import read_header as read_bracket_header
from hdrio.io.masks import mask_files, read_masks
from hdrio.io.paths import check_inputs, check_outputs
from hdrio.io.raw import is_raw, is_raw_stack, xyz_to_working
from hdrio.io.write import write_preview
from hdrio.merge.debevec1997 import estimate_tables
from hdrio.merge.estimators import (
    MERGE_METHODS,
    NOISE_AWARE,
    effective_weights,
    merge_domain,
)
from hdrio.merge.exclusion import colour_exclusion, either, masked_statistics, remerge_excluded
from hdrio.merge.exposures import exposures_from_data
from hdrio.merge.highlights import HIGHLIGHT_MODES, reconstruct_highlights
from hdrio.merge.ladder import (
    in_brightness_order,
    infer_exposures,
    needs_inference,
    starting_response,
)
from hdrio.merge.nd import NDReport, filter_gains, nd_stops, unfiltered, with_nd
from hdrio.merge.noise import code_variance_floor, fit_noise
from hdrio.merge.saturation import SolveFilter, solve_filter
from hdrio.merge.uncertainty import relative_uncertainty
from hdrio.merge_job import MergeOptions, MergeResult, PhaseClock, Progress
from hdrio.merge_output import (
    exr_attributes,
    merge_alpha,
    merge_layers,
    output_pixels,
    write_radiance,
)
from hdrio.response import RESPONSE_METHODS, CameraResponse
from hdrio.response.stored import check_response_fits, read_response
from hdrio.skips import SkipReport, classify
from hdrio.stack import ExposureStack
from hdrio.tonemap import TONEMAP_METHODS
from hdrio.tonemap.display import preview_OCIO_display
from hdrio.tonemap.preview import render_preview


def describe_set(stack: ExposureStack) -> str:
    """The files of a stack for a message: ``a.png .. d.png (4 brackets, 32x24, all
    dark: a.png)``, with the brackets that have no well-exposed pixel named."""
    height, width = stack.shape[:2]
    names = [Path(name).name for name in stack.files]
    span = names[0] if len(names) == 1 else f"{names[0]} .. {names[-1]}"
    notes = [f"{len(names)} brackets of {width}x{height}"]
    dropped = [Path(name).name for name, _ in stack.dropped]
    if dropped:
        notes.append(f"no well-exposed pixel in {', '.join(dropped)}")
    kinds = [classify(codes, stack.code_max) for codes in stack.codes]
    for kind, label in (("dark", "all dark"), ("bright", "all bright")):
        which = [name for name, k in zip(names, kinds) if k == kind]
        if which:
            notes.append(f"{label}: {', '.join(which)}")
    return f"{span} ({'; '.join(notes)})"


def exclusions(stack: ExposureStack, options: MergeOptions,
               masks: np.ndarray | None) -> np.ndarray | None:
    """``(P, H, W)`` bool: the observations ``--exclude-color`` and ``--mask`` (``masks``,
    read by :func:`hdrio.io.masks.read_masks` in the stack's order) keep out of the solve
    and the merge (:mod:`hdrio.merge.exclusion`), else ``None``."""
    return either(colour_exclusion(stack.codes, options.exclude_colour), masks)


def merge_stack(stack: ExposureStack, options: MergeOptions = MergeOptions(),
                progress: Progress | None = None,
                response: CameraResponse | None = None, owned: bool = False) -> MergeResult:
    """Recover the response, align and merge ``stack`` (no file I/O).

    ``response``, when given (e.g. read back with :func:`hdrio.response.stored.read_response`),
    is used instead of a solve; camera RAW stacks use the linear response. The skips in
    ``options.skips`` apply (:mod:`hdrio.skips`); ``result.skipped`` says which did.
    ``--mask`` files (``options.masks``) are the only files read.
    ``owned``: the caller hands the stack over (its codes may be warped in place, so
    alignment needs no second copy of the brackets); otherwise ``stack`` is left as is.
    """
    say = progress or (lambda message: None)
    check_modes(options.align, options.deghost)
    if options.highlights not in HIGHLIGHT_MODES:
        raise ValueError(f"highlights {options.highlights!r}: choose from "
                         f"{', '.join(HIGHLIGHT_MODES)}")
    skips = options.skips
    skipped = SkipReport(dropped=list(stack.dropped))
    clock = PhaseClock()
    timings = clock.wall
    solve = None
    filtered = None  # stops of ND filter per bracket
    if options.nd:
        stack, filtered = with_nd(stack, nd_stops(stack.files, options.nd))
    inferring = needs_inference(stack)
    if inferring:  # no exposure metadata: order by brightness, before masks
        stack = in_brightness_order(stack)
    masks = read_masks(options.masks, stack.files, stack.shape[:2])  # in the stack's order
    excluded = exclusions(stack, options, masks)
    if response is not None:
        check_response_fits(response, stack.code_max, stack.shape[2])
    else:
        method = "linear" if is_raw_stack(stack) else options.response
        say(f"camera response: {method}" + ("" if method == "linear"
                                            else f", lambda {options.smoothing:g}"))

        def solve(stack: ExposureStack, exclude: np.ndarray | None) -> CameraResponse:
            if filtered is not None and np.count_nonzero(filtered == 0) >= 2:
                stack = unfiltered(stack, filtered)  # a filter's cast would bend g

            def solved_with(dropped: SolveFilter | None = None) -> CameraResponse:
                return RESPONSE_METHODS[method](
                    stack, smoothing=options.smoothing, weighting=options.weighting,
                    sampling=options.sampling, samples=options.samples, exclude=exclude,
                    seed=options.seed,
                    **({"solve_identical_once": "channels" in skips,
                        "dropped": dropped} if method != "linear" else {}))

            response = solved_with()
            if method == "linear":
                return response
            # A camera that mixes its channels after the clip: partly clipped
            # observations are biased in every channel, and would bend the curve.
            dropped = solve_filter(options.saturation, stack, response)
            return response if dropped is None else solved_with(dropped)

        def solved(stack: ExposureStack) -> CameraResponse:
            try:
                return solve(stack, None if excluded is None else excluded.any(axis=0))
            except ResponseSolveError as error:
                message = str(error).replace("a saved response", "a saved response "
                                             "(--response-from EXR, from an earlier merge)")
                if "--response-from" not in message:
                    message += "; or give a saved response: --response-from EXR"
                raise ResponseSolveError(f"{describe_set(stack)}: {message}") from None

    exposure_check = None
    if options.exposures_from_data and (stack.count < 3 or filtered is not None):
        raise ValueError("--exposures-from-data needs three brackets or more, and no --nd "
                         f"(the filters are measured on their own); got {stack.count} "
                         "brackets" + (" and --nd" if filtered is not None else ""))
    if inferring:  # no metadata: the ladder from the pixels (--exposures-from-data)
        start = response if response is not None else starting_response(
            stack.code_max, stack.shape[2], resolve_encoding(
                stack.files, stack.metadata, options.input_encoding)[0].name,
            linear=is_raw_stack(stack) or options.response == "linear")
        stack, response, exposure_check = infer_exposures(
            stack, start, None if solve is None else solved)
        say(f"exposures: {exposure_check.line()}")
    elif solve is not None:
        response = solved(stack)
    if solve is not None:
        skipped.channels_solved = response.parameters.get("channels_solved")
    if stack.count > 2 and filtered is None and exposure_check is None:
        # two brackets cannot say which is wrong
        stack, response, exposure_check = exposures_from_data(
            stack, response, options.exposures_from_data, None if solve is None else solved)
    clock.lap("response")
    if options.align != "off" or options.deghost != "off":
        jit.announce(say, "motion")
    if options.align != "off":
        say(f"aligning {stack.count} brackets ({options.align})")
    resolve = solve if excluded is None else None
    stack, response, motion = align_step(stack, response, options.align, resolve,
                                         in_place=owned, skip_warp="warp" in skips)
    if motion.warped and excluded is not None:  # the warped borders' colour
        if masks is not None and len(set(mask_files(options.masks, stack.files))) > 1:
            # A mask per bracket is drawn on that bracket: it moves with it. One shared
            # mask is taken on the reference, where every bracket now is.
            masks = align_masks(masks, motion.alignment)
        excluded = exclusions(stack, options, masks)
    nd_report = None
    if filtered is not None:
        gains, found = filter_gains(stack, response, filtered)
        stack = replace(stack, channel_gains=gains)
        nd_report = NDReport(stack.files, filtered, found)
    if motion.alignment is not None and not motion.warped:
        skipped.warp = True
    clock.lap("align")
    if options.deghost != "off":
        say("deghosting")
    code_floor = code_variance_floor(stack.files)
    if options.deghost != "off" and stack.count > 1:
        before = fit_noise(stack.codes, stack.exposures, response, code_floor=code_floor)
    else:
        before = None
    solved = response
    response = deghost_step(stack, response, motion, options.deghost, resolve, before)
    clock.lap("deghost")
    merged = stack
    kinds = stack.kinds
    if "covered" in skips and not all(kinds):  # not looked at when read
        kinds = tuple(classify(codes, stack.code_max) for codes in stack.codes)
    if "covered" in skips and "covers" in kinds and excluded is None and filtered is None:
        j = len(kinds) - 1 - kinds[::-1].index("covers")  # the longest
        skipped.covering = Path(stack.files[j]).name
        merged = ExposureStack.from_arrays(
            stack.codes[j:j + 1], stack.exposures[j:j + 1], files=stack.files[j:j + 1],
            code_max=stack.code_max, exposure_sources=stack.exposure_sources[j:j + 1],
            metadata=stack.metadata[j:j + 1], kinds=("covers",),
            dropped=stack.dropped + tuple((name, f"{skipped.covering} covers the range")
                                          for name in stack.files if name != stack.files[j]))
    method = MERGE_METHODS.canonical(options.merge)
    noise = None
    if method in NOISE_AWARE or options.uncertainty:  # on the final (re-solved) response
        noise = before if before is not None and response is solved else fit_noise(
            stack.codes, stack.exposures, response, code_floor=code_floor)
    jit.announce(say, "merge")
    say(f"merging {merged.count} brackets ({method}, {merge_domain(method)} domain)")
    radiance, statistics = MERGE_METHODS[method](
        merged, response, options.weighting, options.saturation,
        early_stop="early-stop" in skips, noise=noise)
    skipped.early_stop_fraction = statistics.observations_skipped / (
        statistics.pixels * merged.count)
    clock.lap("merge")
    weights = effective_weights(method, response, merged.channel_exposures, options.weighting,
                                noise)
    unseen = None
    resampled = False  # the re-merge with the resampling weights: alignment's, not deghosting's
    if merged is stack and excluded is not None:
        unseen = remerge_excluded(stack.codes, stack.channel_exposures, response, radiance,
                                  excluded,
                                  motion.keep, CELL, weights, merge_domain(method),
                                  statistics.policy)
        statistics = masked_statistics(stack.codes, excluded, stack.code_max, statistics)
    elif merged is stack:  # not reduced to one covering bracket
        remerge_step(stack, response, radiance, motion, weights, merge_domain(method),
                     statistics.policy, noise if noise is not None else before)
        resampled = motion.warped
    # After a warp the re-merge runs with or without deghosting (the resampling weights,
    # deghosting's drops fused into the same pass): timed as "resample".
    clock.lap("resample" if resampled else "deghost")
    highlights = None
    if options.highlights == "reconstruct":
        say("reconstructing highlights clipped in every bracket")
        highlights = reconstruct_highlights(
            radiance, merged.codes[0],
            statistics.limits or (merged.code_max,) * merged.shape[2],
            estimate_tables(response, merged.channel_exposures, "linear")[0],
            statistics.policy.neutral,
            None if excluded is None or merged is not stack else ~excluded[0])
        skipped.highlights = highlights is None
        clock.lap("highlights")
    uncertainty = None
    if options.uncertainty:
        say("predicting each pixel's uncertainty")
        uncertainty = relative_uncertainty(merged, response, weights, noise,
                                           merge_domain(method), statistics.policy)
    if is_raw_stack(stack):  # LibRaw gave linear XYZ: into the working space
        radiance = xyz_to_working(radiance, options.colourspace)
    clock.lap("merge")
    radiance, colour = colour_stage(
        stack, response, radiance, input_encoding=options.input_encoding,
        white_balance=options.white_balance, calibration=options.calibration)
    options = replace(options, colourspace=colour.encoding.colour_science)
    return MergeResult(stack, response, radiance, statistics, options, timings,
                       cpu_timings=clock.cpu, colour=colour,
                       skipped=skipped, noise=noise, uncertainty=uncertainty,
                       motion=motion, exposures=exposure_check, nd=nd_report,
                       unseen=unseen if unseen is not None and unseen.any() else None,
                       highlights=highlights)


def merge_paths(paths: Sequence[str | Path], *,
                exposures: Sequence[float | str] | None = None,
                exposures_from: str | Path | None = None,
                options: MergeOptions = MergeOptions(), progress: Progress | None = None,
                read_progress: Callable[[int, int, str], None] | None = None) -> MergeResult:
    """Read brackets and merge them (no output written): what every front end calls.

    ``result.radiance`` is in the input encoding's linear primaries; see
    :func:`output_pixels` for the EXR's space.
    """
    say = progress or (lambda message: None)
    # Fail before reading: every input a readable file, given once.
    check_inputs(paths)
    require_scene_linear(options.output_space, options.ocio_config)
    response = None
    if options.response_from is not None and "response" in options.skips:
        response = read_response(options.response_from)
    start = time.perf_counter()
    say(f"reading {len(paths)} brackets")
    stack = read_brackets(paths, exposures=exposures, exposures_from=exposures_from,
                          progress=read_progress, white_balance=options.raw_multipliers,
                          skip_brackets="brackets" in options.skips,
                          stop_when_covered=response is not None
                          and "covered" in options.skips,
                          infer_exposures=options.exposures_from_data)
    read_time = time.perf_counter() - start
    result = merge_stack(stack, options, progress, response, owned=True)
    if response is not None:
        result.skipped.response_from = str(options.response_from)
    result.timings["read"] = read_time
    return result


def _eight_bit_rgb(paths: Sequence[str | Path]) -> bool:
    """Whether the first bracket is 8-bit RGB (its merge kernel is the pair-table path);
    False when its header cannot be read (reading it properly then says why)."""
    if not paths or is_raw(paths[0]):
        return False
    try:
        header = read_bracket_header(paths[0])
    except HdrioError:
        return False
    return header.code_max == 255 and header.channels == 3


def merge_files(paths: Sequence[str | Path], output: str | Path, *,
                preview: str | Path | None = None, tonemap: str = "reinhard-global",
                exposures: Sequence[float | str] | None = None,
                exposures_from: str | Path | None = None,
                options: MergeOptions = MergeOptions(), pixel_type: str = "half",
                progress: Progress | None = None,
                read_progress: Callable[[int, int, str], None] | None = None,
                display_view: tuple[str, str] | None = None,
                observe: Callable[[np.ndarray], None] | None = None,
                tonemap_parameters: dict[str, float] | None = None,
                compile_ahead: bool = False) -> MergeResult:
    """Read brackets, merge them, write the EXR (and a tone-mapped preview), atomically.

    ``display_view``: render the preview through that OCIO display and view instead of
    the ``tonemap`` operator (with ``tonemap_parameters``). ``observe`` sees each band of
    the EXR as stored (see :func:`hdrio.cms.checks.StreamingCheck`). ``compile_ahead``:
    on a first run, compile the merge's, alignment's and deghosting's and the preview's
    kernels in helper processes meanwhile (:func:`hdrio.jit.compile_ahead`; for a command
    run as ``python``, not from inside another application).
    """
    say = progress or (lambda message: None)
    # Fail before reading: outputs named well, in folders that take a new file.
    check_outputs([(output, {".exr"}), *([(preview, None)] if preview is not None else [])],
                  paths)
    tonemapped = (preview is not None and display_view is None
                  and not TONEMAP_METHODS.canonical(tonemap).endswith("tutorial"))
    if compile_ahead:
        jit.compile_ahead(tonemap if tonemapped else None, merge=lambda: _eight_bit_rgb(paths),
                          motion=options.align != "off" or options.deghost != "off")
    result = merge_paths(paths, exposures=exposures, exposures_from=exposures_from,
                         options=options, progress=progress, read_progress=read_progress)
    start = time.perf_counter()
    say(f"writing {output}")
    result.exposure_scale = write_radiance(output, output_pixels(result),
                                           exr_attributes(result), pixel_type=pixel_type,
                                           alpha=merge_alpha(result), observe=observe,
                                           layers=merge_layers(result))
    result.timings["write"] = time.perf_counter() - start
    if preview is not None:
        start = time.perf_counter()
        if display_view is not None and result.colour is not None:
            say(f"rendering preview ({' / '.join(display_view)})")
            pixels = preview_OCIO_display(
                result.radiance, result.colour.encoding.linear_interop_id, *display_view,
                colourspace=result.options.colourspace, config=options.ocio_config)
        else:
            if not TONEMAP_METHODS.canonical(tonemap).endswith("tutorial"):
                jit.announce(say, "preview")
            say(f"tone mapping preview ({tonemap})")
            pixels = render_preview(result.radiance, tonemap, result.options.colourspace,
                                    result.unseen, **(tonemap_parameters or {}))
        write_preview(preview, pixels)
        result.timings["preview"] = time.perf_counter() - start
    return result
