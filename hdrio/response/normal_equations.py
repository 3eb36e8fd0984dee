"""The Debevec (1997) least-squares problem, solved without building its matrix.

:func:`hdrio.response.debevec1997.debevec1997_system` defines the rows: one data row
``u_ij (g(Z_ij) - ln E_i) = u_ij B_ij`` per sample ``i`` and bracket ``j`` (``u_ij =
w(Z_ij)``), the gauge row ``s g(n // 2) = 0`` and the smoothness rows ``c_z (g(z-1) -
2 g(z) + g(z+1)) = 0`` with ``c_z = lambda w(z)``. Every row touches at most three
unknowns, so the products this solve needs come straight from the ``(N, P)`` codes:

* ``A^T (b - A x)`` from gathers and ``np.bincount`` over the codes;
* the normal matrix's ``ln E`` block is diagonal, ``d_i = sum_j u_ij^2``, so eliminating
  it leaves the ``n x n`` Schur complement

      S = diag(sum_ij u_ij^2 e_Z_ij) + s^2 e_mid e_mid^T + L^T L
          - sum_i (1 / d_i) v_i v_i^T,   v_i = sum_j u_ij^2 e_Z_ij,

  where ``L^T L`` (pentadiagonal) is the smoothness rows' part and the last sum runs
  over the ``N P^2`` code pairs ``(Z_ij, Z_ik)`` of each sample, one ``np.bincount``
  into the ``n^2`` entries (:func:`reduced_normal_matrix`). A numba loop did the same
  in 0.1 ms a channel instead of about 0.5, at the price of 1.4 s of compiling on a first
  run, in the job's own process, before anything else could start.

That is ``O(N P^2 + n^2)`` to assemble and one ``n x n`` Cholesky factorisation
(:mod:`hdrio.response.cholesky`) per channel. One channel of 1000 samples in 7 brackets
(the speed benchmark's solve) takes 0.9 ms at 256 levels and 23 ms at 1024 (mostly the
factorisation), where building the sparse ``A`` twice, ``A^T A`` and the Schur
complement by sparse products took 6.6 and 44 ms (same machine, same load).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from hdrio.response.cholesky import cholesky_factor

NORMAL_RCOND = 1e-12
"""Below this reciprocal condition number the normal equations lose too many digits."""


class IllConditioned(Exception):
    """The reduced normal matrix is singular or too ill-conditioned to factor."""


class Debevec1997Rows:
    """The rows of the tutorial's objective for one channel, as products, not a matrix.

    ``Z`` is ``(N, P)`` integer levels in ``0 .. n-1``, ``B`` the ``(N, P)`` ``ln dt_j``,
    ``weights`` ``w`` at each of the ``n`` levels, ``smoothing`` lambda.
    ``gauge_weight`` (``s``) scales the row ``g(n // 2) = 0``; ``None`` takes the norm
    of the heaviest column of ``A`` (at least 1): the same solution, since the gauge
    row is always met exactly, but a better-conditioned normal matrix.
    """

    def __init__(self, Z: np.ndarray, B: np.ndarray, weights: np.ndarray, smoothing: float,
                 gauge_weight: float | None = None) -> None:
        self.n = weights.size
        self.mid = self.n // 2
        self.Z = Z
        self.flat_Z = Z.reshape(-1)
        self.B = B
        self.curvature = smoothing * weights[1:-1]  # c_z, z = 1 .. n-2
        u = weights[Z]
        self.squares = u * u  # u_ij^2
        self.sample_norm2 = self.squares.sum(axis=1)  # d_i: the diagonal ln E block
        self.level_norm2 = np.bincount(self.flat_Z, weights=self.squares.reshape(-1),
                                       minlength=self.n)
        self.smoothness_bands = _smoothness_bands(self.curvature)
        if gauge_weight is None:
            columns = self.level_norm2 + self.smoothness_bands[0]
            columns[self.mid] += 1.0
            heaviest = max(columns.max(), self.sample_norm2.max(initial=0.0))
            gauge_weight = max(1.0, float(np.sqrt(heaviest)))
        self.gauge_weight = gauge_weight

    def normal_residual(self, g: np.ndarray, log_e: np.ndarray) -> tuple[np.ndarray,
                                                                           np.ndarray]:
        """``A^T (b - A x)`` for ``x = (g, ln E)``, split into its ``g`` and ``ln E`` parts."""
        c = self.curvature
        weighted = self.squares * (self.B - g[self.Z] + log_e[:, None])  # u * data residual
        r_g = np.bincount(self.flat_Z, weights=weighted.reshape(-1), minlength=self.n)
        r_g[self.mid] -= self.gauge_weight**2 * g[self.mid]
        smooth = c * c * (g[:-2] - 2.0 * g[1:-1] + g[2:])  # c * (smoothness residual)
        r_g[:-2] -= smooth
        r_g[1:-1] += 2.0 * smooth
        r_g[2:] -= smooth
        return r_g, -weighted.sum(axis=1)


def _smoothness_bands(curvature: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``L^T L`` of the smoothness rows ``c_z (g(z-1) - 2 g(z) + g(z+1))``, by its bands.

    Returns the main diagonal ``(n,)`` and the first and second superdiagonals
    ``(n-1,)``, ``(n-2,)`` (the matrix is symmetric).
    """
    c2 = curvature * curvature
    main = np.zeros(c2.size + 2)
    main[:-2] += c2
    main[1:-1] += 4.0 * c2
    main[2:] += c2
    first = np.zeros(c2.size + 1)
    first[:-1] -= 2.0 * c2
    first[1:] -= 2.0 * c2
    return main, first, c2


def reduced_normal_matrix(Z: np.ndarray, squares: np.ndarray, l_inverse: np.ndarray,
                          diagonal: np.ndarray, first: np.ndarray, second: np.ndarray
                          ) -> np.ndarray:
    """The Schur complement of the ``ln E`` block of ``A^T A``, ``(n, n)``.

    ``diag(diagonal) + bands(first, second) - sum_i l_inverse[i] v_i v_i^T`` with
    ``v_i = sum_j squares[i, j] e_{Z[i, j]}``: ``Z`` and ``squares`` (``u_ij^2``) are
    ``(N, P)``, ``diagonal`` ``(n,)`` and the symmetric first and second off-diagonal
    bands ``(n-1,)``, ``(n-2,)``.
    """
    n = diagonal.size
    products = squares[:, :, None] * squares[:, None, :] * l_inverse[:, None, None]
    pairs = Z[:, :, None] * n + Z[:, None, :]
    out = -np.bincount(pairs.reshape(-1), weights=products.reshape(-1),
                       minlength=n * n).reshape(n, n)
    z = np.arange(n)
    out[z, z] += diagonal
    out[z[:-1], z[1:]] += first
    out[z[1:], z[:-1]] += first
    out[z[:-2], z[2:]] += second
    out[z[2:], z[:-2]] += second
    return out


class ReducedNormalSolver:
    """Solve ``A^T A x = r`` by eliminating the diagonal ``ln E`` block (Schur complement).

    Raises :class:`IllConditioned` when the Cholesky factorisation fails or LAPACK's
    reciprocal condition estimate of the reduced matrix is at most :data:`NORMAL_RCOND`.
    """

    def __init__(self, rows: Debevec1997Rows) -> None:
        self.rows = rows
        d = rows.sample_norm2
        self.l_inverse = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)
        main, first, second = rows.smoothness_bands
        diagonal = rows.level_norm2 + main
        diagonal[rows.mid] += rows.gauge_weight**2
        self.g_active = diagonal > 0
        schur = reduced_normal_matrix(rows.Z, rows.squares, self.l_inverse, diagonal, first,
                                      second)
        reduced = schur if self.g_active.all() else schur[np.ix_(self.g_active, self.g_active)]
        # The 1-norm before the factorisation overwrites the matrix (symmetric, so its
        # transpose is the Fortran-ordered array LAPACK takes without a copy).
        norm1 = scipy.linalg.lapack.dlange("1", reduced.T)
        try:
            self.factor = cholesky_factor(reduced)
        except np.linalg.LinAlgError:
            raise IllConditioned from None
        # LAPACK's 1-norm reciprocal condition estimate from the Cholesky factor, O(n^2).
        rcond, info = scipy.linalg.lapack.dpocon(self.factor[0], norm1,
                                                 uplo="L" if self.factor[1] else "U")
        if info != 0 or rcond <= NORMAL_RCOND:
            raise IllConditioned

    def solve(self, r_g: np.ndarray, r_l: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(g, ln E)`` with ``A^T A (g, ln E) = (r_g, r_l)``."""
        rows = self.rows
        y = self.l_inverse * r_l
        rhs = r_g + np.bincount(rows.flat_Z, weights=(rows.squares * y[:, None]).reshape(-1),
                                minlength=rows.n)
        g = np.zeros(rows.n)
        g[self.g_active] = scipy.linalg.cho_solve(self.factor, rhs[self.g_active],
                                                  check_finite=False)
        log_e = self.l_inverse * (r_l + (rows.squares * g[rows.Z]).sum(axis=1))
        return g, log_e
