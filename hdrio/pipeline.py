"""The one place that chains the steps: brackets -> response -> radiance -> EXR (+ preview).

Every front end (the command line, the Blender add-on) calls these functions.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from hdrio import __version__, jit
from hdrio.align.deghost import CELL
from hdrio.align.registration import align_masks
from hdrio.align.stage import Motion, align_step, check_modes, deghost_step, remerge_step
from hdrio.cms.calibration import Calibration, Region
from hdrio.cms.checks import dynamic_range_stops
from hdrio.cms.encoding import resolve_encoding
from hdrio.cms.luminance import DEFAULT_SPACE, luminance, rgb_chromaticities
from hdrio.cms.spaces import DEFAULT_WORKING_SPACE, require_scene_linear
from hdrio.cms.stage import ColourState, colour_attributes, colour_stage, output_radiance
from hdrio.errors import HdrioError, ResponseSolveError
from hdrio.io.brackets import read_brackets
from hdrio.io.brackets import read_header as read_bracket_header
from hdrio.io.masks import mask_files, read_masks
from hdrio.io.paths import check_inputs, check_outputs
from hdrio.io.raw import is_raw, is_raw_stack, xyz_to_working
from hdrio.io.write import HALF_MAX, write_exr, write_preview
from hdrio.merge.debevec1997 import MergeStatistics, clipped_everywhere_mask, estimate_tables
from hdrio.merge.estimators import (
    MERGE_METHODS,
    NOISE_AWARE,
    effective_weights,
    merge_domain,
)
from hdrio.merge.exclusion import colour_exclusion, either, masked_statistics, remerge_excluded
from hdrio.merge.exposures import ExposureCheck, exposures_from_data
from hdrio.merge.highlights import HIGHLIGHT_MODES, HighlightReport, reconstruct_highlights
from hdrio.merge.ladder import (
    in_brightness_order,
    infer_exposures,
    needs_inference,
    starting_response,
)
from hdrio.merge.nd import NDFilter, NDReport, filter_gains, nd_stops, unfiltered, with_nd
from hdrio.merge.noise import NoiseModel, code_variance_floor, fit_noise
from hdrio.merge.uncertainty import relative_uncertainty
from hdrio.numbers import MERGE_NUMBERS, check_fields, check_tonemap_parameters
from hdrio.response import RESPONSE_METHODS, CameraResponse
from hdrio.response.stored import check_response_fits, read_response
from hdrio.skips import SKIPS, SkipReport, classify
from hdrio.stack import ExposureStack
from hdrio.tonemap import TONEMAP_METHODS, encode_sRGB
from hdrio.tonemap.display import preview_OCIO_display
from hdrio.tonemap.reinhard2002 import DELTA, log_average_luminance

Progress = Callable[[str], None]


@dataclass(frozen=True)
class MergeOptions:
    """How to turn a stack into radiance; every field is recorded in the EXR header."""

    response: str = "Debevec1997"
    smoothing: float = 50.0
    # The paper's triangle (zero at both ends) rather than the tutorial's never-zero hat:
    # the hat lets saturated and black observations pull g(255) and g(0) and leak into
    # the merge (median error 6 % against 1.2 % on the demo; see docs/method.md).
    weighting: str = "Debevec1997"
    sampling: str = "stratified"
    samples: int | None = None
    # Inverse-variance weights from the stack's own noise model (hdrio.merge.estimators):
    # on the truth harness's core stacks median error 1.03 % against 1.25 % for the
    # tutorial's log-domain triangle-weighted mean ("log"), p99 3.4 % against 4.8 %.
    merge: str = "inverse-variance"
    # "auto": an observation counts only where every channel is safely below its own white
    # level when the stack shows its channels mixed after the clip (hue-true on camera
    # JPEGs), else channel by channel (hdrio/merge/saturation.py).
    saturation: str = "auto"
    exclude_colour: tuple[int, ...] | None = None
    # --mask files (hdrio.io.masks): kept out of the solve and the merge, as the colour.
    masks: tuple[str, ...] = ()
    # Merge with each bracket's exposure estimated from the data (hdrio.merge.exposures);
    # the metadata's are checked against the data's either way.
    exposures_from_data: bool = False
    # --nd: brackets shot through a neutral-density filter (hdrio.merge.nd).
    nd: tuple[NDFilter, ...] = ()
    seed: int = 0
    # colour-science name of the radiance's primaries: set from the input encoding.
    colourspace: str = DEFAULT_SPACE
    # Colour management (hdrio.cms): see docs/colour.md.
    input_encoding: str | None = None  # when the files do not say; None: sRGB
    output_space: str = DEFAULT_WORKING_SPACE  # OpenColorIO name of the EXR's space
    ocio_config: str | None = None  # path or ocio:// URI; None: $OCIO, else built-in
    calibration: Calibration | None = None  # None: relative radiance
    white_balance: Region | None = None  # neutral region x, y, w, h; None: camera's
    # Camera RAW white-balance multipliers R, G, B for the set; None: as shot.
    raw_multipliers: tuple[float, float, float] | None = None
    # A saved response (an EXR written by hdrio) instead of a solve: hdrio.skips.
    response_from: str | None = None
    # Names in hdrio.skips.SKIPS turned off (all on by default).
    no_skip: tuple[str, ...] = ()
    # Also predict each pixel's relative standard deviation (hdrio.merge.uncertainty),
    # written as the EXR layer "uncertainty".
    uncertainty: bool = False
    # Registration and deghosting (hdrio.align): docs/motion.md.
    # auto | off | translation | euclidean | homography.
    align: str = "auto"
    # auto | off.
    deghost: str = "auto"
    motion_layer: bool = False  # the deghosting mask as an EXR channel "motion.Y"
    clip_mask: bool = False  # pixels clipped in every bracket as an EXR channel "clipped.Y"
    # clip | reconstruct: channels clipped in every bracket estimated from the unclipped
    # ones and the neighbours' colour (hdrio.merge.highlights); clip leaves the bounds.
    highlights: str = "clip"

    def __post_init__(self) -> None:
        check_fields(self, MERGE_NUMBERS)  # --lambda, --samples, --seed: before any work

    @property
    def skips(self) -> frozenset[str]:
        """The skips (:mod:`hdrio.skips`) in force."""
        return frozenset(SKIPS) - set(self.no_skip)


class PhaseClock:
    """Wall-clock and CPU seconds per phase of a run: :meth:`lap` adds the time since
    the last lap (or the start) to a phase."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self._wall, self._cpu = time.perf_counter(), time.process_time()

    def lap(self, phase: str) -> None:
        wall, cpu = time.perf_counter(), time.process_time()
        self.wall[phase] = self.wall.get(phase, 0.0) + wall - self._wall
        self.cpu[phase] = self.cpu.get(phase, 0.0) + cpu - self._cpu
        self._wall, self._cpu = wall, cpu


