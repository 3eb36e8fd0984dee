"""Ground truth: procedural HDR scenes, brackets rendered through known responses, errors.

Used by ``hdrio demo``, the round-trip tests and the truth harness in ``benchmarks/``.
Everything is seeded, so a rerun reproduces the same brackets bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.ndimage

from hdrio.radiometry.curve import CameraResponse
from hdrio.skips import WELL_EXPOSED

Response = Callable[[np.ndarray], np.ndarray]


def gamma_response(x: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """A known camera response for the demo: ``f(x) = x^(1/gamma)`` on [0, 1]."""
    return np.clip(x, 0.0, 1.0) ** (1.0 / gamma)


def gamma_inverse_response(code_max: int = 255, channels: int = 3, gamma: float = 2.2
                           ) -> tuple[CameraResponse, float]:
    """The exact inverse of :func:`gamma_response` as a response table (``g(mid) = 0``;
    code 0 taken at half a code so that ``g`` stays finite), and the sensor exposure at
    the middle code: the unit of the table's relative ``X``."""
    g = gamma * np.log(np.maximum(np.arange(code_max + 1), 0.5) / code_max)
    middle = g[(code_max + 1) // 2]
    table = np.repeat((g - middle)[:, None], channels, axis=1)
    return (CameraResponse(table, code_max, np.ones(table.shape, bool), method="truth"),
            float(np.exp(middle)))


def tabulated_response(irradiance: np.ndarray, brightness: np.ndarray) -> Response:
    """A response from a measured table (DoRF's ``I`` and ``B`` rows, both on [0, 1])."""
    irradiance = np.asarray(irradiance, dtype=np.float64)
    brightness = np.asarray(brightness, dtype=np.float64)
    return lambda x: np.interp(np.clip(x, 0.0, 1.0), irradiance, brightness)


def demo_scene(height: int = 400, width: int = 600, seed: int = 0) -> np.ndarray:
    """A procedural interior-with-window scene, relative radiance, about 17 stops.

    A dim room (textured walls 0.003 to 0.3), a colour chart, a lamp, and a window onto
    a bright sky with a sun glint: every code value of every bracket gets used.
    """
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    u, v = x / width, y / height
    texture = scipy.ndimage.gaussian_filter(rng.standard_normal((height, width)), 6)
    texture = np.exp(1.2 * texture / texture.std()).astype(np.float32)
    room = (0.003 + 0.3 * u**1.5 * (1.0 - 0.6 * v)) * texture
    scene = np.stack([room * 1.05, room, room * 0.85], axis=-1)

    window = (u > 0.55) & (u < 0.92) & (v > 0.12) & (v < 0.55)
    sky = 8.0 + 30.0 * (1.0 - v)
    scene[window] = np.stack([sky * 0.75, sky * 0.9, sky * 1.25], axis=-1)[window]
    sun = np.exp(-(((u - 0.8) * width) ** 2 + ((v - 0.25) * height) ** 2) / (2 * 6.0**2))
    scene += (3000.0 * sun * window)[..., None] * np.array([1.0, 0.95, 0.85], np.float32)

    lamp = np.exp(-(((u - 0.2) * width) ** 2 + ((v - 0.3) * height) ** 2) / (2 * 18.0**2))
    scene += (60.0 * lamp)[..., None] * np.array([1.0, 0.8, 0.5], np.float32)

    chart = [(0.45, 0.31, 0.24), (0.77, 0.58, 0.50), (0.36, 0.48, 0.61), (0.35, 0.42, 0.25),
             (0.51, 0.50, 0.69), (0.38, 0.74, 0.67), (0.85, 0.47, 0.18), (0.27, 0.36, 0.65),
             (0.76, 0.33, 0.38), (0.36, 0.24, 0.42), (0.62, 0.73, 0.25), (0.89, 0.63, 0.16)]
    patch = max(4, width // 40)
    for k, colour in enumerate(chart):
        top = int(0.68 * height) + (k // 6) * (patch + 2)
        left = int(0.08 * width) + (k % 6) * (patch + 2)
        scene[top: top + patch, left: left + patch] = np.asarray(colour) * 0.25
    return np.maximum(scene, 1e-5).astype(np.float32)


DEFAULT_SHOT_NOISE = 3e-5
"""Variance per unit sensor exposure, relative to full well (about 33,000 electrons)."""
DEFAULT_READ_NOISE = 2e-4
"""Standard deviation relative to full well (about 6.6 electrons)."""


def render_brackets(radiance: np.ndarray, exposures, response: Response = gamma_response,
                    bit_depth: int = 8, shot_noise: float = DEFAULT_SHOT_NOISE,
                    read_noise: float = DEFAULT_READ_NOISE, seed: int = 0) -> np.ndarray:
    """Render code values ``(P, H, W, C)`` of ``radiance`` for each exposure time.

    Sensor exposure ``X = E * t`` saturates at 1; noise is Gaussian with variance
    ``shot_noise * X + read_noise^2`` (photon and read noise, relative to full well; the
    defaults are a full well of about 33,000 electrons with 6.6 electrons of read noise);
    then the response ``f`` maps [0, 1] to [0, 1] and codes are quantised to
    ``bit_depth`` bits.
    """
    rng = np.random.default_rng(seed)
    code_max = 2**bit_depth - 1
    dtype = np.uint8 if bit_depth <= 8 else np.uint16
    radiance = np.asarray(radiance, dtype=np.float64)
    out = np.empty((len(exposures), *radiance.shape), dtype=dtype)
    for j, t in enumerate(exposures):
        X = radiance * t
        X = X + rng.standard_normal(X.shape) * np.sqrt(shot_noise * np.clip(X, 0, 1)
                                                       + read_noise**2)
        codes = np.rint(response(np.clip(X, 0.0, 1.0)) * code_max)
        out[j] = np.clip(codes, 0, code_max).astype(dtype)
    return out


def well_exposed(codes: np.ndarray, code_max: int, low: float = WELL_EXPOSED[0],
                 high: float = WELL_EXPOSED[1]) -> np.ndarray:
    """``(H, W)``: pixels with every channel inside ``(low, high) * code_max`` in some bracket."""
    inside = np.all((codes > low * code_max) & (codes < high * code_max), axis=-1)
    return np.any(inside, axis=0)


def radiance_error(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None
                   ) -> dict[str, float]:
    """Relative error after one best global scale (the median ratio in log space).

    Returns ``median``, ``p95``, ``p99`` of ``|s E - T| / T``, the scale ``s``, and
    ``stops`` (median ``|log2(s E / T)|``), over ``mask`` pixels (all channels).
    """
    estimate = np.asarray(estimate, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    if mask is not None:
        estimate, truth = estimate[mask], truth[mask]
    valid = (truth > 0) & (estimate > 0) & np.isfinite(estimate)
    ratio = np.log(truth[valid] / estimate[valid])
    scale = float(np.exp(np.median(ratio)))
    relative = np.abs(scale * estimate[valid] - truth[valid]) / truth[valid]
    return {
        "median": float(np.median(relative)),
        "p95": float(np.percentile(relative, 95)),
        "p99": float(np.percentile(relative, 99)),
        "stops": float(np.median(np.abs(ratio - np.log(scale))) / np.log(2)),
        "scale": scale,
        "invalid": int(np.count_nonzero(~valid)),
    }


# -------------------------------------------------------------- a camera-like pipeline

CANON_5D_MARK_II_XYZ_TO_CAMERA = np.array([[0.4716, 0.0603, -0.0830],
                                            [-0.7798, 1.5474, 0.2480],
                                            [-0.1496, 0.1937, 0.6651]])
"""The camera's colour matrix, CIE XYZ (D65) to raw RGB, as dcraw and Adobe DNG Converter
tabulate it (``adobe_coeff``, divided by 10000): the camera of ``frobisher_001``."""

SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805],
                        [0.2126, 0.7152, 0.0722],
                        [0.0193, 0.1192, 0.9505]])
"""Linear sRGB / Rec. 709 (D65) to CIE XYZ (IEC 61966-2-1)."""


def camera_matrices(xyz_to_camera: np.ndarray = CANON_5D_MARK_II_XYZ_TO_CAMERA
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """dcraw's ``cam_xyz_coeff`` for a scene in linear Rec. 709.

    Returns
    -------
    camera_from_working
        ``(3, 3)``: white-balanced raw RGB from linear Rec. 709, rows summing to 1 (a
        white scene gives equal white-balanced raw values).
    working_from_camera
        Its inverse: what the camera's JPEG engine applies after white balance.
    gains
        ``(3,)`` daylight white-balance multipliers, the least 1 (green): raw channel
        ``c`` is white-balanced raw ``c`` divided by ``gains[c]``.
    """
    camera_rgb = np.asarray(xyz_to_camera, dtype=np.float64) @ SRGB_TO_XYZ
    gains = 1.0 / camera_rgb.sum(axis=1)
    camera_from_working = camera_rgb * gains[:, None]
    return camera_from_working, np.linalg.inv(camera_from_working), gains / gains.min()


def render_camera_brackets(radiance: np.ndarray, exposures, response: Response = gamma_response,
                           *, mixing: bool = True, bit_depth: int = 8,
                           shot_noise: float = DEFAULT_SHOT_NOISE,
                           read_noise: float = DEFAULT_READ_NOISE, seed: int = 0,
                           xyz_to_camera: np.ndarray = CANON_5D_MARK_II_XYZ_TO_CAMERA,
                           mix_before_clip: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Brackets as a camera's JPEG engine makes them, ``(P, H, W, 3)`` codes.

    Per bracket (exposure ``t`` seconds; ``radiance`` linear Rec. 709, relative):

    1. raw RGB ``= camera_from_working @ (radiance t) / gains`` (:func:`camera_matrices`):
       the sensor's own channels, green the most sensitive;
    2. shot and read noise (as :func:`render_brackets`), then each raw channel clipped
       at the sensor's white level 1: the channels clip at different scene levels;
    3. white balance: times ``gains``, clipped at 1 (a raw clip stays a clip);
    4. the colour matrix ``working_from_camera`` back to Rec. 709, clipped to [0, 1]:
       a clipped raw channel now pulls the *other* output channels, below the top code
       (the colour casts and bands of partly clipped highlights);
    5. the response ``f`` and quantisation to ``bit_depth`` bits.

    ``mixing=False`` is the same camera without channel mixing (both matrices the
    identity; the same gains, noise and clipping): the control of the hue tests.
    ``mix_before_clip=True`` keeps the matrix but applies it to the unclipped
    white-balanced raw values and clips each output channel after it (steps 2-4 without
    the raw clip): the same noise draws and the same noise gain of the matrix, but
    nothing mixes after a clip, so dropping a clipped channel alone is right (the
    control that isolates what mixing after the clip costs).

    Returns
    -------
    codes
        ``(P, H, W, 3)`` uint8 or uint16.
    raw_clipped
        ``(P, H, W, 3)`` booleans: raw channel clipped (step 2 or 3) in that bracket
        (with ``mix_before_clip``, output channel clipped).
    """
    rng = np.random.default_rng(seed)
    code_max = 2**bit_depth - 1
    dtype = np.uint8 if bit_depth <= 8 else np.uint16
    camera_from_working, working_from_camera, gains = camera_matrices(xyz_to_camera)
    if not mixing:
        camera_from_working = working_from_camera = np.eye(3)
    radiance = np.asarray(radiance, dtype=np.float64)
    raw_linear = np.maximum(radiance @ camera_from_working.T, 0.0) / gains
    codes = np.empty((len(exposures), *radiance.shape), dtype=dtype)
    clipped = np.empty((len(exposures), *radiance.shape), dtype=bool)
    for j, t in enumerate(exposures):
        X = raw_linear * t
        X = X + rng.standard_normal(X.shape) * np.sqrt(shot_noise * np.clip(X, 0, 1)
                                                       + read_noise**2)
        if mix_before_clip:
            output = np.maximum(X, 0.0) * gains @ working_from_camera.T
            clipped[j] = output >= 1.0
            output = np.clip(output, 0.0, 1.0)
        else:
            balanced = np.clip(X, 0.0, 1.0) * gains
            clipped[j] = balanced >= 1.0
            output = np.clip(np.minimum(balanced, 1.0) @ working_from_camera.T, 0.0, 1.0)
        codes[j] = np.clip(np.rint(response(output) * code_max), 0, code_max).astype(dtype)
    return codes, clipped


def hue_angle_error(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray,
                    min_chroma: float = 0.02) -> np.ndarray:
    """Hue angle error in degrees, ``(n,)``, over ``mask`` pixels with a hue.

    The hue is the angle of the chromaticity ``(r, g) = (R, G) / (R + G + B)`` of linear
    RGB about the white ``(1/3, 1/3)`` (the working space's own chromaticity plane);
    pixels whose true chromaticity lies within ``min_chroma`` of white have no hue to
    keep and are left out. Scale-free: no exposure match is needed.
    """
    def hue_and_chroma(rgb):
        rgb = np.asarray(rgb, dtype=np.float64)[mask]
        total = np.maximum(rgb.sum(axis=-1, keepdims=True), 1e-30)
        r, g = (rgb[:, :2] / total - 1.0 / 3.0).T
        return np.arctan2(g, r), np.hypot(r, g)

    hue, _ = hue_and_chroma(estimate)
    true_hue, chroma = hue_and_chroma(truth)
    difference = np.angle(np.exp(1j * (hue - true_hue)))
    return np.degrees(np.abs(difference[chroma >= min_chroma]))
