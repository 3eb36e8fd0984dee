"""The Reinhard Global node's inside: Reinhard et al. (2002) eqs. 1-3 in native nodes.

As :func:`hdrio.tonemap.reinhard2002.tonemap_Reinhard2002_global` (no white point)::

    L     = luminance of the working space's primaries (linear Rec.709 in Blender)
    L_bar = exp(mean(ln(delta + max(L, 0))))      the key: Levels' mean of ln (eq. 1)
    L_m   = a / L_bar * L                          (eq. 2)
    L_d   = L_m / (1 + L_m)                        (eq. 3)
    C_d   = clamp((max(C / L, 0))^saturation * L_d, 0, 1), black where L <= 0

Input: scene-linear RGB (any scale). Output: display-linear RGB in [0, 1].
"""

from __future__ import annotations

import math

import bpy

from hdrio.radiometry.luminance import DEFAULT_SPACE, DELTA, luminance_weights

from .graph import GraphBuilder

DEFAULT_KEY = 0.72
DEFAULT_SATURATION = 0.6


def _ensure_interface(tree: bpy.types.NodeTree) -> None:
    if tree.interface.items_tree:
        return
    new = tree.interface.new_socket
    new("Image", in_out="INPUT", socket_type="NodeSocketColor")
    key = new("Key", in_out="INPUT", socket_type="NodeSocketFloat")
    key.default_value, key.min_value, key.max_value = DEFAULT_KEY, 0.0, 10.0
    saturation = new("Saturation", in_out="INPUT", socket_type="NodeSocketFloat")
    saturation.default_value, saturation.min_value, saturation.max_value = (
        DEFAULT_SATURATION, 0.0, 2.0)
    new("Image", in_out="OUTPUT", socket_type="NodeSocketColor")


def build_reinhard_global_graph(tree: bpy.types.NodeTree, space: str = DEFAULT_SPACE) -> None:
    """Fill ``tree`` (inputs Image, Key, Saturation; output Image) with the operator."""
    _ensure_interface(tree)
    build = GraphBuilder(tree)
    build.clear()
    group_in = build.add("NodeGroupInput")
    image, key, saturation = group_in.outputs[0], group_in.outputs[1], group_in.outputs[2]
    build.column += 1
    rgb = build.separate(image)
    L = build.weighted_sum(list(zip(rgb, luminance_weights(space))))
    build.column += 1
    log_L = build.math("LOGARITHM", build.math("ADD", build.math("MAXIMUM", L, 0.0), DELTA),
                       math.e)
    levels = build.add("CompositorNodeLevels", label="log-average key")
    build.connect(log_L, levels.inputs[0])
    build.column += 1
    log_average = build.math("EXPONENT", levels.outputs[0])
    scaled = build.math("DIVIDE", build.math("MULTIPLY", L, key), log_average)
    display_L = build.math("DIVIDE", scaled, build.math("ADD", scaled, 1.0))
    build.column += 1
    channels = []
    for channel in rgb:
        ratio = build.math("MAXIMUM", build.math("DIVIDE", channel, L), 0.0)
        lit = build.math("GREATER_THAN", L, 0.0)
        colour = build.math("MULTIPLY", build.math("POWER", ratio, saturation), display_L)
        channels.append(build.math("MULTIPLY", colour, lit, clamp=True))
    build.column += 1
    result = build.combine(channels)
    group_out = build.add("NodeGroupOutput")
    tree.links.new(result, group_out.inputs[0])