@dataclass
class MergeResult:
    stack: ExposureStack
    response: CameraResponse
    radiance: np.ndarray
    statistics: MergeStatistics
    options: MergeOptions
    timings: dict[str, float] = field(default_factory=dict)
    """Wall-clock seconds per phase (``response``, ``align``, ``deghost``, ``merge``, ...)."""
    cpu_timings: dict[str, float] = field(default_factory=dict)
    """The same phases' CPU seconds (``time.process_time``: every thread of the process),
    which a loaded machine inflates less than the wall clock (the benchmarks' ratios)."""
    exposure_scale: float = 1.0
    colour: ColourState | None = None
    skipped: SkipReport = field(default_factory=SkipReport)
    noise: NoiseModel | None = None
    uncertainty: np.ndarray | None = None
    """``sigma_E / E`` per pixel and channel (``--uncertainty``), else ``None``."""
    motion: Motion = field(default_factory=Motion)
    exposures: ExposureCheck | None = None
    """The metadata's exposures against the data's (three brackets or more)."""
    nd: NDReport | None = None
    unseen: np.ndarray | None = None
    """``(H, W)`` bool: excluded in every bracket (radiance 0, alpha 0), else ``None``."""
    highlights: HighlightReport | None = None
    """What ``--highlights reconstruct`` changed (``None``: not asked, or nothing clipped)."""

    @property
    def dynamic_range_stops(self) -> tuple[float, float]:
        """``(full, robust)``: log2 of max/min luminance, and of its 99.9/0.1 percentiles."""
        return dynamic_range_stops(luminance(self.radiance, self.options.colourspace))


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
    if needs_inference(stack):  # no exposure metadata: order by brightness, before masks
        stack = in_brightness_order(stack)
    masks = read_masks(options.masks, stack.files, stack.shape[:2])  # in the stack's order
    excluded = exclusions(stack, options, masks)
    if response is not None:
        check_response_fits(response, stack.code_max, stack.shape[2])
    else:
        method = "linear" if is_raw_stack(stack) else options.response
        if method != "linear":
            jit.announce(say, "response")
        say(f"camera response: {method}" + ("" if method == "linear"
                                            else f", lambda {options.smoothing:g}"))

        def solve(stack: ExposureStack, exclude: np.ndarray | None) -> CameraResponse:
            if filtered is not None and np.count_nonzero(filtered == 0) >= 2:
                stack = unfiltered(stack, filtered)  # a filter's cast would bend g
            return RESPONSE_METHODS[method](
                stack, smoothing=options.smoothing, weighting=options.weighting,
                sampling=options.sampling, samples=options.samples, exclude=exclude,
                seed=options.seed,
                **({"solve_identical_once": "channels" in skips} if method != "linear"
                   else {}))

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
    if needs_inference(stack):  # no metadata: the ladder from the pixels (--exposures-from-data)
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
    if merged is stack and excluded is not None:
        unseen = remerge_excluded(stack.codes, stack.channel_exposures, response, radiance,
                                  excluded,
                                  motion.keep, CELL, weights, merge_domain(method),
                                  options.saturation == "channel")
        statistics = masked_statistics(stack.codes, excluded, stack.code_max, statistics)
    elif merged is stack:  # not reduced to one covering bracket
        remerge_step(stack, response, radiance, motion, weights, merge_domain(method),
                     not statistics.pixel_rule, statistics.limits,  # the policy's
                     noise if noise is not None else before)
    clock.lap("deghost")
    highlights = None
    if options.highlights == "reconstruct":
        say("reconstructing highlights clipped in every bracket")
        highlights = reconstruct_highlights(
            radiance, merged.codes[0],
            statistics.limits or (merged.code_max,) * merged.shape[2],
            estimate_tables(response, merged.channel_exposures, "linear")[0],
            statistics.pixel_rule,
            None if excluded is None or merged is not stack else ~excluded[0])
        skipped.highlights = highlights is None
        clock.lap("highlights")
    uncertainty = None
    if options.uncertainty:
        say("predicting each pixel's uncertainty")
        uncertainty = relative_uncertainty(merged, response, weights, noise,
                                           merge_domain(method),
                                           "pixel" if statistics.pixel_rule else "channel")
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


