"""The code levels a response is solved at and stored at.

Up to 1024 codes (8-bit input, 10-bit), every code is a level. Deeper codes are pooled
into :data:`DEEP_LEVELS` levels, spaced ``sqrt-even``: evenly in ``sqrt(z)`` up to a
quarter of the range (:data:`KNEE`), evenly in ``z`` above it, the two joined with the
same slope (levels 80 codes apart at the top of a 16-bit range, 0.1 at its bottom).

Why not evenly in ``z``, as until stop 52 (64 codes a level): Debevec's smoothness
term penalises ``g''`` per level, and a linear sensor's ``g = ln z`` bends hardest
exactly where its shadows are (``-1 / z^2``). Linear 16-bit ladders' solved curves came
out 5x too bright at code 100 and 2x at code 300, and their registration then compared
brackets that disagreed in the shadows (docs/motion.md). In ``sqrt(z)`` a level is about
as many shot-noise standard deviations wide at every code, and those curves are within
0.06 of ``ln z`` at code 300 and 0.014 from code 1000 up. Above the knee the levels stay
nearly as fine as the even ones, where gamma-like curves bend at their shoulder: levels
evenly in ``sqrt(z)`` all the way up (128 codes apart at the top) put the truth
harness's 16-bit group's clipped pixels 9-13 % further off, and levels evenly in ``ln
z`` nearly tripled its error (docs/method.md)."""

from __future__ import annotations

import numpy as np

DEEP_LEVELS = 1024
"""Levels of a response solved for more than 1024 codes."""

KNEE = 0.25
"""The fraction of the code range up to which ``sqrt-even`` levels are even in
``sqrt(z)``."""

SPACINGS = ("even", "sqrt-even")
"""How levels sit on the code axis: ``even`` (level ``k`` is code ``k code_max / (n -
1)``; every code a level when ``n = code_max + 1``) or ``sqrt-even``
(:func:`level_of`)."""


def solve_levels(code_max: int) -> tuple[int, str]:
    """``(levels, spacing)`` a response of codes ``0 .. code_max`` is solved at."""
    return (code_max + 1, "even") if code_max < DEEP_LEVELS else (DEEP_LEVELS, "sqrt-even")


def _root(codes: np.ndarray, code_max: int) -> np.ndarray:
    """``u(z)``: ``sqrt(z)`` up to the knee ``z_k``, ``sqrt(z_k) + (z - z_k) / (2
    sqrt(z_k))`` above it (continuous, with a continuous slope)."""
    knee = KNEE * (code_max + 1)
    return np.where(codes <= knee, np.sqrt(np.maximum(codes, 0.0)),
                    np.sqrt(knee) + (codes - knee) / (2.0 * np.sqrt(knee)))


def level_of(codes, code_max: int, levels: int, spacing: str = "even") -> np.ndarray:
    """Each code's position on the level axis (float64: ``0 .. levels - 1``)."""
    codes = np.asarray(codes, dtype=np.float64)
    if spacing == "sqrt-even":
        return (levels - 1) * _root(codes, code_max) / _root(np.float64(code_max), code_max)
    return codes * ((levels - 1) / code_max)


def code_of(levels: int, code_max: int, spacing: str = "even") -> np.ndarray:
    """The code (float64) each of ``levels`` levels stands for."""
    if spacing == "sqrt-even":
        knee = KNEE * (code_max + 1)
        u = np.arange(levels, dtype=np.float64) * (_root(np.float64(code_max), code_max)
                                                   / (levels - 1))
        codes = np.where(u <= np.sqrt(knee), u * u, knee + (u - np.sqrt(knee)) * 2.0
                         * np.sqrt(knee))
        codes[-1] = code_max  # exactly, not to rounding
        return codes
    return np.linspace(0.0, float(code_max), levels)
