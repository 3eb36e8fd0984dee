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

from hdrio import __version__
from hdrio.align.stage import Motion, align_step, check_modes, deghost_step, remerge_step
from hdrio.cms.calibration import Calibration, Region
from hdrio.cms.checks import dynamic_range_stops
from hdrio.cms.luminance import DEFAULT_SPACE, luminance, rgb_chromaticities
from hdrio.cms.spaces import DEFAULT_WORKING_SPACE, require_scene_linear
from hdrio.cms.stage import ColourState, colour_attributes, colour_stage, output_radiance
from hdrio.io.brackets import read_brackets
from hdrio.io.raw import is_raw_stack, xyz_to_working
from hdrio.io.write import HALF_MAX, write_exr, write_preview
from hdrio.merge.debevec1997 import MERGE_METHODS, MergeStatistics
from hdrio.response import RESPONSE_METHODS, CameraResponse
from hdrio.response.stored import read_response
from hdrio.skips import SKIPS, SkipReport, classify
from hdrio.stack import ExposureStack
from hdrio.tonemap import TONEMAP_METHODS, encode_sRGB
from hdrio.tonemap.display import preview_OCIO_display

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
    merge: str = "log"
    # Drop a saturated channel on its own, not the whole pixel (the tutorial's "pixel"):
    # see hdrio/merge/debevec1997.py.
    saturation: str = "channel"
    exclude_colour: tuple[int, ...] | None = None
    seed: int = 0
    # colour-science name of the radiance's primaries: set from the input encoding.
    colourspace: str = DEFAULT_SPACE
    # Colour management (hdrio.cms): see docs/colour.md.
    input_encoding: str | None = None  # when the files do not say; None: sRGB
    output_space: str = DEFAULT_WORKING_SPACE  # OpenColorIO name of the EXR's space
    ocio_config: str | None = None  # path or ocio:// URI; None: $OCIO, else built-in
    calibration: Calibration | None = None  # None: relative radiance
    white_balance: Region | None = None  # neutral region x, y, w, h; None: camera's
    # A saved response (an EXR written by hdrio) instead of a solve: hdrio.skips.
    response_from: str | None = None
    # Names in hdrio.skips.SKIPS turned off (all on by default).
    no_skip: tuple[str, ...] = ()
    # Registration and deghosting (hdrio.align): docs/motion.md.
    align: str = "auto"  # auto | off | translation | euclidean | homography
    deghost: str = "auto"  # auto | off
    motion_layer: bool = False  # the deghosting mask as an EXR channel "motion.Y"

    @property
    def skips(self) -> frozenset[str]:
        """The skips (:mod:`hdrio.skips`) in force."""
        return frozenset(SKIPS) - set(self.no_skip)


@dataclass
class MergeResult:
    stack: ExposureStack
    response: CameraResponse
    radiance: np.ndarray
    statistics: MergeStatistics
    options: MergeOptions
    timings: dict[str, float] = field(default_factory=dict)
    exposure_scale: float = 1.0
    colour: ColourState | None = None
    skipped: SkipReport = field(default_factory=SkipReport)
    motion: Motion = field(default_factory=Motion)

    @property
    def dynamic_range_stops(self) -> tuple[float, float]:
        """``(full, robust)``: log2 of max/min luminance, and of its 99.9/0.1 percentiles."""
        return dynamic_range_stops(luminance(self.radiance, self.options.colourspace))


def exclusion_mask(stack: ExposureStack, colour: Sequence[int] | None) -> np.ndarray | None:
    """Pixels equal to ``colour`` in any bracket (registration borders), else ``None``."""
    if colour is None:
        return None
    target = np.asarray(colour, dtype=stack.codes.dtype)
    if target.size != stack.codes.shape[-1]:
        raise ValueError(f"exclusion colour has {target.size} values, images have "
                         f"{stack.codes.shape[-1]} channels")
    return np.any(np.all(stack.codes == target, axis=-1), axis=0)


