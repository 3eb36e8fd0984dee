"""Debevec (1997) response recovery: dense reference, colour-hdri reference, bad data."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.errors import ResponseSolveError
from hdrio.radiometry.weighting import weighting_Debevec1997, weighting_tutorial_hat
from hdrio.response.debevec1997 import debevec1997_system, g_solve_Debevec1997


def _small_problem(seed: int, n_samples: int = 60, n_brackets: int = 5):
    rng = np.random.default_rng(seed)
    times = 0.01 * 2.0 ** np.arange(n_brackets)
    radiance = np.exp(rng.uniform(-1, 6, n_samples))
    x = np.clip(radiance[:, None] * times[None, :], 0, 1)
    return np.rint(255 * x ** (1 / 2.2)).astype(int), np.log(times)


@pytest.mark.parametrize("smoothing", [1e-3, 1.0, 50.0, 1e3, 1e5])
@pytest.mark.parametrize("weighting", [weighting_tutorial_hat, weighting_Debevec1997])
@pytest.mark.parametrize("seed", [0, 1])
def test_sparse_solve_matches_dense_lstsq(smoothing, weighting, seed):
    # The bound: 1e-6 of the range of g. Both sides are float64 least squares
    # (dense SVD vs Schur complement + refinement, or projected SVD when stiff).
    Z, log_t = _small_problem(seed)
    weights = weighting(np.arange(256), 0, 255)
    g, log_e = g_solve_Debevec1997(Z, log_t, smoothing, weights)
    A, b = debevec1997_system(Z, log_t, smoothing, weights)
    reference = np.linalg.lstsq(A.toarray(), b, rcond=None)[0]
    scale = np.ptp(reference[:256])
    assert np.max(np.abs(g - reference[:256])) <= 1e-6 * scale
    assert np.max(np.abs(log_e - reference[256:])) <= 1e-6 * scale


def test_system_is_the_tutorials(tmp_path):
    # gsolve.m: (N P + 257) x (256 + N) with the tutorial's rows; g(128) = 0.
    Z, log_t = _small_problem(3, n_samples=10, n_brackets=3)
    weights = weighting_tutorial_hat(np.arange(256), 0, 255)
    A, b = debevec1997_system(Z, log_t, 50.0, weights)
    assert A.shape == (10 * 3 + 1 + 254, 256 + 10)
    row = A.getrow(30).toarray().ravel()
    assert row[128] == 1 and np.count_nonzero(row) == 1
    smooth = A.getrow(31).toarray().ravel()  # z = 1
    assert np.allclose(smooth[:3], 50 * weights[1] * np.array([1, -2, 1]))
    g, _ = g_solve_Debevec1997(Z, log_t, 50.0, weights)
    assert abs(g[128]) < 1e-9


def test_matches_colour_hdri_reference_on_frobisher(shared_data):
    # colour-hdri's own g_solve outputs for these samples (its tests use rtol=atol=1e-3);
    # same samples, same weighting (triangle on [0.01, 0.99]), lambda 30, and the same
    # exposure normalisation ln(t S / (N^2 K)) with N = 8, S = 100, K = 12.5.
    reference = shared_data("frobisher_001") / "reference"
    samples = np.load(reference / "test_samples_Grossberg2003.npy")
    times = np.array([1 / 8, 1, 8])
    log_exposure = np.log(times * 100 / (8.0**2 * 12.5))
    weights = weighting_Debevec1997(np.linspace(0, 1, 256), 0, 1, low=0.01, high=0.99)
    for c in range(3):
        g, log_e = g_solve_Debevec1997(samples[..., c], log_exposure, 30, weights / weights.max())
        np.testing.assert_allclose(g, np.load(reference / f"test_g_solve_g_{c}.npy"),
                                   rtol=1e-3, atol=1e-3)
        np.testing.assert_allclose(log_e, np.load(reference / f"test_g_solve_lE_{c}.npy"),
                                   rtol=1e-3, atol=1e-3)


def test_flat_stack_is_refused_not_solved():
    # Every sample shows the same code in every bracket: the slope of g is undetermined.
    Z = np.full((50, 4), 100)
    with pytest.raises(ResponseSolveError, match="do not determine"):
        g_solve_Debevec1997(Z, np.log([1, 2, 4, 8]), 50, weighting_tutorial_hat(np.arange(256)))
