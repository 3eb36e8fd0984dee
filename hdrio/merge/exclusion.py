"""Pixels kept out of the merge (``--exclude-color``, ``--mask``), not only out of the solve.

An excluded observation (bracket ``j`` at pixel ``x``) gets keep weight 0 in the masked
re-merge (:func:`hdrio.merge.masked.remerge_masked`, the one deghosting uses, here on a
grid of one-pixel cells), so the pixel is filled from the brackets where it is not
excluded, with the merge's own weights and saturation policy. A pixel excluded in every
bracket is *unseen*: its radiance is set to 0 and it is written with alpha 0, counted
apart in the statistics, and left out of the clipped fraction and the preview's key.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from hdrio.merge.masked import remerge_masked
from hdrio.merge.saturation import ClipPolicy
from hdrio.merge.weighted_mean import MergeStatistics
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.tables import merge_tables


def colour_exclusion(codes: np.ndarray, colour: Sequence[int] | None) -> np.ndarray | None:
    """``(P, H, W)`` bool: bracket ``j``'s pixel equals ``colour`` in every channel
    (registration borders); ``None`` when no colour is given. Raises ``ValueError`` when
    ``colour`` has the wrong number of values."""
    if colour is None:
        return None
    target = np.asarray(colour, dtype=codes.dtype)
    if target.size != codes.shape[-1]:
        raise ValueError(f"exclusion colour has {target.size} values, images have "
                         f"{codes.shape[-1]} channels")
    return np.all(codes == target, axis=-1)


def either(first: np.ndarray | None, second: np.ndarray | None) -> np.ndarray | None:
    """The union of two optional exclusion masks."""
    if first is None or second is None:
        return second if first is None else first
    return first | second


def pixel_keep(excluded: np.ndarray, motion_keep: np.ndarray | None, cell: int) -> np.ndarray:
    """``(P, H, W)`` float32 keep weights per pixel: 0 where excluded, times the
    deghosting's cell weights ``motion_keep`` ``(P, rows, cols)`` interpolated bilinearly
    between cell centres (as :func:`hdrio.merge.masked.remerge_masked` does)."""
    import scipy.ndimage
    keep = (~excluded).astype(np.float32)
    if motion_keep is not None:
        height, width = excluded.shape[1:]
        for j in range(keep.shape[0]):
            zoom = scipy.ndimage.zoom(motion_keep[j].astype(np.float32), cell, order=1,
                                      grid_mode=True, mode="nearest")
            keep[j] *= np.clip(zoom[:height, :width], 0.0, 1.0)
    return keep


def remerge_excluded(codes: np.ndarray, exposures: np.ndarray, response: CameraResponse,
                     radiance: np.ndarray, excluded: np.ndarray, *,
                     motion_keep: np.ndarray | None, cell: int, weights: np.ndarray,
                     domain: str, policy: ClipPolicy) -> np.ndarray:
    """Re-merge, in place in ``radiance`` ``(H, W, C)``, every pixel some bracket is
    excluded at (and those ``motion_keep`` drops); set unseen pixels to 0.

    Parameters
    ----------
    codes, exposures
        The stack's ``(P, H, W, C)`` codes and exposure times (seconds).
    excluded
        ``(P, H, W)`` bool, true where bracket ``j`` must not be used.
    motion_keep, cell
        The deghosting's keep weights on cells of ``cell`` pixels, or ``None``.
    weights, domain, policy
        The merge's weights (:meth:`hdrio.radiometry.estimators.Estimator.weight_tables`),
        domain and saturation policy
        (:attr:`hdrio.merge.weighted_mean.MergeStatistics.policy`).

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` bool, the unseen pixels (excluded in every bracket).
    """
    keep = pixel_keep(excluded, motion_keep, cell)
    terms, estimates = merge_tables(response, exposures, "Debevec1997", domain, weights)
    remerge_masked(codes, keep, 1, terms, estimates, policy, domain == "log", radiance)
    unseen = excluded.all(axis=0)
    radiance[unseen] = 0.0
    return unseen


def masked_statistics(codes: np.ndarray, excluded: np.ndarray, code_max: int,
                      statistics: MergeStatistics) -> MergeStatistics:
    """``statistics`` counted over the observations not excluded: clipped everywhere is a
    channel at or above its limit (``statistics.limits``, else ``code_max``) in the
    shortest bracket kept there, black everywhere code 0 in every channel in the longest
    one kept; unseen pixels are ``masked_everywhere``. ``codes`` are shortest exposure
    first."""
    count = codes.shape[0]
    limits = np.asarray(statistics.limits or (code_max,) * codes.shape[-1])
    clipped = np.zeros(excluded.shape[1:], bool)
    black = np.zeros_like(clipped)
    found = np.zeros_like(clipped)
    for j in range(count):  # shortest kept bracket first
        here = ~found & ~excluded[j]
        clipped |= here & np.any(codes[j] >= limits, axis=-1)
        found |= here
    found[:] = False
    for j in range(count - 1, -1, -1):  # longest kept bracket first
        here = ~found & ~excluded[j]
        black |= here & np.all(codes[j] == 0, axis=-1)
        found |= here
    return replace(statistics, clipped_everywhere=int(np.count_nonzero(clipped)),
                   black_everywhere=int(np.count_nonzero(black)),
                   masked_everywhere=int(np.count_nonzero(~found)))
