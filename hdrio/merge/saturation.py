"""Saturation policies: which observations near the top of the code range the merge drops.

A camera clips its *raw* channels at the sensor's white level, then white-balances and
mixes them with its colour matrix before the response curve. Once one raw channel has
clipped, every output channel of that pixel is wrong, and most of them are below the top
code: dropping only the codes at ``Z_max`` (``channel``) keeps those biased observations
and gives partly clipped highlights a false hue (the orange and yellow-green bands at a
clipped cloud's edge). On brackets rendered through such a camera
(:func:`hdrio.synthetic.render_camera_brackets`: the 5D Mark II's matrix) the hue error
on clip-transition pixels reaches p99 90 degrees with ``channel``.

``safe`` (the default)
    an observation (one bracket at one pixel) counts only where *every* channel is
    safely below clipping: below its own white level, found in the data
    (:func:`white_levels`), by more than the noise model's margin (the shoulder,
    :func:`saturation_limits`). Otherwise the whole observation is dropped, from its
    bracket and every longer one (as the others).
``pixel`` (the tutorial's ``hdr.m``)
    any channel at ``Z_max`` drops the observation.
``channel``
    a channel at ``Z_max`` drops that channel alone: right only for a camera that does
    not mix its channels after the clip (the truth harness's renders).

Pixels dropped even from the shortest bracket (clipped in every bracket) take a neutral
lower bound in the kernel (:func:`hdrio.merge.kernel.merge_kernel`): every channel the
largest of the shortest bracket's estimates, so they carry no colour cast.
"""

from __future__ import annotations

import numpy as np

from hdrio.merge.noise import NoiseModel, noise_grid
from hdrio.response.curve import CameraResponse

SATURATION_POLICIES = ("safe", "channel", "pixel")

_PILE_UP = 8.0  # a white level's count is this many times its neighbours' median
_TOP_FRACTION = 0.75  # white levels are looked for above this fraction of the code range
_MIN_PILE_FRACTION = 1e-3  # and must hold this fraction of the sampled observations
_MARGIN_SIGMAS = 2.0  # the shoulder: codes within this many sigmas of the white level


def white_levels(grid: np.ndarray, code_max: int) -> np.ndarray:
    """Each channel's white level (code), ``(C,)`` int64, from sampled codes ``(P, n, C)``.

    A clipped channel piles up at one code: ``Z_max`` for most files, lower where the
    camera's white balance scaled the raw white level below the top code. The white level
    is ``Z_max`` when it holds at least 0.1 % of the observations; otherwise the code of
    the largest pile-up above 75 % of the range (at least 8 times the median count of the
    8 codes below it, and 0.1 % of the observations); otherwise ``Z_max``.
    """
    channels = grid.shape[-1]
    levels = np.full(channels, code_max, dtype=np.int64)
    for c in range(channels):
        codes = grid[..., c].reshape(-1)
        counts = np.bincount(codes, minlength=code_max + 1).astype(np.float64)
        least = _MIN_PILE_FRACTION * codes.size
        if counts[code_max] >= least or codes.size == 0:
            continue
        start = max(int(_TOP_FRACTION * code_max), 8)
        best = 0.0
        for z in range(start, code_max):
            below = np.median(counts[z - 8:z])
            if counts[z] >= least and counts[z] >= _PILE_UP * max(below, 1.0) \
                    and counts[z] > best:
                best, levels[c] = counts[z], z
    return levels


def saturation_limits(codes: np.ndarray, response: CameraResponse, noise: NoiseModel,
                      grid: np.ndarray | None = None) -> np.ndarray:
    """The first dropped code of each channel, ``(C,)`` int64: the white level, or lower
    by the shoulder where the exposure ``f^-1(z)`` is within two of its own standard
    deviations (``noise``) of the white level's.

    ``codes`` ``(P, H, W, C)``; ``grid`` the noise fit's sample (:func:`noise_grid`),
    when already read.
    """
    grid = noise_grid(codes) if grid is None else grid
    white = white_levels(grid, response.code_max)
    X = np.exp(response.log_inverse)
    sigma = np.sqrt(noise.exposure_variance(response))
    limits = white.copy()
    for c, level in enumerate(white):
        z = int(level)
        while z > 1 and X[level, c] - X[z - 1, c] <= _MARGIN_SIGMAS * sigma[z - 1, c]:
            z -= 1
        limits[c] = z
    return limits


def policy_limits(policy: str, codes: np.ndarray, response: CameraResponse,
                  noise: NoiseModel | None) -> tuple[np.ndarray, bool]:
    """``(limits, pixel_rule)`` of ``policy`` for the kernel: the first dropped code per
    channel, and whether a dropped channel drops the whole observation."""
    if policy not in SATURATION_POLICIES:
        raise ValueError(f"saturation policy must be one of {SATURATION_POLICIES}, "
                         f"not {policy!r}")
    channels = codes.shape[-1]
    if policy != "safe":
        return np.full(channels, response.code_max, np.int64), policy == "pixel"
    if noise is None:
        noise = NoiseModel.quantisation_only(channels)
    return saturation_limits(codes, response, noise), True