def merge_stack(stack: ExposureStack, options: MergeOptions = MergeOptions(),
                progress: Progress | None = None,
                response: CameraResponse | None = None, owned: bool = False) -> MergeResult:
    """Recover the response, align and merge ``stack`` (no file I/O).

    ``response``, when given (e.g. read back with :func:`hdrio.response.stored.read_response`),
    is used instead of a solve; camera RAW stacks use the linear response. The skips in
    ``options.skips`` apply (:mod:`hdrio.skips`); ``result.skipped`` says which did.
    ``owned``: the caller hands the stack over (its codes may be warped in place, so
    alignment needs no second copy of the brackets); otherwise ``stack`` is left as is.
    """
    say = progress or (lambda message: None)
    check_modes(options.align, options.deghost)
    skips = options.skips
    skipped = SkipReport(dropped=list(stack.dropped))
    timings: dict[str, float] = {}
    start = time.perf_counter()
    solve = None
    if response is None:
        method = "linear" if is_raw_stack(stack) else options.response
        say(f"camera response: {method}" + ("" if method == "linear"
                                            else f", lambda {options.smoothing:g}"))

        def solve(stack: ExposureStack, exclude: np.ndarray | None) -> CameraResponse:
            return RESPONSE_METHODS[method](
                stack, smoothing=options.smoothing, weighting=options.weighting,
                sampling=options.sampling, samples=options.samples, exclude=exclude,
                seed=options.seed,
                **({"solve_identical_once": "channels" in skips} if method != "linear"
                   else {}))

        response = solve(stack, exclusion_mask(stack, options.exclude_colour))
        skipped.channels_solved = response.parameters.get("channels_solved")
    timings["response"] = time.perf_counter() - start
    start = time.perf_counter()
    if options.align != "off":
        say(f"aligning {stack.count} brackets ({options.align})")
    resolve = solve if options.exclude_colour is None else None
    stack, response, motion = align_step(stack, response, options.align, resolve,
                                         in_place=owned, skip_warp="warp" in skips)
    if motion.alignment is not None and not motion.warped:
        skipped.warp = True
    timings["align"] = time.perf_counter() - start
    start = time.perf_counter()
    if options.deghost != "off":
        say("deghosting")
    response = deghost_step(stack, response, motion, options.deghost, resolve)
    timings["deghost"] = time.perf_counter() - start
    start = time.perf_counter()
    merged = stack
    kinds = stack.kinds
    if "covered" in skips and not all(kinds):  # not looked at when read
        kinds = tuple(classify(codes, stack.code_max) for codes in stack.codes)
    if "covered" in skips and "covers" in kinds:
        j = len(kinds) - 1 - kinds[::-1].index("covers")  # the longest
        skipped.covering = Path(stack.files[j]).name
        merged = ExposureStack.from_arrays(
            stack.codes[j:j + 1], stack.exposures[j:j + 1], files=stack.files[j:j + 1],
            code_max=stack.code_max, exposure_sources=stack.exposure_sources[j:j + 1],
            metadata=stack.metadata[j:j + 1], kinds=("covers",),
            dropped=stack.dropped + tuple((name, f"{skipped.covering} covers the range")
                                          for name in stack.files if name != stack.files[j]))
    say(f"merging {merged.count} brackets ({options.merge} domain)")
    radiance, statistics = MERGE_METHODS[options.merge](
        merged, response, options.weighting, options.saturation,
        early_stop="early-stop" in skips)
    skipped.early_stop_fraction = statistics.observations_skipped / (
        statistics.pixels * merged.count)
    timings["merge"] = time.perf_counter() - start
    start = time.perf_counter()
    if merged is stack:  # not reduced to one covering bracket
        remerge_step(stack, response, radiance, motion, options.weighting,
                     MERGE_METHODS.canonical(options.merge), options.saturation == "channel")
    timings["deghost"] += time.perf_counter() - start
    start = time.perf_counter()
    if is_raw_stack(stack):  # LibRaw gave linear XYZ: into the working space
        radiance = xyz_to_working(radiance, options.colourspace)
    timings["merge"] += time.perf_counter() - start
    radiance, colour = colour_stage(
        stack, response, radiance, input_encoding=options.input_encoding,
        white_balance=options.white_balance, calibration=options.calibration)
    options = replace(options, colourspace=colour.encoding.colour_science)
    return MergeResult(stack, response, radiance, statistics, options, timings, colour=colour,
                       skipped=skipped, motion=motion)


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
        # Exact decimal text: a float list of 2, 3, 9 or 16 would become an EXR vector/matrix.
        "hdrio:exposures": [repr(float(t)) for t in stack.exposures],
        "hdrio:exposureSource": stack.exposure_sources[0],
        "hdrio:codeMax": int(stack.code_max),
        "hdrio:responseMethod": response.method,
        "hdrio:responseLevels": levels,
        "hdrio:weighting": options.weighting,
        "hdrio:lambda": float(options.smoothing),
        "hdrio:sampling": options.sampling,
        "hdrio:samples": int(response.parameters.get("samples", 0)),
        "hdrio:seed": int(options.seed),
        "hdrio:mergeDomain": options.merge,
        "hdrio:saturation": options.saturation,
        "hdrio:clippedFraction": result.statistics.clipped_everywhere
        / result.statistics.pixels,
    }
    skipped = result.skipped.lines(stack.shape[2])
    if skipped:
        attributes["hdrio:skipped"] = "; ".join(skipped)
    attributes.update(motion_attributes(result))
    if options.exclude_colour is not None:
        attributes["hdrio:excludeColor"] = ",".join(str(v) for v in options.exclude_colour)
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
                   space: str = DEFAULT_SPACE, **parameters: float) -> np.ndarray:
    """Tone-map ``radiance`` and encode it for an sRGB display: values in [0, 1].

    ``parameters`` go to the operator (e.g. ``key=0.18`` for the Reinhard operators).
    """
    function = TONEMAP_METHODS[operator]
    canonical = TONEMAP_METHODS.canonical(operator)
    if canonical.endswith("tutorial"):
        display = function(radiance.astype(np.float64), **parameters)
    else:
        display = function(radiance, space=space, **parameters)
    display = np.nan_to_num(display, nan=0.0)
    if display.shape[-1] == 1:
        display = np.repeat(display, 3, axis=-1)
    return encode_sRGB(display)


