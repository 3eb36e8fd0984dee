"""What a merge writes: the EXR's pixels (in the output space, scaled into half's range),
its extra layers and alpha, and its header (``chromaticities``, capture and provenance
under ``hdrio:``; docs/cli.md lists them)."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hdrio import __version__
from hdrio.cms.colour_stage import colour_attributes, output_radiance
from hdrio.io.orientation import UPRIGHT, turned
from hdrio.io.paths import resolved, with_relative_sources
from hdrio.io.write import HALF_MAX, Window, write_exr
from hdrio.job.result import MergeResult
from hdrio.merge.weighted_mean import MergeStatistics, clipped_everywhere_mask
from hdrio.radiometry.levels import code_of
from hdrio.radiometry.luminance import rgb_chromaticities
from hdrio.stack import ExposureStack


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
    spacing = str(response.parameters.get("spacing", "even"))
    at = code_of(levels, response.code_max, spacing)  # every code a level: whole codes
    curves = np.stack([np.interp(at, np.arange(response.code_max + 1), g)
                       for g in response.log_inverse.T], axis=1)
    attributes: dict[str, object] = {
        "chromaticities": rgb_chromaticities(options.colourspace),
        "Software": f"hdrio {__version__}",
        "hdrio:version": __version__,
        "hdrio:units": "relative",
        "hdrio:exposureScale": float(result.exposure_scale),
        "hdrio:sourceFiles": [resolved(name) for name in stack.files],
        # Decimal text: a float list of 2, 3, 9 or 16 would become an EXR vector/matrix.
        "hdrio:exposures": [exposure_text(t) for t in stack.exposures],
        "hdrio:exposureSource": stack.exposure_sources[0],
        "hdrio:codeMax": int(stack.code_max),
        "hdrio:responseMethod": response.method,
        "hdrio:responseLevels": levels,
        "hdrio:responseSpacing": spacing,
        "hdrio:weighting": options.weighting,
        "hdrio:lambda": float(options.smoothing),
        "hdrio:sampling": options.sampling,
        "hdrio:samples": int(response.parameters.get("samples", 0)),
        "hdrio:seed": int(options.seed),
        "hdrio:merge": result.plan.estimator.name,
        "hdrio:mergeDomain": result.plan.estimator.domain,
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
    orientations = turned(stack.metadata)
    if any(o != UPRIGHT for o in orientations):  # the pixels are upright; the files were not
        attributes["hdrio:sourceOrientation"] = [str(o) for o in orientations]
    if result.exposures is not None:
        attributes.update(result.exposures.attributes())
    if result.nd is not None:
        attributes.update(result.nd.attributes())
    if result.noise is not None:
        attributes.update(result.noise.attributes())
    if result.uncertainty is not None:
        finite = result.uncertainty[np.isfinite(result.uncertainty)]  # a copy
        attributes["hdrio:uncertainty"] = (
            "layer uncertainty: predicted relative standard deviation sigma/E per channel")
        if finite.size:  # partitioned in place: no second copy (288 MB at 24 MP)
            median, p99 = np.percentile(finite, [50, 99], overwrite_input=True)
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
    policy = statistics.policy
    if policy is None or policy.rule == "channel":
        return "channel: a channel at its limit is dropped alone"
    if policy.rule == "pixel":
        return "pixel: an observation with any channel at its limit is dropped whole"
    share = "" if policy.dropped is None else f" ({100 * policy.dropped:.0f} % of them)"
    shortest = ("whole (the channels mix after the clip)" if policy.neutral
                else "channel by channel")
    return ("test: a partly clipped observation is dropped whole where its other channels "
            f"disagree with the next shorter bracket's{share}, else its clipped channels "
            f"alone; in the shortest bracket {shortest}")


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
        attributes["hdrio:alignReference"] = resolved(result.stack.files[alignment.reference])
        attributes["hdrio:alignWarped"] = int(motion.warped)
        attributes["hdrio:alignTransforms"] = [
            " ".join(f"{v:.6g}" for v in warp.reshape(-1)[:8])
            for warp in alignment.transforms]
        attributes["hdrio:alignUncovered"] = float(motion.uncovered)
        refused = [j for j, _ in alignment.refused]
        if refused and motion.warped:  # merged unwarped where only they see the scene
            attributes["hdrio:alignUnregistered"] = [
                str(result.stack.files[j]) for j in refused]
            attributes["hdrio:alignUnregisteredFraction"] = motion.unregistered_fraction()
        if alignment.by_highlights and motion.warped:
            attributes["hdrio:alignByHighlights"] = [
                str(result.stack.files[j]) for j in alignment.by_highlights]
    if motion.deghosting is not None:
        attributes["hdrio:deghostedFraction"] = float(motion.deghosting.fraction)
        if result.motion_test_exposures is not None:
            attributes["hdrio:deghostExposures"] = [
                exposure_text(t) for t in result.motion_test_exposures]
    return attributes


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
        if result.motion.unregistered is not None:  # seen by an unregistered bracket only
            height, width = result.radiance.shape[:2]
            cells = result.motion.unregistered
            size = result.motion.deghosting.cell
            layers["motion"] = np.maximum(layers["motion"], np.repeat(np.repeat(
                cells, size, 0), size, 1)[:height, :width].astype(np.float32))
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
                   layers: dict[str, np.ndarray] | None = None,
                   positive: bool = True,
                   channels: dict[str, np.ndarray] | None = None,
                   window: Window | None = None) -> float:
    """Write scene-linear ``pixels`` as EXR, scaled into half's range when needed.

    ``scale`` is the factor already applied to the merged radiance (``--exposure``);
    ``hdrio:exposureScale`` (and ``whiteLuminance`` for absolute units) record it times
    the half-range factor, which is returned. ``alpha`` ``(H, W, 1)``, when given, is
    written unscaled as channel A. ``observe`` sees each band as stored. ``layers``: extra
    unscaled layers (:func:`hdrio.io.write.write_exr`), e.g. ``uncertainty``, and
    ``channels`` under their own names (an input's); ``positive`` false keeps zeros and
    negative values (an image the chain read); ``window`` places the pixels in a larger
    frame (an input's, :class:`hdrio.io.write.Window`). Source
    paths get their copies relative to ``path`` (:func:`hdrio.io.paths.with_relative_sources`).
    """
    extra = half_safe_scale(pixels) if pixel_type == "half" else 1.0
    attributes = with_relative_sources(attributes, path)
    attributes["hdrio:exposureScale"] = float(scale * extra)
    if "whiteLuminance" in attributes:  # OpenEXR: cd/m^2 of RGB (1, 1, 1) as stored
        attributes["whiteLuminance"] = 1.0 / float(scale * extra)
    if alpha is not None:  # the band scaling below must leave alpha as it is
        pixels = np.concatenate([pixels, alpha / np.float32(extra)], axis=-1)
    write_exr(path, pixels, attributes, pixel_type=pixel_type, compression=compression,
              scale=extra, observe=observe, layers=layers, positive=positive,
              channels=channels, window=window)
    return extra
