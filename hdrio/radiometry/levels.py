"""The code levels a response is solved at and stored at.

Up to 1024 codes (8-bit input, 10-bit), every code is a level. Deeper codes are pooled
into :data:`DEEP_LEVELS` levels, spaced one of two ways:

* ``toe`` (:func:`solve_levels`'): evenly in ``sqrt(z)`` in the bottom :data:`TOE` of
  the range and evenly in ``z`` above it, the level density the larger of the two
  (continuous at the join: 0.28 codes apart at the bottom of a 16-bit range, 8.5 at
  code 64, 68 from code 4096 up);
* ``sqrt``: evenly in ``sqrt(z)`` over the whole range (0.06 codes apart at the bottom
  of a 16-bit range, 128 at the top), every level about as many shot-noise standard
  deviations wide: for a linear sensor's codes (a linear TIFF from a raw converter),
  which :func:`hdrio.response.debevec1997.deep_spacing` tells from the others.

Until stop 52 they were evenly spaced in ``z`` (64 codes a level). Debevec's smoothness
term penalises ``g''`` per level, and a linear sensor's ``g = ln z`` bends hardest
exactly where its shadows are (``-1 / z^2``): linear 16-bit ladders' solved curves came
out 5x too bright at code 100 and 2x at code 300, and their registration then compared
brackets that disagreed in the shadows (docs/motion.md). In ``sqrt(z)``, ``g = 2 ln
sqrt(z)`` bends 350 times less at code 100, and those curves are within 0.04 of ``ln z``
at code 300 and 0.02 from code 1000 up. Other spacings were measured and not kept
(docs/method.md): evenly in ``ln z`` nearly tripled the truth harness's 16-bit error;
``sqrt(z)`` up to a quarter of the range and even above it was better on its gamma-like
16-bit curves but 35 % worse on linear ones. ``sqrt`` for every curve (stop 52) was 3-18 %
worse than even levels on curves with a toe or a shoulder (DoRF rows 0, 50, 150, 200;
``python -m benchmarks.levels``: six scenes, two ladders each), and ``toe`` is the best
of the three or within 2.1 % of it on every curve but a linear one, where ``sqrt``'s
error is 14 % lower (docs/method.md).
"""

from __future__ import annotations

import numpy as np

DEEP_LEVELS = 1024
"""Levels of a response solved for more than 1024 codes."""

SPACINGS = ("even", "sqrt", "toe")
"""How levels sit on the code axis: ``even`` (level ``k`` is code ``k code_max / (n -
1)``; every code a level when ``n = code_max + 1``), ``sqrt`` (level ``k`` is code
``code_max (k / (n - 1))^2``) or ``toe`` (``sqrt`` below :data:`TOE` of the range,
``even`` above it)."""

TOE = 1 / 16
"""The fraction of the code range that ``toe`` levels space evenly in ``sqrt(z)``."""


def solve_levels(code_max: int) -> tuple[int, str]:
    """``(levels, spacing)`` a response of codes ``0 .. code_max`` is solved at first."""
    return (code_max + 1, "even") if code_max < DEEP_LEVELS else (DEEP_LEVELS, "toe")


def _toe_axis(x: np.ndarray) -> np.ndarray:
    """``toe``'s level axis at ``x`` (codes over ``code_max``): ``2 sqrt(TOE x)`` below
    ``TOE``, then ``x + TOE`` (its slope 1 at the join, as ``sqrt``'s is there)."""
    return 2.0 * np.sqrt(TOE * np.minimum(x, TOE)) + np.maximum(x - TOE, 0.0)


def level_of(codes, code_max: int, levels: int, spacing: str = "even") -> np.ndarray:
    """Each code's position on the level axis (float64: ``0 .. levels - 1``)."""
    codes = np.asarray(codes, dtype=np.float64)
    if spacing == "sqrt":
        return (levels - 1) * np.sqrt(codes / code_max)
    if spacing == "toe":
        return (levels - 1) * _toe_axis(codes / code_max) / (1.0 + TOE)
    return codes * ((levels - 1) / code_max)


def code_of(levels: int, code_max: int, spacing: str = "even") -> np.ndarray:
    """The code (float64) each of ``levels`` levels stands for."""
    k = np.arange(levels, dtype=np.float64) / (levels - 1)
    if spacing == "sqrt":
        return code_max * k**2
    if spacing == "toe":
        t = k * (1.0 + TOE)  # back from the axis: t = 2 sqrt(TOE x) below 2 TOE, x + TOE above
        return code_max * np.where(t < 2 * TOE, t * t / (4 * TOE), t - TOE)
    return np.linspace(0.0, float(code_max), levels)
