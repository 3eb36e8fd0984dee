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
from hdrio.cms.luminance import normalised_primary_matrix
from hdrio.errors import HdrioError, InputError, library_message
from hdrio.parallel import read_ahead

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
    masked_fraction: float | None = None
    """Pixels masked in every bracket (alpha 0; ``hdrio:maskedFraction``)."""
    delta_E: list[float] | None = None
    uncertainty: dict[str, float] | None = None
    """Of the ``uncertainty`` layer (``hdrio merge --uncertainty``): its median, 99th
    percentile and the fraction of pixels above 10 % (relative standard deviation)."""
    source: str = ""
    notes: list[str] = field(default_factory=list)


def dynamic_range_stops(Y: np.ndarray) -> tuple[float, float]:
    """``(full, robust)``: log2 of max/min positive ``Y``, and of its 99.9/0.1 percentiles."""
    Y = np.asarray(Y, dtype=np.float64)
    Y = Y[np.isfinite(Y) & (Y > 0)]
    if Y.size == 0:
        return 0.0, 0.0
    low, high = np.percentile(Y, [0.1, 99.9])
    return float(np.log2(Y.max() / Y.min())), float(np.log2(high / low))


def check_chart_region(region: Region, width: int, height: int) -> None:
    """Raise unless the 6 x 4 chart ``region`` lies inside a ``width x height`` image."""
    x, y, w, h = region
    if w < 12 or h < 8 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise HdrioError(f"chart region {x},{y},{w},{h} must lie inside the {width}x{height} "
                         "image and span at least 2 pixels per patch")


def chart_patches(rgb: np.ndarray, region: Region) -> np.ndarray:
    """Mean RGB ``(24, 3)`` of the central half of each patch of a 6 x 4 chart region.

    Patches in reading order, dark skin at top left, black at bottom right.
    """
    x, y, w, h = region
    check_chart_region(region, rgb.shape[1], rgb.shape[0])
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

    measured = chart_patches(rgb, region) @ normalised_primary_matrix(chromaticities).T
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
    to_xyz = normalised_primary_matrix(chromaticities)
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


def _gamut_matrix(chromaticities: tuple[float, ...], gamut: str | None) -> np.ndarray | None:
    """RGB (own primaries) to ``gamut`` RGB, Bradford-adapted; ``None`` for own primaries."""
    if gamut is None:
        return None
    import colour

    space = colour.RGB_COLOURSPACES[gamut]
    return space.matrix_XYZ_to_RGB @ colour.adaptation.matrix_chromatic_adaptation_VonKries(
        colour.xy_to_XYZ(np.asarray(chromaticities[6:8])),
        colour.xy_to_XYZ(space.whitepoint), transform="Bradford") @ normalised_primary_matrix(
        chromaticities)


# Luminance histogram of StreamingCheck: the float32 bit pattern of a positive number,
# shifted right by this many bits, orders bins of relative width 2**-(23 - shift).
_BIN_SHIFT = 12
_BINS = 1 << (31 - _BIN_SHIFT)


