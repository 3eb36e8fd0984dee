"""Which brackets can carry a share of the merge's weight in a cell, from the range of
their codes there (:mod:`hdrio.align.resampling` computes a warped bracket's resampling
weights only where it can)."""

from __future__ import annotations

import numpy as np

SHARE = 0.02
"""A warped bracket's resampling weights are computed only in cells where it can carry
this share of the merge's weight (at its largest over the cell's codes, the other
brackets' at their smallest): elsewhere lowering it moves the merge by less."""


def range_tables(weights: np.ndarray, limits) -> tuple[np.ndarray, np.ndarray, int]:
    """The largest and smallest of each bracket's merge weight ``(P, C, levels)`` over
    every range of codes, ``(P, C, bins, bins)`` float32 indexed by the range's first
    and last code shifted right by the returned shift (bins of at most 256 codes' worth:
    a 16-bit range is read on bins of 256 codes, taking the extremes of the bins it
    touches). Codes at or above ``limits`` (``(C,)``) weigh 0."""
    count, channels, levels = weights.shape
    shift = max(0, int(np.ceil(np.log2(levels / 256.0))))
    w = np.array(weights, np.float64)
    for c in range(channels):
        w[:, c, int(limits[c]):] = 0.0
    bins = -(-levels // (1 << shift))
    padded = np.pad(w, ((0, 0), (0, 0), (0, bins * (1 << shift) - levels)), mode="edge")
    binned = padded.reshape(count, channels, bins, 1 << shift)
    most_bin, least_bin = binned.max(axis=-1), binned.min(axis=-1)
    most = np.zeros((count, channels, bins, bins), np.float32)
    least = np.zeros_like(most)
    for b in range(bins):
        most[:, :, b, b:] = np.maximum.accumulate(most_bin[:, :, b:], axis=-1)
        least[:, :, b, b:] = np.minimum.accumulate(least_bin[:, :, b:], axis=-1)
    return most, least, shift


def weighty_cells(low: np.ndarray, high: np.ndarray, kept: np.ndarray, tables,
                  limits, share: float = SHARE) -> np.ndarray:
    """``(P, rows, cols)`` bool: the cells where a bracket can carry ``share`` of the
    merge's weight in some channel, from each bracket's codes' range there ``low``,
    ``high`` ``(P, rows, cols, C)`` and :func:`range_tables`: its largest weight over the
    range against the others' smallest (0 where a bracket is saturated in some channel,
    or where ``kept`` ``(P, rows, cols)``, the cells' keep weights at their smallest over
    the cell and its neighbours, lowers it)."""
    most, least, shift = tables
    count, channels = low.shape[0], low.shape[-1]
    lo, hi = low.astype(np.int64) >> shift, high.astype(np.int64) >> shift
    saturated = (high >= np.asarray(limits)).any(axis=-1)
    kept = np.where(saturated, 0.0, kept)
    largest = np.stack([most[j, c][lo[j, ..., c], hi[j, ..., c]]
                        for j in range(count) for c in range(channels)]).reshape(
        (count, channels) + low.shape[1:3])
    smallest = np.stack([least[j, c][lo[j, ..., c], hi[j, ..., c]] * kept[j]
                         for j in range(count) for c in range(channels)]).reshape(
        largest.shape)
    others = smallest.sum(axis=0) - smallest  # (P, C, rows, cols)
    with np.errstate(invalid="ignore", divide="ignore"):
        fraction = largest / (largest + others)
    return (np.nan_to_num(fraction, nan=0.0) >= share).any(axis=1)
