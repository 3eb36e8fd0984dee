"""The merge's tables, per bracket, channel and code value: each bracket's radiance
estimate ``x_j(z)`` and its weight ``w_j(z)``.

What every merge reads (the fused kernel, the masked re-merges after deghosting and
alignment, the uncertainty layer, the Blender node's baked curves), so it sits in the
radiometry layer, below the stages that read it:

* :func:`estimate_tables`: ``x_j(z) = g(z) - ln dt_j`` (log domain) or
  ``f^-1(z) / dt_j`` (linear domain);
* :func:`code_weights`: a code weighting ``w(z)`` (:mod:`hdrio.radiometry.weighting`)
  on the codes the solve supported;
* :func:`merge_tables`: the kernel's interface, ``w_j(z) x_j(z) + i w_j(z)``.
"""

from __future__ import annotations

import numpy as np

from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.weighting import weights_table
from hdrio.stack import exposure_columns


def estimate_tables(response: CameraResponse, exposures: np.ndarray, domain: str) -> np.ndarray:
    """Per-bracket estimates ``(P, code_max + 1, C)``: ``g(z) - ln dt`` or ``f^-1(z) / dt``."""
    exposures = exposure_columns(exposures)[:, None, :]  # (P, 1, 1 or C)
    if domain == "log":
        return response.log_inverse[None] - np.log(exposures)
    with np.errstate(over="ignore"):
        return np.exp(response.log_inverse)[None] / exposures


def code_weights(response: CameraResponse, weighting: str) -> np.ndarray:
    """``weighting``'s ``w(z)`` on the codes the solve supported, ``(1, C, levels)``."""
    table = weights_table(weighting, response.code_max)[:, None] * response.supported
    return np.ascontiguousarray(table.T)[None]


def merge_tables(response: CameraResponse, exposures: np.ndarray, weighting: str,
                 domain: str, weights: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's tables ``(P, C, levels)``: the terms ``w_j(z) x_j(z) + i w_j(z)``
    (complex128: the numerator's term, the denominator's), with ``w(Z_max) = 0``, and
    the estimates ``x_j(z)`` (float64).

    ``weights`` ``(P, C, levels)``: per-bracket weights (the noise-aware estimators);
    else ``weighting``'s ``w(z)``, the same for every bracket. Per channel, codes where
    ``g`` is extrapolated (no weighted sample fell there) say little about radiance, so
    they get no weight; the fallbacks still cover every pixel.
    """
    weights = code_weights(response, weighting) if weights is None else \
        np.array(weights, dtype=np.float64)  # a copy: the end is zeroed below
    weights[..., -1] = 0.0  # a saturated observation never counts (the kernel relies on it)
    estimates = np.ascontiguousarray(
        estimate_tables(response, exposures, domain).transpose(0, 2, 1))
    return weights * estimates + 1j * weights, estimates
