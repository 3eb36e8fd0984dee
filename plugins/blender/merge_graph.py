"""The HDR Merge node's inside: hdrio's merge in native compositor nodes.

Per channel ``c`` and bracket ``j`` (brackets wired from the shortest exposure up), with
``z`` the bracket read as Non-Color (code / code_max) and the tables of
:func:`~.baking.bake_merge` (hdrio's :func:`~hdrio.radiometry.tables.merge_tables`)::

    w_j   = weights_jc(z) * keep_cj                  baked per bracket, 0 once saturated
    x_j   = estimates_jc(z)                          E_j, or ln E_j in the log domain
    keep_cj = 0 if channel c of a bracket <= j is at or above its limit, or that
              bracket's observation is dropped whole by the core's saturation policy
              (the pixel rule; the clip test, against the bracket before it), else 1
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


def _any(build: GraphBuilder, values: list):
    """1 where any of the three is 1 (0 or 1 values)."""
    return build.math("MAXIMUM", build.math("MAXIMUM", *values[:2]), values[2])


def _every(build: GraphBuilder, values: list):
    """1 where all three are 1."""
    return build.math("MINIMUM", build.math("MINIMUM", *values[:2]), values[2])


class _ClipTest:
    """The saturation policy of :mod:`hdrio.radiometry.cliptest` in Math nodes, one bracket
    after another (shortest first): which channels of each observation are dropped."""

    def __init__(self, build: GraphBuilder, baked: BakedMerge) -> None:
        self.build, self.baked = build, baked
        policy = baked.policy
        self.limits = baked.level(policy.limits)
        self.gates = baked.level(policy.limits if policy.gates is None else policy.gates)
        self.previous = None  # the last bracket's (clipped, estimates, variances, codes)

    def dropped(self, image, codes, rank: int, estimates, label: str) -> list:
        """1 where channel ``c`` of bracket ``rank`` is dropped (0 or 1 per channel): at or
        above its limit, or dropped by the policy (whole, or alone)."""
        build, policy = self.build, self.baked.policy
        clipped = [build.math("GREATER_THAN", codes[c], self.limits[c]) for c in range(3)]
        if policy.rule == "channel":
            return clipped
        if policy.rule == "pixel" or rank == 0:  # nothing shorter to test against
            remembered = self._remember(image, codes, clipped, rank, estimates, label)
            if policy.rule == "pixel" or policy.neutral:
                return [_any(build, clipped)] * 3
            return remembered
        near = [build.math("GREATER_THAN", codes[c], self.gates[c]) for c in range(3)]
        shorter_clipped, shorter_x, shorter_v, shorter_codes = self.previous
        clipped = self._remember(image, codes, clipped, rank, estimates, label)

        x, v = self.previous[1], self.previous[2]
        thresholds = policy.kernel_args()[-1][rank]  # the core's, per channel
        reach = self.baked.reach(rank)
        flags = []
        under = []  # below its limit where the shorter bracket is at it
        for c in range(3):
            below = build.math("SUBTRACT", 1.0, clipped[c])
            under.append(build.math("MULTIPLY", below, shorter_clipped[c]))
            d = build.math("SUBTRACT", x[c], shorter_x[c])
            allowed = build.math("MULTIPLY", build.math("ADD", v[c], shorter_v[c]),
                                 float(thresholds[c]))
            fails = build.math("GREATER_THAN", build.math("MULTIPLY", d, d), allowed)
            # Where this bracket must have clipped (the core's REACH), as a code of the
            # shorter one: exact, where the curves' sampled estimates are not.
            beyond = build.math("GREATER_THAN", shorter_codes[c],
                                float(self.baked.level(reach[c])))
            # Below its limit here, and disagreeing, beyond its reach or at its limit in
            # the shorter one.
            flags.append(build.math("MULTIPLY", below, build.math(
                "MAXIMUM", build.math("MAXIMUM", shorter_clipped[c], fails), beyond)))
        # Tested near a gate; and, wherever it is, an observation below its limit where
        # the shorter bracket is at it (this one must have clipped: a mover, or a
        # misregistered edge).
        whole = build.math("MAXIMUM", build.math(
            "MULTIPLY", _any(build, near), _any(build, flags)), _any(build, under))
        return [build.math("MAXIMUM", clipped[c], whole) for c in range(3)]

    def _remember(self, image, codes, clipped, rank, estimates, label):
        """Keep bracket ``rank``'s clip flags, linear estimates and variances for the
        next bracket's test (the test's own tables in the log domain)."""
        if self.baked.policy.rule == "test":
            build, baked = self.build, self.baked
            x = estimates if not baked.log_domain else _table_values(
                build, image, baked, baked.clip_estimates, rank, f"clip test x ({label})")
            sd = _table_values(build, image, baked, baked.clip_deviations, rank,
                               f"clip test sd ({label})")
            self.previous = (clipped, x, [build.math("MULTIPLY", s, s) for s in sd], codes)
        return clipped


def build_merge_graph(tree: bpy.types.NodeTree, baked: BakedMerge,
                      exposures: Sequence[float], gain: bpy.types.Image | None = None
                      ) -> None:
    """Replace the nodes of ``tree`` by the merge of its first ``len(exposures)`` inputs.

    ``exposures[i]`` is the exposure of input ``i``; ``baked`` holds the tables of the
    same exposures sorted shortest first (``sorted_order``). ``gain``: hdrio's highlight
    reconstruction over its clip merge (:func:`~.baking.highlight_gain`, made by the
    Solve), multiplied in.
    """
    build = GraphBuilder(tree)
    build.clear()
    group_in = build.add("NodeGroupInput")
    build.column += 1
    numerator: list = [None] * 3
    denominator: list = [None] * 3
    fallback: list = [None] * 3
    dropped: list = [None] * 3
    test = _ClipTest(build, baked)
    for rank, index in enumerate(sorted_order(exposures)):
        exposure = float(exposures[index])
        image = group_in.outputs[index]
        codes = build.separate(image)
        weights = _table_values(build, image, baked, baked.weights, rank,
                                f"weight ({exposure:g} s)")
        estimates = _table_values(build, image, baked, baked.estimates, rank,
                                  f"estimate ({exposure:g} s)")
        saturated = test.dropped(image, codes, rank, estimates, f"{exposure:g} s")
        if rank == 0:  # clipped in every bracket: every channel, or dropped whole
            clipped = _every(build, saturated)
            neutral = build.math("MAXIMUM", build.math("MAXIMUM", *estimates[:2]),
                                 estimates[2])
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
    if gain is not None:  # the Solve's --highlights reconstruct, hdrio's own
        source = build.add("CompositorNodeImage", label="highlights (reconstruct)")
        source.image = gain
        gains = build.separate(source.outputs["Image"])
        channels = [build.math("MULTIPLY", channels[c], gains[c]) for c in range(3)]
    build.column += 1
    result = build.combine(channels)
    build.column += 1
    group_out = build.add("NodeGroupOutput")
    tree.links.new(result, group_out.inputs[0])
