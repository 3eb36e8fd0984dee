"""Merge estimators: how each bracket's estimate ``x_j`` of a pixel's radiance is weighted.

Every estimator is a weighted mean ``E = sum_j w_j(Z_j) x_j / sum_j w_j(Z_j)`` computed by
the one fused kernel (:func:`hdrio.merge.weighted_mean.merge_brackets`), with the same
saturation policy and fallbacks; they differ in the weights and the domain, which an
:class:`Estimator` states once (:data:`ESTIMATORS`, by name; the merge functions of
:data:`hdrio.merge.methods.MERGE_METHODS` and the job's plan read them):

``inverse-variance`` (the default; alias ``Granados2010``, ``noise-optimal``)
    Linear domain, ``w_j(z) = 1 / var(x_j | z)`` from the stack's own noise model
    (:mod:`hdrio.radiometry.noise`): the minimum-variance unbiased combination of independent
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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hdrio.method_registry import MethodRegistry
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.noise import (
    NoiseModel,
    observation_variance,
    supported_range,
    usable_codes,
)
from hdrio.radiometry.tables import code_weights
from hdrio.stack import exposure_columns


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


NoiseWeights = Callable[[CameraResponse, np.ndarray, NoiseModel], np.ndarray]


@dataclass(frozen=True)
class Estimator:
    """One merge estimator: its weights and the domain it averages in.

    Attributes
    ----------
    name
        Canonical name (``hdrio:merge`` in the header).
    domain
        ``log`` or ``linear``: where the weighted mean is taken.
    noise_weights
        Per-bracket weights from the noise model, ``(P, C, levels)``; ``None`` for the
        code-weighted estimators, whose ``w(z)`` comes from ``--weighting``.
    """

    name: str
    domain: str
    noise_weights: NoiseWeights | None = None

    @property
    def needs_noise(self) -> bool:
        """Whether the weights read the noise model (:mod:`hdrio.radiometry.noise`)."""
        return self.noise_weights is not None

    def weight_tables(self, response: CameraResponse, exposures, weighting: str,
                      noise: NoiseModel | None) -> np.ndarray:
        """The weights this estimator merges with, ``(P or 1, C, levels)``, zero at
        ``Z_max``: the noise model's (``noise`` required) or ``weighting``'s ``w(z)``."""
        if self.noise_weights is None:
            weights = code_weights(response, weighting)
        elif noise is None:
            raise ValueError(f"the {self.name} merge needs a noise model")
        else:
            weights = self.noise_weights(response, exposures, noise)
        weights[..., -1] = 0.0
        return weights


ESTIMATORS: MethodRegistry[Estimator] = MethodRegistry(
    "merge",
    {"inverse-variance": Estimator("inverse-variance", "linear", weights_inverse_variance),
     "Poisson": Estimator("Poisson", "linear", weights_Poisson),
     "log": Estimator("log", "log"),
     "linear": Estimator("linear", "linear")},
    aliases={"Granados2010": "inverse-variance", "noise-optimal": "inverse-variance",
             "Hanji2020": "Poisson", "Debevec1997": "log", "tutorial": "log"},
)