def half_safe_scale(radiance: np.ndarray) -> float:
    """The largest power of two ``<= 1`` that brings ``radiance`` within half's range."""
    peak = float(np.max(radiance))
    if peak <= HALF_MAX:
        return 1.0
    return 2.0 ** -math.ceil(math.log2(peak / HALF_MAX))


def exr_attributes(result: MergeResult) -> dict[str, object]:
    """The EXR header: ``chromaticities`` plus provenance under ``hdrio:`` (see docs)."""
    stack, response, options = result.stack, result.response, result.options
    levels = int(response.parameters.get("levels", response.code_max + 1))
    positions = np.rint(np.arange(levels) * (response.code_max / (levels - 1))).astype(int)
    curves = response.log_inverse[positions]
    attributes: dict[str, object] = {
        "chromaticities": rgb_chromaticities(options.colourspace),
        "Software": f"hdrio {__version__}",
        "hdrio:version": __version__,
        "hdrio:units": "relative",
        "hdrio:exposureScale": float(result.exposure_scale),
        "hdrio:sourceFiles": [str(name) for name in stack.files],
        # Decimal text: a float list of 2, 3, 9 or 16 would become an EXR vector/matrix.
        "hdrio:exposures": [exposure_text(t) for t in stack.exposures],
        "hdrio:exposureSource": stack.exposure_sources[0],
        "hdrio:codeMax": int(stack.code_max),
        "hdrio:responseMethod": response.method,
        "hdrio:responseLevels": levels,
        "hdrio:weighting": options.weighting,
        "hdrio:lambda": float(options.smoothing),
        "hdrio:sampling": options.sampling,
        "hdrio:samples": int(response.parameters.get("samples", 0)),
        "hdrio:seed": int(options.seed),
        "hdrio:merge": MERGE_METHODS.canonical(options.merge),
        "hdrio:mergeDomain": merge_domain(options.merge),
        "hdrio:saturation": options.saturation,
        "hdrio:clippedFraction": result.statistics.clipped_fraction,
        "hdrio:highlights": options.highlights,
    }
    if result.highlights is not None:
        attributes["hdrio:highlightsReconstructed"] = result.highlights.text()
    if result.statistics.limits:
        attributes["hdrio:saturationRule"] = saturation_rule(result.statistics)
        attributes["hdrio:saturationLimits"] = ", ".join(
            f"{name} {limit}" for name, limit in zip("RGB" if response.channels == 3 else "Y",
                                                      result.statistics.limits))
    if options.clip_mask:
        attributes["hdrio:clipMask"] = ("layer clipped: 1 where the pixel is clipped in "
                                        "every bracket (merged to a neutral lower bound"
                                        + (", then reconstructed" if result.highlights
                                           else "") + ")")
    attributes.update(capture_attributes(stack))
    if result.exposures is not None:
        attributes.update(result.exposures.attributes())
    if result.nd is not None:
        attributes.update(result.nd.attributes())
    if result.noise is not None:
        attributes.update(result.noise.attributes())
    if result.uncertainty is not None:
        finite = result.uncertainty[np.isfinite(result.uncertainty)]
        attributes["hdrio:uncertainty"] = (
            "layer uncertainty: predicted relative standard deviation sigma/E per channel")
        if finite.size:
            median, p99 = np.percentile(finite, [50, 99])
            attributes["hdrio:uncertaintyMedian"] = float(median)
            attributes["hdrio:uncertaintyP99"] = float(p99)
    skipped = result.skipped.lines(stack.shape[2])
    if skipped:
        attributes["hdrio:skipped"] = "; ".join(skipped)
    attributes.update(motion_attributes(result))
    if options.exclude_colour is not None:
        attributes["hdrio:excludeColor"] = ",".join(str(v) for v in options.exclude_colour)
    if options.masks:
        attributes["hdrio:masks"] = [str(name) for name in options.masks]
    if options.exclude_colour is not None or options.masks:  # unseen: alpha 0
        statistics = result.statistics
        attributes["hdrio:maskedFraction"] = statistics.masked_everywhere / statistics.pixels
    if result.colour is not None:
        attributes.update(colour_attributes(result.colour, options.output_space,
                                            options.ocio_config, result.exposure_scale))
    names = "RGB" if response.channels == 3 else "Y"
    supported = []
    for c, name in enumerate(names[: response.channels]):
        attributes[f"hdrio:response{name}"] = [float(v) for v in curves[:, c]]
        codes = np.flatnonzero(response.supported[:, c])
        supported.append(f"{name} {codes[0]}-{codes[-1]}" if codes.size else f"{name} none")
    attributes["hdrio:responseSupport"] = ", ".join(supported)
    return attributes


