"""The merge's own stages, in the order :func:`hdrio.job.run.run_plan` runs them: the
weighted mean of the brackets, the re-merge where brackets are dropped (exclusions,
movers, resampled brackets), highlights clipped in every bracket and the uncertainty
layer.

Each takes and returns plain data; the estimator, its domain and its weight tables are
the plan's (:class:`~hdrio.job.plan.MergePlan`), the tables built once per merge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hdrio import jit
from hdrio.align.comparametric import comparametric_correction, consistency_variance
from hdrio.align.deghost import CELL
from hdrio.align.motion import Motion
from hdrio.align.registration import linear_tables
from hdrio.align.resampling import ResamplingTables, remerge_resampled
from hdrio.job.plan import MergePlan
from hdrio.job.result import Progress
from hdrio.merge.exclusion import masked_statistics, remerge_excluded
from hdrio.merge.highlights import HighlightReport, reconstruct_highlights
from hdrio.merge.masked import remerge_masked
from hdrio.merge.saturation import ClipPolicy, Survey, clip_policy
from hdrio.merge.uncertainty import relative_uncertainty
from hdrio.merge.weighted_mean import MergeStatistics, merge_brackets
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import NoiseModel, observation_variance
from hdrio.radiometry.noise_fit import fit_noise
from hdrio.radiometry.tables import estimate_tables, merge_tables
from hdrio.stack import ExposureStack


@dataclass
class Merged:
    """The merge's radiance and what produced it.

    Attributes
    ----------
    radiance
        ``(H, W, C)`` float32 relative radiance (changed in place by the later stages).
    statistics
        What the merge saw (:class:`~hdrio.merge.weighted_mean.MergeStatistics`).
    weights
        The weight tables it merged with, ``(P or 1, C, levels)``.
    brackets
        How many brackets it merged.
    """

    radiance: np.ndarray
    statistics: MergeStatistics
    weights: np.ndarray
    brackets: int

    @property
    def early_stop_fraction(self) -> float:
        """Pixel-brackets the kernel's early stop never read, of all (skip ``early-stop``)."""
        return self.statistics.observations_skipped / (self.statistics.pixels * self.brackets)


def merge_stage(stack: ExposureStack, response: CameraResponse, plan: MergePlan,
                noise: NoiseModel | None, say: Progress, *,
                excluded: np.ndarray | None = None,
                policy: ClipPolicy | None = None, survey: Survey | None = None) -> Merged:
    """The weighted mean of ``stack``'s brackets with the plan's estimator, under the
    saturation policy decided on the observations not ``excluded`` (``(P, H, W)``:
    ``--mask``, ``--exclude-color``; :func:`hdrio.merge.saturation.clip_policy`, reading
    ``survey``, the response solve's measures of this stack with ``noise``, where given),
    or ``policy`` where deghosting already decided it on the same stack, response and
    noise."""
    options, estimator = plan.options, plan.estimator
    jit.announce(say, "merge")
    say(f"merging {stack.count} brackets ({estimator.name}, {estimator.domain} domain)")
    weights = plan.weight_tables(response, stack.channel_exposures, noise)
    if policy is None:
        policy = clip_policy(options.saturation, stack.codes, response, noise,
                             stack.exposures, exclude=excluded, survey=survey)
    radiance, statistics = merge_brackets(
        stack, response, options.weighting, estimator.domain, options.saturation,
        early_stop="early-stop" in plan.skips, weights=weights, policy=policy)
    return Merged(radiance, statistics, weights, stack.count)


def remerge_exclusions(stack: ExposureStack, response: CameraResponse, merged: Merged,
                       plan: MergePlan, excluded: np.ndarray, motion: Motion
                       ) -> np.ndarray | None:
    """Re-merge, in place, the pixels some bracket is excluded at (``--exclude-color``,
    ``--mask``) or dropped for motion; returns the pixels excluded in every bracket
    (``None`` when there are none) and counts them in ``merged.statistics``."""
    unseen = remerge_excluded(stack.codes, stack.channel_exposures, response,
                              merged.radiance, excluded, motion_keep=motion.keep, cell=CELL,
                              weights=merged.weights, domain=plan.estimator.domain,
                              policy=merged.statistics.policy)
    merged.statistics = masked_statistics(stack.codes, excluded, stack.code_max,
                                          merged.statistics)
    return unseen if unseen.any() else None


