"""Exposures of brackets with no metadata at all, inferred from the pixels
(``--exposures-from-data`` when no EXIF, file-name convention, sidecar or ``--exposures``
gives them).

The brackets are put in order of brightness: every pixel's code grows with exposure, so
the longer of two brackets has the higher codes at every percentile (which holds when
the brackets are not registered, as scans and hand-held shots are not;
:func:`brightness_order`). Their ratios are measured, as with metadata
(:func:`hdrio.merge.exposure_check.fit_log_exposures`: medians of ``g(z_k) - g(z_j)`` over
pixels well exposed in both), first through a *starting response*, the standard curve of
the input encoding (:func:`starting_response`: sRGB's for 8-bit, linear for 16-bit and
RAW), then through the response solved with them, iterated (Mitsunaga & Nayar 1999).

What the metadata fixed must now be fixed another way: a set of brackets and its response
are known only up to ``g -> s g + c``, ``ln t -> s ln t + c`` (the exponent ambiguity of
self-calibration; Grossberg & Nayar 2003). ``c`` is a choice of unit: the exposures are
relative, the middle bracket of the ladder (the 0 EV frame of an auto-exposure bracket)
is 1. ``s`` is fixed by the step: cameras bracket in steps of 1/3 stop, so when the
neighbouring ratios agree on one step (each within :data:`STEP_AGREEMENT` of their
median) the median rounded to 1/3 stop is taken as exact and the uniform ladder anchors
the set ("step inferred: 2 stops"); otherwise the starting response's own estimates
anchor it (its slope is then the assumption, and is said).

References
----------
Mitsunaga, T., Nayar, S. K. (1999). Radiometric self calibration. CVPR 1999, 374-380.
Grossberg, M. D., Nayar, S. K. (2003). Determining the camera response from images:
what is knowable? IEEE TPAMI 25(11), 1455-1467.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from hdrio.errors import InputError
from hdrio.io.brackets import PLACEHOLDERS
from hdrio.io.exposure import exposure_from_exif, relative_exif_exposures
from hdrio.io.staging import strided_copy
from hdrio.merge.exposure_check import (
    WARN_STOPS,
    ExposureCheck,
    exposure_text,
    exposures_from_data,
    in_order,
    said_in,
)
from hdrio.merge.exposure_check import fit_log_exposures as fit
from hdrio.radiometry.curve import CameraResponse, linear_response
from hdrio.skips import classify, srgb_decoded
from hdrio.stack import ExposureStack, repeated_exposures

CAMERA_STEP = 1 / 3
"""Stops: cameras bracket in multiples of a third of a stop."""
STEP_AGREEMENT = 0.1
"""Stops: the ladder is uniform when every neighbouring ratio is this close to their
median (after self-calibration the ratios scatter by about 0.01 stop; an irregular
ladder's by a third of a stop or more)."""
ORDER_LEVELS = np.concatenate([np.arange(1.0, 100.0), 100.0 - np.logspace(0, -3, 13)[1:]])
"""Percentiles of each bracket's codes compared when ordering: 1 to 99, and 12 more up to
99.999 (in a short exposure only the brightest pixels show anything)."""
ORDER_AGREEMENT = 0.75
"""Of the percentiles that differ by more than a code, the share that must be higher in
the brighter of two neighbours for them to be ordered."""
ORDER_MIN_LEVELS = 3
"""Percentiles that must be higher in the brighter of two neighbours."""
ADOBE_RGB_GAMMA = 563 / 256


def needs_inference(stack: ExposureStack) -> bool:
    """Whether ``stack``'s exposures are placeholders (read with no metadata)."""
    return bool(stack.exposure_sources) and stack.exposure_sources[0] == PLACEHOLDERS


def starting_response(code_max: int, channels: int, encoding: str = "sRGB",
                      linear: bool = False) -> CameraResponse:
    """The standard inverse response of an encoding: where the ratios start.

    Parameters
    ----------
    code_max
        255 for 8-bit codes; larger codes (16-bit) are taken as linear.
    channels
        Columns of the table.
    encoding
        :mod:`hdrio.cms.encoding` name: ``"Adobe RGB (1998)"`` is a pure power of
        563/256; sRGB and Display P3 share the sRGB curve (IEC 61966-2-1).
    linear
        Linear codes (camera RAW, ``--response linear``) whatever their depth.

    Returns
    -------
    CameraResponse
        ``g(z) = ln f^-1(z)``, ``g(z_mid) = 0``, method ``"start:<curve>"``; codes 0 and
        ``code_max`` unsupported.
    """
    if linear or code_max > 255:
        response = linear_response(code_max, channels)
        return replace(response, method="start:linear")
    v = np.arange(code_max + 1, dtype=np.float64) / code_max
    if encoding == "Adobe RGB (1998)":
        curve, x = "Adobe RGB", v ** ADOBE_RGB_GAMMA
    else:
        curve = "sRGB"
        x = srgb_decoded(v)
    g = np.log(np.maximum(x, x[1] / 2))
    g -= g[(code_max + 1) // 2]
    supported = np.ones((code_max + 1, channels), bool)
    supported[[0, code_max]] = False
    return CameraResponse(np.repeat(g[:, None], channels, axis=1), code_max, supported,
                          method=f"start:{curve}")


def _brightness_levels(stack: ExposureStack, pixels: int = 1 << 16) -> np.ndarray:
    """``(P, levels)``: each bracket's codes at :data:`ORDER_LEVELS` percentiles, on a
    regular sample of at most ``pixels``; pixels with a channel black and another
    clipped (registration borders, pure colours) say nothing of the exposure and are
    left out."""
    count, height, width, _ = stack.codes.shape
    stride = max(1, math.ceil(math.sqrt(height * width / pixels)))
    sample = strided_copy(stack.codes, stride).reshape(count, -1, stack.shape[2])
    pure = (sample == 0).any(axis=-1) & (sample == stack.code_max).any(axis=-1)
    return np.array([np.percentile(codes[~out] if not out.all() else codes, ORDER_LEVELS)
                     for codes, out in zip(sample, pure)])


def _brighter(levels: np.ndarray, darker: int, brighter: int) -> tuple[int, int]:
    """Percentiles at which bracket ``brighter`` is above ``darker`` by more than a code,
    and below it."""
    difference = levels[brighter] - levels[darker]
    return int(np.count_nonzero(difference > 1)), int(np.count_nonzero(difference < -1))


def _ordered(up: int, down: int) -> bool:
    """Whether ``up`` percentiles above and ``down`` below order two brackets."""
    return up >= ORDER_MIN_LEVELS and down <= (1 - ORDER_AGREEMENT) * (up + down)


def brightness_order(stack: ExposureStack) -> np.ndarray:
    """Indices of ``stack``'s brackets from darkest to brightest.

    Raises :class:`InputError` naming the file when a bracket has no well-exposed code
    (all black or all clipped: nothing places it on the ladder), or when two neighbours
    cannot be told apart (too few pixels differ, or they differ both ways).
    """
    for name, codes in zip(stack.files, stack.codes):
        kind = classify(codes, stack.code_max)
        if kind in ("dark", "bright"):
            said = "black" if kind == "dark" else "clipped"
            raise InputError(name, f"all {said} (no well-exposed code): its exposure cannot "
                                   "be inferred from the pixels; leave it out or give "
                                   "--exposures")
    levels = _brightness_levels(stack)
    order = np.argsort(levels.mean(axis=1), kind="stable")
    for darker, brighter in zip(order[:-1], order[1:]):
        up, down = _brighter(levels, darker, brighter)
        if not _ordered(up, down):
            raise InputError(stack.files[brighter],
                             f"cannot be ordered against {Path(stack.files[darker]).name} "
                             f"by brightness ({up} of {levels.shape[1]} percentiles "
                             f"brighter, {down} darker): the same exposure, or a different "
                             "picture; give --exposures")
    return order


ORDER_CHECK_STOPS = 2 / 3
"""Brackets whose exposures (as the metadata give them) differ by more than this are
checked against their brightness (:func:`check_exposure_order`): nearer ones may swap
places within a neutral-density filter's tolerance (``--nd`` folds in its nominal
stops) or a camera's third-stop rounding."""
ORDER_CHECK_PIXELS = 1 << 14
"""Pixels sampled for :func:`check_exposure_order`, which runs on every merge: 0.05 s for
7 x 24 MP at 2^16, 0.017 s at 2^14 (this 2-core machine); frobisher's reversed brackets
are lower at 87 and 96 of the 111 percentiles either way."""


def check_exposure_order(stack: ExposureStack, filtered: np.ndarray | None = None) -> None:
    """Raise :class:`InputError` naming a bracket whose exposure the metadata put more
    than :data:`ORDER_CHECK_STOPS` above another's while its codes are lower, as
    :func:`brightness_order` orders brackets (at most percentiles, by more than a code).
    Every code grows with exposure: exposures that say otherwise belong to other files
    (a list typed in another order than the files', a sidecar's lines swapped), and a
    merge with them was garbage (frobisher with its times reversed: a flat response, 100
    % of the pixels clipped in every bracket, and a warning that named one bracket).
    ``filtered``: the stops of ``--nd`` filter folded into each bracket's exposure, which
    the message then says."""
    if stack.count < 2:
        return
    exposures = np.asarray(stack.exposures, np.float64)

    def text(j: int) -> str:
        stops = 0.0 if filtered is None else float(filtered[j])
        return exposure_text(exposures[j]) + (f" (--nd's {stops:g} stops counted)"
                                              if stops else "")

    levels = _brightness_levels(stack, ORDER_CHECK_PIXELS)
    backwards = np.array_equal(np.argsort(levels.mean(axis=1), kind="stable"),
                               np.arange(stack.count)[::-1])
    why = ("they run the other way: 1/t given for t, e.g. 125 for 1/125 s?" if backwards
           else "given in another order?")
    for longer in range(1, stack.count):
        for shorter in range(longer):
            stops = math.log2(exposures[longer] / exposures[shorter])
            if stops <= ORDER_CHECK_STOPS:
                continue
            up, down = _brighter(levels, longer, shorter)
            if _ordered(up, down):
                said = said_in(stack.exposure_sources[longer])
                raise InputError(stack.files[longer], (
                    f"exposure {text(longer)} {said}, {stops:.2f} stops longer than "
                    f"{Path(stack.files[shorter]).name}'s {text(shorter)}, yet its codes "
                    f"are lower at {up} of {levels.shape[1]} percentiles: these exposures "
                    f"belong to other files ({why}); "
                    + ("check them, and --nd's filters" if filtered is not None
                       and np.any(filtered) else
                       "check them, or leave them out where the files' EXIF has them (a "
                       "bracket shot through a neutral-density filter: --nd)")))


REPEAT_SAMPLES = 1 << 18
"""Pixels of each frame of a repeated exposure sampled (a regular grid) by
:func:`check_repeated_exposures`."""
REPEAT_BLOCK = 4
"""Samples a side of the blocks whose mean codes are compared: 16 samples average a
frame's noise down fourfold, and a hand-held frame's shift of a few pixels moves a block
by a fraction of itself (4 pixels a side at 200 x 300, 40 at 24 MP)."""
REPEAT_LEVELS = (0.05, 0.95)
"""Mean codes (fractions of ``code_max``) a block must lie within in both frames to be
compared: black and clipped blocks agree whatever the picture."""
REPEAT_MIN_BLOCKS = 16
"""Blocks compared at least, else the frames are not judged (the shortest frame of a
ladder is black but for its highlights)."""
REPEAT_AGREEMENT = 0.07
"""The median relative difference of two frames' block means above which they are not
one picture at one exposure. Measured (:func:`picture_difference`) on generated frames
of ``tests/hard_cases.py``' cameras, 200 x 300: repeats of one exposure 0.001-0.019
(JPEG, PNG, linear 16-bit, a phone's night frames), hand-held repeats (up to 6 px and
0.3 degrees apart) 0.006-0.050; a third of a stop apart 0.10-0.21, other scenes
0.64-1.17. A pan of 60 px (a fifth of the frame) over a scene of smooth sky measured
0.043-0.055: a view that overlaps that much is taken for the same picture, and
deghosting handles what differs. Film scans' short frames, whose fog floor barely moves
with exposure, measure 0.014-0.042 a stop apart (memorial's 1/1024 .. 1/64 s): one of
them typed with its neighbour's exposure is merged as a repeat, and the exposure check
names it (memorial0072.png listed at 1/32 s: "the data say 1/60.86 (-0.93 stop)")."""


def picture_difference(first: np.ndarray, second: np.ndarray, code_max: int) -> float | None:
    """The median, over blocks well exposed in both (:data:`REPEAT_LEVELS`), of the
    relative difference of two frames' mean codes ``|a - b| / ((a + b) / 2)`` per channel
    (:data:`REPEAT_BLOCK` samples a side on a grid of about :data:`REPEAT_SAMPLES`
    pixels); ``None`` when fewer than :data:`REPEAT_MIN_BLOCKS` can be compared."""
    height, width = first.shape[:2]
    stride = max(1, math.ceil(math.sqrt(height * width / REPEAT_SAMPLES)))
    rows = len(range(0, height, stride)) // REPEAT_BLOCK * REPEAT_BLOCK
    cols = len(range(0, width, stride)) // REPEAT_BLOCK * REPEAT_BLOCK

    def means(codes):
        grid = np.asarray(codes[::stride, ::stride][:rows, :cols], np.float64)
        return grid.reshape(rows // REPEAT_BLOCK, REPEAT_BLOCK, cols // REPEAT_BLOCK,
                            REPEAT_BLOCK, -1).mean(axis=(1, 3))

    a, b = means(first), means(second)
    low, high = (v * code_max for v in REPEAT_LEVELS)
    both = (a > low) & (a < high) & (b > low) & (b < high)
    if np.count_nonzero(both) < REPEAT_MIN_BLOCKS:
        return None
    return float(np.median(np.abs(a - b)[both] / (0.5 * (a + b)[both])))


def check_repeated_exposures(stack: ExposureStack) -> None:
    """Raise :class:`InputError` naming a frame that repeats another's exposure
    (:func:`hdrio.stack.repeated_exposures`) but is not another view of its picture: the
    same pixels (one image given twice), or a different picture
    (:func:`picture_difference` above :data:`REPEAT_AGREEMENT`: exposures typed for other
    files, or two bracket sets in one list). Frames that repeat an exposure and show the
    same scene (a ladder capped by the camera's shortest or longest shutter time, a
    burst) are merged, each an observation."""
    for group in repeated_exposures(stack.exposures):
        first = group[0]
        name = Path(stack.files[first]).name
        for j in group[1:]:
            if np.array_equal(stack.codes[first], stack.codes[j]):
                raise InputError(stack.files[j], f"the same pixels as {name}: one image "
                                                 "given twice; leave one out")
            difference = picture_difference(stack.codes[first], stack.codes[j],
                                            stack.code_max)
            if difference is not None and difference > REPEAT_AGREEMENT:
                said = said_in(stack.exposure_sources[j])
                raise InputError(stack.files[j], (
                    f"the same exposure ({exposure_text(stack.exposures[j])}, {said}) as "
                    f"{name}, but not the same picture: their codes differ by "
                    f"{100 * difference:.0f} % (the median over blocks; frames of one "
                    f"exposure differ by noise, under {100 * REPEAT_AGREEMENT:.0f} %): the "
                    "exposures belong to other files, or the list holds two bracket sets "
                    "(hdrio FOLDER --group --merge -o {first_stem}.exr merges each set of "
                    "a shoot)"))


def in_brightness_order(stack: ExposureStack) -> ExposureStack:
    """``stack`` (read with no metadata) sorted from darkest to brightest
    (:func:`brightness_order`), placeholder exposures 1, 2, 3...; raises
    :class:`InputError` naming a file when the set cannot be inferred (fewer than three
    brackets, a bracket all black or all clipped, two that cannot be ordered)."""
    if stack.count < 3:
        raise InputError(stack.files[-1], "no exposure metadata, and two brackets cannot "
                                          "show their step (--exposures-from-data infers "
                                          "it from three brackets or more); give --exposures")
    order = brightness_order(stack)
    if np.all(order == np.arange(stack.count)):
        return stack
    placeholders = np.empty(stack.count)
    placeholders[order] = np.arange(1.0, stack.count + 1)
    return ExposureStack.from_arrays(
        stack.codes, placeholders, files=stack.files, code_max=stack.code_max,
        exposure_sources=stack.exposure_sources, metadata=stack.metadata or None,
        dropped=stack.dropped)


def infer_exposures(stack: ExposureStack, start: CameraResponse,
                    solve: Callable[[ExposureStack], CameraResponse] | None = None,
                    exclude: np.ndarray | None = None
                    ) -> tuple[ExposureStack, CameraResponse, ExposureCheck]:
    """The exposures of a stack read with no metadata (:func:`needs_inference`).

    Parameters
    ----------
    stack
        Three brackets or more, darkest first (:func:`in_brightness_order`), exposures
        placeholders.
    start
        The starting response (:func:`starting_response`), or a saved one.
    solve
        Solves the response of a stack (``None``: ``start`` is kept, as for a saved
        response).
    exclude
        ``(H, W)`` pixels not compared (a warp's borders and sharp edges), or ``None``.

    Returns
    -------
    tuple
        The stack with the inferred exposures (relative: the middle bracket is 1; in
        seconds when some brackets kept an EXIF exposure time: :func:`exif_exposures`),
        the response to merge with, and the check (``inferred`` says how the set was
        anchored).

    Brackets that kept their EXIF fix what the pixels cannot: two exposure times or more
    fix the step (the exponent ambiguity), one or more the unit.
    """
    log_t, unlinked = fit(stack.codes, start, exclude=exclude)
    if unlinked:
        c = unlinked[0]
        raise InputError(stack.files[c + 1], "no well-exposed pixels in common with "
                                             f"{Path(stack.files[c]).name}: its exposure "
                                             "cannot be inferred; give --exposures")
    known = exif_exposures(stack)
    # Self-calibration with the starting curve's scale: the ratios become consistent.
    first = replace(stack, exposures=in_order(stack.files, np.exp(log_t)))
    _, response, check = exposures_from_data(first, start, True, solve, exclude=exclude)
    stops = np.diff(np.log2(check.estimated))
    median = float(np.median(stops))
    regular = median > 0 and bool(np.all(np.abs(stops - median) <= STEP_AGREEMENT))
    if len(known) >= 2:  # two exposure times fix the scale the curve would otherwise set
        a, b = min(known), max(known)
        per_bracket = float(np.median([math.log2(known[k] / known[j]) / (k - j)
                                       for j in known for k in known if k > j]))
        step = round(per_bracket / CAMERA_STEP) * CAMERA_STEP  # one wrong time of 3+ is outvoted
        if regular and step > 0:
            anchor = np.exp2(step * np.arange(stack.count))
            how = f"step from the EXIF of {_names(stack, known)}: {_stops(step)}"
        else:  # the data's ratios, stretched to the known times' span
            span = math.log(known[b] / known[a]) / (log_t[b] - log_t[a])
            anchor = np.exp(span * (log_t - log_t[a]))
            how = f"step irregular: anchored to the EXIF of {_names(stack, known)}"
        _, response, check = exposures_from_data(replace(stack, exposures=anchor),
                                                 response, True, solve, exclude=exclude)
        estimated = check.estimated
    elif regular:
        step = round(median / CAMERA_STEP) * CAMERA_STEP
        anchor = np.exp2(step * np.arange(stack.count))
        how = f"step inferred: {_stops(step)}"
        _, response, check = exposures_from_data(replace(stack, exposures=anchor),
                                                 response, True, solve, exclude=exclude)
        estimated = check.estimated
    else:  # check.estimated is anchored to log_t already (Theil-Sen)
        anchor = np.exp(log_t)
        how = (f"step irregular ({stops.min():.2f} .. {stops.max():.2f} stops): anchored to "
               f"the {start.method.removeprefix('start:')} curve")
        estimated = check.estimated
    exif = None
    if known:  # in the EXIF's units (seconds): the known times' median scale
        scale = math.exp(float(np.median([math.log(t / estimated[j])
                                          for j, t in known.items()])))
        exif = np.array([known.get(j, np.nan) for j in range(stack.count)])
        reference = ""
        if len(known) == 1:
            how += f"; in seconds from the EXIF of {_names(stack, known)}"
    else:  # relative: the middle bracket is 1
        reference = stack.files[stack.count // 2]
        scale = 1.0 / estimated[stack.count // 2]
    estimated = estimated * scale
    for j, t in known.items():  # the EXIF's own value, unless the data contradict it
        if abs(math.log2(estimated[j] / t)) <= WARN_STOPS:
            estimated[j] = t
    middle = stack.count // 2
    anchor = anchor * (estimated[middle] / anchor[middle])
    stack = replace(stack, exposures=estimated)
    return stack, response, ExposureCheck(stack.files, anchor, estimated, True, how,
                                          reference, exif)


def with_unregistered(check: ExposureCheck, stack: ExposureStack) -> ExposureCheck:
    """``check``, inferred on the registered brackets of ``stack`` only (alignment's
    aligned sample: :class:`hdrio.job.stages.ExposureCalibration`), for every bracket of
    ``stack``: one that could not be registered is placed by the ladder's step from the
    registered ones (interpolated between them, extrapolated beyond), said in
    ``inferred`` and listed in ``unmeasured``; relative exposures keep the middle
    bracket at 1."""
    index = {name: i for i, name in enumerate(check.files)}
    kept = np.array([j for j, name in enumerate(stack.files) if name in index])
    order = [index[stack.files[j]] for j in kept]
    everywhere = np.arange(stack.count)

    def placed(values: np.ndarray) -> np.ndarray:
        logs = np.log2(values[order])
        step = float(np.median(np.diff(logs) / np.diff(kept)))
        inside = np.interp(everywhere, kept, logs)
        below, above = everywhere < kept[0], everywhere > kept[-1]
        inside[below] = logs[0] - step * (kept[0] - everywhere[below])
        inside[above] = logs[-1] + step * (everywhere[above] - kept[-1])
        return np.exp2(inside)

    estimated, anchor = placed(check.estimated), placed(check.metadata)
    unmeasured = tuple(int(j) for j in np.setdiff1d(everywhere, kept))
    reference = ""
    if check.exif is None:  # relative: the middle bracket is 1
        reference = stack.files[stack.count // 2]
        anchor = anchor / estimated[stack.count // 2]
        estimated = estimated / estimated[stack.count // 2]
    exif = None if check.exif is None else np.array(
        [check.exif[index[name]] if name in index else np.nan for name in stack.files])
    names = ", ".join(Path(stack.files[j]).name for j in unmeasured)
    how = check.inferred + (f"; {names} not registered: placed by the step" if names else "")
    return ExposureCheck(tuple(stack.files), anchor, estimated, True, how, reference, exif,
                         unmeasured)


def exif_exposures(stack: ExposureStack) -> dict[int, float]:
    """``{bracket: exposure}`` for the brackets of a metadata-less read whose EXIF has an
    exposure time after all (a set where only some files kept their EXIF): seconds, or
    ``t ISO/100 / N^2`` when aperture or ISO vary among them; ``{}`` when those are
    incomplete, or when the times do not grow with the brackets' brightness (the EXIF
    is then not trusted; :func:`in_brightness_order` put the brackets in order)."""
    readings = {j: exposure_from_exif(entry) for j, entry in enumerate(stack.metadata or ())
                if entry}
    readings = {j: reading for j, reading in readings.items() if reading is not None}
    if not readings:
        return {}
    try:
        values = relative_exif_exposures(list(readings.values()))
    except ValueError:
        return {}
    known = dict(zip(readings, values))
    order = sorted(known)
    if any(known[k] >= known[later] for k, later in zip(order, order[1:])):
        return {}
    return known


def _names(stack: ExposureStack, known: dict[int, float]) -> str:
    return ", ".join(Path(stack.files[j]).name for j in sorted(known))


def _stops(step: float) -> str:
    thirds = round(step * 3)
    whole, rest = divmod(thirds, 3)
    text = str(whole) if rest == 0 else (f"{rest}/3" if whole == 0 else f"{whole} {rest}/3")
    return f"{text} stop" + ("s" if thirds > 3 else "")
