"""The benchmark's bracket sets: the demo scene rendered small, tiled to full size."""

from __future__ import annotations

import numpy as np

from benchmarks.truth.curves import Curve
from hdrio.response.curve import CameraResponse
from hdrio.stack import ExposureStack
from hdrio.synthetic import demo_scene, render_brackets

TILE = (1000, 1500)
_LEVELS = np.linspace(0.0, 1.0, 4097)
GAMMA = Curve("gamma 2.2", _LEVELS, _LEVELS ** (1 / 2.2))
"""The camera response the benchmark's brackets are rendered through."""


def exposures(count: int, step_ev: float = 2.0) -> np.ndarray:
    """``count`` exposure times ``step_ev`` apart, centred on 1/60 s."""
    return (2.0 ** (step_ev * (np.arange(count) - (count - 1) / 2))) / 60.0


def bracket_stack(height: int, width: int, count: int = 7, step_ev: float = 2.0,
                  seed: int = 0) -> tuple[ExposureStack, np.ndarray]:
    """8-bit brackets of the demo scene ``(count, height, width, 3)`` and their radiance.

    The scene is rendered at ``TILE`` (or smaller) and tiled, which keeps the setup to
    seconds at 24 MP while every tile has the full scene's range.
    """
    tile_h, tile_w = min(height, TILE[0]), min(width, TILE[1])
    radiance = demo_scene(tile_h, tile_w, seed=seed) * 40.0
    times = exposures(count, step_ev)
    codes = render_brackets(radiance, times, GAMMA.response, seed=seed)
    reps = (1, -(-height // tile_h), -(-width // tile_w), 1)
    codes = np.tile(codes, reps)[:, :height, :width]
    radiance = np.tile(radiance, reps[1:])[:height, :width]
    return ExposureStack.from_arrays(np.ascontiguousarray(codes), times), radiance


def true_response(code_max: int = 255, channels: int = 3) -> CameraResponse:
    """:data:`GAMMA`'s inverse as a response table, ``g(z_mid) = 0``."""
    g = GAMMA.log_inverse(np.arange(code_max + 1), code_max)
    g -= g[(code_max + 1) // 2]
    table = np.repeat(g[:, None], channels, axis=1)
    return CameraResponse(table, code_max, np.ones(table.shape, bool), method="truth")
