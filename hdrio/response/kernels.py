"""The compiled loop of the response recovery: the normal matrix.

:func:`reduced_normal_matrix` replaces NumPy code whose cost was its temporaries rather
than its arithmetic, at the speed benchmark's size (24 MP, 7 brackets, 1000 samples): in
NumPy the ``N P^2`` code pairs, their products and their ``np.bincount`` into ``n^2``
bins took 0.3 ms per channel, against 0.04 ms here. (The sampler's draw was compiled
too, to save 0.8 ms; it cost seconds of compiling on a first run, and is NumPy again:
:func:`hdrio.response.sampling._draw_from_bins`.)

Compiled by numba on first use and cached on disk beside this module (or in
``NUMBA_CACHE_DIR``), like the merge kernel.
"""

from __future__ import annotations

from numba import njit


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
    for z in range(n):  # not out[:] = 0.0: numba's slice assignment is more to compile
        for k in range(n):
            out[z, k] = 0.0
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
