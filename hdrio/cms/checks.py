"""``hdrio check``: what a compositor should know about an EXR before trusting it.

Computed with colour-science from the pixels and the file's own ``chromaticities``
(Rec.709 primaries and D65 when absent, as OpenEXR specifies): luminance, dynamic range
in stops, negative and non-finite values, the fraction of pixels outside a target gamut,
the fraction clipped in every bracket (recorded by ``hdrio merge``), and, for a
ColorChecker 24 region, the patches' CIE Delta E 2000 against their reference values.
"""

from __future__ import annotations

import contextlib
import io
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hdrio.cms.calibration import Region
from hdrio.cms.chart import chart_delta_E, check_chart_region
from hdrio.errors import HdrioError, InputError
from hdrio.io.header import require_exr
from hdrio.parallel import on_threads, threads
from hdrio.radiometry.luminance import normalised_primary_matrix

REC709_D65 = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)


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


def check_pixels(rgb: np.ndarray, chromaticities: tuple[float, ...] = REC709_D65, *,
                 units: str = "relative", clipped_fraction: float | None = None,
                 gamut: str | None = None, chart: Region | None = None) -> CheckReport:
    """Checks of linear ``rgb`` ``(H, W, 3)`` whose primaries are ``chromaticities``.

    ``gamut``: a colour-science RGB space name to count pixels outside of (converted
    with Bradford adaptation); default the pixels' own space (then: any channel < 0).
    """
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
    to_gamut = _gamut_matrix(chromaticities, gamut)
    target = rgb if to_gamut is None else rgb @ to_gamut.T
    gamut_name = "own primaries" if gamut is None else gamut
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
_CHUNK_PIXELS = 1 << 16
"""Pixels counted per NumPy pass: each float32 temporary (256 KB) stays in cache."""
_OUTSIDE = np.float32(-1e-6)
"""Outside a gamut: a channel below this fraction of the pixel's luminance (float
rounding is not)."""


def _count_chunk(red, green, blue, weights, to_gamut, partial, bins) -> None:
    """Add one chunk of pixels (flat planes) to ``partial`` (non-finite, negative and
    outside counts, lowest and highest positive finite luminance) and its luminance
    histogram to ``bins`` as ``(first bin, counts)``.

    float32 throughout, in the order of :func:`check_pixels`' definitions: ``Y`` the
    weighted sum of R, G, B; non-finite where ``Y`` is (the weights are positive, so
    exactly where a channel is); negative where the least channel is below 0 (NaN is
    not); outside where a finite pixel's least channel in the target gamut (its own
    primaries without ``to_gamut``) is below -1e-6 of ``|Y|``.
    """
    with np.errstate(invalid="ignore", over="ignore"):  # inf - inf: non-finite, counted
        _count_float32_chunk(*(np.asarray(plane, dtype=np.float32)
                               for plane in (red, green, blue)),
                             weights, to_gamut, partial, bins)


def _count_float32_chunk(r, g, b, weights, to_gamut, partial, bins) -> None:
    """:func:`_count_chunk` of float32 planes."""
    Y = r * weights[0]
    Y += g * weights[1]
    Y += b * weights[2]
    finite = np.isfinite(Y)
    lowest = np.minimum(r, g)
    np.minimum(lowest, b, out=lowest)
    negative = lowest < 0
    partial[0] += Y.size - int(np.count_nonzero(finite))
    partial[1] += int(np.count_nonzero(negative))
    if to_gamut is None:  # outside its own primaries: only where a channel is negative
        where = np.flatnonzero(negative)
        low, Yw = lowest[where], Y[where]
    else:
        m = to_gamut
        low = np.minimum(np.minimum(m[0, 0] * r + m[0, 1] * g + m[0, 2] * b,
                                    m[1, 0] * r + m[1, 1] * g + m[1, 2] * b),
                         m[2, 0] * r + m[2, 1] * g + m[2, 2] * b)
        Yw = Y
    partial[2] += int(np.count_nonzero(np.isfinite(Yw) & (low < _OUTSIDE * np.abs(Yw))))
    positive = Y[finite & (Y > 0)]
    if positive.size:
        codes = positive.view(np.int32) >> _BIN_SHIFT
        first = int(codes.min())
        bins.append((first, np.bincount(codes - first)))
        partial[3] = min(partial[3], float(positive.min()))
        partial[4] = max(partial[4], float(positive.max()))