def remerge_motion(stack: ExposureStack, response: CameraResponse, merged: Merged,
                   plan: MergePlan, motion: Motion, noise: NoiseModel | None) -> None:
    """Re-merge, in place, the pixels where ``motion.keep`` drops some bracket
    (:func:`hdrio.merge.masked.remerge_masked`), with the merge's own weights, domain and
    saturation policy.

    When the brackets were warped, every warped bracket's weight is also lowered where
    its resampling error outweighs its noise (:mod:`hdrio.align.resampling`; ``noise``:
    the stack's noise model, fitted here when not given)."""
    if motion.keep is None and not motion.warped:
        return
    domain, statistics = plan.estimator.domain, merged.statistics
    terms, estimates = merge_tables(response, stack.channel_exposures, "Debevec1997", domain,
                                    merged.weights)

    def remerge(codes, keep, out, first_row=0, rows=None, factors=None):
        remerge_masked(codes, keep, CELL, terms, estimates, statistics.policy,
                       domain == "log", out, first_row=first_row, rows=rows, factors=factors)

    if not motion.warped:
        remerge(stack.codes, motion.keep, merged.radiance)
        return
    if noise is None:
        noise = fit_noise(stack.codes, stack.exposures, response)
    reference = motion.alignment.reference
    allowed = consistency_variance(response, stack.exposures, noise)
    tables = ResamplingTables(
        comparametric_correction(stack.codes, linear_tables(response, stack.exposures),
                                 allowed, reference),
        observation_variance(response, stack.exposures, noise), allowed)
    remerge_resampled(stack.codes, tables, remerge, merged.radiance, reference=reference,
                      cell=CELL, cells=motion.keep, limits=statistics.limits,
                      code_max=stack.code_max, weights=terms.imag,
                      warped=np.array(motion.alignment.motion) > 0)


def remerge_stage(stack: ExposureStack, merged_stack: ExposureStack,
                  response: CameraResponse, merged: Merged, plan: MergePlan,
                  excluded: np.ndarray | None, motion: Motion, noise: NoiseModel | None
                  ) -> tuple[np.ndarray | None, bool]:
    """The re-merge where brackets are dropped, in place: exclusions (and movers with
    them), else movers and resampled brackets; nothing when ``merged_stack`` is one
    covering bracket. ``(unseen, resampled)``: the pixels excluded in every bracket
    (``None`` when none) and whether warped brackets were re-weighed (alignment's work,
    timed as its ``resample`` phase)."""
    if excluded is not None:
        return remerge_exclusions(stack, response, merged, plan, excluded, motion), False
    if merged_stack is stack:
        remerge_motion(stack, response, merged, plan, motion, noise)
        return None, motion.warped
    return None, False


def highlight_stage(merged_stack: ExposureStack, response: CameraResponse, merged: Merged,
                    excluded: np.ndarray | None, say: Progress) -> HighlightReport | None:
    """``--highlights reconstruct``: the channels clipped in every bracket estimated, in
    place, from the unclipped ones (``excluded``: the merge's exclusions, or ``None``)."""
    say("reconstructing highlights clipped in every bracket")
    statistics = merged.statistics
    return reconstruct_highlights(
        merged.radiance, merged_stack.codes[0],
        statistics.limits or (merged_stack.code_max,) * merged_stack.shape[2],
        estimate_tables(response, merged_stack.channel_exposures, "linear")[0],
        statistics.policy.neutral, None if excluded is None else ~excluded[0])


def uncertainty_stage(merged_stack: ExposureStack, response: CameraResponse, merged: Merged,
                      plan: MergePlan, noise: NoiseModel, say: Progress) -> np.ndarray:
    """``--uncertainty``: each pixel's predicted relative standard deviation."""
    say("predicting each pixel's uncertainty")
    return relative_uncertainty(merged_stack, response, merged.weights, noise,
                                plan.estimator.domain, merged.statistics.policy)
