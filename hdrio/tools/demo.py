"""The built-in sample: a procedural scene rendered to bracket files with known truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hdrio.io.write import write_image
from hdrio.merge.methods import MERGE_METHODS
from hdrio.radiometry.noise import QUANTISATION, NoiseModel
from hdrio.stack import ExposureStack
from hdrio.tools.synthetic import (
    DEFAULT_READ_NOISE,
    DEFAULT_SHOT_NOISE,
    demo_scene,
    gamma_inverse_response,
    gamma_response,
    render_brackets,
)

# 7 brackets, 2 EV apart: 1/1024 s .. 4 s (numerator, denominator).
DEMO_EXPOSURES = [(1, 1024), (1, 256), (1, 64), (1, 16), (1, 4), (1, 1), (4, 1)]


def write_demo_brackets(folder: str | Path, seed: int = 0) -> tuple[np.ndarray, list[Path]]:
    """Write the demo brackets as 8-bit PNGs named by the tutorial's convention.

    ``bracket_1_64.png`` is the 1/64 s frame. Returns the true radiance and the paths.
    """
    folder = Path(folder)
    truth = demo_scene(seed=seed)
    times = [n / d for n, d in DEMO_EXPOSURES]
    codes = render_brackets(truth, times, gamma_response, seed=seed)
    files = []
    for (n, d), frame in zip(DEMO_EXPOSURES, codes):
        # zlib level 1: 35 ms a bracket instead of 95 ms, files 9 % larger.
        files.append(write_image(folder / f"bracket_{n}_{d}.png", frame, "uint8",
                                 {"png:compressionLevel": 1}))
    return truth, files


def oracle_radiance(stack: ExposureStack, gamma: float = 2.2) -> np.ndarray:
    """The noise-aware bound on the demo brackets: the inverse-variance merge given the true
    curve (``x^(1/gamma)``) and the renderer's true noise, in the response's units."""
    channels = stack.shape[2]
    response, unit = gamma_inverse_response(stack.code_max, channels, gamma)
    noise = NoiseModel(np.full(channels, DEFAULT_SHOT_NOISE / unit),
                       np.full(channels, DEFAULT_READ_NOISE**2 / unit**2),
                       np.full(channels, QUANTISATION), "truth")
    radiance, _ = MERGE_METHODS["inverse-variance"](stack, response, noise=noise)
    return radiance
