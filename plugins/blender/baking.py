"""Bake a camera response into the tables the compositor's RGB Curves nodes hold.

No ``bpy`` here: this module turns a :class:`hdrio.CameraResponse` and a weighting
function into plain arrays (and JSON, which the HDR Merge node stores), so it is tested
without Blender.

The compositor sees a bracket as code values scaled to [0, 1] (the image read as
*Non-Color*: ``z = Z / Z_max``). For each channel two curves are baked over that range:

``inverse``
    ``f^-1(Z) / peak``: the relative exposure that produced code ``Z`` (linear, not
    ``g = ln f^-1``), divided by its largest value so that it fits a curve's [0, 1].
``weights``
    ``w(Z) * supported(Z)`` divided by its peak: the merge weight of hdrio's core
    (:func:`hdrio.merge.debevec1997.merge_brackets`), zero where ``g`` was extrapolated.

The node multiplies ``inverse`` back by ``peak / dt`` to get the bracket's radiance
estimate ``E = f^-1(Z) / dt`` (relative scene-linear units, as hdrio's EXRs).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from hdrio.merge.weighting import weights_table
from hdrio.response.curve import CameraResponse

CURVE_POINTS = 256
"""Points per baked curve. For 8-bit brackets there is one point at every code value, so
the curve is exact there; 16-bit responses are sampled at 256 evenly spaced codes."""

CURVE_TABLE_SIZE = 256
"""Blender's curve table resolution (``CM_TABLE`` in DNA_color_types.h)."""


def table_squeeze(positions: np.ndarray) -> float:
    """Factor putting evenly spaced ``positions`` on [0, 1] onto the curve table's samples.

    ``N`` points from 0 to 1 land on samples ``0 .. N - 1`` when multiplied by
    ``(N - 1) / CURVE_TABLE_SIZE``; anything else is left as it is (factor 1).
    """
    count = len(positions)
    # 16-bit codes are rounded to integers: within half a code (< 1e-5) of even.
    even = np.allclose(positions, np.linspace(0.0, 1.0, count), rtol=0, atol=1e-5)
    if not even or count - 1 > CURVE_TABLE_SIZE:
        return 1.0
    return (count - 1) / CURVE_TABLE_SIZE


@dataclass(frozen=True)
class BakedResponse:
    """Per-channel curve tables of a response, ready for RGB Curves nodes.

    Attributes
    ----------
    positions
        ``(N,)`` curve abscissae in [0, 1]: code ``Z`` at ``Z / code_max``.
    inverse
        ``(N, 3)`` ``f^-1`` at each position divided by ``peak`` (values in [0, 1]).
    peak
        ``(3,)`` largest ``f^-1`` of each channel (relative exposure ``E * dt``).
    weights
        ``(N, 3)`` merge weight at each position, peak 1 (unitless).
    code_max
        Saturation code of the brackets (255 or 65535); a channel at
        ``code_max`` is saturated (dropped from that bracket and every longer one).
    label
        Where the response came from (shown in the node).
    """

    positions: np.ndarray
    inverse: np.ndarray
    peak: np.ndarray
    weights: np.ndarray
    code_max: int
    label: str

    @property
    def saturation_level(self) -> float:
        """Normalised code above which a channel counts as saturated (half a code below 1)."""
        return (self.code_max - 0.5) / self.code_max

    def to_json(self) -> str:
        return json.dumps({
            "positions": self.positions.tolist(), "inverse": self.inverse.tolist(),
            "peak": self.peak.tolist(), "weights": self.weights.tolist(),
            "code_max": self.code_max, "label": self.label,
        })

    @classmethod
    def from_json(cls, text: str) -> BakedResponse:
        data = json.loads(text)
        return cls(
            positions=np.asarray(data["positions"], dtype=np.float64),
            inverse=np.asarray(data["inverse"], dtype=np.float64),
            peak=np.asarray(data["peak"], dtype=np.float64),
            weights=np.asarray(data["weights"], dtype=np.float64),
            code_max=int(data["code_max"]), label=str(data["label"]),
        )


def bake_response(response: CameraResponse, weighting: str = "Debevec1997",
                  points: int = CURVE_POINTS, label: str | None = None) -> BakedResponse:
    """Sample ``response`` and ``weighting`` at ``points`` codes for the HDR Merge node.

    Parameters
    ----------
    response
        hdrio's inverse response ``g = ln f^-1`` per code value (1 or 3 channels; a grey
        response is used for all three).
    weighting
        Name in :data:`hdrio.WEIGHTING_METHODS`, as given to hdrio's merge.
    points
        Curve points (at least 2); with ``code_max + 1`` or more, every code is a point.
    """
    if points < 2:
        raise ValueError(f"a curve needs at least 2 points, not {points}")
    code_max = int(response.code_max)
    count = min(points, code_max + 1)
    codes = np.unique(np.rint(np.linspace(0.0, code_max, count)).astype(np.int64))
    g = np.asarray(response.log_inverse, dtype=np.float64)[codes]
    supported = np.asarray(response.supported, dtype=bool)[codes]
    if g.shape[1] == 1:
        g, supported = np.repeat(g, 3, axis=1), np.repeat(supported, 3, axis=1)
    # Divide inside the exponent: exp(g - max g) stays in [0, 1] without overflow.
    peak_log = g.max(axis=0)
    inverse = np.exp(g - peak_log)
    weights = weights_table(weighting, code_max)[codes, np.newaxis] * supported
    top = weights.max(axis=0)
    if np.any(top <= 0):
        raise ValueError("the response has a channel with no supported code value")
    return BakedResponse(
        positions=codes / code_max, inverse=inverse, peak=np.exp(peak_log),
        weights=weights / top, code_max=code_max,
        label=label or f"{response.method} ({code_max + 1} codes)",
    )


def linear_response(code_max: int = 255) -> CameraResponse:
    """The identity response ``f^-1(Z) = Z / code_max`` (for brackets already linear,
    such as render passes); the node's starting point before a solve.

    ``g(0)`` is taken at half a code, so it stays finite (weights are zero there).
    """
    codes = np.arange(code_max + 1, dtype=np.float64)
    g = np.log(np.maximum(codes, 0.5) / code_max)[:, np.newaxis].repeat(3, axis=1)
    g -= g[(code_max + 1) // 2]
    return CameraResponse(g, code_max, np.ones_like(g, dtype=bool), method="linear",
                          parameters={"levels": code_max + 1})
