"""Reinhard et al. (2002) tone mapping: tutorial variants against a literal loop port of the
MATLAB listing (reinhardGlobal.m / reinhardLocal.m), and properties of the paper variants."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdrio.radiometry.luminance import luminance_weights
from hdrio.tonemap import TONEMAP_METHODS
from hdrio.tonemap.reinhard2002 import (
    tonemap_Reinhard2002_global,
    tonemap_Reinhard2002_global_tutorial,
    tonemap_Reinhard2002_local,
    tonemap_Reinhard2002_local_tutorial,
)

PAPER = [tonemap_Reinhard2002_global, tonemap_Reinhard2002_local]


# --- literal loop port of the MATLAB tutorial --------------------------------------------

def port_luminance(hdr):
    """makeLuminanceMap: ``0.2125 R + 0.7154 G + 0.0721 B``, pixel by pixel."""
    rows, cols = hdr.shape[:2]
    L = np.zeros((rows, cols))
    for i in range(rows):
        for j in range(cols):
            r, g, b = hdr[i, j]
            L[i, j] = 0.2125 * r + 0.7154 * g + 0.0721 * b
    return L


def port_colour(hdr, L, Ld, saturation):
    """``ldr = ((hdr ./ L) .^ saturation) .* Ld`` per channel, then ``ldr(ldr > 1) = 1``."""
    ldr = np.zeros(hdr.shape)
    for i in range(hdr.shape[0]):
        for j in range(hdr.shape[1]):
            for c in range(3):
                value = (hdr[i, j, c] / L[i, j]) ** saturation * Ld[i, j]
                ldr[i, j, c] = 1.0 if value > 1.0 else value
    return ldr


def port_global(hdr, a=0.72, saturation=0.6):
    """reinhardGlobal.m: log-average key with ``delta = 1e-4``, ``L_d = s / (s + 1)``."""
    L = port_luminance(hdr)
    rows, cols = L.shape
    total = 0.0
    for i in range(rows):
        for j in range(cols):
            total += math.log(L[i, j] + 0.0001)
    key = math.exp(total / (rows * cols))
    Ld = np.zeros_like(L)
    for i in range(rows):
        for j in range(cols):
            scaled = L[i, j] * (a / key)
            Ld[i, j] = scaled / (scaled + 1.0)
    return port_colour(hdr, L, Ld, saturation)


def port_fspecial(sigma):
    """``fspecial('gaussian', [2 ceil(2 sigma) + 1, 1], sigma)`` as a list."""
    radius = math.ceil(2.0 * sigma)
    h = [math.exp(-(x * x) / (2.0 * sigma * sigma)) for x in range(-radius, radius + 1)]
    peak = max(h)
    h = [0.0 if v < np.finfo(float).eps * peak else v for v in h]
    total = sum(h)
    return [v / total for v in h]


def port_conv2_same(image, kernel, axis):
    """``conv2(image, kernel, 'same')`` for a column (axis 0) or row (axis 1) kernel:
    zero padding, output the size of ``image``, kernel centred (and flipped)."""
    rows, cols = image.shape
    half = (len(kernel) - 1) // 2
    out = np.zeros_like(image)
    for i in range(rows):
        for j in range(cols):
            acc = 0.0
            for u, k in enumerate(kernel):
                ii, jj = (i + half - u, j) if axis == 0 else (i, j + half - u)
                if 0 <= ii < rows and 0 <= jj < cols:
                    acc += k * image[ii, jj]
            out[i, j] = acc
    return out


def port_local(hdr, saturation=0.6, eps=0.05, phi=8.0):
    """reinhardLocal.m; returns ``(ldr, sm)`` with ``sm`` the chosen 1-based scale per pixel.
    Quirk kept: every activity is normalised with the loop's last ``s = 1.6^8``."""
    L = port_luminance(hdr)
    rows, cols = L.shape
    alpha, key = 1.0 / (2.0 * math.sqrt(2.0)), 0.18
    v1 = []
    for scale in range(1, 10):
        s = 1.6 ** (scale - 1)
        kernel = port_fspecial(alpha * s)
        v1.append(port_conv2_same(port_conv2_same(L, kernel, 0), kernel, 1))
    v = [np.abs(v1[i] - v1[i + 1]) / ((2.0**phi) * key / (s**2) + v1[i]) for i in range(8)]
    sm = np.zeros((rows, cols), dtype=int)
    Lc = np.zeros_like(L)
    for i in range(rows):
        for j in range(cols):
            chosen = 0
            for scale in range(1, 9):
                if v[scale - 1][i, j] > eps:
                    chosen = 1 if scale == 1 else scale - 1
                    break
            sm[i, j] = 8 if chosen == 0 else chosen
            Lc[i, j] = L[i, j] / (1.0 + v1[sm[i, j] - 1][i, j])
    return port_colour(hdr, L, Lc, saturation), sm


# --- images --------------------------------------------------------------------------------

