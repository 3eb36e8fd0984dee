"""Compiled loops of the response recovery: the sampler's draw and the normal matrix.

Both replace NumPy code whose cost was its temporaries rather than its arithmetic, at
the speed benchmark's size (24 MP, 7 brackets, 1000 samples):

* :func:`draw_from_bins`: in NumPy the draw needed a stable argsort of the ``(P, M)``
  bin labels and a bincount, each making a 64-bit copy of them: 1.2 ms of the
  sampler's 3 ms, against 0.4 ms here.
* :func:`reduced_normal_matrix`: in NumPy the ``N P^2`` code pairs, their products and
  their ``np.bincount`` into ``n^2`` bins took 0.3 ms per channel, against 0.04 ms here.

Compiled by numba on first use and cached on disk beside this module (or in
``NUMBA_CACHE_DIR``), like the merge kernel.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def draw_from_bins(labels, phase, per_bin, picked):  # pragma: no cover - compiled
    """Write up to ``per_bin`` pixels of every bin of every bracket to ``picked``.

    ``labels`` is ``(P, M)`` ``uint8``: each grid pixel's bin in each bracket, or
    ``B = phase.shape[1]`` or more where it is no candidate there. A bin of ``n``
    members, in raster order, gives its members of rank ``floor((k + u) n / per_bin)``
    for ``k = 0 .. per_bin - 1``, ``u = phase[j, b]``: a systematic sample, every member
    equally likely and the draws spread over the image; a bin of at most ``per_bin``
    members gives them all. Each pixel is written once however many brackets draw it.
    ``picked`` needs room for ``P * B * per_bin`` entries; returns how many were written.
    """
    count, size = labels.shape
    n_bins = phase.shape[1]
    members = np.zeros(n_bins, np.int64)
    seen = np.zeros(n_bins, np.int64)
    drawn = np.zeros(n_bins, np.int64)
    target = np.zeros(n_bins, np.int64)
    taken = np.zeros(size, np.bool_)
    n_picked = 0
    for j in range(count):
        members[:] = 0
        for m in range(size):
            if labels[j, m] < n_bins:
                members[labels[j, m]] += 1
        for b in range(n_bins):
            seen[b] = 0
            drawn[b] = 0
            target[b] = int(phase[j, b] * members[b] / per_bin)
        for m in range(size):
            b = labels[j, m]
            if b >= n_bins or drawn[b] == per_bin:
                continue
            if seen[b] == target[b]:
                if not taken[m]:
                    taken[m] = True
                    picked[n_picked] = m
                    n_picked += 1
                while drawn[b] < per_bin and target[b] <= seen[b]:  # ranks repeat in
                    drawn[b] += 1                                    # small bins
                    target[b] = int((drawn[b] + phase[j, b]) * members[b] / per_bin)
            seen[b] += 1
    return n_picked


@njit(cache=True, nogil=True)
def reduced_normal_matrix(Z, squares, l_inverse, diagonal, first, second,
                          out):  # pragma: no cover - compiled
    """Write the Schur complement of the ``ln E`` block of ``A^T A`` to ``out`` ``(n, n)``.

    ``out = diag(diagonal) + bands(first, second) - sum_i l_inverse[i] v_i v_i^T`` with
    ``v_i = sum_j squares[i, j] e_{Z[i, j]}``: ``Z`` and ``squares`` (``u_ij^2``) are
    ``(N, P)``, ``diagonal`` ``(n,)`` and the symmetric first and second off-diagonal
    bands ``(n-1,)``, ``(n-2,)`` (see :mod:`hdrio.response.normal_equations`).
    """
    n = out.shape[0]
    n_samples, n_brackets = Z.shape
    out[:] = 0.0
    for i in range(n_samples):
        for j in range(n_brackets):
            scaled = squares[i, j] * l_inverse[i]
            for k in range(n_brackets):
                out[Z[i, j], Z[i, k]] -= scaled * squares[i, k]
    for z in range(n):
        out[z, z] += diagonal[z]
    for z in range(n - 1):
        out[z, z + 1] += first[z]
        out[z + 1, z] += first[z]
    for z in range(n - 2):
        out[z, z + 2] += second[z]
        out[z + 2, z] += second[z]
