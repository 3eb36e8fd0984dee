"""The HDR Merge node's inside: hdrio's merge in native compositor nodes.

Per channel ``c`` and bracket ``j`` (brackets wired from the shortest exposure up), with
``z`` the bracket read as Non-Color (code / code_max) and the tables of
:func:`~.baking.bake_merge` (hdrio's :func:`~hdrio.radiometry.tables.merge_tables`)::

    w_j   = weights_jc(z) * keep_cj                  baked per bracket, 0 once saturated
    x_j   = estimates_jc(z)                          E_j, or ln E_j in the log domain
    keep_cj = 0 if channel c (any channel: "pixel" policy) of a bracket <= j is at
              code_max, else 1
    m     = sum_j w_j x_j / sum_j w_j                where the weights sum above 0
            else x of the longest bracket kept (the shortest if none)
    E     = m, or exp(m) in the log domain

exactly as hdrio's merge kernel (:mod:`hdrio.merge.kernel`). The result is relative
scene-linear radiance (``E * dt = f^-1(Z)``), as in hdrio's EXRs.
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy

from .baking import BakedMerge, CurveTable
from .exposures import sorted_order
from .graph import GraphBuilder

FLOAT32_TINY = 1.1754944e-38  # the core clips radiance to float32's smallest normal
_DENOMINATOR_FLOOR = 1e-30


def _table_values(build: GraphBuilder, image, baked: BakedMerge, table: CurveTable,
                  rank: int, label: str) -> list:
    """Bracket ``rank``'s table at the codes of ``image``, per channel, in its units."""
    curves = build.separate(build.curves(image, baked.positions, table.curves[rank], label))
    values = []
    for c in range(3):
        low, span = float(table.low[rank, c]), float(table.span[rank, c])
        values.append(build.math("MULTIPLY", curves[c], span) if low == 0.0
                      else build.math("MULTIPLY_ADD", curves[c], span, low))
    return values


def build_merge_graph(tree: bpy.types.NodeTree, baked: BakedMerge,
                      exposures: Sequence[float]) -> None:
    """Replace the nodes of ``tree`` by the merge of its first ``len(exposures)`` inputs.

    ``exposures[i]`` is the exposure of input ``i``; ``baked`` holds the tables of the
    same exposures sorted shortest first (``sorted_order``).
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
        weights = _table_values(build, image, baked, baked.weights, rank,
                                f"weight ({exposure:g} s)")
        estimates = _table_values(build, image, baked, baked.estimates, rank,
                                  f"estimate ({exposure:g} s)")
        saturated = [build.math("GREATER_THAN", codes[c], baked.saturation_level)
                     for c in range(3)]
        if rank == 0:  # clipped in every bracket: all channels, or any (pixel rule)
            combine = "MINIMUM" if baked.per_channel else "MAXIMUM"
            clipped = build.math(combine, build.math(combine, *saturated[:2]), saturated[2])
            neutral = build.math("MAXIMUM", build.math("MAXIMUM", *estimates[:2]),
                                 estimates[2])
        if not baked.per_channel:  # the pixel rule: any channel drops the pixel
            anywhere = build.math("MAXIMUM", build.math("MAXIMUM", *saturated[:2]),
                                  saturated[2])
            saturated = [anywhere] * 3
        for c in range(3):
            dropped[c] = (saturated[c] if dropped[c] is None
                          else build.math("MAXIMUM", dropped[c], saturated[c]))
            keep = build.math("SUBTRACT", 1.0, dropped[c])
            weight = build.math("MULTIPLY", weights[c], keep)
            if rank == 0:
                numerator[c] = build.math("MULTIPLY", weight, estimates[c])
                denominator[c] = weight
                fallback[c] = estimates[c]
            else:
                numerator[c] = build.math("MULTIPLY_ADD", weight, estimates[c], numerator[c])
                denominator[c] = build.math("ADD", weight, denominator[c])
                change = build.math("SUBTRACT", estimates[c], fallback[c])
                fallback[c] = build.math("MULTIPLY_ADD", keep, change, fallback[c])
        build.column += 1
    channels = []
    for c in range(3):
        mean = build.math("DIVIDE", numerator[c],
                          build.math("MAXIMUM", denominator[c], _DENOMINATOR_FLOOR))
        weighted = build.math("GREATER_THAN", denominator[c], 0.0)
        merged = build.math("MULTIPLY_ADD", weighted,
                            build.math("SUBTRACT", mean, fallback[c]), fallback[c])
        # A pixel clipped in every bracket: the neutral lower bound (the largest of the
        # shortest bracket's estimates), as hdrio's merge kernel.
        merged = build.math("MULTIPLY_ADD", clipped, build.math("SUBTRACT", neutral, merged),
                            merged)
        if baked.log_domain:
            merged = build.math("EXPONENT", merged)
        channels.append(build.math("MAXIMUM", merged, FLOAT32_TINY))
    build.column += 1
    result = build.combine(channels)
    build.column += 1
    group_out = build.add("NodeGroupOutput")
    tree.links.new(result, group_out.inputs[0])
