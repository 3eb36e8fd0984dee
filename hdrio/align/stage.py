"""The merge's alignment and deghosting steps, as :func:`hdrio.pipeline.merge_stack` runs
them (``--align``, ``--deghost``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hdrio.align import ALIGN_MODES, DEGHOST_MODES
from hdrio.align.deghost import (
    CELL,
    Deghosting,
    comparametric_correction,
    consistency_variance,
    deghost,
)
from hdrio.align.pyramid import base_factor
from hdrio.align.quick import looks_still, usable_masks
from hdrio.align.registration import (
    Alignment,
    align_stack,
    best_exposed_bracket,
    linear_tables,
    reference_bracket,
    register,
    sharp_edges,
)
from hdrio.align.resampling import remerge_resampled
from hdrio.align.warp import coverage
from hdrio.errors import HdrioError
from hdrio.merge.debevec1997 import merge_tables
from hdrio.merge.masked import remerge_masked
from hdrio.merge.noise import NoiseModel, fit_noise, observation_variance
from hdrio.merge.saturation import ClipPolicy
from hdrio.response.curve import CameraResponse
from hdrio.stack import ExposureStack


@dataclass
class Motion:
    """What alignment and deghosting did, for the summary and the header.

    Attributes
    ----------
    alignment
        The measured warps (``None`` with ``--align off``).
    warped
        Whether the brackets were resampled (``auto`` skips it when every bracket is
        within :data:`hdrio.align.registration.WITHIN` pixels).
    deghosting
        Keep weights and the fraction deghosted (``None`` with ``--deghost off``).
    uncovered
        Fraction of pixels some warped bracket does not cover (dropped there).
    best_exposed
        :func:`hdrio.align.registration.best_exposed_bracket`, when the still check has
        found it (the deghosting test's reference: not looked for twice).
    """

    alignment: Alignment | None = None
    warped: bool = False
    deghosting: Deghosting | None = None
    uncovered: float = 0.0
    best_exposed: int | None = None
    keep: np.ndarray | None = None
    """``(P, rows, cols)`` keep weights on cells of :data:`hdrio.align.deghost.CELL`
    pixels, or ``None`` when no bracket is dropped anywhere."""


def check_modes(align: str, deghost_mode: str) -> None:
    """Raise ``ValueError`` naming the option when a mode is unknown."""
    if align not in ALIGN_MODES:
        raise ValueError(f"--align must be one of {', '.join(ALIGN_MODES)}, not {align!r}")
    if deghost_mode not in DEGHOST_MODES:
        raise ValueError(f"--deghost must be one of {', '.join(DEGHOST_MODES)}, "
                         f"not {deghost_mode!r}")


def align_step(stack: ExposureStack, response: CameraResponse, mode: str,
               solve: Callable[[ExposureStack, np.ndarray], CameraResponse] | None,
               in_place: bool = False, skip_warp: bool = True
               ) -> tuple[ExposureStack, CameraResponse, Motion]:
    """Measure and (unless ``auto`` finds nothing moved) warp; ``solve`` re-solves the
    response on the aligned brackets (``None``: keep ``response``, e.g. a saved one).
    ``skip_warp`` false (``--no-skip warp``) makes ``auto`` measure fully and warp."""
    motion = Motion()
    if mode == "off" or stack.count < 2:
        return stack, response, motion
    model = "euclidean" if mode == "auto" else mode
    if mode == "auto" and skip_warp:
        masks = usable_masks(stack.codes, stack.code_max)  # read once for all three
        # Stillness is checked from the bracket that sees most of the scene: from the
        # merge's reference (often a long bracket) the shortest ones share too few points.
        best = best_exposed_bracket(stack.codes, stack.code_max, masks=masks)
        motion.best_exposed = best
        still, refused = looks_still(stack.codes, linear_tables(response, stack.exposures),
                                     stack.code_max, best, masks)
        if still:
            reference = reference_bracket(stack.codes, stack.code_max, masks=masks)
            motion.alignment = Alignment(reference, np.repeat(np.eye(3)[None], stack.count, 0),
                                         model, (0.0,) * stack.count,
                                         tuple(sorted(refused.items())))
            return stack, response, motion
    motion.alignment, response = register(stack, response, model, solve)
    if mode != "auto" or motion.alignment.moved or not skip_warp:
        stack = align_stack(stack, motion.alignment, in_place=in_place)
        motion.warped = True
    return stack, response, motion


def deghost_step(stack: ExposureStack, response: CameraResponse, motion: Motion,
                 deghost_mode: str,
                 solve: Callable[[ExposureStack, np.ndarray], CameraResponse] | None,
                 noise: NoiseModel | None = None) -> CameraResponse:
    """Per-bracket keep weights (``motion.keep``): uncovered borders of warped brackets
    and, with ``deghost_mode`` ``auto``, observations inconsistent with the reference.

    When motion is found and ``solve`` is given, the response is re-solved without the
    moving pixels and returned: the sampler draws from rare code values first, and a
    moving object's codes are rare (a bright object in one bracket bent the response
    enough to double the error inside it on the truth scene).

    ``noise``: the stack's noise model (:mod:`hdrio.merge.noise`), which the consistency
    test reads (:func:`hdrio.align.deghost.consistency_variance`)."""
    if stack.count < 2 or (deghost_mode == "off" and not motion.warped):
        return response
    count, height, width, _ = stack.codes.shape
    # The bracket the others are tested against: the one that sees most of the scene (not
    # necessarily the one they were aligned to, which carries most of the merge).
    reference = (motion.best_exposed if motion.best_exposed is not None
                 else best_exposed_bracket(stack.codes, stack.code_max))
    cells = None
    if motion.warped:
        cells = np.stack([coverage(motion.alignment.transforms[j], height, width, CELL)
                          for j in range(count)])
        cells[motion.alignment.reference] = 1.0
        motion.uncovered = float(np.mean(cells.min(axis=0) < 1))
    if deghost_mode == "off":
        motion.keep = cells
        return response
    motion.deghosting = deghost(
        stack.codes, linear_tables(response, stack.exposures),
        consistency_variance(response, stack.exposures, noise), reference, cells,
        resampled=motion.warped)
    keep = motion.deghosting.keep
    motion.keep = keep if cells is not None or keep.min() < 1.0 else None  # nothing dropped
    if solve is not None and motion.deghosting.fraction > 0:
        dropped = motion.deghosting.keep.min(axis=0) < 1
        exclude = np.repeat(np.repeat(dropped, CELL, axis=0), CELL, axis=1)[:height, :width]
        if motion.warped:  # as register's re-solve: no invented borders, no sharp edges
            step = base_factor(height, width)  # the solve samples a coarse grid anyway
            for j in range(count):
                exclude |= sharp_edges(stack.codes[j], stack.code_max, step)
        try:
            response = solve(stack, exclude)
        except HdrioError:  # too little left to solve from: keep the first response
            pass
    return response


def remerge_step(stack: ExposureStack, response: CameraResponse, radiance: np.ndarray,
                 motion: Motion, weights: np.ndarray, domain: str, policy: ClipPolicy,
                 noise: NoiseModel | None = None) -> None:
    """Re-merge, in place in ``radiance``, the pixels where ``motion.keep`` drops some
    bracket (:func:`hdrio.merge.masked.remerge_masked`), with the merge's own weights
    (:func:`hdrio.merge.estimators.effective_weights`) in its ``domain`` and its
    saturation ``policy`` (:attr:`hdrio.merge.debevec1997.MergeStatistics.policy`).

    When the brackets were warped, every warped bracket's weight is also lowered where
    its resampling error outweighs its noise (:mod:`hdrio.align.resampling`; ``noise``:
    the stack's noise model, fitted here when not given)."""
    if motion.keep is None and not motion.warped:
        return
    terms, estimates = merge_tables(response, stack.channel_exposures, "Debevec1997", domain,
                                    weights)

    def remerge(codes, keep, out, first_row=0, rows=None, factors=None):
        remerge_masked(codes, keep, CELL, terms, estimates, policy, domain == "log", out,
                       first_row=first_row, rows=rows, factors=factors)

    if not motion.warped:
        remerge(stack.codes, motion.keep, radiance)
        return
    if noise is None:
        noise = fit_noise(stack.codes, stack.exposures, response)
    reference = motion.alignment.reference
    allowed = consistency_variance(response, stack.exposures, noise)
    remerge_resampled(stack.codes, stack.code_max, policy.limits, motion.keep, CELL, reference,
                      comparametric_correction(stack.codes, linear_tables(
                          response, stack.exposures), allowed, reference),
                      observation_variance(response, stack.exposures, noise), allowed,
                      terms.imag, remerge, radiance)