def merge_files(paths: Sequence[str | Path], output: str | Path, *,
                preview: str | Path | None = None, tonemap: str = "reinhard-global",
                exposures: Sequence[float | str] | None = None,
                exposures_from: str | Path | None = None,
                options: MergeOptions = MergeOptions(), pixel_type: str = "half",
                progress: Progress | None = None,
                read_progress: Callable[[int, int, str], None] | None = None,
                display_view: tuple[str, str] | None = None) -> MergeResult:
    """Read brackets, merge them, write the EXR (and a tone-mapped preview), atomically.

    ``display_view``: render the preview through that OCIO display and view instead of
    the ``tonemap`` operator.
    """
    say = progress or (lambda message: None)
    require_scene_linear(options.output_space, options.ocio_config)  # fail before reading
    response = None
    if options.response_from is not None and "response" in options.skips:
        response = read_response(options.response_from)
    start = time.perf_counter()
    say(f"reading {len(paths)} brackets")
    stack = read_brackets(paths, exposures=exposures, exposures_from=exposures_from,
                          progress=read_progress, skip_brackets="brackets" in options.skips,
                          stop_when_covered=response is not None
                          and "covered" in options.skips)
    read_time = time.perf_counter() - start
    result = merge_stack(stack, options, progress, response, owned=True)
    if response is not None:
        result.skipped.response_from = str(options.response_from)
    result.timings["read"] = read_time
    start = time.perf_counter()
    radiance = result.radiance
    if result.colour is not None:
        radiance = output_radiance(radiance, result.colour, options.output_space,
                                   options.ocio_config)
    if pixel_type == "half":
        result.exposure_scale = half_safe_scale(radiance)
    say(f"writing {output}")
    layers = None
    if options.motion_layer and result.motion.deghosting is not None:
        layers = {"motion.Y": result.motion.deghosting.motion_mask(*radiance.shape[:2])}
    write_exr(output, radiance, exr_attributes(result), pixel_type=pixel_type,
              scale=result.exposure_scale, layers=layers)
    result.timings["write"] = time.perf_counter() - start
    if preview is not None:
        start = time.perf_counter()
        if display_view is not None and result.colour is not None:
            say(f"rendering preview ({' / '.join(display_view)})")
            pixels = preview_OCIO_display(
                result.radiance, result.colour.encoding.linear_interop_id, *display_view,
                colourspace=options.colourspace, config=options.ocio_config)
        else:
            say(f"tone mapping preview ({tonemap})")
            pixels = render_preview(result.radiance, tonemap, options.colourspace)
        write_preview(preview, pixels)
        result.timings["preview"] = time.perf_counter() - start
    return result
