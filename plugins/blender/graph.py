"""A small builder for compositor node graphs made of native nodes (Math, Separate and
Combine Color, RGB Curves), shared by the HDR Merge and Reinhard Global groups.

Sockets or plain numbers can be given wherever a node input is expected: a number sets
the input's default value, a socket is linked.
"""

from __future__ import annotations

from collections.abc import Sequence

import bpy
import numpy as np

from .baking import table_squeeze
from .compat import MATH_NODE

Operand = "bpy.types.NodeSocket | float"


class GraphBuilder:
    """Adds nodes to ``tree``, laying them out in columns from left to right."""

    def __init__(self, tree: bpy.types.NodeTree) -> None:
        self.tree = tree
        self.column = 0
        self._rows: dict[int, int] = {}

    def clear(self) -> None:
        """Remove every node (the tree's interface, and so outside links, stay)."""
        for node in list(self.tree.nodes):
            self.tree.nodes.remove(node)

    def add(self, idname: str, label: str = "", hide: bool = False) -> bpy.types.Node:
        node = self.tree.nodes.new(idname)
        row = self._rows.get(self.column, 0)
        self._rows[self.column] = row + 1
        node.location = (self.column * 220.0, -row * (40.0 if hide else 220.0))
        node.hide = hide
        if label:
            node.label = label
        return node

    def connect(self, value, socket: bpy.types.NodeSocket) -> None:
        if isinstance(value, bpy.types.NodeSocket):
            self.tree.links.new(value, socket)
        else:
            socket.default_value = float(value)

    def math(self, operation: str, *operands, clamp: bool = False) -> bpy.types.NodeSocket:
        """A Math node ``operation(operands...)``; returns its output socket."""
        node = self.add(MATH_NODE, hide=True)
        node.operation = operation
        node.use_clamp = clamp
        for socket, value in zip(node.inputs, operands, strict=False):
            self.connect(value, socket)
        return node.outputs[0]

    def weighted_sum(self, terms: Sequence[tuple[object, float]]) -> bpy.types.NodeSocket:
        """``sum(value * weight)`` with Multiply and Multiply Add nodes."""
        (first, weight), *rest = terms
        total = self.math("MULTIPLY", first, weight)
        for value, weight in rest:
            total = self.math("MULTIPLY_ADD", value, weight, total)
        return total

    def separate(self, colour: bpy.types.NodeSocket) -> tuple[bpy.types.NodeSocket, ...]:
        """Red, green and blue of an image socket."""
        node = self.add("CompositorNodeSeparateColor", hide=True)
        self.connect(colour, node.inputs[0])
        return tuple(node.outputs[:3])

    def combine(self, channels: Sequence[object]) -> bpy.types.NodeSocket:
        """An RGB image from three values (alpha 1)."""
        node = self.add("CompositorNodeCombineColor", hide=True)
        for socket, value in zip(node.inputs, channels, strict=False):
            self.connect(value, socket)
        return node.outputs[0]

    def curves(self, colour: bpy.types.NodeSocket, positions: np.ndarray, values: np.ndarray,
               label: str) -> bpy.types.NodeSocket:
        """An RGB Curves node mapping each channel through ``values[:, c]`` at ``positions``.

        Points are joined by straight segments (vector handles); the combined curve
        stays the identity. Blender evaluates a curve through a table of
        257 samples at ``i / 256``, interpolating between
        them; evenly spaced points are therefore squeezed onto those samples (and the
        input scaled to match), so that each point's value is returned exactly there. A
        one-code notch in the weights (a code the solve never sampled) survives this;
        points between samples would be blurred into their neighbours.
        """
        node = self.add("CompositorNodeCurveRGB", label=label)
        squeeze = table_squeeze(positions)
        for channel in range(3):
            set_curve(node.mapping.curves[channel], positions * squeeze, values[:, channel])
        node.mapping.update()
        # White Level divides the input: z * squeeze reaches the squeezed points.
        node.inputs["White Level"].default_value = (1.0 / squeeze,) * 3 + (1.0,)
        self.connect(colour, node.inputs["Image"])
        return node.outputs[0]


def set_curve(curve: bpy.types.CurveMap, positions: np.ndarray, values: np.ndarray) -> None:
    """Make ``curve`` the polyline through ``(positions[i], values[i])``."""
    points = curve.points
    while len(points) > 2:
        points.remove(points[len(points) - 1])
    points[0].location = (float(positions[0]), float(values[0]))
    points[1].location = (float(positions[-1]), float(values[-1]))
    for x, y in zip(positions[1:-1], values[1:-1]):
        points.new(float(x), float(y))
    for point in points:
        point.handle_type = "VECTOR"
