"""Helpers for the Blender tests: a clean compositor, Image nodes, a background render."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np

from plugins.blender.compat import IS_5, compositor_result_socket, compositor_tree


def clean_compositor(scene: bpy.types.Scene) -> bpy.types.NodeTree:
    """The scene's compositor tree with nothing in it but its output node."""
    tree = compositor_tree(scene)
    for node in list(tree.nodes):
        if node.bl_idname not in {"NodeGroupOutput", "CompositorNodeComposite"}:
            tree.nodes.remove(node)
    compositor_result_socket(tree)
    return tree


def image_node(tree: bpy.types.NodeTree, path: Path) -> bpy.types.Node:
    node = tree.nodes.new("CompositorNodeImage")
    node.image = bpy.data.images.load(str(path), check_existing=False)
    return node


def render_to_exr(scene: bpy.types.Scene, result: bpy.types.NodeSocket, path: Path,
                  size: tuple[int, int]) -> np.ndarray:
    """Composite ``result`` at ``size`` (height, width), write a float EXR, read it back.

    Returns ``(H, W, 3)`` float32 as stored (EXR is scene-linear: no view transform).
    """
    import OpenImageIO as oiio

    tree = compositor_tree(scene)
    tree.links.new(result, compositor_result_socket(tree))
    render = scene.render
    render.resolution_y, render.resolution_x = size
    render.resolution_percentage = 100
    render.engine = "BLENDER_WORKBENCH"
    render.use_compositing = True
    render.image_settings.file_format = "OPEN_EXR"
    render.image_settings.color_depth = "32"
    render.filepath = str(path)
    if not IS_5:
        scene.use_nodes = True
    bpy.ops.render.render(write_still=True, scene=scene.name)
    pixels = oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)
    assert pixels is not None, f"render wrote no readable EXR at {path}"
    return np.asarray(pixels)[..., :3]


def relative_difference(estimate: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``|estimate - reference| / reference`` per pixel and channel."""
    return np.abs(estimate.astype(np.float64) - reference) / np.abs(reference)


def merge_node_with(tree: bpy.types.NodeTree, paths) -> bpy.types.Node:
    """An HDR Merge node fed by one Image node per path, its exposures read from them."""
    node = tree.nodes.new("CompositorNodeHdrioMerge")
    node.bracket_count = len(paths)
    for index, path in enumerate(paths):
        tree.links.new(image_node(tree, path).outputs["Image"], node.inputs[index])
    node.update()
    return node


def solved_merge_node(tree: bpy.types.NodeTree, paths) -> bpy.types.Node:
    """:func:`merge_node_with` after Solve Camera Response (which must succeed)."""
    node = merge_node_with(tree, paths)
    assert node.placeholder_brackets() == []
    assert bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name) == {
        "FINISHED"}
    return node


def assert_matches_merge(label: str, merged: np.ndarray, reference: np.ndarray) -> None:
    """The HDR Merge node's render against hdrio's merge of the same brackets."""
    difference = relative_difference(merged, reference)
    print(f"{label}: median {np.median(difference):.2e} "
          f"p99 {np.percentile(difference, 99):.2e} max {difference.max():.2e}")
    # The acceptance bounds ...
    assert np.median(difference) <= 0.01
    assert np.percentile(difference, 99) <= 0.03
    # ... and what the node actually achieves: its curves return the baked values exactly
    # at every code, so only float32 rounding in the Math nodes is left (measured max
    # 2e-6); 1e-4 still catches a curve blurred between codes (1e-3 to 0.6 measured).
    assert difference.max() <= 1e-4
