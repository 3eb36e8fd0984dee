"""Accuracy of one method's output on one stack, against the ground truth.

Regions (disjoint), from the codes the methods actually saw:

``well``
    well exposed in at least one bracket (:func:`hdrio.tools.synthetic.well_exposed`: every
    channel inside 5-95 % of the code range).
``clipped``
    a channel at or above 95 % of the code range even in the shortest bracket.
``black``
    every channel at or below 5 % of the code range even in the longest bracket.
``other``
    the rest: extreme colours, one channel dark in every bracket where another is in
    range (a deep red whose blue never leaves the toe).

The global scale is fitted once on ``well`` (:func:`hdrio.tools.synthetic.radiance_error`)
and the same scale is applied to ``clipped``, ``black`` and ``other``. Errors use finite, positive
pixels only; the others are counted.
"""

from __future__ import annotations

import math

import numpy as np

from benchmarks.truth.curves import Curve
from benchmarks.truth.methods import MethodOutput
from benchmarks.truth.stacks import Stack
from hdrio.radiometry.luminance import luminance
from hdrio.tools.synthetic import radiance_error, well_exposed

LOW, HIGH = 0.05, 0.95
RESPONSE_RANGE = (10 / 255, 245 / 255)  # codes 10..245 for 8-bit


def regions(codes: np.ndarray, code_max: int) -> dict[str, np.ndarray]:
    """Boolean ``(H, W)`` masks ``well``, ``clipped``, ``black`` and ``other``."""
    well = well_exposed(codes, code_max, LOW, HIGH)
    clipped = ~well & np.any(codes[0] >= HIGH * code_max, axis=-1)
    black = ~well & ~clipped & np.all(codes[-1] <= LOW * code_max, axis=-1)
    return {"well": well, "clipped": clipped, "black": black,
            "other": ~(well | clipped | black)}


def errors_at_scale(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray,
                    scale: float) -> dict[str, float | None]:
    """Relative errors of ``scale * estimate`` over ``mask`` pixels (all channels).

    Like :func:`hdrio.tools.synthetic.radiance_error` but with a given scale, plus ``bias``:
    the median signed ``log2(scale * E / T)`` (negative = underestimated).
    """
    e = np.asarray(estimate[mask], dtype=np.float64).ravel()
    t = np.asarray(truth[mask], dtype=np.float64).ravel()
    valid = (t > 0) & (e > 0) & np.isfinite(e)
    if not np.any(valid) or not math.isfinite(scale):
        return {"median": None, "p95": None, "p99": None, "stops": None, "bias": None}
    e, t = e[valid], t[valid]
    relative = np.abs(scale * e - t) / t
    stops = np.log2(scale * e / t)
    return {"median": float(np.median(relative)), "p95": float(np.percentile(relative, 95)),
            "p99": float(np.percentile(relative, 99)), "stops": float(np.median(np.abs(stops))),
            "bias": float(np.median(stops))}


def response_rms_stops(log_inverse: np.ndarray | None, curve: Curve, code_max: int
                       ) -> tuple[float | None, int]:
    """RMS (stops) of ``ln f^-1`` against the true inverse over codes 10..245 (of 255).

    One constant offset per channel is removed first (responses are known up to a
    scale). A table of ``L`` levels is read at ``round(z (L - 1) / code_max)``. Returns
    the RMS over finite entries and the count of non-finite entries in the range.
    """
    if log_inverse is None:
        return None, 0
    low, high = (round(v * code_max) for v in RESPONSE_RANGE)
    codes = np.unique(np.rint(np.linspace(low, high, min(high - low + 1, 4096))).astype(int))
    levels = log_inverse.shape[0]
    g = np.asarray(log_inverse, dtype=np.float64)[np.rint(codes * (levels - 1) / code_max)
                                                  .astype(int)]
    difference = g - curve.log_inverse(codes, code_max)[:, None]
    finite = np.isfinite(difference)
    if not np.any(finite):
        return None, int(difference.size)
    offsets = np.array([np.mean(difference[finite[:, c], c]) if np.any(finite[:, c]) else 0.0
                        for c in range(difference.shape[1])])
    residual = (difference - offsets)[finite]
    return float(np.sqrt(np.mean(residual**2)) / np.log(2)), int(np.count_nonzero(~finite))


def evaluate(output: MethodOutput, stack: Stack, masks: dict[str, np.ndarray]
             ) -> dict[str, object]:
    """Every accuracy metric of ``output`` on ``stack`` (``masks`` from :func:`regions`)."""
    radiance = np.asarray(output.radiance)
    truth = stack.truth
    if radiance.shape != truth.shape:
        raise ValueError(f"output shape {radiance.shape} != truth {truth.shape}")
    finite = np.all(np.isfinite(radiance), axis=-1)
    positive = finite & np.all(radiance > 0, axis=-1)
    row: dict[str, object] = {
        "nonfinite": int(np.count_nonzero(~finite)),
        "nonpositive": int(np.count_nonzero(finite & ~positive)),
        "pixels": {name: int(np.count_nonzero(mask)) for name, mask in masks.items()},
        "bad_pixels": {name: int(np.count_nonzero(mask & ~positive))
                       for name, mask in masks.items()},
    }
    good = masks["well"] & positive
    if np.any(good):
        well = radiance_error(radiance, truth, good)
        scale = well.pop("scale")
        well.pop("invalid")
        truth_l, estimate_l = luminance(truth), luminance(np.where(positive[..., None],
                                                                   radiance, 0))
        lum = radiance_error(estimate_l[..., None], truth_l[..., None], good)
        row["luminance_median"] = lum["median"]
    else:
        well, scale = {"median": None, "p95": None, "p99": None, "stops": None}, math.nan
        row["luminance_median"] = None
    row["scale"] = scale
    row["well"] = well
    for name in ("clipped", "black", "other"):
        row[name] = errors_at_scale(radiance, truth, masks[name] & positive, scale)
    rms, bad = response_rms_stops(output.log_inverse, stack.curve, stack.code_max)
    row["response_rms_stops"] = rms
    row["response_nonfinite"] = bad
    if stack.clipped is not None:  # camera-like: hue where a raw clip puts it at risk
        from benchmarks.truth.camera import transition_hue, transition_pixels

        mask = transition_pixels(stack.codes, stack.clipped, stack.code_max, LOW, HIGH)
        row["transition"] = {**transition_hue(radiance, truth, mask & positive),
                             **{k: v for k, v in errors_at_scale(
                                 radiance, truth, mask & positive, scale).items()
                                if k in ("median", "bias")}}
    return row
