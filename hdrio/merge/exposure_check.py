"""Each bracket's relative exposure from the data (``--exposures-from-data``).

EXIF exposure times are nominal (a camera's "1/30 s" is 1/32 s, shutters and apertures
drift): an error of 1/3 stop in one bracket bends the solved response and leaves a band
in the merge. With the recovered response ``g = ln f^-1``, a pixel well exposed in
brackets ``j`` and ``k`` gives ``ln(t_k / t_j) = g(z_k) - g(z_j)``; the median over
every such pixel and channel is a robust estimate of the ratio (moving objects, a few
clipped or noisy codes do not move it). The ratios of neighbouring brackets (and those
two apart) are fitted by weighted least squares to one log exposure per bracket, a
weak tie to the metadata's ratios keeps brackets with no overlap where the metadata
puts them, and the whole set is anchored to the metadata by the median offset (one
wrong bracket does not move the others). Iterating estimate and response solve is
Mitsunaga & Nayar's scheme (the ratio update of their eq. 9, here as a median in the
log domain).

References
----------
Mitsunaga, T., Nayar, S. K. (1999). Radiometric self calibration. CVPR 1999, 374-380.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hdrio.errors import InputError
from hdrio.io.exposure import EV_STEPS
from hdrio.io.staging import strided_copy
from hdrio.parallel import map_on_threads
from hdrio.radiometry.curve import CameraResponse
from hdrio.skips import well_exposed_codes
from hdrio.stack import (
    ExposureStack,
    distinct_exposures,
    first_too_close,
    repeated_exposures,
)

WARN_STOPS = 1 / 6
"""A bracket whose estimate differs from its metadata by more than this is named."""
TEST_STOPS = 0.1
"""Off by more than this (about 7 %), a bracket's exposure from the data replaces the
metadata's in deghosting's test (:meth:`ExposureCheck.for_the_motion_test`): the
estimates have errors of their own, up to 0.05 stop on a generated JPEG tripod stack
whose exposures are exact (``tests/hard_cases.py``' ``tripod_stack``)..."""
TEST_MAX_STOPS = 0.5
"""... and by at most this: further off, the metadata is wrong or the estimate is (brackets
that moved between exposures: the check runs before they are registered), and the user
is told (:data:`WARN_STOPS`)."""
WELL_EXPOSED_CODES = (0.15, 0.9)
"""Codes used, as fractions of ``code_max``: away from the noise floor and the shoulder
(deeper than 8 bits, as far down in light as on sRGB codes: :func:`compared_codes`)."""
MAX_PIXELS = 1 << 18
"""Pixels per bracket looked at (a regular subsample of larger images)."""
MIN_OVERLAP = 200
"""Observations (pixel-channels) a pair of brackets must share to be compared."""
PRIOR_WEIGHT = 1e-3
"""Weight of the metadata's ratio of neighbours, against ``sqrt(overlap)`` for data."""
SLOPE_BOUND = 1.25
"""Through a response not solved from the brackets (``--response linear``, a saved one),
their exposure steps measuring more than this times the metadata's, or less than its
inverse (:func:`exposure_slope`), say that the response does not fit them
(:meth:`ExposureCheck.response_misfit`). Measured at stop 55
(``tests/test_merge_exposures.py``): linear 16-bit brackets through the linear response
0.986-0.999 (the generator's tripod and hand-held ladders); sRGB-encoded brackets
through it 0.51-0.61 (memorial, frobisher, ``ghost/``, the canal), 0.48 (a generated
PNG tripod ladder), 0.73 (a phone-like night stack of JPEGs); a response solved from
the brackets 0.989-1.003, as it fits the metadata's steps."""


def compared_codes(response: CameraResponse) -> tuple[int, int]:
    """``(low, high)``: the codes ``low .. high`` that brackets are compared on
    (:data:`WELL_EXPOSED_CODES`, through ``response`` for deep codes:
    :func:`hdrio.skips.well_exposed_codes`). On a linear 16-bit ladder 15-90 % of the
    range is 2.6 stops, and neighbours 2 EV apart shared 0.6 of them: its two shortest
    brackets, which see little but a sun and a sky, were measured 0.44 stop brighter
    than they are (stop 52)."""
    return well_exposed_codes(response.code_max, WELL_EXPOSED_CODES,
                              np.exp(response.log_inverse).T)


def estimate_exposures(codes: np.ndarray, exposures: np.ndarray,
                       response: CameraResponse, unmeasured: Sequence[int] = (),
                       exclude: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Relative exposures ``(P,)`` of ``codes`` ``(P, H, W, C)`` (shortest first) from
    the data, in the units of ``exposures`` (the metadata's, which anchor the set), and
    the data's exposure steps over the metadata's (:func:`exposure_slope`, NaN with
    fewer than three brackets measured).

    Parameters
    ----------
    codes
        Code values of the brackets, sorted by increasing exposure.
    exposures
        The metadata's exposures (seconds, or any relative unit).
    response
        The camera response whose ``log_inverse`` linearises the codes.
    unmeasured
        Brackets whose pixels say nothing of their exposure (on a hand-held stack, those
        that could not be registered: their pixels are not the others' scene points).
        They keep the metadata's exposure, and neither they nor their pairs move the
        others' estimates or the anchor.
    exclude
        ``(H, W)`` pixels not compared (a warp's borders and sharp edges), or ``None``.
    """
    meta = np.log(np.asarray(exposures, np.float64))
    log_t, _ = fit_log_exposures(codes, response, prior=meta, unmeasured=unmeasured,
                                 exclude=exclude)
    measured = np.ones(meta.size, bool)
    measured[list(unmeasured)] = False
    slope = exposure_slope(log_t[measured], meta[measured])
    found = meta.copy()
    found[measured] = anchor_Theil_Sen(log_t[measured], meta[measured], slope)
    return np.exp(found), slope


def fit_log_exposures(codes: np.ndarray, response: CameraResponse,
                      prior: np.ndarray | None = None, unmeasured: Sequence[int] = (),
                      exclude: np.ndarray | None = None) -> tuple[np.ndarray, list[int]]:
    """``(log_t, unlinked)``: natural-log exposures ``(P,)`` of ``codes`` (brackets in
    increasing exposure), up to a common offset (``log_t[0] = 0`` when nothing else
    fixes it), fitted by weighted least squares to the median log ratios of brackets one
    and two apart; and the cuts ``c`` (between bracket ``c`` and ``c + 1``) that no
    measured ratio spans (empty when every bracket is placed by the data).

    ``prior``: log exposures whose neighbouring ratios tie the fit weakly (the
    metadata's; they place a bracket with no overlap). Without it, an unlinked cut
    leaves the brackets on either side unrelated (their offset is arbitrary).
    ``unmeasured``: brackets whose pixels are not compared (only ``prior`` places
    them); ``exclude``: ``(H, W)`` pixels not compared.
    """
    count, height, width, channels = codes.shape
    stride = max(1, math.ceil(math.sqrt(height * width / MAX_PIXELS)))
    sample = strided_copy(codes, stride).reshape(count, -1, channels)  # staged: paged out
    low, high = compared_codes(response)
    columns = np.arange(channels)
    log_e = response.log_inverse[sample, columns]
    good = (sample >= low) & (sample <= high) & response.supported[sample, columns]
    good[list(unmeasured)] = False
    if exclude is not None:
        good &= ~exclude[::stride, ::stride].reshape(1, -1, 1)
    pairs = [(j, k) for j in range(count) for k in range(j + 1, min(count, j + 3))]

    def measured(pair: tuple[int, int]) -> tuple[int, float]:
        """The pair's overlap, and the median log ratio over it (NaN when too small)."""
        j, k = pair
        both = good[j] & good[k]
        overlap = int(np.count_nonzero(both))
        return overlap, (float(np.median(log_e[k][both] - log_e[j][both]))
                         if overlap >= MIN_OVERLAP else math.nan)

    rows, targets, weights = [], [], []
    linked = np.zeros(max(count - 1, 0), bool)
    for (j, k), (overlap, ratio) in zip(pairs, map_on_threads(measured, pairs)):
        if overlap >= MIN_OVERLAP:
            rows.append((j, k))
            targets.append(ratio)
            weights.append(math.sqrt(overlap))
            linked[j:k] = True
        if k == j + 1 and prior is not None:  # the weak tie to the metadata
            rows.append((j, k))
            targets.append(prior[k] - prior[j])
            weights.append(PRIOR_WEIGHT)
    design = np.zeros((len(rows) + 1, count))
    for r, (j, k) in enumerate(rows):
        design[r, j], design[r, k] = -weights[r], weights[r]
    design[-1, 0] = 1.0  # the gauge; the caller's anchor replaces it
    target = np.append(np.asarray(targets) * np.asarray(weights), 0.0)
    log_t = np.linalg.lstsq(design, target, rcond=None)[0]
    return log_t, [int(c) for c in np.flatnonzero(~linked)]


def exposure_slope(log_t: np.ndarray, meta: np.ndarray) -> float:
    """The Theil-Sen slope of ``log_t`` (the data's log exposures) against ``meta`` (the
    metadata's): the median of the pairwise slopes, the data's stops per metadata stop.
    NaN for fewer than three different exposures (two give one slope, which cannot tell
    a wrong exposure from a wrong response; a repeat adds none)."""
    if distinct_exposures(np.exp(meta)) < 3:
        return math.nan
    j, k = np.triu_indices(log_t.size, 1)
    spread = meta[k] - meta[j]
    ok = np.abs(spread) > 1e-9
    return float(np.median((log_t[k] - log_t[j])[ok] / spread[ok]))


def anchor_Theil_Sen(log_t: np.ndarray, meta: np.ndarray,
                     slope: float | None = None) -> np.ndarray:
    """``log_t`` mapped onto the metadata's scale: ``(log_t - c) / s`` for the
    Theil-Sen line ``log_t = s meta + c`` (the median of the pairwise slopes,
    :func:`exposure_slope`, when ``slope`` is not given already measured; then of the
    offsets), so one wrong bracket moves neither. A set of brackets and its response
    are only known up to such a line (``g -> s g + c``, ``ln t -> s ln t + c``: the
    exponent ambiguity of self-calibration); the metadata's spacing fixes it. Two
    brackets give no slope: only the offset is fitted."""
    slope = exposure_slope(log_t, meta) if slope is None else slope
    if not slope > 0:  # the data contradict the order (or no slope): trust only the offset
        slope = 1.0
    offset = float(np.median(log_t - slope * meta))
    return (log_t - offset) / slope


@dataclass(frozen=True)
class ExposureCheck:
    """The metadata's exposures against the data's, per bracket (shortest first).

    Attributes
    ----------
    files
        The brackets.
    metadata, estimated
        Relative exposures (the metadata's units): as read, and from the data.
    used
        Whether the merge used ``estimated`` (``--exposures-from-data``).
    inferred
        With no metadata at all (:mod:`hdrio.merge.ladder`): how the set was anchored,
        e.g. ``"step inferred: 2 stops"``; ``metadata`` then holds the anchor's
        exposures and ``estimated`` is relative to :attr:`reference`. Empty otherwise.
    reference
        The bracket whose inferred exposure is 1 (with ``inferred`` and no ``exif``).
    exif
        With ``inferred``, when some brackets kept an EXIF exposure time (a set where
        only some files have metadata): those times, NaN for the others; the estimates
        are then in their units (seconds).
    unmeasured
        Brackets the data could not check (on a hand-held stack, those that could not be
        registered: :func:`estimate_exposures`): their ``estimated`` is the metadata's
        (with ``inferred``: placed by the ladder's step).
    deferred
        Provisional exposures (``inferred`` ``"provisional"``) to register brackets with:
        the error their inference before registration raised, which stands unless the
        registered brackets give them (:func:`hdrio.job.stages.registered_exposures`).
    slope
        The data's exposure steps over the metadata's, before the estimates were
        anchored to it (:func:`exposure_slope`; NaN where not measured).
    response
        The response the brackets were linearised with, in words, where it was not
        solved from them (``--response linear``, ``--response-from``): a solved one fits
        the metadata's steps by construction, one given may not fit the brackets at all
        (:data:`SLOPE_BOUND`). Empty for a solved response.
    """

    files: tuple[str, ...]
    metadata: np.ndarray
    estimated: np.ndarray
    used: bool = False
    inferred: str = ""
    reference: str = ""
    exif: np.ndarray | None = None
    unmeasured: tuple[int, ...] = ()
    deferred: InputError | None = None
    slope: float = math.nan
    response: str = ""

    @property
    def stops(self) -> np.ndarray:
        """``log2(estimated / metadata)`` per bracket."""
        return np.log2(self.estimated / self.metadata)

    def for_the_motion_test(self) -> np.ndarray | None:
        """The data's exposures, for deghosting's consistency test to read on a still
        stack, where the merge keeps the metadata's (not ``used``) and they disagree: a
        bracket more than :data:`TEST_STOPS` (and at most :data:`TEST_MAX_STOPS`) off the
        others' common offset, the estimates in the brackets' order. ``None`` otherwise
        (the test then reads the merge's exposures, as it always did).

        A bracket whose exposure is off by a few per cent disagrees with its neighbours by
        that much everywhere, which the test reads as motion where the noise is low:
        memorial's list (1/1024 .. 32 s in stops; the data say 1/1161 .. 30.19 s) had
        5.11 % of its pixels deghosted, 1.64 % when the test read the data's exposures
        (docs/motion.md, "Memorial's listed exposures")."""
        if self.used or self.inferred or self.estimated.size < 2:
            return None
        spread = self.spread()
        if not (np.isfinite(spread) and TEST_STOPS < spread <= TEST_MAX_STOPS):
            return None
        # Shortest first, as the stack: an estimate out of that order is not one to trust.
        return self.estimated if np.all(np.diff(self.estimated) > 0) else None

    def spread(self) -> float:
        """Stops the metadata's exposure of the bracket most off is from the data's,
        beyond the brackets' common offset (NaN where an exposure is unknown)."""
        stops = self.stops
        return float(np.max(np.abs(stops - np.median(stops))))

    def warnings(self, source: str = "") -> list[str]:
        """One line per bracket off by more than :data:`WARN_STOPS`, naming its file and
        where its exposure came from (``source``: the stack's exposure source, ``exif``,
        ``sidecar``...); none when there was no metadata to be off."""
        said = said_in(source)
        shown = ev_text if source == EV_STEPS and self.exif is None else exposure_text
        lines: list[str] = []
        if self.inferred and self.exif is None:
            return lines
        metadata = self.metadata if self.exif is None else self.exif
        for name, meta, data in zip(self.files, metadata, self.estimated, strict=True):
            stops = math.log2(data / meta) if math.isfinite(meta) else 0.0
            if abs(stops) > WARN_STOPS:
                lines.append(
                    f"{Path(name).name}: exposure {shown(meta)} {said}, the data "
                    f"say {shown(data)} ({stops:+.2f} stop); "
                    + ("used the data's (--exposures-from-data)" if self.used
                       else "--exposures-from-data uses the data's"))
        misfit = self.response_misfit()
        return lines if misfit is None else [misfit, *lines]

    def response_misfit(self) -> str | None:
        """One line when the brackets do not fit a :attr:`response` that was not solved
        from them: through it, their exposure steps measure more than
        :data:`SLOPE_BOUND` times the metadata's, or less than its inverse (a wrong
        exposure moves one bracket, a response that does not fit moves every step
        alike); else ``None``."""
        if not self.response or not math.isfinite(self.slope) or \
                1 / SLOPE_BOUND <= self.slope <= SLOPE_BOUND:
            return None
        hint = (" (display-encoded codes, as an sRGB JPEG's are?)"
                if self.slope < 1 and self.response.startswith("the linear") else "")
        return (f"the brackets do not fit {self.response}: through it their exposure "
                f"steps measure {self.slope:.2f}x the metadata's, where brackets that fit "
                f"it measure 1{hint}; merged anyway: leave the option out to solve their "
                "own curve, or check the exposures")

    def attributes(self) -> dict[str, object]:
        """``hdrio:exposuresMetadata``, ``hdrio:exposuresEstimated`` (decimal text, like
        ``hdrio:exposures``) and ``hdrio:exposuresFromData`` (1 when used); with no
        metadata, ``hdrio:exposuresInferred`` (how the set was anchored) and
        ``hdrio:exposureUnits`` instead of the metadata's; ``hdrio:exposuresUnmeasured``
        (file names) where some brackets could not be checked."""
        unmeasured = {"hdrio:exposuresUnmeasured": [Path(self.files[j]).name
                                                    for j in self.unmeasured]}
        if self.inferred:
            return {"hdrio:exposuresEstimated": [f"{t:.9g}" for t in self.estimated],
                    "hdrio:exposuresFromData": 1,
                    "hdrio:exposuresInferred": self.inferred,
                    "hdrio:exposureUnits": self.units,
                    **(unmeasured if self.unmeasured else {})}
        return {"hdrio:exposuresMetadata": [f"{t:.9g}" for t in self.metadata],
                "hdrio:exposuresEstimated": [f"{t:.9g}" for t in self.estimated],
                "hdrio:exposuresFromData": int(self.used),
                **(unmeasured if self.unmeasured else {}),
                **({"hdrio:exposuresSlope": round(self.slope, 4)}
                   if math.isfinite(self.slope) else {})}

    @property
    def units(self) -> str:
        """What the exposures are measured in (seconds, unless inferred)."""
        if self.inferred and self.exif is not None:
            return (f"seconds, from the EXIF of {', '.join(self.exif_files)} (the others' "
                    "inferred from the pixels)")
        if self.inferred:
            return (f"relative to {Path(self.reference).name} = 1 (no exposure metadata: "
                    "inferred from the pixels)")
        return "the metadata's (seconds, or t ISO/100 / N^2 when aperture or ISO vary)"

    def line(self) -> str:
        """The summary's one line on inferred exposures (empty when there was metadata)."""
        if not self.inferred:
            return ""
        if self.exif is not None:
            return (f"inferred from the pixels for {len(self.files) - len(self.exif_files)} "
                    f"of {len(self.files)} brackets (EXIF on {', '.join(self.exif_files)}), "
                    f"{self.inferred}; {exposure_text(self.estimated[0])} .. "
                    f"{exposure_text(self.estimated[-1])} s")
        stops = np.log2(self.estimated)
        return (f"inferred from the pixels (no metadata), {self.inferred}; relative, "
                f"{Path(self.reference).name} = 1, {stops[0]:+.2f} .. {stops[-1]:+.2f} stops")

    @property
    def exif_files(self) -> list[str]:
        """Names of the brackets whose EXIF gave their exposure (with ``exif``)."""
        return [Path(name).name for name, t in zip(self.files, self.exif)
                if math.isfinite(t)] if self.exif is not None else []


# Where a stack's exposures were read (hdrio.stack.ExposureStack.exposure_sources).
_SAID_IN = {"exif": "in the EXIF", "sidecar": "in the exposure list (--exposures-from)",
            "filename": "in the file name", "explicit": "given by --exposures",
            EV_STEPS: "given by --exposures (in EV)"}


def said_in(source: str) -> str:
    """Where exposures of ``source`` (an exposure source of
    :class:`~hdrio.stack.ExposureStack`) were read, in the words of a warning."""
    return _SAID_IN.get(source, "in the metadata")


def ev_text(t: float) -> str:
    """A relative exposure as the step in EV it was typed as: ``-2 EV``, ``+1.58 EV``."""
    steps = round(math.log2(t), 2)
    return f"{steps:+g} EV" if steps else "0 EV"


def exposure_text(t: float) -> str:
    """An exposure as a camera shows it: ``1/125``, ``8``."""
    return f"1/{1 / t:.4g}" if t < 1 else f"{t:.4g}"


def exposures_from_data(stack: ExposureStack, response: CameraResponse, use: bool,
                        solve: Callable[[ExposureStack], CameraResponse] | None = None,
                        iterations: int = 4, tolerance_stops: float = 1e-3,
                        unmeasured: Sequence[int] = (), exclude: np.ndarray | None = None
                        ) -> tuple[ExposureStack, CameraResponse, ExposureCheck]:
    """Estimate the exposures; with ``use``, merge with them: the stack's exposures are
    replaced and the response re-solved (``solve``, when given) until the estimates
    move less than ``tolerance_stops`` (at most ``iterations`` solves). ``unmeasured``:
    brackets that keep the metadata's exposure, ``exclude`` pixels not compared
    (:func:`estimate_exposures`).

    Returns the stack and response to merge with, and the check (for the warnings and
    the header). Raises :class:`~hdrio.errors.InputError` when ``use`` and the data put
    a bracket no longer than the one before it.
    """
    metadata = np.asarray(stack.exposures, np.float64)
    estimated, slope = estimate_exposures(stack.codes, metadata, response, unmeasured,
                                          exclude)
    if use:
        for _ in range(iterations if solve is not None else 0):
            stack = replace(stack, exposures=in_order(stack.files, estimated, metadata))
            response = solve(stack)
            again, slope = estimate_exposures(stack.codes, metadata, response, unmeasured,
                                              exclude)
            moved = float(np.max(np.abs(np.log2(again / estimated))))
            estimated = again
            if moved < tolerance_stops:
                break
        stack = replace(stack, exposures=in_order(stack.files, estimated, metadata))
    return stack, response, ExposureCheck(tuple(stack.files), metadata, estimated, use,
                                          unmeasured=tuple(int(j) for j in unmeasured),
                                          slope=slope)


def in_order(files: Sequence[str], estimated: np.ndarray,
             metadata: np.ndarray | None = None) -> np.ndarray:
    """``estimated``, where each bracket is longer than the one before it (as the stack
    is sorted), but where ``metadata`` gives both the same exposure (a repeat:
    :func:`hdrio.stack.repeated_exposures`); else an error naming the first that is not,
    instead of merging with exposures the brackets themselves contradict. A repeat's
    frames keep the stack's order: where the data put a later one shorter, it takes the
    earlier one's estimate (a shutter's jitter between two frames of one exposure)."""
    j = first_too_close(estimated, metadata)
    if j is not None:
        raise InputError(files[j + 1], (
            "--exposures-from-data: the data say its exposure is "
            f"{exposure_text(estimated[j + 1])}, not longer than {Path(files[j]).name}'s "
            f"{exposure_text(estimated[j])}: the brackets "
            "do not agree on the scene (something moved, or they could not be "
            "registered), so their exposures cannot come from the data: give them "
            "(--exposures), or merge with the metadata's (no --exposures-from-data)"))
    if metadata is None:
        return estimated
    estimated = np.array(estimated, np.float64)
    for group in repeated_exposures(metadata):
        estimated[list(group)] = np.maximum.accumulate(estimated[list(group)])
    return estimated

