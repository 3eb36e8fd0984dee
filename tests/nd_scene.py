"""A synthetic sun scene for --nd (hdrio.merge.nd): a sky from 0.01 to 3000 times mid-grey,
a sun peaking at 1e6, a mid-grey patch (1.0) and a sunlit grey card (3e4), shot as seven
brackets 2 stops apart plus three through a 10-stop ND filter with a colour cast."""

from __future__ import annotations

import numpy as np

from hdrio.tools.synthetic import render_brackets

SUN_PEAK = 1e6
GREY = 1.0  # mid-grey: the unit of relative radiance
CARD = 3e4  # a neutral card in sunlight: seen unclipped only through the filter
ND_TRUE_STOPS = 9.9  # the filter's real density (nominal 10)
ND_CAST = np.array([1.0, 0.93, 1.12])  # its transmission per channel, relative
PATCH = (slice(52, 60), slice(8, 20))
CARD_PATCH = (slice(52, 60), slice(60, 72))


def sun_scene(height: int = 64, width: int = 96) -> np.ndarray:
    """``(H, W, 3)`` radiance relative to mid-grey, float64."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    sky = 0.01 * (3e5 ** (x / (width - 1)))  # 0.01 .. 3000 left to right
    tint = np.array([0.85, 0.95, 1.1])
    scene = sky[..., None] * tint
    r2 = (x - 30.0) ** 2 + (y - 14.0) ** 2
    glow = SUN_PEAK * np.exp(-r2 / (2 * 1.5**2)) + 2e4 * np.exp(-r2 / (2 * 6.0**2))
    scene += glow[..., None] * np.array([1.0, 0.97, 0.9])
    scene[PATCH] = GREY
    scene[CARD_PATCH] = CARD
    return scene


def sun_brackets(response, seed: int = 0) -> tuple[np.ndarray, list[float], list[float]]:
    """Codes of the 7 + 3 brackets, their shutter times (s), and the stops of filter."""
    t0 = 0.18 / 64  # the shortest main bracket; mid-grey at 0.18 in the middle one
    main = [t0 * 4.0**k for k in range(7)]
    filtered = [t0 * 128, t0 * 2, t0 / 32]  # through the filter: t0 / 8 .. t0 / 32768
    scene = sun_scene()
    codes_main = render_brackets(scene, main, response, seed=seed)
    through = scene * ND_CAST * 2.0 ** -ND_TRUE_STOPS
    codes_nd = render_brackets(through, filtered, response, seed=seed + 1)
    return (np.concatenate([codes_main, codes_nd]), main + filtered,
            [0.0] * 7 + [10.0] * 3)