class StreamingCheck:
    """The checks of :func:`check_pixels`, fed band by band (constant memory).

    ``add(rows)`` takes ``(rows, W, C)`` pixels (first three channels RGB, any float
    dtype) as stored; :meth:`report` gives the :class:`CheckReport`. Minimum, maximum,
    counts and gamut are exact; luminance percentiles come from a histogram of
    luminance with bins 2**-11 (0.05 %) wide in relative terms, so they are within
    0.05 % of the exact order statistics. ``hdrio check`` and the report after a merge
    (fed as the EXR is written) both use it, so they print the same numbers.

    ``compiled``: count with numba's kernel (:mod:`hdrio.cms.check_counts`: one pass, no
    GIL), as the writer does, whose process runs numba anyway; else with NumPy, which
    ``hdrio check`` uses since it never loads numba (0.5 s a 24 MP check here, against
    1.0 s with numba's start-up). Both count the same, bit for bit.
    """

    def __init__(self, chromaticities: tuple[float, ...] = REC709_D65, *,
                 units: str = "relative", clipped_fraction: float | None = None,
                 gamut: str | None = None, masked_fraction: float | None = None,
                 compiled: bool = False) -> None:
        self.compiled = compiled
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
        self._lock = threading.Lock()

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
        """Count one band ``(rows, W, C)`` of the image (first three channels RGB, as
        stored: half, float32 or any dtype NumPy converts to float32; one channel is
        greyscale, Y as equal R, G, B)."""
        rows = np.asarray(rows)
        pixels = rows.reshape(-1, rows.shape[-1])  # a view: rows are a writer's pieces
        self.add_planes(*(pixels[:, 0 if rows.shape[-1] == 1 else c] for c in range(3)))

    def add_planes(self, red: np.ndarray, green: np.ndarray, blue: np.ndarray) -> None:
        """Count pixels given as three planes of one shape (any dtype that converts to
        float32). Safe to call from several threads at once (the counts are merged under
        a lock), which is how :func:`check_exr` and the writer
        (:func:`hdrio.io.write.write_exr`) count an image on every core."""
        count = self._count_compiled if self.compiled else self._count_numpy
        pixels, partial, bins = count(red, green, blue)
        with self._lock:
            self.pixels += pixels
            self.non_finite += partial[0]
            self.negative += partial[1]
            self.outside += partial[2]
            self._low, self._high = min(self._low, partial[3]), max(self._high, partial[4])
            for first, histogram in bins:
                self._counts[first:first + histogram.size] += histogram

    def _count_numpy(self, red, green, blue) -> tuple[int, list, list]:
        """``(pixels, [non-finite, negative, outside, low, high], [(first bin, counts)])``
        of three planes, in chunks of NumPy passes."""
        red, green, blue = (np.ravel(plane) for plane in (red, green, blue))
        partial = [0, 0, 0, np.inf, 0.0]  # non-finite, negative, outside, low, high
        bins: list[tuple[int, np.ndarray]] = []
        for start in range(0, red.size, _CHUNK_PIXELS):
            chunk = slice(start, start + _CHUNK_PIXELS)
            _count_chunk(red[chunk], green[chunk], blue[chunk], self._weights,
                         self._to_gamut if self._use_gamut else None, partial, bins)
        return red.size, partial, bins

    def _count_compiled(self, red, green, blue) -> tuple[int, list, list]:
        """:meth:`_count_numpy`'s numbers, bit for bit, from one pass of
        :func:`hdrio.cms.check_counts.count_pixels` (half planes read as stored)."""
        from hdrio.cms.check_counts import count_pixels

        planes = [np.asarray(plane) for plane in (red, green, blue)]
        if all(plane.dtype == np.float16 for plane in planes):
            planes = [plane.view(np.uint16) for plane in planes]
        else:
            planes = [plane.astype(np.float32, copy=False) for plane in planes]
        planes = [plane.reshape(-1) for plane in planes]
        *partial, first, histogram = count_pixels(*planes, self._weights, self._to_gamut,
                                                  self._use_gamut, _BIN_SHIFT)
        partial[3], partial[4] = float(partial[3]), float(partial[4])
        return planes[0].size, partial, [(first, histogram)] if histogram.size else []

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


def check_exr(path: str | Path, *, chart: Region | None = None, gamut: str | None = None
              ) -> CheckReport:
    """Check ``path`` (RGB channels, or Y alone; part 0 of any EXR) with
    :class:`StreamingCheck`, counting on every core.

    The pixels are decoded by OpenEXR (half the CPU time of OpenImageIO's reader for a
    ZIP-compressed half image), on every core, as whole planes, as stored: a 24 MP half
    RGB image holds 144 MB, plus the uncertainty layer's plane when there is one.
    """
    import OpenEXR

    from hdrio.io.header import read_header
    from hdrio.io.native import quiet_native_output

    require_exr(path)
    try:
        header = read_header(path)
    except InputError as error:
        raise InputError(path, f"a damaged or truncated OpenEXR file: {error.problem}"
                         ) from None
    # OpenEXR's own threads decompress the line blocks (24 MP: 0.45 s on one, 0.21 s on two).
    OpenEXR.set_global_thread_count(threads())
    try:
        # OpenEXR prints what it found broken (through Python's stdout, or the C++
        # library's) and returns no parts: one line of ours.
        with quiet_native_output(), contextlib.redirect_stdout(io.StringIO()), \
                OpenEXR.File(str(path), separate_channels=True) as exr:
            planes = {name: channel.pixels for part in exr.parts[:1]
                      for name, channel in part.channels.items()}
    except Exception as error:  # what OpenEXR raises for a file it cannot open
        raise InputError(path, f"cannot decode pixels ({error})") from None
    if not planes:
        raise InputError(path, "cannot decode pixels: the file is damaged or truncated")
    names = list(planes)
    grey = not {"R", "G", "B"} <= set(names) and "Y" in names
    if not grey and not {"R", "G", "B"} <= set(names):
        raise InputError(path, f"has channels {','.join(names)}; checks need R, G, B "
                               "(or Y alone)")
    # Greyscale: Y as equal R, G, B (whose luminance is Y whatever the primaries).
    rgb = [planes[c] for c in ("YYY" if grey else "RGB")]
    check = StreamingCheck.for_attributes(header, gamut=gamut)
    on_threads(lambda top, bottom: check.add_planes(*(p[top:bottom] for p in rgb)),
               rgb[0].shape[0])
    delta_E = None
    if chart is not None:
        x, y, w, h = chart
        check_chart_region(chart, rgb[0].shape[1], rgb[0].shape[0])
        band = np.stack([p[y:y + h] for p in rgb], axis=-1).astype(np.float32)
        delta_E = chart_delta_E(band, (x, 0, w, h), check.chromaticities)
    report = check.report(str(path))
    report.delta_E = delta_E
    layer = [planes[n] for n in names if n.startswith("uncertainty.")]
    if layer:  # every 4th row and column
        report.uncertainty = uncertainty_summary(np.concatenate(
            [np.asarray(p[::4, ::4], dtype=np.float32).reshape(-1) for p in layer]))
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
