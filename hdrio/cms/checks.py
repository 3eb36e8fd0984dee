"""``hdrio check``: what a compositor should know about an EXR before trusting it.

Computed with colour-science from the pixels and the file's own ``chromaticities``
(Rec.709 primaries and D65 when absent, as OpenEXR specifies): luminance, dynamic range
in stops, negative and non-finite values, the fraction of pixels outside a target gamut,
the fraction clipped in every bracket (recorded by ``hdrio merge``), and, for a
ColorChecker 24 region, the patches' CIE Delta E 2000 against their reference values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hdrio.cms.calibration import Region
from hdrio.errors import HdrioError, InputError, library_message

REC709_D65 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
COLORCHECKER = "ColorChecker24 - After November 2014"
NEUTRAL_PATCHES = slice(18, 24)  # white 9.5 .. black 2, the chart's bottom row


@dataclass
class CheckReport:
    """Results of :func:`check_pixels`; ``None`` where a check did not apply."""

    pixels: int
    units: str
    dynamic_range_stops: float
    robust_range_stops: float
    luminance_percentiles: dict[str, float]
    negative: int
    non_finite: int
    out_of_gamut: float
    gamut: str
    clipped_fraction: float | None = None
    delta_E: list[float] | None = None
    uncertainty: dict[str, float] | None = None
    """Of the ``uncertainty`` layer (``hdrio merge --uncertainty``): its median, 99th
    percentile and the fraction of pixels above 10 % (relative standard deviation)."""
    source: str = ""
    notes: list[str] = field(default_factory=list)


def rgb_to_xyz_matrix(chromaticities: tuple[float, ...]) -> np.ndarray:
    """The normalised primary matrix of an OpenEXR ``chromaticities`` (8 floats)."""
    import colour

    values = np.asarray(chromaticities, dtype=np.float64)
    return colour.normalised_primary_matrix(values[:6].reshape(3, 2), values[6:])


def dynamic_range_stops(Y: np.ndarray) -> tuple[float, float]:
    """``(full, robust)``: log2 of max/min positive ``Y``, and of its 99.9/0.1 percentiles."""
    Y = np.asarray(Y, dtype=np.float64)
    Y = Y[np.isfinite(Y) & (Y > 0)]
    if Y.size == 0:
        return 0.0, 0.0
    low, high = np.percentile(Y, [0.1, 99.9])
    return float(np.log2(Y.max() / Y.min())), float(np.log2(high / low))


def chart_patches(rgb: np.ndarray, region: Region) -> np.ndarray:
    """Mean RGB ``(24, 3)`` of the central half of each patch of a 6 x 4 chart region.

    Patches in reading order, dark skin at top left, black at bottom right.
    """
    x, y, w, h = region
    height, width = rgb.shape[:2]
    if w < 12 or h < 8 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise HdrioError(f"chart region {x},{y},{w},{h} must lie inside the {width}x{height} "
                         "image and span at least 2 pixels per patch")
    means = []
    for row in range(4):
        for column in range(6):
            left, right = x + (column + 0.25) * w / 6, x + (column + 0.75) * w / 6
            top, bottom = y + (row + 0.25) * h / 4, y + (row + 0.75) * h / 4
            patch = rgb[int(top): max(int(bottom), int(top) + 1),
                        int(left): max(int(right), int(left) + 1)]
            means.append(patch.reshape(-1, 3).astype(np.float64).mean(axis=0))
    return np.asarray(means)


def chart_delta_E(rgb: np.ndarray, region: Region, chromaticities: tuple[float, ...]
                  ) -> list[float]:
    """CIE Delta E 2000 of each ColorChecker patch against colour-science's reference.

    Exposure is unknown, so measured ``XYZ`` is first scaled (least squares on ``Y`` of
    the six neutral patches) to the reference. Both sides go to CIE Lab under the file's
    white; the reference (D50) is adapted to it with Bradford.
    """
    import colour

    measured = chart_patches(rgb, region) @ rgb_to_xyz_matrix(chromaticities).T
    chart = colour.CCS_COLOURCHECKERS[COLORCHECKER]
    white = np.asarray(chromaticities[6:8], dtype=np.float64)
    reference = colour.chromatic_adaptation(
        colour.xyY_to_XYZ(np.asarray(list(chart.data.values()))),
        colour.xy_to_XYZ(chart.illuminant), colour.xy_to_XYZ(white), method="Von Kries",
        transform="Bradford")
    Y_m, Y_r = measured[NEUTRAL_PATCHES, 1], reference[NEUTRAL_PATCHES, 1]
    scale = float(np.dot(Y_m, Y_r) / np.dot(Y_m, Y_m))
    if not np.isfinite(scale) or scale <= 0:
        raise HdrioError("chart region: the neutral patches have no light")
    lab_measured = colour.XYZ_to_Lab(measured * scale, white)
    lab_reference = colour.XYZ_to_Lab(reference, white)
    return [float(v) for v in colour.delta_E(lab_measured, lab_reference, method="CIE 2000")]


def check_pixels(rgb: np.ndarray, chromaticities: tuple[float, ...] = REC709_D65, *,
                 units: str = "relative", clipped_fraction: float | None = None,
                 gamut: str | None = None, chart: Region | None = None) -> CheckReport:
    """Checks of linear ``rgb`` ``(H, W, 3)`` whose primaries are ``chromaticities``.

    ``gamut``: a colour-science RGB space name to count pixels outside of (converted
    with Bradford adaptation); default the pixels' own space (then: any channel < 0).
    """
    import colour

    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.ndim != 3 or rgb.shape[-1] != 3:
        raise HdrioError(f"checks need RGB pixels, got shape {rgb.shape}")
    finite = np.all(np.isfinite(rgb), axis=-1)
    to_xyz = rgb_to_xyz_matrix(chromaticities)
    Y = rgb @ to_xyz[1]
    full, robust = dynamic_range_stops(Y[finite])
    values = Y[finite]
    percentiles = dict(zip(("p1", "median", "p99"),
                           (float(v) for v in np.percentile(values, [1, 50, 99])))) \
        if values.size else {}
    if gamut is None:
        target, gamut_name = rgb, "own primaries"
    else:
        space = colour.RGB_COLOURSPACES[gamut]
        target = rgb @ (space.matrix_XYZ_to_RGB @ colour.adaptation.
                        matrix_chromatic_adaptation_VonKries(
                            colour.xy_to_XYZ(np.asarray(chromaticities[6:8])),
                            colour.xy_to_XYZ(space.whitepoint), transform="Bradford")
                        @ to_xyz).T
        gamut_name = gamut
    # Outside: a channel below -1e-6 of the pixel's luminance (float rounding is not).
    outside = np.any(target < -1e-6 * np.abs(Y)[..., None], axis=-1) & finite
    return CheckReport(
        pixels=int(finite.size), units=units, dynamic_range_stops=full,
        robust_range_stops=robust, luminance_percentiles=percentiles,
        negative=int(np.count_nonzero(np.any(rgb < 0, axis=-1))),
        non_finite=int(np.count_nonzero(~finite)), out_of_gamut=float(outside.mean()),
        gamut=gamut_name, clipped_fraction=clipped_fraction,
        delta_E=None if chart is None else chart_delta_E(rgb, chart, chromaticities))


def check_exr(path: str | Path, *, chart: Region | None = None, gamut: str | None = None
              ) -> CheckReport:
    """Read ``path`` (RGB channels, any EXR) and run :func:`check_pixels` on it."""
    import OpenImageIO as oiio

    from hdrio.io.header import read_header

    header = read_header(path)
    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(path, f"cannot read image ({library_message(oiio.geterror)})")
    try:
        names = list(image.spec().channelnames)
        grey = not {"R", "G", "B"} <= set(names) and "Y" in names
        if not grey and not {"R", "G", "B"} <= set(names):
            raise InputError(path, f"has channels {','.join(names)}; checks need R, G, B "
                                   "(or Y alone)")
        pixels = image.read_image("float")
        if pixels is None:
            raise InputError(path, f"cannot decode pixels ({library_message(image.geterror)})")
    finally:
        image.close()
    pixels = np.asarray(pixels).reshape(*np.shape(pixels)[:2], len(names))
    # Greyscale: Y as equal R, G, B (whose luminance is Y whatever the primaries).
    rgb = pixels[..., [names.index(c) for c in ("YYY" if grey else "RGB")]]
    layer = [names.index(n) for n in names if n.startswith("uncertainty.")]
    chromaticities = tuple(header.get("chromaticities", REC709_D65))
    clipped = header.get("hdrio:clippedFraction")
    report = check_pixels(rgb, chromaticities, units=str(header.get("hdrio:units", "unknown")),
                          clipped_fraction=None if clipped is None else float(clipped),
                          gamut=gamut, chart=chart)
    report.source = str(path)
    if layer:
        report.uncertainty = uncertainty_summary(pixels[..., layer])
    if grey:
        report.notes.append("greyscale (Y): luminance checks only, no colour")
    elif "chromaticities" not in header:
        report.notes.append("no chromaticities: assumed Rec.709 primaries, D65")
    return report


def uncertainty_summary(layer: np.ndarray) -> dict[str, float]:
    """Median, 99th percentile and share above 10 % of a relative-uncertainty layer."""
    values = np.asarray(layer, dtype=np.float64)
    values = values[np.isfinite(values)]
    if not values.size:
        return {"median": math.nan, "p99": math.nan, "above_10pct": math.nan}
    median, p99 = np.percentile(values, [50, 99])
    return {"median": float(median), "p99": float(p99),
            "above_10pct": float(np.mean(values > 0.1))}


def format_report(report: CheckReport) -> str:
    """The report as aligned lines (``hdrio check``, and after ``hdrio merge``)."""
    p = report.luminance_percentiles
    lines = [f"check:     {report.source}" if report.source else "check:",
             f"  range:        {report.dynamic_range_stops:.1f} stops (0.1-99.9 percentile: "
             f"{report.robust_range_stops:.1f} stops)"]
    if p:
        lines.append(f"  luminance:    median {p['median']:.4g}, 1 % {p['p1']:.4g}, 99 % "
                     f"{p['p99']:.4g} ({report.units})")
    lines += [f"  negative:     {report.negative} pixels; non-finite: {report.non_finite}",
              f"  out of gamut: {100 * report.out_of_gamut:.3f} % ({report.gamut})"]
    if report.clipped_fraction is not None:
        lines.append(f"  clipped:      {100 * report.clipped_fraction:.2f} % of pixels "
                     "saturated in every bracket")
    if report.delta_E is not None:
        dE = np.asarray(report.delta_E)
        lines.append(f"  chart:        Delta E 2000 mean {dE.mean():.2f}, max {dE.max():.2f} "
                     f"(patch {int(dE.argmax()) + 1})")
    if report.uncertainty is not None:
        u = report.uncertainty
        lines.append(f"  uncertainty:  median {100 * u['median']:.2f} %, 99 % "
                     f"{100 * u['p99']:.1f} % (relative sigma); "
                     f"{100 * u['above_10pct']:.2f} % of values above 10 %")
    lines += [f"  note:         {note}" for note in report.notes]
    return "\n".join(lines)
