"""Camera-like truth stacks: raw clipping, white balance and a colour matrix, and their
clipped-observation oracle.

A camera's JPEG engine clips each *raw* channel at the sensor's white level, then
white-balances the raw channels and mixes them with its colour matrix before the tone
curve (:func:`hdrio.tools.synthetic.render_camera_brackets`). Once a raw channel has clipped,
every output channel of that pixel is off, most of them below the top code. These stacks
render each scene through real cameras' matrices (dcraw's ``adobe_coeff`` table, XYZ to
camera RGB, divided by 10000) with each camera's daylight white balance (the gains that
make D65 white equal in raw, :func:`hdrio.tools.synthetic.camera_matrices`), shot and read
noise, and the harness's typical response curve; the renderer says which observations
clipped in raw.

*oracle (clipped observations)* knows that: it drops exactly the observations with a
raw channel clipped (whole, from their bracket and every longer one), merges with the
true curve and weights each observation by its exposure (the Poisson estimator, true
noise model for the usable codes). No saturation policy can know more.

The score (:func:`transition_hue`): hue angle error on *clip-transition* pixels, well
exposed in some bracket (every channel inside 5-95 % of the range) with some but not all
raw channels clipped in another, nothing clipped in the shortest.
"""

from __future__ import annotations

import numpy as np

from hdrio.tools.synthetic import (
    DEFAULT_READ_NOISE,
    DEFAULT_SHOT_NOISE,
    hue_angle_error,
    render_camera_brackets,
)

CAMERAS = {
    "5DMarkII": (4716, 603, -830, -7798, 15474, 2480, -1496, 1937, 6651),
    "D700": (8139, -2171, -663, -8747, 16541, 2295, -1925, 2008, 8093),
    "ILCE-7": (5271, -712, -347, -6153, 13653, 2763, -1601, 2366, 7242),
    "X-T1": (8458, -2451, -855, -4597, 12447, 2407, -1475, 2482, 6526),
}
"""XYZ (D65) to camera RGB of Canon's EOS 5D Mark II (the camera of ``frobisher_001``),
Nikon's D700, Sony's ILCE-7 and Fujifilm's X-T1, times 10000: dcraw 9.27's
``adobe_coeff`` (Adobe DNG Converter's ColorMatrix2)."""

NOISE_LEVELS = {"sensor": 1.0, "low": 0.1}
"""Variance scale of the renderer's shot and read noise: ``sensor`` is hdrio.tools.synthetic's
(a full well of about 33,000 electrons, 6.6 electrons of read noise); ``low`` a tenth of
that variance, as a camera's JPEG engine leaves after its noise reduction, where the bias
a clip leaves stands out of the noise."""


def camera_matrix(name: str) -> np.ndarray:
    """``(3, 3)`` XYZ to camera RGB of :data:`CAMERAS` ``name``."""
    return np.asarray(CAMERAS[name], dtype=np.float64).reshape(3, 3) / 10000.0


def render_camera_stack(radiance: np.ndarray, times, response, camera: str, noise: str,
                        seed: int) -> tuple[np.ndarray, np.ndarray]:
    """8-bit codes ``(P, H, W, 3)`` and raw-clipped flags of ``radiance`` through
    ``camera`` (:data:`CAMERAS`) at :data:`NOISE_LEVELS` ``noise``."""
    scale = NOISE_LEVELS[noise]
    return render_camera_brackets(radiance, times, response, seed=seed,
                                  xyz_to_camera=camera_matrix(camera),
                                  shot_noise=DEFAULT_SHOT_NOISE * scale,
                                  read_noise=DEFAULT_READ_NOISE * np.sqrt(scale))


def transition_pixels(codes: np.ndarray, clipped: np.ndarray, code_max: int,
                      low: float = 0.05, high: float = 0.95) -> np.ndarray:
    """``(H, W)``: well exposed in some bracket (every channel inside ``(low, high) *
    code_max``), some but not all raw channels clipped in some bracket, no raw channel
    clipped in the shortest: the pixels a clip before the colour matrix puts at risk."""
    inside = np.all((codes > low * code_max) & (codes < high * code_max), axis=-1)
    count = clipped.sum(axis=-1)
    return (np.any(inside, axis=0) & np.any((count > 0) & (count < 3), axis=0)
            & ~np.any(clipped[0], axis=-1))


def transition_hue(radiance: np.ndarray, truth: np.ndarray, mask: np.ndarray
                   ) -> dict[str, float | int | None]:
    """Hue angle error (degrees) over ``mask``: ``hue_p99``, ``hue_median`` and ``pixels``
    (those with a hue, :func:`hdrio.tools.synthetic.hue_angle_error`)."""
    error = hue_angle_error(radiance, truth, mask)
    if not error.size:
        return {"hue_p99": None, "hue_median": None, "pixels": 0}
    return {"hue_p99": float(np.percentile(error, 99)),
            "hue_median": float(np.median(error)), "pixels": int(error.size)}


def oracle_codes(codes: np.ndarray, clipped: np.ndarray, code_max: int) -> np.ndarray:
    """``codes`` with every observation that has a raw channel clipped set to
    ``code_max`` in every channel: what the oracle drops, whole."""
    out = codes.copy()
    out[np.any(clipped, axis=-1)] = code_max
    return out
