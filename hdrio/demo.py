"""The built-in sample: a procedural scene rendered to bracket files with known truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hdrio.io.write import write_image
from hdrio.synthetic import demo_scene, gamma_response, render_brackets

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
        files.append(write_image(folder / f"bracket_{n}_{d}.png", frame, "uint8"))
    return truth, files
