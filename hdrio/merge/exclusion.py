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

from hdrio.io.staging import release
from hdrio.merge.masked import remerge_masked
from hdrio.merge.saturation import ClipPolicy
from hdrio.merge.weighted_mean import MergeStatistics
from hdrio.parallel import row_bands
from hdrio.radiometry.curve import CameraResponse
from hdrio.radiometry.tables import merge_tables
from hdrio.stack import every_channel, some_channel


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
    excluded = np.empty(codes.shape[:-1], bool)
    for j in range(codes.shape[0]):  # band by band: no (P, H, W, C) comparison
        bands = row_bands(codes[j])
        for top in bands:
            rows = slice(top, top + bands.step)
            excluded[j, rows] = every_channel(codes[j, rows], np.equal, target)
        release(codes, j)
    return excluded


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
    terms, estimates = merge_tables(response, exposures, "Debevec1997", domain, weights)
    if motion_keep is not None:
        remerge_masked(codes, pixel_keep(excluded, motion_keep, cell), 1, terms, estimates,
                       policy, domain == "log", radiance)
    else:
        # Band by band of rows, the bands with an excluded observation only: one band's
        # weights at a time, not (P, H, W) float32 (672 MB at 7 x 24 MP, 1.5 s of page
        # faults here). One-pixel cells share nothing across rows: the same pixels.
        bands = row_bands(codes[0])
        for top in bands:
            rows = slice(top, top + bands.step)
            gone = excluded[:, rows]
            if gone.any():
                remerge_masked(np.ascontiguousarray(codes[:, rows]),
                               (~gone).astype(np.float32), 1, terms, estimates, policy,
                               domain == "log", radiance[rows])
                release(codes, None, top, top + bands.step)
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
    clipped = black = unseen = 0
    zero = np.zeros(codes.shape[-1], codes.dtype)
    bands = row_bands(codes[0])
    for top in bands:  # band by band of rows: no full-size temporaries
        rows = slice(top, top + bands.step)
        gone = excluded[:, rows]
        found = np.zeros(gone.shape[1:], bool)
        clipped_here = np.zeros_like(found)
        for j in range(count):  # shortest kept bracket first
            here = ~found & ~gone[j]
            clipped_here |= here & some_channel(codes[j, rows], np.greater_equal, limits)
            found |= here
        found[:] = False
        black_here = np.zeros_like(found)
        for j in range(count - 1, -1, -1):  # longest kept bracket first
            here = ~found & ~gone[j]
            black_here |= here & every_channel(codes[j, rows], np.equal, zero)
            found |= here
        clipped += int(np.count_nonzero(clipped_here))
        black += int(np.count_nonzero(black_here))
        unseen += int(np.count_nonzero(~found))
        release(codes, None, top, top + bands.step)
    return replace(statistics, clipped_everywhere=clipped, black_everywhere=black,
                   masked_everywhere=unseen)
