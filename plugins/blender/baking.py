"""Bake hdrio's merge into the tables the compositor's RGB Curves nodes hold.

No ``bpy`` here: this module turns a :class:`hdrio.CameraResponse`, the brackets'
exposures and hdrio's :class:`~hdrio.job.options.MergeOptions` into plain arrays, so it is
tested without Blender.

The tables come from hdrio's own merge (:func:`hdrio.radiometry.tables.merge_tables`,
the kernel's interface, with the weights of the estimator the options' plan resolves,
:meth:`hdrio.job.plan.MergePlan.weight_tables`): per bracket ``j``, channel ``c`` and
code ``z``, the weight ``w_j(z)`` (the inverse-variance weights of the noise model the
Solve fitted, by default) and the estimate ``x_j(z)`` (``f^-1(z) / dt_j`` in the linear
domain, ``g(z) - ln dt_j`` in the log domain). Whatever weights and domain the options
name, the node follows: it computes ``sum_j w_j x_j / sum_j w_j`` (then ``exp`` in the
log domain) with the core's saturation reset and fallback (``merge_graph.py``).

The compositor sees a bracket as code values scaled to [0, 1] (the image read as
*Non-Color*: ``z = Z / Z_max``). A curve holds values in [0, 1], so each table is stored
as ``(value - low) / span`` and the node maps it back with one Multiply Add.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hdrio.job.options import MergeOptions
from hdrio.job.plan import plan_merge
from hdrio.radiometry.curve import CameraResponse, linear_response
from hdrio.radiometry.noise import NoiseModel
from hdrio.radiometry.tables import merge_tables

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
class CurveTable:
    """Per-bracket, per-channel curves: ``value = curve * span + low``.

    Attributes
    ----------
    curves
        ``(P, N, 3)`` values in [0, 1] at the baked positions.
    low, span
        ``(P, 3)`` the affine map back to the table's units.
    """

    curves: np.ndarray
    low: np.ndarray
    span: np.ndarray

    @classmethod
    def from_values(cls, values: np.ndarray) -> CurveTable:
        """Normalise ``(P, N, 3)`` finite values per bracket and channel (a constant
        table gets span 1 and curve 0)."""
        if not np.all(np.isfinite(values)):
            raise ValueError("the merge's tables are not finite: the response overflows")
        low = values.min(axis=1)
        span = values.max(axis=1) - low
        span = np.where(span > 0, span, 1.0)
        return cls(np.clip((values - low[:, None]) / span[:, None], 0.0, 1.0), low, span)

    def values(self) -> np.ndarray:
        """The table back in its own units, ``(P, N, 3)``."""
        return self.curves * self.span[:, None] + self.low[:, None]


@dataclass(frozen=True)
class BakedMerge:
    """hdrio's merge of ``P`` brackets (shortest exposure first) as curve tables.

    Attributes
    ----------
    positions
        ``(N,)`` curve abscissae in [0, 1]: code ``Z`` at ``Z / code_max``.
    weights
        ``w_j(z)`` of each bracket and channel (unitless; 0 at ``code_max``).
    estimates
        ``x_j(z)`` of each bracket and channel: relative radiance, or its natural log
        when ``log_domain``.
    log_domain
        The weighted mean is of ``ln E`` (then exponentiated), else of ``E``.
    per_channel
        Saturation drops a channel on its own (hdrio's ``"channel"`` policy), else the
        whole pixel (``"pixel"``; also ``"auto"`` and ``"safe"``, which the node applies
        at the top code: it has no stack to find white levels, shoulders or channel
        mixing in). A pixel clipped in every bracket takes the neutral lower bound.
    code_max
        Saturation code of the brackets (255 or 65535).
    """

    positions: np.ndarray
    weights: CurveTable
    estimates: CurveTable
    log_domain: bool
    per_channel: bool
    code_max: int

    @property
    def saturation_level(self) -> float:
        """Normalised code above which a channel counts as saturated (half a code below 1)."""
        return (self.code_max - 0.5) / self.code_max


def bake_merge(response: CameraResponse, exposures: Sequence[float],
               options: MergeOptions | None = None,
               points: int = CURVE_POINTS, noise: NoiseModel | None = None) -> BakedMerge:
    """hdrio's merge tables for brackets of ``exposures`` (shortest first), sampled at
    ``points`` codes for the HDR Merge node.

    Parameters
    ----------
    response
        hdrio's inverse response ``g = ln f^-1`` per code value (1 or 3 channels; a grey
        response is used for all three).
    exposures
        Exposure of each bracket (seconds, or relative), in increasing order.
    options
        hdrio's merge options: ``weighting``, ``merge`` (the domain) and ``saturation``
        are the ones the merge reads; ``None``: ``MergeOptions()``, ``hdrio merge``'s
        defaults.
    points
        Curve points (at least 2); with ``code_max + 1`` or more, every code is a point.
    noise
        The noise model the noise-aware estimators weigh by (the one ``merge_stack``
        fitted when the node was solved); ``None``: rounding of the codes alone (an
        unsolved node, e.g. a render pass).
    """
    if points < 2:
        raise ValueError(f"a curve needs at least 2 points, not {points}")
    options = MergeOptions() if options is None else options
    exposures = np.asarray(exposures, dtype=np.float64)
    if np.any(np.diff(exposures) < 0):
        raise ValueError("exposures must be given shortest first")
    plan = plan_merge(options)
    if plan.estimator.needs_noise and noise is None:
        noise = NoiseModel.quantisation_only(response.channels)
    domain = plan.estimator.domain
    weights = plan.weight_tables(response, exposures, noise)
    terms, estimates = merge_tables(response, exposures, options.weighting, domain, weights)
    code_max = int(response.code_max)
    count = min(points, code_max + 1)
    codes = np.unique(np.rint(np.linspace(0.0, code_max, count)).astype(np.int64))
    weights = terms.imag[:, :, codes].transpose(0, 2, 1)  # (P, N, C)
    values = estimates[:, :, codes].transpose(0, 2, 1)
    if weights.shape[2] == 1:
        weights, values = np.repeat(weights, 3, axis=2), np.repeat(values, 3, axis=2)
    if np.any(weights.max(axis=(0, 1)) <= 0):
        raise ValueError("the response has a channel with no supported code value")
    return BakedMerge(
        positions=codes / code_max, weights=CurveTable.from_values(weights),
        estimates=CurveTable.from_values(values), log_domain=domain == "log",
        per_channel=options.saturation == "channel", code_max=code_max)


def scene_linear_response(code_max: int = 255) -> CameraResponse:
    """hdrio's linear response rescaled so that ``f^-1(z) = z`` on [0, 1] codes.

    The node's starting point before a solve: a render pass (scene-linear) with exposure
    1 comes back at its own scale. (hdrio's :func:`~hdrio.radiometry.curve.linear_response`
    puts 1 at the middle code instead, which would make a pass 255/128 too bright.)
    """
    linear = linear_response(code_max, 3)
    shift = np.log(((code_max + 1) // 2) / code_max)
    return CameraResponse(linear.log_inverse + shift, code_max, linear.supported,
                          method="linear", parameters=dict(linear.parameters))


def response_to_json(response: CameraResponse, label: str,
                     noise: NoiseModel | None = None) -> str:
    """What the node stores of a solved response and its noise model (its tables are
    baked from them)."""
    data = {
        "log_inverse": response.log_inverse.tolist(), "supported": response.supported.tolist(),
        "code_max": int(response.code_max), "method": response.method, "label": label,
    }
    if noise is not None:
        data["noise"] = {"shot": np.asarray(noise.shot).tolist(),
                         "read": np.asarray(noise.read).tolist(),
                         "code": np.asarray(noise.code).tolist(), "source": noise.source}
        for term in ("relative", "common"):  # the weights read ``common`` (JPEG's)
            if getattr(noise, term) is not None:
                data["noise"][term] = np.asarray(getattr(noise, term)).tolist()
    return json.dumps(data)


def response_from_json(text: str) -> tuple[CameraResponse, str, NoiseModel | None]:
    """The response, its label and its noise model (``None`` in a file saved before the
    node stored one) stored by :func:`response_to_json`."""
    data = json.loads(text)
    response = CameraResponse(np.asarray(data["log_inverse"], dtype=np.float64),
                              int(data["code_max"]),
                              np.asarray(data["supported"], dtype=bool),
                              method=str(data["method"]))
    noise = data.get("noise")
    if noise is not None:
        extra = {term: np.asarray(noise[term], dtype=np.float64)
                 for term in ("relative", "common") if term in noise}
        noise = NoiseModel(np.asarray(noise["shot"], dtype=np.float64),
                           np.asarray(noise["read"], dtype=np.float64),
                           np.asarray(noise["code"], dtype=np.float64), str(noise["source"]),
                           **extra)
    return response, str(data["label"]), noise
