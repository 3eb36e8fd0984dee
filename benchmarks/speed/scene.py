"""The benchmark's bracket sets: the demo scene rendered small, tiled to full size."""

from __future__ import annotations

import numpy as np

from benchmarks.truth.curves import Curve
from hdrio.radiometry.curve import CameraResponse
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import demo_scene, render_brackets

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


# Scenes built to need each skip of hdrio.skips (tests/test_skips.py uses them too). Each
# is rendered at TILE size (or smaller) and tiled, as bracket_stack is.

def narrow_scene(height: int, width: int, stops: float = 4.0, seed: int = 0) -> np.ndarray:
    """The demo room's texture squeezed into ``stops`` of range (0.5 .. 0.5 * 2^stops):
    a flat, evenly lit scene that one exposure can hold. At most :data:`TILE` in size."""
    room = demo_scene(min(height, TILE[0]), min(width, TILE[1]), seed=seed)
    log_room = np.log2(room)
    low, high = np.percentile(log_room, [0.1, 99.9])
    return (0.5 * 2.0 ** (stops * np.clip((log_room - low) / (high - low), 0, 1))
            ).astype(np.float32)


def render(radiance: np.ndarray, times: np.ndarray, height: int, width: int,
           seed: int = 0) -> ExposureStack:
    """8-bit brackets of ``radiance`` through :data:`GAMMA`, tiled to ``height x width``."""
    codes = render_brackets(radiance, times, GAMMA.response, seed=seed)
    reps = (1, -(-height // radiance.shape[0]), -(-width // radiance.shape[1]), 1)
    codes = np.tile(codes, reps)[:, :height, :width]
    return ExposureStack.from_arrays(np.ascontiguousarray(codes), times)


def tiled(radiance: np.ndarray, height: int, width: int) -> np.ndarray:
    """``radiance`` tiled to ``height x width`` (the truth of a :func:`render` stack)."""
    reps = (-(-height // radiance.shape[0]), -(-width // radiance.shape[1]), 1)
    return np.tile(radiance, reps)[:height, :width]


def ladder_beyond_scene(height: int, width: int) -> ExposureStack:
    """9 brackets 2.5 EV apart around a 3-stop scene: the two shortest are all dark and
    the two longest all bright, so the outermost ones need not even be decoded (skip
    ``brackets``)."""
    return render(narrow_scene(height, width, stops=3.0), exposures(9, 2.5), height, width)


def covered_scene(height: int, width: int) -> ExposureStack:
    """5 brackets 1 EV apart around a 3.5-stop scene: the middle one alone holds every
    code between 25 and 95 % of the range (skip ``covered``)."""
    return render(narrow_scene(height, width, stops=3.5), exposures(5, 1.0) * 9.0,
                  height, width)


def sky_scene(height: int, width: int) -> ExposureStack:
    """7 brackets 2 EV apart of the demo room under a band of open sky (the top 40 % of
    each tile's rows), which saturates across whole rows in the long exposures (skip
    ``early-stop``)."""
    radiance = demo_scene(min(height, TILE[0]), min(width, TILE[1])) * 40.0
    radiance[: int(0.4 * radiance.shape[0])] = np.array([60.0, 70.0, 90.0], np.float32)
    return render(radiance, exposures(7), height, width)


def grey_scene(height: int, width: int) -> ExposureStack:
    """7 brackets of the demo scene's green channel stored as RGB: three identical
    channels (skip ``channels``)."""
    grey = demo_scene(min(height, TILE[0]), min(width, TILE[1]))[..., 1:2] * 40.0
    stack = render(grey, exposures(7), height, width)
    return ExposureStack.from_arrays(np.repeat(stack.codes, 3, axis=-1), stack.exposures)
