"""Running a merge job: :func:`run_plan` lists its stages in order; :func:`merge_stack`,
:func:`merge_paths` and :func:`merge_files` are what every front end (the command line,
the chain, the Blender add-on, a farm's worker) calls.

The job's parts: what it is asked (:mod:`hdrio.job.options`), the settings resolved once
(:mod:`hdrio.job.plan`), the stages (:mod:`hdrio.job.stages`, :mod:`hdrio.job.radiance`),
what it gives (:mod:`hdrio.job.result`) and what the EXR holds (:mod:`hdrio.job.output`);
the preview is :mod:`hdrio.tonemap.preview`'s.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from hdrio import jit
from hdrio.cms.colour_stage import colour_stage
from hdrio.cms.display import preview_OCIO_display
from hdrio.cms.encoding import xyz_to_working
from hdrio.cms.spaces import require_scene_linear
from hdrio.errors import HdrioError
from hdrio.io.brackets import read_brackets
from hdrio.io.brackets import read_header as read_bracket_header
from hdrio.io.paths import check_inputs, check_outputs
from hdrio.io.raw import is_raw, is_raw_stack
from hdrio.io.write import write_preview
from hdrio.job import radiance as merging
from hdrio.job import stages
from hdrio.job.options import MergeOptions
from hdrio.job.output import (
    exr_attributes,
    merge_alpha,
    merge_layers,
    output_pixels,
    write_radiance,
)
from hdrio.job.plan import MergePlan, plan_merge
from hdrio.job.result import MergeResult, PhaseClock, Progress
from hdrio.merge.saturation import Surveys
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.saved_response import read_response
from hdrio.skips import SkipReport
from hdrio.stack import ExposureStack
from hdrio.tonemap import TONEMAP_METHODS
from hdrio.tonemap.preview import render_preview


def _quiet(message: str) -> None:
    """A progress callback that says nothing."""


def run_plan(stack: ExposureStack, plan: MergePlan, progress: Progress | None = None,
             response: CameraResponse | None = None, owned: bool = False) -> MergeResult:
    """Recover the response, align and merge ``stack`` as ``plan`` says (no file I/O):
    the job's stages, in order. See :func:`merge_stack`."""
    say, clock, options = progress or _quiet, PhaseClock(), plan.options
    skipped = SkipReport(dropped=list(stack.dropped))
    prepared = stages.prepare(stack, plan)
    surveys = Surveys()  # what the solve's clip filter measured, for deghosting's policy
    solve = None if response is not None else stages.response_solver(prepared, plan, say,
                                                                      surveys)
    prepared, response, exposure_check = stages.response_stage(prepared, plan, response,
                                                               solve, say)
    if solve is not None:
        skipped.channels_solved = response.parameters.get("channels_solved")
    clock.lap("response")
    resolve = solve if prepared.excluded is None else None  # no re-solve under exclusions
    calibration = stages.exposure_calibration(prepared, plan, resolve, exposure_check)
    prepared, response, motion = stages.align_stage(prepared, response, plan,
                                                    calibration or resolve, owned, say)
    prepared, response, exposure_check = stages.registered_exposures(
        prepared, response, plan, solve, motion, exposure_check, calibration, say)
    exposure_check = stages.with_given_response(exposure_check, plan, prepared.stack,
                                                given=solve is None)
    stack, nd_report = stages.nd_stage(prepared.stack, response, prepared.filtered)
    skipped.warp = motion.alignment is not None and not motion.warped
    clock.lap("align")
    solved = response
    test_exposures = stages.motion_test_exposures(stack, motion, plan, exposure_check)
    response, tested, clip = stages.deghost_stage(stack, response, motion, plan, resolve,
                                                  prepared.excluded, say, surveys,
                                                  test_exposures)
    clock.lap("deghost")
    merged_stack, skipped.covering = stages.covering_bracket(stack, prepared, plan)
    fitted, survey = tested if response is solved else None, None
    if fitted is None and clip is None and plan.fits_noise:  # no deghosting: the solve's
        survey = stages.held_survey(stack, response, motion, prepared.excluded, surveys)
        fitted = None if survey is None else survey.noise
    noise = stages.noise_stage(stack, response, plan, fitted, prepared.excluded)
    excluded = prepared.excluded if merged_stack is stack else None
    # Deghosting's policy holds where the merge sees its stack, response and noise.
    same = response is solved and merged_stack is stack and noise is tested
    merged = merging.merge_stage(merged_stack, response, plan, noise, say, excluded=excluded,
                                 policy=clip if same else None,
                                 survey=survey if merged_stack is stack else None)
    skipped.early_stop_fraction = merged.early_stop_fraction
    clock.lap("merge")
    unseen, resampled = merging.remerge_stage(stack, merged_stack, response, merged, plan,
                                              excluded, motion,
                                              noise if noise is not None else tested)
    clock.lap("resample" if resampled else "deghost")
    highlights = uncertainty = None
    if options.highlights == "reconstruct":
        highlights = merging.highlight_stage(merged_stack, response, merged, excluded, say)
        skipped.highlights = highlights is None
        clock.lap("highlights")
    if options.uncertainty:
        uncertainty = merging.uncertainty_stage(merged_stack, response, merged, plan, noise,
                                                say)
    radiance = merged.radiance
    if is_raw_stack(stack):  # LibRaw gave linear XYZ: into the working space
        radiance = xyz_to_working(radiance, options.colourspace)
    clock.lap("merge")
    radiance, colour = colour_stage(
        stack, response, radiance, input_encoding=options.input_encoding,
        white_balance=options.white_balance, calibration=options.calibration)
    return MergeResult(stack, response, radiance, merged.statistics,
                       replace(options, colourspace=colour.encoding.colour_science), plan,
                       timings=clock.wall, cpu_timings=clock.cpu, colour=colour,
                       skipped=skipped, noise=noise, uncertainty=uncertainty, motion=motion,
                       exposures=exposure_check, motion_test_exposures=test_exposures,
                       nd=nd_report, unseen=unseen,
                       highlights=highlights)