class StreamingCheck:
    """The checks of :func:`check_pixels`, fed band by band (constant memory).

    ``add(rows)`` takes ``(rows, W, C)`` pixels (first three channels RGB, any float
    dtype) as stored; :meth:`report` gives the :class:`CheckReport`. Minimum, maximum,
    counts and gamut are exact; luminance percentiles come from a histogram of
    luminance with bins 2**-11 (0.05 %) wide in relative terms, so they are within
    0.05 % of the exact order statistics. ``hdrio check`` and the report after a merge
    (fed as the EXR is written) both use it, so they print the same numbers.
    """

    def __init__(self, chromaticities: tuple[float, ...] = REC709_D65, *,
                 units: str = "relative", clipped_fraction: float | None = None,
                 gamut: str | None = None, masked_fraction: float | None = None) -> None:
        self.chromaticities = tuple(float(v) for v in chromaticities)
        self.units, self.clipped_fraction, self.gamut = units, clipped_fraction, gamut
        self.masked_fraction = masked_fraction
        self._weights = normalised_primary_matrix(self.chromaticities)[1].astype(np.float32)
        to_gamut = _gamut_matrix(self.chromaticities, gamut)
        self._use_gamut = to_gamut is not None
        self._to_gamut = (np.eye(3) if to_gamut is None else to_gamut).astype(np.float32)
        self._counts = np.zeros(_BINS, dtype=np.int64)
        self.pixels = self.negative = self.non_finite = self.outside = 0
        self._low, self._high = np.inf, 0.0

    @classmethod
    def for_attributes(cls, attributes: dict[str, object], **kwargs) -> StreamingCheck:
        """A check of an image whose header is ``attributes`` (chromaticities, units)."""
        def plain(name: str, default: object) -> object:
            value = attributes.get(name, default)
            return getattr(value, "value", value)

        clipped = plain("hdrio:clippedFraction", None)
        masked = plain("hdrio:maskedFraction", None)
        kwargs.setdefault("masked_fraction", None if masked is None else float(masked))  # type: ignore[arg-type]
        return cls(tuple(plain("chromaticities", REC709_D65)),  # type: ignore[arg-type]
                   units=str(plain("hdrio:units", "unknown")),
                   clipped_fraction=None if clipped is None else float(clipped),  # type: ignore[arg-type]
                   **kwargs)

    def add(self, rows: np.ndarray) -> None:
        """Count one band ``(rows, W, C)`` of the image (half or float32 kept as they
        are; other dtypes are converted to float32)."""
        from hdrio.cms import check_kernel

        rows = np.asarray(rows)
        if rows.shape[-1] == 1:  # greyscale: Y as equal R, G, B
            rows = np.repeat(rows, 3, axis=-1)
        if rows.dtype not in (np.float16, np.float32):
            rows = rows.astype(np.float32)
        rows = np.ascontiguousarray(rows).reshape(-1, rows.shape[-1])
        extremes = np.array([np.inf, 0.0], np.float32)
        half = rows.dtype == np.float16
        bad, negative, outside = check_kernel.count_rows(
            rows.view(np.uint16) if half else rows,
            check_kernel.HALF_TABLE, self._weights, self._to_gamut,
            self._use_gamut, self._counts, _BIN_SHIFT, extremes)
        self.pixels += rows.shape[0]
        self.non_finite += int(bad)
        self.negative += int(negative)
        self.outside += int(outside)
        if extremes[1] > 0:
            self._low = min(self._low, float(extremes[0]))
            self._high = max(self._high, float(extremes[1]))

    def _order_statistic(self, cumulative: np.ndarray, k: int) -> float:
        """The ``k``-th smallest luminance (0-based): its bin's centre, within the
        exact extremes."""
        index = int(np.searchsorted(cumulative, k + 1))
        centre = np.array([(index << _BIN_SHIFT) + (1 << (_BIN_SHIFT - 1))],
                          dtype=np.int32).view(np.float32)[0]
        return min(max(float(centre), self._low), self._high)

    def _percentile(self, q: float) -> float:
        """As ``numpy.percentile`` (linear between order statistics), from the bins."""
        cumulative = np.cumsum(self._counts)
        rank = q / 100.0 * (int(cumulative[-1]) - 1)
        k = int(np.floor(rank))
        low = self._order_statistic(cumulative, k)
        if rank == k:
            return low
        high = self._order_statistic(cumulative, k + 1)
        return low + (rank - k) * (high - low)

    def report(self, source: str = "", clipped_fraction: float | None = None,
               masked_fraction: float | None = None) -> CheckReport:
        """The :class:`CheckReport` of everything added so far."""
        counted = int(self._counts.sum())
        percentiles: dict[str, float] = {}
        full = robust = 0.0
        if counted:
            percentiles = {name: self._percentile(q)
                           for name, q in (("p1", 1), ("median", 50), ("p99", 99))}
            full = float(np.log2(self._high / self._low))
            robust = float(np.log2(self._percentile(99.9) / self._percentile(0.1)))
        clipped = self.clipped_fraction if clipped_fraction is None else clipped_fraction
        return CheckReport(
            pixels=self.pixels, units=self.units, dynamic_range_stops=full,
            robust_range_stops=robust, luminance_percentiles=percentiles,
            negative=self.negative, non_finite=self.non_finite,
            out_of_gamut=self.outside / max(self.pixels, 1),
            gamut="own primaries" if self.gamut is None else self.gamut,
            clipped_fraction=clipped, source=source,
            masked_fraction=self.masked_fraction if masked_fraction is None
            else masked_fraction)


