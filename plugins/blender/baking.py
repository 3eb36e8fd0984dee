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

The saturation policy is the core's too, as the Solve's merge decided it on the
brackets (:class:`hdrio.merge.saturation.ClipPolicy`: each channel's limit, the clip
test's gates, whether the shortest bracket's partly clipped observations take the
neutral lower bound); the clip test's tables for the node's exposures come from
:meth:`~hdrio.merge.saturation.ClipPolicy.for_brackets` (``x_j(z)`` and the standard
deviation of each observation, :mod:`hdrio.radiometry.cliptest`).

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
from hdrio.merge.saturation import ClipPolicy
from hdrio.radiometry.cliptest import REACH
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
    policy
        The core's saturation policy (:class:`hdrio.merge.saturation.ClipPolicy`) with
        its clip test's tables for these exposures: a channel at or above its limit is
        dropped, an observation the policy drops whole every channel. A pixel dropped
        even from the shortest bracket, whole or in every channel, takes the neutral
        lower bound.
    clip_estimates, clip_deviations
        ``rule == "test"``: the test's ``x_j(z)`` (relative radiance) and the standard
        deviation of each observation, else ``None``.
    code_max
        Saturation code of the brackets (255 or 65535).
    """

    positions: np.ndarray
    weights: CurveTable
    estimates: CurveTable
    log_domain: bool
    policy: ClipPolicy
    code_max: int
    clip_estimates: CurveTable | None = None
    clip_deviations: CurveTable | None = None

    def level(self, codes: np.ndarray) -> np.ndarray:
        """Normalised codes above which a channel is at or above ``codes`` (half a code
        below each, as the node reads codes in [0, 1])."""
        return (np.asarray(codes, np.float64) - 0.5) / self.code_max

    def reach(self, rank: int) -> np.ndarray:
        """``(3,)``: per channel, the least code of bracket ``rank - 1`` whose estimate is
        above :data:`hdrio.radiometry.cliptest.REACH` times the radiance at which bracket
        ``rank`` clips (past the top code where none is), the clip test's reach
        (:func:`hdrio.radiometry.cliptest.dropped_channels`) as a code: the node compares
        codes exactly, where its curves' sampled estimates are not."""
        x = self.policy.tables.estimates
        out = np.full(3, self.code_max + 1, np.int64)
        for c in range(3):
            limit = int(self.policy.limits[c])
            above = np.nonzero(x[rank - 1, c] > REACH * x[rank, c, limit])[0]
            if above.size:
                out[c] = above[0]
        return out


def bake_merge(response: CameraResponse, exposures: Sequence[float],
               options: MergeOptions | None = None,
               points: int = CURVE_POINTS, noise: NoiseModel | None = None,
               policy: ClipPolicy | None = None) -> BakedMerge:
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
    policy
        The saturation policy the Solve's merge applied (``statistics.policy``); ``None``
        (an unsolved node, which has no stack to find white levels in): the top code,
        channel by channel under ``--saturation channel``, else whole observations.
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

    def sampled(table: np.ndarray) -> np.ndarray:  # (P, C, levels) -> (P, N, 3)
        values = table[:, :, codes].transpose(0, 2, 1)
        return np.repeat(values, 3, axis=2) if values.shape[2] == 1 else values

    weights, values = sampled(terms.imag), sampled(estimates)
    if np.any(weights.max(axis=(0, 1)) <= 0):
        raise ValueError("the response has a channel with no supported code value")
    if policy is None:
        rule = "channel" if options.saturation == "channel" else "pixel"
        policy = ClipPolicy.at_top(code_max, 3, rule)
    policy = policy.for_brackets(response, exposures, noise)  # the test's tables
    tables = policy.tables
    return BakedMerge(
        positions=codes / code_max, weights=CurveTable.from_values(weights),
        estimates=CurveTable.from_values(values), log_domain=domain == "log",
        policy=policy, code_max=code_max,
        clip_estimates=None if tables is None else CurveTable.from_values(
            sampled(tables.estimates)),
        clip_deviations=None if tables is None else CurveTable.from_values(
            np.sqrt(sampled(tables.variances))))


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


@dataclass(frozen=True)
class Solved:
    """What the node stores of a Solve: hdrio's response, its label, the noise model and
    the saturation policy the Solve's merge applied (its decisions; the tables are baked
    for the node's exposures), ``None`` where a file saved before the node stored them."""

    response: CameraResponse
    label: str
    noise: NoiseModel | None = None
    policy: ClipPolicy | None = None


def response_to_json(response: CameraResponse, label: str,
                     noise: NoiseModel | None = None,
                     policy: ClipPolicy | None = None) -> str:
    """What the node stores of a solved response, its noise model and saturation policy
    (its tables are baked from them)."""
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
    if policy is not None:
        data["clip"] = {"limits": [int(v) for v in policy.limits],
                        "gates": None if policy.gates is None
                        else [int(v) for v in policy.gates],
                        "rule": policy.rule, "neutral": bool(policy.neutral),
                        "spreads": None if policy.spreads is None
                        else np.asarray(policy.spreads).tolist()}
    return json.dumps(data)


def response_from_json(text: str) -> Solved:
    """The response, its label, noise model and saturation policy stored by
    :func:`response_to_json`."""
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
    clip = data.get("clip")
    policy = None
    if clip is not None:
        policy = ClipPolicy(np.asarray(clip["limits"], np.int64),
                            None if clip["gates"] is None else np.asarray(clip["gates"],
                                                                         np.int64),
                            str(clip["rule"]), bool(clip["neutral"]),
                            spreads=None if clip.get("spreads") is None
                            else np.asarray(clip["spreads"], np.float64))
    return Solved(response, str(data["label"]), noise, policy)


def highlight_gain(clip: np.ndarray, reconstructed: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` float32: hdrio's ``--highlights reconstruct`` merge over its ``clip``
    merge of the same brackets, 1 where they agree (every pixel not clipped in every
    bracket): what the HDR Merge node multiplies its clip merge by to reconstruct."""
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.asarray(reconstructed, np.float64) / np.asarray(clip, np.float64)
    return np.where(np.isfinite(gain) & (np.asarray(clip) > 0), gain, 1.0).astype(np.float32)
