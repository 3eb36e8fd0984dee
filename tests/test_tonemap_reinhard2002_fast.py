"""The fast (numba) Reinhard 2002 paper operators against the reference numpy/scipy
implementation in ``reinhard2002_reference.py`` (the code they replaced), on images of a
few sizes and shapes, and the kernel's building blocks on their own."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage

from hdrio.parallel import threads
from hdrio.tonemap import reinhard2002_kernels as kernels
from hdrio.tonemap.reinhard2002 import (
    ALPHA_1,
    SCALE_RATIO,
    SCALES,
    tonemap_Reinhard2002_global,
    tonemap_Reinhard2002_local,
)
from hdrio.tools.synthetic import demo_scene
from tests.reinhard2002_reference import reference_global, reference_local
from tests.test_tonemap_reinhard2002 import hdr_image

# Output tolerance, absolute on display values in [0, 1]. Both sides are float32; the fast
# side differs in summation order (blurs: float32 sums where scipy sums in float64, about
# 1e-6 relative) and evaluates x^0.6 and ln with polynomials (about 2e-7 relative). Measured
# worst case over these tests: 1.8e-7 (global) and 4.8e-7 (local, away from scale flips).
ATOL = 2e-6


def demo(height: int, width: int) -> np.ndarray:
    return demo_scene(height, width, seed=height + width)


IMAGES = {
    "demo-400x600": lambda: demo(400, 600),
    "demo-37x301": lambda: demo(37, 301),  # odd sizes, a partial tile of rows
    "demo-1000x1500": lambda: demo(1000, 1500),
    "random-32x32": lambda: hdr_image(seed=4).astype(np.float32),  # smaller than the kernels
    "column-200x1": lambda: demo(200, 3)[:, 1:2],
    "pixel-1x1": lambda: np.array([[[0.3, 0.2, 0.1]]], dtype=np.float32),
}


def local_scale_flips(rgb: np.ndarray, fast: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Pixels beyond ATOL: where the activity sits at ``epsilon`` to within the blurs'
    rounding, the two sides may pick neighbouring scales (eq. 8 is a hard threshold)."""
    return np.argwhere(np.abs(fast - reference).max(axis=-1) > ATOL)


@pytest.mark.parametrize("name", list(IMAGES))
def test_global_matches_reference(name):
    rgb = IMAGES[name]()
    for options in ({}, {"key": 0.18, "saturation": 1.0}, {"white": 3.0}):
        fast = tonemap_Reinhard2002_global(rgb, **options)
        assert fast.dtype == np.float32 and fast.shape == rgb.shape
        np.testing.assert_allclose(fast, reference_global(rgb, **options), rtol=0, atol=ATOL,
                                   err_msg=str(options))


@pytest.mark.parametrize("name", list(IMAGES))
def test_local_matches_reference(name):
    rgb = IMAGES[name]()
    for options in ({}, {"key": 0.36, "phi": 4.0, "epsilon": 0.1, "saturation": 0.8}):
        fast = tonemap_Reinhard2002_local(rgb, **options)
        reference = reference_local(rgb, **options)
        assert fast.dtype == np.float32 and fast.shape == rgb.shape
        flips = local_scale_flips(rgb, fast, reference)
        # Measured: 3 and 2 pixels of the 1.5 M of demo-1000x1500 (differences up to
        # 0.032), none elsewhere. A flip must stay a rare pixel (<= 1 in 100,000), never
        # a pattern.
        assert len(flips) <= rgb.shape[0] * rgb.shape[1] // 100_000, flips[:5]
        mask = np.ones(rgb.shape[:2], dtype=bool)
        mask[tuple(flips.T)] = False
        np.testing.assert_allclose(fast[mask], reference[mask], rtol=0, atol=ATOL,
                                   err_msg=str(options))


def test_local_uses_every_scale_on_the_demo_scene():
    """The comparison above is only meaningful if pixels settle at many different scales:
    count the scale each pixel of the demo scene gets from the reference's blurs."""
    rgb = demo(400, 600)
    L = rgb @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    L_m = (0.18 / np.exp(np.mean(np.log(1e-4 + L.astype(np.float64))))) * L
    v1 = [scipy.ndimage.gaussian_filter(L_m, ALPHA_1 * SCALE_RATIO**i, mode="mirror")
          for i in range(SCALES + 1)]
    activity = np.stack([np.abs(v1[i] - v1[i + 1]) / (2**8 * 0.18 / SCALE_RATIO ** (2 * i)
                                                      + v1[i]) for i in range(SCALES)])
    first_above = np.where((activity > 0.05).any(axis=0), (activity > 0.05).argmax(axis=0),
                           SCALES)
    assert len(np.unique(first_above)) >= 7, np.unique(first_above)