def hdr_image(seed=0, size=32, passes=3, grain=0.4):
    """Positive colour HDR: exp of box-smoothed noise (~6 decades), per-pixel ``grain``,
    and a few hot pixels."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(size=(size, size, 3))
    for _ in range(passes):
        noise = sum(np.roll(noise, (di, dj), axis=(0, 1)) for di in (-1, 0, 1) for dj in (-1, 0, 1))
        noise = noise / noise.std()
    log_rgb = 2.5 * noise[..., :1] + 0.3 * noise[..., 1:2] * np.array([1.0, 0.0, -1.0])
    img = np.exp(log_rgb + grain * rng.normal(size=(size, size, 3)))
    img[3, 4] = (4e3, 1e3, 2e2)
    img[20, 25] = (1e2, 9e2, 3e2)
    img[10:13, 17:20] = (5e2, 4e2, 6e3)
    return img


def ramp(vertical=False, kind="geometric"):
    """A grey ramp, 16 x 256, luminance from 1e-3 to 1e3 along the long axis."""
    x = np.geomspace(1e-3, 1e3, 256) if kind == "geometric" else np.linspace(1e-3, 1e3, 256)
    img = np.repeat(np.repeat(x[None, :, None], 16, axis=0), 3, axis=2).astype(np.float32)
    return np.ascontiguousarray(img.transpose(1, 0, 2)) if vertical else img


# --- tutorial variants against the port ----------------------------------------------------

def test_global_tutorial_matches_loop_port():
    hdr = hdr_image()
    expected = port_global(hdr)
    assert (expected == 1.0).any() and (expected < 1.0).any()  # the clamp is exercised
    # 1e-6: both are float64 evaluations of the same formulas; only summation order differs.
    np.testing.assert_allclose(tonemap_Reinhard2002_global_tutorial(hdr), expected, rtol=0,
                               atol=1e-6)


@pytest.mark.parametrize("saturation, eps, phi",
                         [(0.6, 0.05, 8.0), (0.8, 0.1, 4.0), (0.5, 0.2, 10.0)])
def test_local_tutorial_matches_loop_port(saturation, eps, phi):
    hdr = hdr_image(seed=1, passes=6, grain=0.0)  # smooth areas as well as hot spots
    expected, sm = port_local(hdr, saturation, eps, phi)
    assert len(np.unique(sm)) >= 3, np.unique(sm)  # pixels settle at different scales
    actual = tonemap_Reinhard2002_local_tutorial(hdr, saturation=saturation, eps=eps, phi=phi)
    # 1e-6: float64 on both sides; only the order of the convolution sums differs (~1e-15).
    np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-6)


# --- paper variants -----------------------------------------------------------------------

def noisy_black_image(magnitude):
    """HDR with a zero pixel and merge-noise negatives of ``magnitude`` (grey and one channel)."""
    img = hdr_image(seed=2).astype(np.float32)
    img[0, 0] = 0.0
    img[5, 5] = -magnitude
    img[6, 6] = (-magnitude, 0.5, 0.5)
    img[7, 7, 2] = -magnitude
    return img


@pytest.mark.parametrize("operator", PAPER, ids=["global", "local"])
@pytest.mark.parametrize("image", ["random", "negatives-1e-6", "negatives-1e-3"])
def test_paper_output_is_finite_float32_in_unit_range(operator, image):
    rgb = (hdr_image(seed=3).astype(np.float32) if image == "random"
           else noisy_black_image(float(image.split("-", 1)[1])))
    out = operator(rgb)
    assert out.dtype == np.float32 and out.shape == rgb.shape
    assert np.isfinite(out).all(), f"{np.isnan(out).sum()} NaN of {out.size}"
    assert out.min() >= 0.0 and out.max() <= 1.0  # exact: the operator clips


# The local operator reverses order near the border of a steep geometric ramp (6 decades
# in 256 px): the mirrored blur flattens the centre-surround activity there, so the chosen
# scale jumps from 6 to 8 (measured: 32 decreasing steps, worst -0.07). A property of the
# paper's hard scale selection, kept visible here until it is addressed.
_LOCAL_STEEP = pytest.mark.xfail(strict=True, reason="paper's scale switch at the border")


@pytest.mark.parametrize("vertical", [False, True], ids=["horizontal", "vertical"])
@pytest.mark.parametrize("operator, kind", [
    (PAPER[0], "geometric"), (PAPER[0], "linear"), (PAPER[1], "linear"),
    pytest.param(PAPER[1], "geometric", marks=_LOCAL_STEEP),
], ids=["global-geometric", "global-linear", "local-linear", "local-geometric"])
def test_paper_preserves_luminance_order_on_ramp(operator, kind, vertical):
    out = operator(ramp(vertical, kind))[..., 1]
    steps = np.diff(out, axis=0 if vertical else 1)
    # Exact (>= 0): a tone curve must never reverse the order of grey levels.
    bad = np.argwhere(steps < 0)
    assert bad.size == 0, f"{len(bad)} decreasing steps, min {steps.min():.4g} at {bad[0]}"


@pytest.mark.parametrize("Y", [1e-3, 0.18, 1.0, 50.0])
@pytest.mark.parametrize("a", [0.18, 0.72])
def test_global_uniform_grey_known_value(Y, a):
    grey = np.full((4, 5, 3), Y, dtype=np.float32)
    Lm = a * Y / (1e-4 + Y)  # L_bar = exp(log(1e-4 + Y)) for a uniform image
    # rtol 1e-6: the operator works and returns float32 (eps 1.2e-7), a few roundings deep.
    np.testing.assert_allclose(tonemap_Reinhard2002_global(grey, key=a), Lm / (1 + Lm),
                               rtol=1e-6)
    white = 2.0  # eq. 4, with Lm < white so that L_d < 1 is not clamped
    expected = Lm * (1 + Lm / white**2) / (1 + Lm)
    np.testing.assert_allclose(tonemap_Reinhard2002_global(grey, key=a, white=white),
                               expected, rtol=1e-6)


def test_global_white_point_result_clamped_to_one():
    grey = np.full((2, 2, 3), 1.0, dtype=np.float32)
    # key 4, white 1.5: eq. 4 gives ~2.2 before the clamp; exactly 1 after it.
    assert (tonemap_Reinhard2002_global(grey, key=4.0, white=1.5) == 1.0).all()


def test_luminance_weights_from_colour_science():
    # 1e-4: Rec.709 primaries with D65 give 0.21264, 0.71517, 0.07219 (the rounded textbook
    # values differ by < 5e-5).
    np.testing.assert_allclose(luminance_weights("ITU-R BT.709"), (0.2126, 0.7152, 0.0722),
                               atol=1e-4)


def test_global_pure_green_uses_working_space_weight():
    w_green = luminance_weights("ITU-R BT.709")[1]
    g, a, saturation = 2.0, 0.72, 0.6
    rgb = np.ones((4, 8, 3), dtype=np.float32)  # left half grey Y = 1, right half pure green
    rgb[:, 4:] = (0.0, g, 0.0)

    def expected_green(weight):
        L_bar = math.exp(0.5 * (math.log(1e-4 + 1.0) + math.log(1e-4 + weight * g)))
        Lm = a / L_bar * weight * g
        return (g / (weight * g)) ** saturation * Lm / (1 + Lm)

    out = tonemap_Reinhard2002_global(rgb, key=a, saturation=saturation)
    assert (out[:, 4:, [0, 2]] == 0).all()
    # rtol 1e-6 (float32 output): the tutorial's 0.7154 would be off by ~2e-4 relative.
    np.testing.assert_allclose(out[:, 4:, 1], expected_green(w_green), rtol=1e-6)
    assert abs(expected_green(0.7154) / expected_green(w_green) - 1) > 1e-5


# --- registry -----------------------------------------------------------------------------

def test_registry_resolves_names_case_insensitively():
    assert TONEMAP_METHODS["reinhard-global"] is tonemap_Reinhard2002_global
    assert TONEMAP_METHODS["REINHARD_LOCAL"] is tonemap_Reinhard2002_local
    assert TONEMAP_METHODS["reinhard-local-tutorial"] is tonemap_Reinhard2002_local_tutorial
    with pytest.raises(KeyError) as info:
        TONEMAP_METHODS["drago"]
    message = str(info.value)
    assert "drago" in message
    assert all(name in message for name in ("reinhard-global", "reinhard-local-tutorial"))


def test_log_average_luminance_is_eq_1_with_negatives_counted_as_zero():
    from hdrio.radiometry.luminance import log_average_luminance

    L = np.array([[0.01, 1.0], [100.0, -5.0]])
    # rtol 1e-12: the same float64 formula written out.
    expected = np.exp(np.mean(np.log(1e-4 + np.array([0.01, 1.0, 100.0, 0.0]))))
    np.testing.assert_allclose(log_average_luminance(L), expected, rtol=1e-12)


def test_srgb_encoding_is_colour_sciences_inverse_eotf():
    """The preview's sRGB encoding, written out to spare the colour-science import,
    agrees with colour-science's ``eotf_inverse_sRGB`` to float32 rounding (2e-7 on
    values up to 1; 1e-6 leaves room for float32 ``pow``), is clipped to [0, 1], and
    keeps the toe's linear segment exactly."""
    from colour.models import eotf_inverse_sRGB

    from hdrio.tonemap import encode_sRGB

    linear = np.concatenate([np.linspace(-0.5, 1.5, 20001), [0.0031308, 1e-8, 0.0]])
    encoded = encode_sRGB(linear.astype(np.float32))
    assert encoded.dtype == np.float32
    np.testing.assert_allclose(encoded, eotf_inverse_sRGB(np.clip(linear, 0.0, 1.0)),
                               atol=1e-6)
    assert encoded.min() == 0.0 and encoded.max() == np.float32(1.0)
