"""Merge estimators: how each bracket's estimate ``x_j`` of a pixel's radiance is weighted.

Every estimator is a weighted mean ``E = sum_j w_j(Z_j) x_j / sum_j w_j(Z_j)`` computed by
the one fused kernel (:func:`hdrio.merge.debevec1997.merge_brackets`), with the same
saturation policy and fallbacks; they differ in the weights and the domain:

``inverse-variance`` (the default; alias ``Granados2010``, ``noise-optimal``)
    Linear domain, ``w_j(z) = 1 / var(x_j | z)`` from the stack's own noise model
    (:mod:`hdrio.merge.noise`): the minimum-variance unbiased combination of independent
    estimates, which Granados et al. (2010) show reaches the Cramér-Rao bound of the
    raw-noise model with few frames. Observations within two of their own standard
    deviations of black or of saturation stay out (their noise was cut off there).
``Poisson`` (alias ``Hanji2020``)
    Linear domain, ``w_j = dt_j`` on the same usable codes: ``E = sum X_j / sum dt_j``,
    the maximum-likelihood estimate of a photon count, needing no noise parameters
    (Hanji, Banterle & Mantiuk 2020).
``log`` (alias ``Debevec1997``, ``tutorial``)
    The tutorial's ``hdr.m``: the mean of ``g(Z_j) - ln dt_j`` under the code weighting
    ``w(z)`` (``--weighting``), exponentiated.
``linear``
    The mean of ``f^-1(Z_j) / dt_j`` under the code weighting ``w(z)``.

The weights of every estimator are per-bracket tables ``(P, C, levels)``, so all take the
kernel's fast path at the same speed.

References
----------
Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel, H.-P., & Lensch, H. P. A.
(2010). Optimal HDR reconstruction with linear digital cameras. CVPR 2010, 215-222.

Hanji, P., Zhong, F., Mantiuk, R. K. (2020). Noise-aware merging of high dynamic range
image stacks without camera calibration. ECCV 2020 Workshops.
"""

from __future__ import annotations

import numpy as np

from hdrio.merge.debevec1997 import (
    MergeStatistics,
    code_weights,
    merge_brackets,
)
from hdrio.merge.noise import (
    NoiseModel,
    code_variance_floor,
    fit_noise,
    observation_variance,
    usable_codes,
)
from hdrio.merge.saturation import ClipPolicy, clip_policy
from hdrio.registry import MethodRegistry
from hdrio.response.curve import CameraResponse
from hdrio.stack import ExposureStack, exposure_columns

NOISE_AWARE = ("inverse-variance", "Poisson")
"""Estimators whose weights read the noise model."""


def supported_range(response: CameraResponse) -> np.ndarray:
    """``(levels, C)``: codes from the first to the last the solve supported, per channel.

    Codes inside that range that no sample fell on (most of them at 16 bits, where the
    solve sees 1024 levels) have ``g`` interpolated between supported neighbours: as good
    as their neighbours, so they keep their weight.
    """
    supported = np.asarray(response.supported, dtype=bool)
    after_first = np.logical_or.accumulate(supported, axis=0)
    before_last = np.logical_or.accumulate(supported[::-1], axis=0)[::-1]
    return after_first & before_last


def weights_inverse_variance(response: CameraResponse, exposures, noise: NoiseModel
                             ) -> np.ndarray:
    """``w_j(z) = 1 / var(x_j | z)`` on usable codes, else 0: ``(P, C, levels)``.

    Units: 1 / relative radiance squared (only ratios matter).
    """
    variance = observation_variance(response, exposures, noise)
    usable = (usable_codes(response, noise) & supported_range(response)).T[None]
    return np.where(usable, 1.0 / variance, 0.0)


def weights_Poisson(response: CameraResponse, exposures, noise: NoiseModel) -> np.ndarray:
    """``w_j(z) = dt_j`` on usable codes, else 0: ``(P, C, levels)`` (seconds)."""
    usable = (usable_codes(response, noise) & supported_range(response)).T[None]
    return np.where(usable, exposure_columns(exposures)[:, :, None], 0.0)


def merge_weights(method: str, response: CameraResponse, exposures,
                  noise: NoiseModel | None) -> np.ndarray | None:
    """The per-bracket weight tables of ``method``, or ``None`` for the code-weighted
    merges (``log``, ``linear``), whose ``w(z)`` comes from ``--weighting``."""
    canonical = MERGE_METHODS.canonical(method)
    if canonical not in NOISE_AWARE:
        return None
    if noise is None:
        raise ValueError(f"the {canonical} merge needs a noise model")
    function = weights_inverse_variance if canonical == "inverse-variance" else weights_Poisson
    return function(response, exposures, noise)


def effective_weights(method: str, response: CameraResponse, exposures, weighting: str,
                      noise: NoiseModel | None) -> np.ndarray:
    """The weights ``method`` merges with, ``(P or 1, C, levels)``, zero at ``Z_max``."""
    weights = merge_weights(method, response, exposures, noise)
    weights = code_weights(response, weighting) if weights is None else weights.copy()
    weights[..., -1] = 0.0
    return weights


def merge_domain(method: str) -> str:
    """``log`` or ``linear``: where ``method`` averages."""
    return "log" if MERGE_METHODS.canonical(method) == "log" else "linear"


def _merge(method: str):
    def merge(stack: ExposureStack, response: CameraResponse, weighting: str = "Debevec1997",
              saturation: str = "auto", early_stop: bool = True,
              noise: NoiseModel | None = None, policy: ClipPolicy | None = None
              ) -> tuple[np.ndarray, MergeStatistics]:
        if method in NOISE_AWARE and noise is None:
            noise = fit_noise(stack.codes, stack.exposures, response,
                              code_floor=code_variance_floor(stack.files))
        weights = merge_weights(method, response, stack.channel_exposures, noise)
        if policy is None:
            policy = clip_policy(saturation, stack.codes, response, noise, stack.exposures)
        return merge_brackets(stack, response, weighting, merge_domain(method), saturation,
                              early_stop, weights, policy)

    merge.__name__ = f"merge_{method.replace('-', '_')}"
    merge.__doc__ = (f"Merge ``stack`` with the ``{method}`` estimator (see "
                     ":mod:`hdrio.merge.estimators`); ``noise`` is fitted when not given, "
                     "``policy`` (``saturation`` decided on the stack, "
                     ":func:`hdrio.merge.saturation.clip_policy`) decided when not given.")
    return merge


MERGE_METHODS: MethodRegistry = MethodRegistry(
    "merge", {name: _merge(name) for name in ("inverse-variance", "Poisson", "log", "linear")},
    aliases={"Granados2010": "inverse-variance", "noise-optimal": "inverse-variance",
             "Hanji2020": "Poisson", "Debevec1997": "log", "tutorial": "log"},
)
