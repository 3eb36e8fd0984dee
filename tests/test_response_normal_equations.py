"""The matrix-free Debevec (1997) solve against the sparse reference system, and the
single-threaded Cholesky factorisation it uses."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from hdrio.radiometry.weighting import weighting_Debevec1997, weighting_tutorial_hat
from hdrio.response import cholesky
from hdrio.response.debevec1997 import debevec1997_system, g_solve_Debevec1997
from hdrio.response.normal_equations import Debevec1997Rows


def rendered_samples(n_samples: int, n_brackets: int, levels: int = 256, seed: int = 0):
    """``(Z, ln t)``: gamma-2.2 codes of log-uniform radiances, 2 EV apart, with clipping."""
    rng = np.random.default_rng(seed)
    times = 4.0 ** np.arange(n_brackets) / 4.0 ** (n_brackets - 1)
    radiance = np.exp(rng.uniform(np.log(0.05), np.log(20.0 * 4.0 ** (n_brackets - 1)),
                                  n_samples))
    x = np.clip(radiance[:, None] * times[None, :] / 20.0, 0, 1) ** (1 / 2.2)
    x = np.clip(x + rng.normal(0, 0.002, x.shape), 0, 1)
    return np.rint((levels - 1) * x).astype(np.int64), np.log(times)


@pytest.mark.parametrize("weighting", [weighting_tutorial_hat, weighting_Debevec1997])
def test_normal_residual_is_the_sparse_systems(weighting):
    # A^T (b - A x) at a random x, from the codes against the sparse A: the same products
    # summed in another order, so equal to rounding (1e-12 of the largest entry).
    Z, log_t = rendered_samples(80, 4, seed=1)
    weights = weighting(np.arange(256), 0, 255)
    B = np.broadcast_to(log_t, Z.shape)
    rows = Debevec1997Rows(Z, B, weights, 30.0)
    A, b = debevec1997_system(Z, log_t, 30.0, weights, rows.gauge_weight)
    x = np.random.default_rng(2).normal(size=A.shape[1])
    r_g, r_l = rows.normal_residual(x[:256], x[256:])
    reference = A.T @ (b - A @ x)
    scale = np.abs(reference).max()
    np.testing.assert_allclose(np.concatenate([r_g, r_l]), reference, rtol=0,
                               atol=1e-12 * scale)


def test_gauge_row_weighs_like_the_heaviest_column():
    # The same column norms as the sparse A with a unit gauge row (to rounding, 1e-12).
    Z, log_t = rendered_samples(60, 5, seed=3)
    weights = weighting_Debevec1997(np.arange(256), 0, 255)
    rows = Debevec1997Rows(Z, np.broadcast_to(log_t, Z.shape), weights, 50.0)
    A, _ = debevec1997_system(Z, log_t, 50.0, weights)
    heaviest = np.sqrt(np.asarray(A.multiply(A).sum(axis=0)).max())
    assert rows.gauge_weight == pytest.approx(heaviest, rel=1e-12)


@pytest.mark.parametrize(("n_samples", "n_brackets", "levels", "smoothing"), [
    (1000, 7, 256, 120.0),  # the speed benchmark's solve
    (150, 5, 1024, 960.0),  # 16-bit input's 1024 bins, lambda scaled as the solve does
])
@pytest.mark.slow
def test_fast_solve_matches_dense_lstsq(n_samples, n_brackets, levels, smoothing):
    # The bound, as in test_response_debevec1997: 1e-6 of the range of g. The
    # Schur complement is assembled from code pairs here, never from A.
    Z, log_t = rendered_samples(n_samples, n_brackets, levels, seed=4)
    weights = weighting_Debevec1997(np.linspace(0, 255, levels), 0, 255)
    g, log_e = g_solve_Debevec1997(Z, log_t, smoothing, weights)
    A, b = debevec1997_system(Z, log_t, smoothing, weights)
    reference = np.linalg.lstsq(A.toarray(), b, rcond=None)[0]
    scale = np.ptp(reference[:levels])
    assert np.max(np.abs(g - reference[:levels])) <= 1e-6 * scale
    assert np.max(np.abs(log_e - reference[levels:])) <= 1e-6 * scale


def test_unblocked_cholesky_is_available():
    # Otherwise every factorisation goes to the threaded dpotrf (correct, but slow on a
    # busy machine): the fallback should be a conscious choice, not a silent one.
    assert cholesky._potf2 is not None, "scipy.linalg.cython_lapack's dpotf2 not found"


@pytest.mark.parametrize("n", [3, 256, cholesky.UNBLOCKED_MAX + 44])
def test_cholesky_factor_solves_like_cho_factor(n):
    # Well-conditioned SPD matrix (condition ~1e2): both factorisations are backward
    # stable, so the solutions agree to ~1e-13; 1e-10 leaves room.
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n + 10))
    matrix = a @ a.T / n + np.eye(n)
    rhs = rng.normal(size=n)
    expected = scipy.linalg.cho_solve(scipy.linalg.cho_factor(matrix), rhs)
    factor = cholesky.cholesky_factor(matrix.copy())
    np.testing.assert_allclose(scipy.linalg.cho_solve(factor, rhs), expected, rtol=1e-10)
    lower = np.tril(factor[0])
    np.testing.assert_allclose(lower @ lower.T, matrix, atol=1e-10)


@pytest.mark.parametrize("n", [4, cholesky.UNBLOCKED_MAX + 44])
def test_cholesky_factor_refuses_an_indefinite_matrix(n):
    matrix = np.eye(n)
    matrix[-1, -1] = -1.0
    with pytest.raises(np.linalg.LinAlgError):
        cholesky.cholesky_factor(matrix)
