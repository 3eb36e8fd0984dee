"""The merge functions by estimator name: ``MERGE_METHODS["inverse-variance"](stack,
response)``, the thin dispatcher for callers that hold a stack and a response (tests,
benchmarks, the demo's oracle). The job runs the same steps stage by stage
(:mod:`hdrio.job.stages`), with the estimator its plan resolved once.

The names, aliases, weights and domains are :data:`hdrio.radiometry.estimators.ESTIMATORS`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hdrio.merge.saturation import ClipPolicy, clip_policy
from hdrio.merge.weighted_mean import MergeStatistics, merge_brackets
from hdrio.method_registry import MethodRegistry
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.estimators import ESTIMATORS, Estimator
from hdrio.radiometry.noise import NoiseModel, noise_encoding
from hdrio.radiometry.noise_fit import fit_noise
from hdrio.stack import ExposureStack

MergeFunction = Callable[..., tuple[np.ndarray, MergeStatistics]]


def merge_with(estimator: Estimator) -> MergeFunction:
    """The merge function of ``estimator``: weights, saturation policy, fused kernel."""
    def merge(stack: ExposureStack, response: CameraResponse, weighting: str = "Debevec1997",
              saturation: str = "auto", early_stop: bool = True,
              noise: NoiseModel | None = None, policy: ClipPolicy | None = None
              ) -> tuple[np.ndarray, MergeStatistics]:
        if estimator.needs_noise and noise is None:
            noise = fit_noise(stack.codes, stack.exposures, response,
                              encoding=noise_encoding(stack.files, stack.code_max))
        weights = (estimator.noise_weights(response, stack.channel_exposures, noise)
                   if estimator.needs_noise else None)
        if policy is None:
            policy = clip_policy(saturation, stack.codes, response, noise, stack.exposures)
        return merge_brackets(stack, response, weighting, estimator.domain, saturation,
                              early_stop=early_stop, weights=weights, policy=policy)

    merge.__name__ = f"merge_{estimator.name.replace('-', '_')}"
    merge.__doc__ = (f"Merge ``stack`` with the ``{estimator.name}`` estimator (see "
                     ":mod:`hdrio.radiometry.estimators`); ``noise`` is fitted when not "
                     "given, ``policy`` (``saturation`` decided on the stack, "
                     ":func:`hdrio.merge.saturation.clip_policy`) decided when not given.")
    return merge


MERGE_METHODS: MethodRegistry[MergeFunction] = ESTIMATORS.derive(merge_with)