@pytest.mark.parametrize("sigma", [ALPHA_1 * SCALE_RATIO**i for i in (0, 3, 8)])
@pytest.mark.parametrize("shape", [(40, 70), (5, 3), (1, 9), (130, 1)])
def test_blur_matches_scipy_mirror(sigma, shape):
    """One blur of the tile kernel against ``scipy.ndimage.gaussian_filter`` (mirror
    borders, truncate 4), including images smaller than the kernel (repeated mirroring)."""
    image = np.exp(np.random.default_rng(7).normal(size=shape)).astype(np.float32)
    kernel = kernels.gaussian_kernel_scipy(sigma).astype(np.float32)
    r = len(kernel) // 2
    out = np.empty_like(image)
    kernels._blur_rows(image, 0, kernel, np.empty_like(image),
                       np.empty(shape[1] + 2 * r, dtype=np.float32), out)
    expected = scipy.ndimage.gaussian_filter(image, sigma, mode="mirror", truncate=4.0)
    # rtol 1e-6: float32 sums of up to 123 positive terms against scipy's float64 sums.
    np.testing.assert_allclose(out, expected, rtol=1e-6)


def test_power_and_log_polynomials():
    """``x^s`` and ``ln x`` over the float32 range, against float64 (``x^s`` where it is a
    normal float32: smaller results are clamped to about 2^-126, then clipped anyway)."""
    x = np.concatenate([np.geomspace(1e-30, 1e30, 20_001), [1.0, 0.5, 2.0]]).astype(np.float32)
    for s in (0.6, 1.0, 0.25, 1.2):
        out = np.array([kernels._power(v, s) for v in x[::50]], dtype=np.float64)
        truth = x[::50].astype(np.float64) ** s
        # rtol 5e-7 (4 float32 ulps): polynomial error ~1e-9 plus float32 roundings.
        np.testing.assert_allclose(out, truth, rtol=5e-7)
    assert kernels._power(np.float32(0.0), 0.6) == 0.0
    assert kernels._power(np.float32(0.0), 0.0) == 1.0  # as numpy: 0^0 = 1
    assert np.isnan(kernels._power(np.float32(np.nan), 0.6))
    logs = np.array([kernels._ln(v) for v in x[::50]])
    # atol 2e-7: ln(m) by series to f^9 (error < 1e-9) on a float32 argument.
    np.testing.assert_allclose(logs, np.log(x[::50].astype(np.float64)), rtol=0, atol=2e-7)


@pytest.mark.parametrize("operator", [tonemap_Reinhard2002_global, tonemap_Reinhard2002_local],
                         ids=["global", "local"])
def test_result_does_not_depend_on_thread_count(operator, monkeypatch):
    # 3 blocks of 65536 pixels (the last partial) and 19 bands of 16 rows (the last
    # partial) shared between 1, 2 and 3 threads.
    rgb = demo(301, 500)
    assert kernels.PIXEL_BLOCK == 65536 and kernels.TILE_ROWS == 16
    results = []
    for count in ("1", "2", "3"):
        monkeypatch.setenv("HDRIO_THREADS", count)
        assert threads() == int(count)
        results.append(operator(rgb))
    # Exact: each pixel and each partial sum is computed the same way whichever thread
    # does it, and the key's partial sums are added in block order.
    assert all(np.array_equal(results[0], other) for other in results[1:])


def test_local_rejects_non_images():
    with pytest.raises(ValueError, match=r"\(height, width, 3\)"):
        tonemap_Reinhard2002_local(np.ones((10, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="RGB"):
        tonemap_Reinhard2002_global(np.ones((4, 4, 4), dtype=np.float32))


def test_input_not_modified_and_any_layout_accepted():
    rgb = demo(60, 80).astype(np.float64)[:, ::-1]  # float64, not contiguous
    before = rgb.copy()
    out = tonemap_Reinhard2002_local(rgb)
    assert np.array_equal(rgb, before)
    np.testing.assert_allclose(out, reference_local(rgb), rtol=0, atol=ATOL)
