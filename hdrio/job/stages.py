"""The stages of a merge before the merge itself, in the order :func:`hdrio.job.run.run_plan`
runs them: the stack prepared (ND filters, brightness order, exclusions), the response
solved (and the exposures checked against the data), the brackets aligned, the noise
model fitted and the movers found.

Each stage takes and returns plain data (stacks, responses, arrays, reports); what it
is to do comes from the job's :class:`~hdrio.job.plan.MergePlan`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hdrio import jit
from hdrio.align.motion import Motion, align_step, deghost_step
from hdrio.align.registration import align_masks
from hdrio.cms.encoding import resolve_encoding
from hdrio.errors import InputError, ResponseSolveError
from hdrio.io.masks import mask_files, read_masks
from hdrio.io.raw import is_raw_stack
from hdrio.job.plan import MergePlan
from hdrio.job.result import Progress
from hdrio.merge.exclusion import colour_exclusion, either
from hdrio.merge.exposure_check import ExposureCheck, exposures_from_data
from hdrio.merge.ladder import (
    check_exposure_order,
    check_repeated_exposures,
    in_brightness_order,
    infer_exposures,
    needs_inference,
    starting_response,
    with_unregistered,
)
from hdrio.merge.nd import NDReport, filter_gains, nd_stops, stops_of, unfiltered, with_nd
from hdrio.merge.saturation import (
    ClipPolicy,
    SolveFilter,
    Survey,
    Surveys,
    clip_policy,
    solve_filter,
)
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel, noise_encoding
from hdrio.radiometry.noise_fit import fit_noise
from hdrio.radiometry.saved_response import check_response_fits
from hdrio.response import RESPONSE_METHODS
from hdrio.response.debevec1997 import deep_spacing
from hdrio.skips import classify
from hdrio.stack import ExposureStack

Solve = Callable[[ExposureStack, "np.ndarray | None"], CameraResponse]


@dataclass(frozen=True)
class Prepared:
    """The stack as the stages see it, and what it carries beside its pixels.

    Attributes
    ----------
    stack
        In exposure order (by brightness when it has no exposure metadata), with ND
        filters' stops folded into its exposures (``--nd``).
    filtered
        Stops of ND filter per bracket, or ``None`` without ``--nd``.
    inferring
        The exposures are to be inferred from the pixels (no metadata).
    masks
        ``--mask`` files read in the stack's order, or ``None``.
    excluded
        ``(P, H, W)`` observations kept out of the solve, registration and the merge, or
        ``None``.
    """

    stack: ExposureStack
    filtered: np.ndarray | None
    inferring: bool
    masks: np.ndarray | None
    excluded: np.ndarray | None


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


def exclusions(stack: ExposureStack, plan: MergePlan,
               masks: np.ndarray | None) -> np.ndarray | None:
    """``(P, H, W)`` bool: the observations ``--exclude-color`` and ``--mask`` (``masks``,
    read by :func:`hdrio.io.masks.read_masks` in the stack's order) keep out of the solve
    and the merge (:mod:`hdrio.merge.exclusion`), else ``None``."""
    return either(colour_exclusion(stack.codes, plan.options.exclude_colour), masks)


def prepare(stack: ExposureStack, plan: MergePlan) -> Prepared:
    """ND filters folded in, brightness order when there is no metadata, exclusions."""
    options = plan.options
    filtered = None
    if options.nd:
        stack, filtered = with_nd(stack, nd_stops(stack.files, options.nd))
    inferring = needs_inference(stack)
    if inferring:  # no exposure metadata: order by brightness, before masks
        stack = in_brightness_order(stack)
    else:  # exposures that belong to other files stop here, not in a flat response
        check_exposure_order(stack, filtered)
        check_repeated_exposures(stack)
    if options.exposures_from_data and (stack.count < 3 or filtered is not None):
        raise ValueError("--exposures-from-data needs three brackets or more, and no --nd "
                         f"(the filters are measured on their own); got {stack.count} "
                         "brackets" + (" and --nd" if filtered is not None else ""))
    # The brackets' encoding, known and one for all, before any work on their pixels.
    resolve_encoding(stack.files, stack.metadata or [{}] * stack.count, options.input_encoding)
    masks = read_masks(options.masks, stack.files, stack.shape[:2])  # in the stack's order
    return Prepared(stack, filtered, inferring, masks, exclusions(stack, plan, masks))


def response_solver(prepared: Prepared, plan: MergePlan, say: Progress,
                    surveys: Surveys | None = None) -> Solve:
    """The solve ``--response`` names (the linear response for camera RAW), as
    ``solve(stack, exclude)``: alignment and deghosting re-solve with it.

    Where the stack mixes its channels after the clip, the solve is run again without
    the observations at or reaching the clip (:func:`hdrio.merge.saturation.solve_filter`:
    they are biased in every channel, and would bend the curve); what that measures is
    kept in ``surveys``, for the deghost stage's policy."""
    options, filtered = plan.options, prepared.filtered
    method = "linear" if is_raw_stack(prepared.stack) else options.response
    say(f"camera response: {method}" + ("" if method == "linear"
                                        else f", lambda {options.smoothing:g}"))
    extra = {"solve_identical_once": "channels" in plan.skips} if method != "linear" else {}

    def solve(stack: ExposureStack, exclude: np.ndarray | None) -> CameraResponse:
        stops = None if filtered is None else stops_of(stack, prepared.stack, filtered)
        if stops is not None and np.count_nonzero(stops == 0) >= 2:
            stack = unfiltered(stack, stops)  # a filter's cast would bend g
        if method != "linear" and "spacing" not in extra:
            # Decided once, on the first stack solved: the brackets as read, with the
            # exposures the solve uses (inferred ones where the files have none; the
            # placeholders before them would mislead it). Re-solves read warped samples.
            extra["spacing"] = deep_spacing(stack, options.smoothing, options.weighting)

        def solved_with(dropped: SolveFilter | None = None) -> CameraResponse:
            return RESPONSE_METHODS[method](
                stack, smoothing=options.smoothing, weighting=options.weighting,
                sampling=options.sampling, samples=options.samples, exclude=exclude,
                seed=options.seed, **extra, **({"dropped": dropped} if dropped else {}))

        response = solved_with()
        if method == "linear":
            return response
        dropped = solve_filter(options.saturation, stack, response, exclude=exclude,
                               surveys=surveys)
        return response if dropped is None else solved_with(dropped)

    return solve


def _solved(solve: Solve, excluded: np.ndarray | None
            ) -> Callable[[ExposureStack], CameraResponse]:
    """``solve`` outside the excluded observations, its errors naming the set."""
    def solved(stack: ExposureStack) -> CameraResponse:
        try:
            return solve(stack, None if excluded is None else excluded.any(axis=0))
        except ResponseSolveError as error:
            message = str(error).replace("a saved response", "a saved response "
                                         "(--response-from EXR, from an earlier merge)")
            if "--response-from" not in message:
                message += "; or give a saved response: --response-from EXR"
            raise ResponseSolveError(f"{describe_set(stack)}: {message}") from None

    return solved


def response_stage(prepared: Prepared, plan: MergePlan, response: CameraResponse | None,
                   solve: Solve | None, say: Progress
                   ) -> tuple[Prepared, CameraResponse, ExposureCheck | None]:
    """The response (``solve``'s, or ``response`` as given), and the exposures inferred
    from the pixels (no metadata) or checked against them (three brackets or more): the
    stack carries the exposures the merge uses."""
    stack, filtered = prepared.stack, prepared.filtered
    solved = None if solve is None else _solved(solve, prepared.excluded)
    if response is not None:
        check_response_fits(response, stack.code_max, stack.shape[2])
    exposure_check = None
    if prepared.inferring:  # no metadata: the ladder from the pixels (--exposures-from-data)
        start = start_response(stack, plan, response)
        try:
            stack, response, exposure_check = infer_exposures(stack, start, solved)
        except InputError as error:
            if not plan.aligns:
                raise
            # Brackets that moved compare different scene points (every hand-held
            # ladder of tests/hard_cases.py failed here): they are registered with
            # provisional exposures a stop apart (the registration does not depend on
            # them: 1 and 3 stops a bracket for a 2-stop hand-held ladder register it
            # the same within 0.1 px), and inferred on the registered brackets; the
            # error stands if the stack was not warped (registered_exposures).
            provisional = np.exp2(np.arange(stack.count, dtype=np.float64))
            stack, response = replace(stack, exposures=provisional), start
            exposure_check = ExposureCheck(tuple(stack.files), provisional, provisional,
                                           True, "provisional", deferred=error)
        if not plan.aligns:
            say(f"exposures: {exposure_check.line()}")
    elif solved is not None:
        response = solved(stack)
    if stack.count > 2 and filtered is None and exposure_check is None:
        # Two brackets cannot say which is wrong. Brackets to register are merged with
        # the data's exposures only once they are (registered_exposures).
        stack, response, exposure_check = exposures_from_data(
            stack, response, plan.options.exposures_from_data and not plan.aligns, solved)
    return replace(prepared, stack=stack), response, exposure_check


def start_response(stack: ExposureStack, plan: MergePlan,
                   response: CameraResponse | None) -> CameraResponse:
    """The response exposures are first inferred through: ``response`` when given, else
    the input encoding's standard curve (:func:`starting_response`)."""
    return response if response is not None else starting_response(
        stack.code_max, stack.shape[2], resolve_encoding(
            stack.files, stack.metadata, plan.options.input_encoding)[0].name,
        linear=is_raw_stack(stack) or plan.options.response == "linear")


class ExposureCalibration:
    """Alignment's re-solve (``solve(stack, exclude)`` on its aligned sample,
    :func:`hdrio.align.registration.register`) with ``--exposures-from-data``: the
    exposures fitted with the response there (:func:`exposures_from_data`; with no
    metadata, inferred from ``start``: :func:`infer_exposures`), where the brackets
    compare the same scene points. ``check``: the last fit, on the registered brackets
    only (``None`` until alignment re-solved)."""

    def __init__(self, solve: Solve, start: CameraResponse | None = None) -> None:
        self.solve, self.start = solve, start
        self.check: ExposureCheck | None = None

    def __call__(self, small: ExposureStack, exclude: np.ndarray | None) -> CameraResponse:
        def solved(tried: ExposureStack) -> CameraResponse:
            return self.solve(tried, exclude)

        # The fits leave out ``exclude`` too (the warp's borders, and sharp edges where
        # resampled brackets differ: with them the exposures of hand_held(7, 1) and (7, 3)
        # came out off enough to take the merge's median error from 1.39 and 1.52x the
        # still stack's to 2.24 and 1.81x). A ladder's shortest brackets may share no
        # other pixels (the sun's edges): with no metadata to place them, the inference
        # then compares every pixel.
        if self.start is None:
            _, response, self.check = exposures_from_data(small, solved(small), True, solved,
                                                          exclude=exclude)
            return response
        try:
            _, response, self.check = infer_exposures(small, self.start, solved, exclude)
        except InputError:
            _, response, self.check = infer_exposures(small, self.start, solved)
        return response


def exposure_calibration(prepared: Prepared, plan: MergePlan, solve: Solve | None,
                         check: ExposureCheck | None) -> ExposureCalibration | None:
    """The calibration alignment's re-solve runs with ``--exposures-from-data`` (``solve``
    is alignment's: ``None`` under exclusions or with a saved response), else ``None``.
    With no metadata, only where the inference before registration failed: inferred on
    the aligned sample, the stripped hand-held `alignment/` stack's step came out 2 2/3
    stops instead of its EXIF's 2 (the exponent ambiguity settles differently on that
    sample's solve), which the inference before registration finds."""
    if solve is None or check is None or not plan.options.exposures_from_data:
        return None
    if not check.inferred:
        return ExposureCalibration(solve)
    if check.deferred is None:
        return None
    return ExposureCalibration(solve, start_response(prepared.stack, plan, None))


def with_given_response(check: ExposureCheck | None, plan: MergePlan, stack: ExposureStack,
                        given: bool) -> ExposureCheck | None:
    """``check`` naming the response it measured through where that response was not
    solved from the brackets (``given``: ``--response-from``, or a caller's; ``--response
    linear`` on brackets that are not camera RAW), so that it can say when the brackets
    do not fit it (:meth:`~hdrio.merge.exposure_check.ExposureCheck.response_misfit`)."""
    options = plan.options
    if given:
        words = (f"the response read from {Path(options.response_from).name} "
                 "(--response-from)" if options.response_from is not None
                 else "the response given")
    elif options.response == "linear" and not is_raw_stack(stack):
        words = "the linear response (--response linear)"
    else:
        return check
    return None if check is None else replace(check, response=words)


def registered_exposures(prepared: Prepared, response: CameraResponse, plan: MergePlan,
                         solve: Solve | None, motion: Motion, check: ExposureCheck | None,
                         calibration: ExposureCalibration | None = None,
                         say: Progress | None = None
                         ) -> tuple[Prepared, CameraResponse, ExposureCheck | None]:
    """The exposures from the data (:func:`response_stage`'s check, or with
    ``--exposures-from-data`` the ones to merge with) on the brackets as alignment left
    them. Measured before registration, brackets that moved compare different scene
    points: on hand-held ladders (``tests/hard_cases.py``) the check named 2-8 brackets
    per stack, up to 4 stops off, and ``--exposures-from-data`` failed. On a warped stack
    the brackets that could not be registered keep the metadata's exposure
    (``unmeasured``), and the exposures merged with are those fitted with alignment's
    re-solved response (``calibration``); on a stack left as it was the check before
    alignment holds. With no metadata, where the inference before registration failed,
    the ladder inferred on the registered brackets (:func:`with_unregistered` places
    the others), said by ``say``."""
    if check is None or not plan.aligns:
        return prepared, response, check
    if check.inferred:
        fitted = calibration.check if motion.warped and calibration is not None else None
        if fitted is None and check.deferred is not None:
            raise check.deferred
        if fitted is not None:
            check = with_unregistered(fitted, prepared.stack)
            prepared = replace(prepared, stack=replace(prepared.stack,
                                                       exposures=check.estimated))
        if say is not None:
            say(f"exposures: {check.line()}")
        return prepared, response, check
    use, stack = plan.options.exposures_from_data, prepared.stack
    if not (use or motion.warped):
        return prepared, response, check
    if not motion.warped:  # the same codes: as response_stage would have, had it used them
        stack, response, check = exposures_from_data(
            stack, response, True, None if solve is None else _solved(solve,
                                                                       prepared.excluded))
        return replace(prepared, stack=stack), response, check
    unmeasured = [j for j, _ in motion.alignment.refused]
    if not use or calibration is None or calibration.check is None:
        # Measured on the warped brackets with the response alignment left (with
        # exclusions, or a saved response, nothing re-solves it).
        stack, response, check = exposures_from_data(stack, response, use,
                                                     unmeasured=unmeasured)
        return replace(prepared, stack=stack), response, check
    fitted = dict(zip(calibration.check.files, calibration.check.estimated, strict=True))
    metadata = np.asarray(stack.exposures, np.float64)
    estimated = np.array([fitted.get(name, t) for name, t in zip(stack.files, metadata)])
    check = ExposureCheck(tuple(stack.files), metadata, estimated, True,
                          unmeasured=tuple(j for j, name in enumerate(stack.files)
                                           if name not in fitted))
    return replace(prepared, stack=replace(stack, exposures=estimated)), response, check


def align_stage(prepared: Prepared, response: CameraResponse, plan: MergePlan,
                solve: Solve | None, owned: bool, say: Progress
                ) -> tuple[Prepared, CameraResponse, Motion]:
    """Brackets registered to the reference (``--align``) and the exclusions moved with
    them; ``solve`` (``None``: keep the response) re-solves on the aligned brackets;
    ``owned``: the stack may be warped in place."""
    options, stack = plan.options, prepared.stack
    if plan.aligns or plan.deghosts:
        jit.announce(say, "motion")
    if plan.aligns:
        say(f"aligning {stack.count} brackets ({options.align})")
    masks, excluded = prepared.masks, prepared.excluded
    stack, response, motion = align_step(stack, response, options.align, solve,
                                         in_place=owned, skip_warp="warp" in plan.skips,
                                         excluded=excluded)
    if motion.warped and excluded is not None:  # the warped borders' colour
        if masks is not None and len(set(mask_files(options.masks, stack.files))) > 1:
            # A mask per bracket is drawn on that bracket: it moves with it. One shared
            # mask is taken on the reference, where every bracket now is.
            masks = align_masks(masks, motion.alignment)
        excluded = exclusions(stack, plan, masks)
    return replace(prepared, stack=stack, masks=masks, excluded=excluded), response, motion


def nd_stage(stack: ExposureStack, response: CameraResponse, filtered: np.ndarray | None
             ) -> tuple[ExposureStack, NDReport | None]:
    """Each ND filter's gains measured on the aligned brackets (``--nd``)."""
    if filtered is None:
        return stack, None
    gains, found = filter_gains(stack, response, filtered)
    return replace(stack, channel_gains=gains), NDReport(stack.files, filtered, found)


def stack_noise(stack: ExposureStack, response: CameraResponse,
                excluded: np.ndarray | None) -> NoiseModel:
    """The noise model of ``stack`` on ``response`` (:func:`fit_noise`), its floors those of
    the brackets' encoding (camera RAW is linear), leaving out ``excluded``."""
    return fit_noise(stack.codes, stack.exposures, response, encoding=noise_encoding(
        stack.files, stack.code_max, is_raw_stack(stack)), exclude=excluded)


def held_survey(stack: ExposureStack, response: CameraResponse, motion: Motion,
                excluded: np.ndarray | None, surveys: Surveys | None) -> Survey | None:
    """What the response solve's clip filter measured (``surveys``), where it holds for
    ``stack`` and ``response``: the same codes (not warped since), exposures, response
    and encoding, nothing excluded; else ``None``."""
    if surveys is None or excluded is not None or motion.warped:
        return None
    return surveys.find(stack.codes, stack.exposures, response, noise_encoding(
        stack.files, stack.code_max, is_raw_stack(stack)))


def motion_test_exposures(stack: ExposureStack, motion: Motion, plan: MergePlan,
                          check: ExposureCheck | None) -> np.ndarray | None:
    """The exposures deghosting's test reads instead of ``stack``'s: the data's, where
    :meth:`~hdrio.merge.exposure_check.ExposureCheck.for_the_motion_test` says so and
    the brackets were not warped (the check ran before they were registered: its
    estimates hold if none moved); else ``None``."""
    if not plan.deghosts or check is None or motion.warped:
        return None
    found = check.for_the_motion_test()
    return found if found is not None and len(found) == stack.count else None


def deghost_stage(stack: ExposureStack, response: CameraResponse, motion: Motion,
                  plan: MergePlan, solve: Solve | None, excluded: np.ndarray | None,
                  say: Progress, surveys: Surveys | None = None,
                  test_exposures: np.ndarray | None = None
                  ) -> tuple[CameraResponse, NoiseModel | None, ClipPolicy | None]:
    """Movers dropped (``--deghost``: ``motion.keep``) and the response re-solved
    without them (``solve``; ``None`` under exclusions): ``(response, noise, clip)``,
    ``noise`` the model the consistency test read and ``clip`` the saturation policy it
    was decided with (:func:`hdrio.merge.saturation.clip_policy` on the first response:
    in a stack that mixes its channels after the clip, the observations it drops whole
    say nothing of motion), both ``None`` without deghosting. ``excluded``: the
    observations the merge leaves out (``--mask``, ``--exclude-color``), left out of the
    noise fit and the test too. ``surveys``: the response solve's measures
    (:class:`hdrio.merge.saturation.Surveys`), read again where they hold: the same
    codes (not warped), exposures and response, nothing excluded. ``test_exposures``
    (:func:`motion_test_exposures`): the exposures the data say, when the metadata's
    are off; the test then reads them, with a noise model fitted on them, while the
    merge keeps ``stack``'s, ``noise`` and a response re-solved in ``stack``'s."""
    if plan.deghosts:
        say("deghosting")
    noise = clip = None
    if plan.deghosts and stack.count > 1:
        survey = held_survey(stack, response, motion, excluded, surveys)
        noise = survey.noise if survey is not None else stack_noise(stack, response,
                                                                     excluded)
        clip = clip_policy(plan.options.saturation, stack.codes, response, noise,
                           stack.exposures, exclude=excluded, survey=survey)
    mixed = clip.kernel_args() if clip is not None and clip.neutral else None
    tested, tested_noise, resolve = stack, noise, solve
    if test_exposures is not None:  # only when deghosting (motion_test_exposures)
        tested = replace(stack, exposures=np.asarray(test_exposures, np.float64))
        tested_noise = stack_noise(tested, response, excluded)
        if solve is not None:  # the response the merge reads: in the merge's exposures
            def resolve(_tested: ExposureStack, exclude: np.ndarray | None
                        ) -> CameraResponse:
                return solve(stack, exclude)
    return deghost_step(tested, response, motion, plan.options.deghost, resolve,
                        tested_noise, excluded, mixed), noise, clip


def noise_stage(stack: ExposureStack, response: CameraResponse, plan: MergePlan,
                fitted: NoiseModel | None, excluded: np.ndarray | None
                ) -> NoiseModel | None:
    """The noise model the merge reads, when the plan needs one: ``fitted`` (deghosting's,
    on this same response) or fitted here; else ``None``."""
    if not plan.fits_noise:
        return None
    if fitted is not None:
        return fitted
    return stack_noise(stack, response, excluded)


def covering_bracket(stack: ExposureStack, prepared: Prepared, plan: MergePlan
                     ) -> tuple[ExposureStack, str | None]:
    """The one bracket that covers the scene (skip ``covered``), as a stack of one, and
    its name; else ``stack`` and ``None``."""
    kinds = stack.kinds
    if "covered" in plan.skips and not all(kinds):  # not looked at when read
        kinds = tuple(classify(codes, stack.code_max) for codes in stack.codes)
    if ("covered" not in plan.skips or "covers" not in kinds
            or prepared.excluded is not None or prepared.filtered is not None):
        return stack, None
    j = len(kinds) - 1 - kinds[::-1].index("covers")  # the longest
    name = Path(stack.files[j]).name
    one = ExposureStack.from_arrays(
        stack.codes[j:j + 1], stack.exposures[j:j + 1], files=stack.files[j:j + 1],
        code_max=stack.code_max, exposure_sources=stack.exposure_sources[j:j + 1],
        metadata=stack.metadata[j:j + 1], kinds=("covers",),
        dropped=stack.dropped + tuple((other, f"{name} covers the range")
                                      for other in stack.files if other != stack.files[j]))
    return one, name