def merge_stack(stack: ExposureStack, options: MergeOptions = MergeOptions(),
                progress: Progress | None = None,
                response: CameraResponse | None = None, owned: bool = False) -> MergeResult:
    """Recover the response, align and merge ``stack`` (no file I/O).

    ``response``, when given (e.g. read back with
    :func:`hdrio.radiometry.saved_response.read_response`), is used instead of a solve;
    camera RAW stacks use the linear response. The skips in force (the plan's,
    :mod:`hdrio.skips`) apply; ``result.skipped`` says which did. ``--mask`` files
    (``options.masks``) are the only files read. ``owned``: the caller hands the stack
    over (its codes may be warped in place, so alignment needs no second copy of the
    brackets); otherwise ``stack`` is left as is.
    """
    return run_plan(stack, plan_merge(options), progress, response, owned)


def _read_and_merge(paths: Sequence[str | Path], plan: MergePlan, *,
                    exposures: Sequence[float | str] | None,
                    exposures_from: str | Path | None, progress: Progress | None,
                    read_progress: Callable[[int, int, str], None] | None) -> MergeResult:
    """Read the brackets (skipping what the plan allows) and run the plan on them."""
    options, skips = plan.options, plan.skips
    say = progress or _quiet
    # Fail before reading: every input a readable file, given once.
    check_inputs(paths)
    require_scene_linear(options.output_space, options.ocio_config)
    response = None
    if options.response_from is not None and "response" in skips:
        response = read_response(options.response_from)
    clock = PhaseClock()
    say(f"reading {len(paths)} bracket{'' if len(paths) == 1 else 's'}")
    # numba's first use (and deghosting's SciPy), prepared while the brackets decode
    jit.warm_up(*(("scipy.ndimage",) if plan.aligns or plan.deghosts else ()))
    stack = read_brackets(paths, exposures=exposures, exposures_from=exposures_from,
                          progress=read_progress, white_balance=options.raw_multipliers,
                          skip_brackets="brackets" in skips,
                          stop_when_covered=response is not None and "covered" in skips,
                          infer_exposures=options.exposures_from_data)
    clock.lap("read")
    result = run_plan(stack, plan, progress, response, owned=True)
    if response is not None:
        result.skipped.response_from = str(options.response_from)
    result.add_timings(clock)
    return result


def merge_paths(paths: Sequence[str | Path], *,
                exposures: Sequence[float | str] | None = None,
                exposures_from: str | Path | None = None,
                options: MergeOptions = MergeOptions(), progress: Progress | None = None,
                read_progress: Callable[[int, int, str], None] | None = None) -> MergeResult:
    """Read brackets and merge them (no output written): what every front end calls.

    ``result.radiance`` is in the input encoding's linear primaries; see
    :func:`hdrio.job.output.output_pixels` for the EXR's space.
    """
    return _read_and_merge(paths, plan_merge(options), exposures=exposures,
                           exposures_from=exposures_from, progress=progress,
                           read_progress=read_progress)


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
                compression: str = "zip", progress: Progress | None = None,
                read_progress: Callable[[int, int, str], None] | None = None,
                display_view: tuple[str, str] | None = None,
                observe: Callable[[np.ndarray], None] | None = None,
                tonemap_parameters: dict[str, float] | None = None,
                compile_ahead: bool = False) -> MergeResult:
    """Read brackets, merge them, write the EXR (and a tone-mapped preview), atomically.

    ``display_view``: render the preview through that OCIO display and view instead of
    the ``tonemap`` operator (with ``tonemap_parameters``). ``compression``: the EXR's
    (:func:`hdrio.io.write.exr_compression`'s names). ``observe`` sees each band of
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
    plan = plan_merge(options)
    if compile_ahead:
        jit.compile_ahead(tonemap if tonemapped else None, merge=lambda: _eight_bit_rgb(paths),
                          motion=plan.aligns or plan.deghosts)
    result = _read_and_merge(paths, plan, exposures=exposures, exposures_from=exposures_from,
                             progress=progress, read_progress=read_progress)
    clock = PhaseClock()
    say(f"writing {output}")
    result.exposure_scale = write_radiance(output, output_pixels(result),
                                           exr_attributes(result), pixel_type=pixel_type,
                                           compression=compression,
                                           alpha=merge_alpha(result), observe=observe,
                                           layers=merge_layers(result))
    clock.lap("write")
    if preview is not None:
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
        clock.lap("preview")
    result.add_timings(clock)
    return result
