"""Weighting functions ``w(z)`` over code values, used by the response solve and the merge.

Each function takes code values ``z`` (any shape) and the code range ``z_min .. z_max``
and returns non-negative weights of the same shape (float64, unnormalised: both the
Debevec solve and the weighted-average merge are invariant to a constant factor).
"""

from __future__ import annotations

import numpy as np

from hdrio.method_registry import MethodRegistry


def weighting_tutorial_hat(z, z_min: float = 0, z_max: float = 255) -> np.ndarray:
    """The tutorial's hat: ``z - z_min + 1`` up to the midpoint, ``z_max - z + 1`` above.

    Never zero ("because that would influence the equation system"), so every code value
    contributes and every smoothness row is active. For 8-bit codes it runs
    1, 2, ..., 128, 128, ..., 2, 1.
    """
    z = np.asarray(z, dtype=np.float64)
    return np.where(z <= 0.5 * (z_min + z_max), z - z_min + 1.0, z_max - z + 1.0)


def weighting_Debevec1997(
    z, z_min: float = 0, z_max: float = 255, low: float = 0.0, high: float = 1.0
) -> np.ndarray:
    """The paper's triangle ``w(z) = z - z_min`` below the midpoint, ``z_max - z`` above.

    Zero at both ends of the code range. ``low`` and ``high`` (fractions of the range)
    move the feet inwards; colour-hdri uses ``low=0.01, high=0.99`` and normalises the
    peak to 1, which does not change either the solve or the merge.
    """
    z = np.asarray(z, dtype=np.float64)
    lo = z_min + low * (z_max - z_min)
    hi = z_min + high * (z_max - z_min)
    w = np.where(z <= 0.5 * (lo + hi), z - lo, hi - z)
    return np.clip(w, 0.0, None)


def weighting_gaussian(z, z_min: float = 0, z_max: float = 255) -> np.ndarray:
    """A Gaussian bump ``exp(-4 ((z - mid) / half_range)**2)`` (Robertson et al. 1999 style).

    Smooth and never exactly zero; it favours mid-tones more strongly than the hat.
    """
    z = np.asarray(z, dtype=np.float64)
    mid = 0.5 * (z_min + z_max)
    half_range = 0.5 * (z_max - z_min)
    return np.exp(-4.0 * ((z - mid) / half_range) ** 2)


WEIGHTING_METHODS: MethodRegistry = MethodRegistry(
    "weighting",
    {
        "tutorial-hat": weighting_tutorial_hat,
        "Debevec1997": weighting_Debevec1997,
        "gaussian": weighting_gaussian,
    },
    aliases={"hat": "tutorial-hat", "triangle": "Debevec1997"},
)


def weights_table(method: str, code_max: int) -> np.ndarray:
    """``w`` evaluated at every code value ``0..code_max``."""
    z = np.linspace(0.0, float(code_max), code_max + 1)
    return WEIGHTING_METHODS[method](z, 0.0, float(code_max))