def saturation_rule(statistics: MergeStatistics) -> str:
    """What the saturation policy dropped, in words (the summary, ``hdrio:saturationRule``)."""
    if statistics.pixel_rule:
        return "pixel: an observation with any channel at its limit is dropped whole"
    return "channel: a channel at its limit is dropped alone"


def exposure_text(seconds: float) -> str:
    """The shortest decimal that reads back as ``seconds``: ``0.01``, not
    ``0.009999999776482582``, for a time that EXIF stored as a 32-bit float."""
    seconds = float(seconds)
    single = np.float32(seconds)
    if float(single) == seconds:  # a 32-bit value: its own shortest form
        return np.format_float_positional(single, unique=True, trim="-")
    return repr(seconds)


def capture_attributes(stack: ExposureStack) -> dict[str, object]:
    """Capture time and camera of the first bracket, from its EXIF, as OpenImageIO names
    them (``DateTime`` is EXR's ``capDate``). An unknown time is written as none (an
    empty ``DateTime``), not as the time of writing."""
    first = stack.metadata[0] if stack.metadata else {}
    attributes: dict[str, object] = {"DateTime": str(first.get("DateTimeOriginal") or "")}
    for name in ("Make", "Model"):
        if first.get(name):
            attributes[name] = str(first[name])
    return attributes


def motion_attributes(result: MergeResult) -> dict[str, object]:
    """``hdrio:align*`` and ``hdrio:deghost*``: the modes, each bracket's warp (text: the
    3x3 matrix, reference pixels to bracket pixels), the deghosted fraction."""
    options, motion = result.options, result.motion
    attributes: dict[str, object] = {"hdrio:align": options.align,
                                     "hdrio:deghost": options.deghost}
    if motion.alignment is not None:
        alignment = motion.alignment
        attributes["hdrio:alignModel"] = alignment.model
        attributes["hdrio:alignReference"] = str(result.stack.files[alignment.reference])
        attributes["hdrio:alignWarped"] = int(motion.warped)
        attributes["hdrio:alignTransforms"] = [
            " ".join(f"{v:.6g}" for v in warp.reshape(-1)[:8])
            for warp in alignment.transforms]
        attributes["hdrio:alignUncovered"] = float(motion.uncovered)
    if motion.deghosting is not None:
        attributes["hdrio:deghostedFraction"] = float(motion.deghosting.fraction)
    return attributes


