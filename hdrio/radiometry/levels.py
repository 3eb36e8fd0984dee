"""The code levels a response is solved at and stored at.

Up to 1024 codes (8-bit input, 10-bit), every code is a level. Deeper codes are pooled
into :data:`DEEP_LEVELS` levels evenly spaced in ``sqrt(z)`` (``sqrt``: 0.06 codes apart
at the bottom of a 16-bit range, 128 at the top), where every level is about as many
shot-noise standard deviations wide.

Until stop 52 they were evenly spaced in ``z`` (64 codes a level). Debevec's smoothness
term penalises ``g''`` per level, and a linear sensor's ``g = ln z`` bends hardest
exactly where its shadows are (``-1 / z^2``): linear 16-bit ladders' solved curves came
out 5x too bright at code 100 and 2x at code 300, and their registration then compared
brackets that disagreed in the shadows (docs/motion.md). In ``sqrt(z)``, ``g = 2 ln
sqrt(z)`` bends 350 times less at code 100, and those curves are within 0.04 of ``ln z``
at code 300 and 0.02 from code 1000 up. Other spacings were measured and not kept
(docs/method.md): evenly in ``ln z`` nearly tripled the truth harness's 16-bit error;
``sqrt(z)`` up to a quarter of the range and even above it was better on its gamma-like
16-bit curves but 35 % worse on linear ones.
"""

from __future__ import annotations

import numpy as np

DEEP_LEVELS = 1024
"""Levels of a response solved for more than 1024 codes."""

SPACINGS = ("even", "sqrt")
"""How levels sit on the code axis: ``even`` (level ``k`` is code ``k code_max / (n -
1)``; every code a level when ``n = code_max + 1``) or ``sqrt`` (level ``k`` is code
``code_max (k / (n - 1))^2``)."""


def solve_levels(code_max: int) -> tuple[int, str]:
    """``(levels, spacing)`` a response of codes ``0 .. code_max`` is solved at."""
    return (code_max + 1, "even") if code_max < DEEP_LEVELS else (DEEP_LEVELS, "sqrt")


def level_of(codes, code_max: int, levels: int, spacing: str = "even") -> np.ndarray:
    """Each code's position on the level axis (float64: ``0 .. levels - 1``)."""
    codes = np.asarray(codes, dtype=np.float64)
    if spacing == "sqrt":
        return (levels - 1) * np.sqrt(codes / code_max)
    return codes * ((levels - 1) / code_max)


def code_of(levels: int, code_max: int, spacing: str = "even") -> np.ndarray:
    """The code (float64) each of ``levels`` levels stands for."""
    if spacing == "sqrt":
        return code_max * (np.arange(levels, dtype=np.float64) / (levels - 1)) ** 2
    return np.linspace(0.0, float(code_max), levels)
