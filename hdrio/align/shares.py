"""Which brackets can carry a share of the merge's weight in a cell, from the range of
their codes there (:mod:`hdrio.align.resampling` computes a warped bracket's resampling
weights only where it can)."""

from __future__ import annotations

import numpy as np
from numba import njit

from hdrio.parallel import on_threads

SHARE = 0.02
"""A warped bracket's resampling weights are computed only in cells where it can carry
this share of the merge's weight (at its largest over the cell's codes, the other
brackets' at their smallest): elsewhere lowering it moves the merge by less."""


STRIDE = 2
"""Pixels: a cell's range of codes is taken on every second pixel each way."""


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


def weighty_cells(codes: np.ndarray, cell: int, first: int, last: int, kept: np.ndarray,
                  tables, limits, *, share: float = SHARE, spread: int = 0) -> np.ndarray:
    """``(P, last - first, cols)`` bool: the cells (of ``cell`` pixels, rows ``first ..
    last - 1``) where a bracket of ``codes`` ``(P, H, W, C)`` can carry ``share`` of the
    merge's weight in some channel, from the range of its codes there (on every
    :data:`STRIDE`-th pixel each way) and :func:`range_tables`: its largest weight over
    the range against the others' smallest (0 where a bracket is saturated in some
    channel, or where ``kept`` ``(P, last - first, cols)``, the cells' keep weights at
    their smallest over the cell and its neighbours, lowers it). With ``spread``, only
    the cells where the bracket's codes also span more than ``spread`` codes in some
    channel (a cell with an edge in it)."""
    most, least, shift = tables
    count, height, width, channels = codes.shape
    out = np.zeros((count, last - first, -(-width // cell)), np.bool_)
    on_threads(_weighty_cells, last - first, codes, cell, first,
               np.ascontiguousarray(kept, np.float32), most, least, shift,
               np.ascontiguousarray(limits, np.int64), float(share), int(spread), out)
    return out


@njit(cache=True, nogil=True)
def _weighty_cells(start, stop, codes, cell, first, kept, most, least, shift, limits, share,
                   spread, out):  # pragma: no cover - compiled
    """Cell rows ``start .. stop - 1`` of :func:`weighty_cells`."""
    count, height, width, channels = codes.shape
    half = STRIDE // 2
    low = np.empty((count, channels), np.int64)
    high = np.empty((count, channels), np.int64)
    smallest = np.empty((count, channels))
    for cy in range(start, stop):
        y0 = (first + cy) * cell
        y1 = min(height, y0 + cell)
        ys = y0 + half if y0 + half < y1 else y0
        for cx in range(out.shape[2]):
            x0 = cx * cell
            x1 = min(width, x0 + cell)
            xs = x0 + half if x0 + half < x1 else x0
            for j in range(count):
                if channels == 3:  # one pass for the three: 1.5x faster than three
                    low0 = high0 = np.int64(codes[j, ys, xs, 0])
                    low1 = high1 = np.int64(codes[j, ys, xs, 1])
                    low2 = high2 = np.int64(codes[j, ys, xs, 2])
                    for y in range(ys, y1, STRIDE):
                        for x in range(xs, x1, STRIDE):
                            z0 = np.int64(codes[j, y, x, 0])
                            z1 = np.int64(codes[j, y, x, 1])
                            z2 = np.int64(codes[j, y, x, 2])
                            low0, high0 = min(low0, z0), max(high0, z0)
                            low1, high1 = min(low1, z1), max(high1, z1)
                            low2, high2 = min(low2, z2), max(high2, z2)
                    low[j, 0], low[j, 1], low[j, 2] = low0, low1, low2
                    high[j, 0], high[j, 1], high[j, 2] = high0, high1, high2
                    continue
                for c in range(channels):  # scalar extremes: kept in registers
                    least_code = most_code = np.int64(codes[j, ys, xs, c])
                    for y in range(ys, y1, STRIDE):
                        for x in range(xs, x1, STRIDE):
                            z = np.int64(codes[j, y, x, c])
                            least_code = min(least_code, z)
                            most_code = max(most_code, z)
                    low[j, c] = least_code
                    high[j, c] = most_code
            total = np.zeros(channels)
            for j in range(count):
                saturated = False
                for c in range(channels):
                    saturated |= high[j, c] >= limits[c]
                k = 0.0 if saturated else kept[j, cy, cx]
                for c in range(channels):
                    smallest[j, c] = least[j, c, low[j, c] >> shift, high[j, c] >> shift] * k
                    total[c] += smallest[j, c]
            for j in range(count):
                if spread > 0:
                    wide = False
                    for c in range(channels):
                        wide |= high[j, c] - low[j, c] > spread
                    if not wide:
                        continue
                for c in range(channels):
                    largest = most[j, c, low[j, c] >> shift, high[j, c] >> shift]
                    whole = largest + total[c] - smallest[j, c]
                    if whole > 0.0 and largest >= share * whole:
                        out[j, cy, cx] = True
                        break
