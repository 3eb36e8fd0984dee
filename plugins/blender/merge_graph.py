"""The HDR Merge node's inside: hdrio's linear-domain merge in native compositor nodes.

Per channel ``c`` and bracket ``j`` (brackets wired from the shortest exposure up), with
``z`` the bracket read as Non-Color (code / code_max), exactly as
:func:`hdrio.merge.debevec1997.merge_brackets` with ``domain="linear"`` and its default
per-channel saturation policy::

    E_j   = inverse_c(z) * peak_c / dt_j             radiance estimate (baked curve)
    w_j   = weights_c(z) * keep_cj                   baked weight, 0 once saturated
    keep_cj = 0 if channel c of any bracket <= j is at code_max, else 1
    E     = sum_j w_j E_j / sum_j w_j                where the weights sum above 0
            else the estimate of the longest bracket kept (the shortest if none)

The result is relative scene-linear radiance (``E * dt = f^-1(Z)``), as in hdrio's EXRs.
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy

from .baking import BakedResponse
from .exposures import sorted_order
from .graph import GraphBuilder

FLOAT32_TINY = 1.1754944e-38  # the core clips radiance to float32's smallest normal
_DENOMINATOR_FLOOR = 1e-30


def build_merge_graph(tree: bpy.types.NodeTree, baked: BakedResponse,
                      exposures: Sequence[float]) -> None:
    """Replace the nodes of ``tree`` by the merge of its first ``len(exposures)`` inputs.

    ``exposures[i]`` is the exposure of input ``i`` (seconds, or any relative unit):
    the output is in the matching relative radiance units.
    """
    build = GraphBuilder(tree)
    build.clear()
    group_in = build.add("NodeGroupInput")
    build.column += 1
    numerator: list = [None] * 3
    denominator: list = [None] * 3
    fallback: list = [None] * 3
    dropped: list = [None] * 3
    for rank, index in enumerate(sorted_order(exposures)):
        exposure = float(exposures[index])
        image = group_in.outputs[index]
        codes = build.separate(image)
        inverse = build.separate(build.curves(
            image, baked.positions, baked.inverse, f"f^-1 ({exposure:g} s)"))
        weights = build.separate(build.curves(
            image, baked.positions, baked.weights, f"weight ({exposure:g} s)"))
        for c in range(3):
            saturated = build.math("GREATER_THAN", codes[c], baked.saturation_level)
            dropped[c] = (saturated if dropped[c] is None
                          else build.math("MAXIMUM", dropped[c], saturated))
            keep = build.math("SUBTRACT", 1.0, dropped[c])
            estimate = build.math("MULTIPLY", inverse[c], float(baked.peak[c]) / exposure)
            weight = build.math("MULTIPLY", weights[c], keep)
            if rank == 0:
                numerator[c] = build.math("MULTIPLY", weight, estimate)
                denominator[c] = weight
                fallback[c] = estimate
            else:
                numerator[c] = build.math("MULTIPLY_ADD", weight, estimate, numerator[c])
                denominator[c] = build.math("ADD", weight, denominator[c])
                change = build.math("SUBTRACT", estimate, fallback[c])
                fallback[c] = build.math("MULTIPLY_ADD", keep, change, fallback[c])
        build.column += 1
    channels = []
    for c in range(3):
        mean = build.math("DIVIDE", numerator[c],
                          build.math("MAXIMUM", denominator[c], _DENOMINATOR_FLOOR))
        weighted = build.math("GREATER_THAN", denominator[c], 0.0)
        merged = build.math("MULTIPLY_ADD", weighted,
                            build.math("SUBTRACT", mean, fallback[c]), fallback[c])
        channels.append(build.math("MAXIMUM", merged, FLOAT32_TINY))
    build.column += 1
    result = build.combine(channels)
    build.column += 1
    group_out = build.add("NodeGroupOutput")
    tree.links.new(result, group_out.inputs[0])