_ROWS_PER_READ = 512


def check_exr(path: str | Path, *, chart: Region | None = None, gamut: str | None = None
              ) -> CheckReport:
    """Check ``path`` (RGB channels, any EXR) band by band with :class:`StreamingCheck`.

    Memory stays at two bands of 512 rows (plus the chart region's rows when given).
    """
    import OpenImageIO as oiio

    from hdrio.io.header import read_header

    header = read_header(path)
    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(path, f"cannot read image ({library_message(oiio.geterror)})")
    try:
        spec = image.spec()
        names = list(spec.channelnames)
        grey = not {"R", "G", "B"} <= set(names) and "Y" in names
        if not grey and not {"R", "G", "B"} <= set(names):
            raise InputError(path, f"has channels {','.join(names)}; checks need R, G, B "
                                   "(or Y alone)")
        # Greyscale: Y as equal R, G, B (whose luminance is Y whatever the primaries).
        order = [names.index(c) for c in ("YYY" if grey else "RGB")]
        layer = [names.index(n) for n in names if n.startswith("uncertainty.")]
        samples = []  # every 4th row and column of the uncertainty layer
        check = StreamingCheck.for_attributes(header, gamut=gamut)
        delta_E = None
        # Half files are read as half (half the bytes to convert); add() decodes them.
        pixel_type = "half" if str(spec.format) == "half" else "float"

        def bands():
            for top in range(spec.y, spec.y + spec.height, _ROWS_PER_READ):
                bottom = min(top + _ROWS_PER_READ, spec.y + spec.height)
                rows = image.read_scanlines(0, 0, top, bottom, 0, 0, spec.nchannels,
                                            pixel_type)
                if rows is None or image.has_error:
                    raise InputError(path, f"cannot decode pixels "
                                           f"({library_message(image.geterror)})")
                yield np.asarray(rows).reshape(bottom - top, spec.width, -1)

        for rows in read_ahead(bands()):  # the next band decodes while this one counts
            check.add(rows if order == [0, 1, 2] and rows.shape[-1] == 3
                      else rows[..., order])
            if layer:
                samples.append(np.array(rows[::4, ::4][..., layer], dtype=np.float32))
        if chart is not None:  # read the chart's rows only
            x, y, w, h = chart
            check_chart_region(chart, spec.width, spec.height)
            rows = image.read_scanlines(0, 0, spec.y + y, spec.y + y + h, 0, 0,
                                        spec.nchannels, "float")
            band = np.asarray(rows).reshape(h, spec.width, -1)[..., order]
            delta_E = chart_delta_E(band, (x, 0, w, h), check.chromaticities)
    finally:
        image.close()
    report = check.report(str(path))
    report.delta_E = delta_E
    if samples:
        report.uncertainty = uncertainty_summary(np.concatenate(
            [band.reshape(-1) for band in samples]))
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
                     "saturated in every bracket"
                     + ("" if not report.masked_fraction else " (of those not masked)"))
    if report.masked_fraction:
        lines.append(f"  masked:       {100 * report.masked_fraction:.2f} % of pixels "
                     "excluded in every bracket (alpha 0)")
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