def render_preview(radiance: np.ndarray, operator: str = "reinhard-global",
                   space: str = DEFAULT_SPACE, unseen: np.ndarray | None = None,
                   **parameters: float) -> np.ndarray:
    """Tone-map ``radiance`` and encode it for an sRGB display: values in [0, 1].

    ``parameters`` go to the operator (e.g. ``key=0.18`` for the Reinhard operators).
    Greyscale radiance (``(H, W, 1)``) is tone-mapped as grey RGB (its luminance is its
    one channel, since the weights sum to 1) and encoded as RGB. ``unseen`` ``(H, W)``
    pixels (masked everywhere) are shown black and leave the key as the rest gives it:
    they are filled, for the operator, with grey at the others' log-average luminance
    (which does not move eq. 1's mean).
    """
    function = TONEMAP_METHODS[operator]
    canonical = TONEMAP_METHODS.canonical(operator)
    check_tonemap_parameters(canonical, parameters)
    if radiance.shape[-1] == 1:
        radiance = np.repeat(radiance, 3, axis=-1)
    if unseen is not None:
        seen = luminance(radiance[~unseen], space)
        radiance = radiance.copy()
        radiance[unseen] = log_average_luminance(seen) - DELTA if seen.size else 0.0
    if canonical.endswith("tutorial"):
        display = function(radiance.astype(np.float64), **parameters)
    else:
        display = function(radiance, space=space, **parameters)
    display = np.nan_to_num(display, nan=0.0)
    if display.shape[-1] == 1:
        display = np.repeat(display, 3, axis=-1)
    if unseen is not None:
        display[unseen] = 0.0
    return encode_sRGB(display)


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


def output_pixels(result: MergeResult) -> np.ndarray:
    """The merge's radiance in the EXR's working space (``options.output_space``)."""
    if result.colour is None:
        return result.radiance
    return output_radiance(result.radiance, result.colour, result.options.output_space,
                           result.options.ocio_config)


def merge_layers(result: MergeResult) -> dict[str, np.ndarray]:
    """The EXR layers the options ask for beside the pixels: ``uncertainty``, ``motion``
    (``--motion-layer``), ``clipped`` (``--clip-mask``)."""
    options = result.options
    layers = {} if result.uncertainty is None else {"uncertainty": result.uncertainty}
    if options.motion_layer and result.motion.deghosting is not None:
        layers["motion"] = result.motion.deghosting.motion_mask(*result.radiance.shape[:2])
    if options.clip_mask:
        limits = result.statistics.limits or (result.stack.code_max,) * result.stack.shape[2]
        layers["clipped"] = clipped_everywhere_mask(result.stack.codes[0], limits)
    return layers


def merge_alpha(result: MergeResult) -> np.ndarray | None:
    """The EXR's alpha, ``(H, W, 1)``: 0 where every bracket was masked out (``--mask``,
    ``--exclude-color``), 1 elsewhere; None when nothing was masked everywhere."""
    return None if result.unseen is None else (~result.unseen)[..., None].astype(np.float32)


def write_radiance(path: str | Path, pixels: np.ndarray, attributes: dict[str, object], *,
                   pixel_type: str = "half", compression: str = "zip", scale: float = 1.0,
                   alpha: np.ndarray | None = None,
                   observe: Callable[[np.ndarray], None] | None = None,
                   layers: dict[str, np.ndarray] | None = None) -> float:
    """Write scene-linear ``pixels`` as EXR, scaled into half's range when needed.

    ``scale`` is the factor already applied to the merged radiance (``--exposure``);
    ``hdrio:exposureScale`` (and ``whiteLuminance`` for absolute units) record it times
    the half-range factor, which is returned. ``alpha`` ``(H, W, 1)``, when given, is
    written unscaled as channel A. ``observe`` sees each band as stored. ``layers``: extra
    unscaled layers (:func:`hdrio.io.write.write_exr`), e.g. ``uncertainty``.
    """
    extra = half_safe_scale(pixels) if pixel_type == "half" else 1.0
    attributes = dict(attributes)
    attributes["hdrio:exposureScale"] = float(scale * extra)
    if "whiteLuminance" in attributes:  # OpenEXR: cd/m^2 of RGB (1, 1, 1) as stored
        attributes["whiteLuminance"] = 1.0 / float(scale * extra)
    if alpha is not None:  # the band scaling below must leave alpha as it is
        pixels = np.concatenate([pixels, alpha / np.float32(extra)], axis=-1)
    write_exr(path, pixels, attributes, pixel_type=pixel_type, compression=compression,
              scale=extra, observe=observe, layers=layers)
    return extra


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
