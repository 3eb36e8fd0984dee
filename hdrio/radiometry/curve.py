"""``CameraResponse``: the inverse response ``g = ln f^-1`` per channel, as a lookup table."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class CameraResponse:
    """A camera's inverse response, tabulated at every code value.

    Attributes
    ----------
    log_inverse
        ``g(z) = ln f^-1(z)``, shape ``(code_max + 1, C)``: natural log of the relative
        exposure ``E * dt`` that produces code ``z``; ``g(z_mid) = 0``.
    code_max
        Largest code value (255 for 8-bit, 65535 for 16-bit).
    supported
        ``(code_max + 1, C)`` booleans: codes that carried weighted samples in the solve.
        Elsewhere ``g`` is extrapolated (by the smoothness term, or linearly where
        nothing constrains it).
    method, parameters
        How it was made (recorded in the EXR's ``hdrio:`` attributes).
    """

    log_inverse: np.ndarray
    code_max: int
    supported: np.ndarray
    method: str = "Debevec1997"
    parameters: dict = field(default_factory=dict)

    @property
    def channels(self) -> int:
        return int(self.log_inverse.shape[1])

    def linearise(self, codes: np.ndarray) -> np.ndarray:
        """``f^-1(Z)``: relative exposure for code values ``(..., C)``."""
        return np.exp(self.log_inverse[codes, np.arange(self.channels)])


def fill_unsupported(g: np.ndarray, determined: np.ndarray) -> np.ndarray:
    """Replace undetermined entries of ``g`` by linear extrapolation from the nearest ends.

    Undetermined entries lie only outside the determined run (weights vanish at the ends
    of the code range), so a straight continuation of the end slope is the smoothest
    fill, the same one the smoothness term produces where it is active.
    """
    g = np.array(g, dtype=np.float64)
    index = np.flatnonzero(determined)
    if index.size < 2:
        return g
    first, last = index[0], index[-1]
    low_slope = g[min(first + 1, last)] - g[first]
    high_slope = g[last] - g[max(last - 1, first)]
    below = np.arange(first)
    above = np.arange(last + 1, g.size)
    g[below] = g[first] - low_slope * (first - below)
    g[above] = g[last] + high_slope * (above - last)
    inner = np.arange(first, last + 1)
    gaps = ~determined[inner]
    if np.any(gaps):
        g[inner[gaps]] = np.interp(inner[gaps], index, g[index])
    return g


def monotone_non_decreasing(g: np.ndarray, anchor: int) -> np.ndarray:
    """Make ``g`` non-decreasing, keeping ``g[anchor]``: a response cannot fall.

    Above the anchor a running maximum, below it a running minimum taken from the anchor
    downwards; noise-driven wiggles at the ends (where few samples fall) are flattened
    rather than inverted.
    """
    g = np.array(g, dtype=np.float64)
    g[anchor:] = np.maximum.accumulate(g[anchor:])
    g[: anchor + 1] = np.minimum.accumulate(g[anchor::-1])[::-1]
    return g


LINEAR_SLOPE = 0.02
"""A solved curve is linear (:func:`linear_deviation`) when ``g`` fitted as ``a + b ln z``
over codes 1-95 % of the range has ``|b - 1|`` at most this in every channel (linear
16-bit ladders solved: 0.999-1.001; a gamma-2.2 one: 2.19)..."""

LINEAR_WITHIN = 0.03
"""... and no code there is further than this from the fit (linear ladders: 0.003-0.012)."""


def log_fit(log_inverse: np.ndarray, code_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Each channel of ``g`` (``(codes, C)``) fitted as ``a + b ln z`` over codes 1-95 %
    of the range: the slopes ``b`` and the largest distance of ``g`` from its fit, both
    ``(C,)``. ``b`` is 1 for a linear sensor's codes, about 2.2 for a gamma-2.2 curve."""
    z = np.arange(code_max + 1, dtype=np.float64)
    inside = (z >= 0.01 * code_max) & (z <= 0.95 * code_max)
    design = np.stack([np.ones(np.count_nonzero(inside)), np.log(z[inside])], axis=1)
    g = np.asarray(log_inverse, dtype=np.float64)[inside]
    fit, *_ = np.linalg.lstsq(design, g, rcond=None)
    return fit[1], np.abs(g - design @ fit).max(axis=0)


def linear_deviation(response: CameraResponse) -> float | None:
    """How far a solved ``g`` is from ``ln z`` (plus a constant) over codes 1-95 % of the
    range, the largest over channels, when it is linear (:data:`LINEAR_SLOPE`,
    :data:`LINEAR_WITHIN`); ``None`` when it is not. Such codes are a linear sensor's
    (a linear TIFF), and ``--response linear`` merges them without a solve and with less
    error (3-15 % at the median on linear 16-bit ladders, docs/method.md)."""
    slopes, deviations = log_fit(response.log_inverse, response.code_max)
    if np.any(np.abs(slopes - 1.0) > LINEAR_SLOPE) or np.any(deviations > LINEAR_WITHIN):
        return None
    return float(deviations.max())


def linear_response(code_max: int, channels: int) -> CameraResponse:
    """``g(z) = ln(z / z_mid)`` for codes ``0..code_max``, ``channels`` identical columns."""
    z = np.arange(code_max + 1, dtype=np.float64)
    z_mid = (code_max + 1) // 2
    g = np.log(np.maximum(z, 0.5) / z_mid)
    supported = np.broadcast_to((z > 0)[:, None], (code_max + 1, channels)).copy()
    return CameraResponse(
        log_inverse=np.repeat(g[:, None], channels, axis=1), code_max=code_max,
        supported=supported, method="linear",
        # The header stores g at 1024 levels at most; read back, a "linear" response is
        # rebuilt exactly (see :mod:`hdrio.radiometry.saved_response`), so nothing is lost.
        parameters={"smoothing": 0.0, "weighting": "n/a", "sampling": "n/a", "samples": 0,
                    "levels": min(code_max + 1, 1024)},
    )
