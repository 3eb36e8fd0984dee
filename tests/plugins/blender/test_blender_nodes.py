"""The extension on the real ``bpy`` (Blender as a Python module): nodes match hdrio.

Run by ``plugins/blender/ci/run_tests.sh`` in environments with bpy 5.0 and 4.5; the main
suite has no ``bpy`` and skips this file.
"""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip(
    "bpy", reason="needs Blender's bpy module (bpy 4.5/5.0 need numpy<2): run "
                  "plugins/blender/ci/run_tests.sh")

from blender_scene import (  # noqa: E402
    assert_matches_merge,
    clean_compositor,
    merge_node_with,
    render_to_exr,
)

import plugins.blender as addon  # noqa: E402
from hdrio.io.brackets import read_brackets  # noqa: E402
from hdrio.merge.debevec1997 import merge_brackets  # noqa: E402
from hdrio.response.curve import CameraResponse  # noqa: E402
from plugins.blender.baking import bake_response  # noqa: E402


@pytest.fixture(scope="module")
def registered():
    addon.register()
    yield addon
    addon.unregister()


def registered_node(idname: str):
    return bpy.types.Node.bl_rna_get_subclass_py(idname)


def registered_in_add_menu() -> bool:
    from plugins.blender import panel

    menu = getattr(bpy.types, panel.ADD_MENU)
    return panel.draw_add_menu in getattr(menu.draw, "_draw_funcs", ())


def gamma_camera_response(gamma: float = 2.2, code_max: int = 255) -> CameraResponse:
    """``f^-1(Z) = (Z / code_max)^gamma``, the response hdrio.synthetic renders with.

    Code 0 is taken at half a code so that ``g`` stays finite; ``g(mid) = 0``.
    """
    codes = np.maximum(np.arange(code_max + 1, dtype=np.float64), 0.5) / code_max
    g = np.repeat((gamma * np.log(codes))[:, None], 3, axis=1)
    g -= g[(code_max + 1) // 2]
    return CameraResponse(g, code_max, np.ones_like(g, dtype=bool), method="gamma 2.2")


def test_register_adds_and_unregister_removes_the_nodes():
    addon.register()
    try:
        assert registered_node("CompositorNodeHdrioMerge") is not None
        assert registered_node("CompositorNodeHdrioReinhardGlobal") is not None
        assert registered_in_add_menu()
        tree = clean_compositor(bpy.context.scene)
        node = tree.nodes.new("CompositorNodeHdrioMerge")
        assert [s.name for s in node.inputs] == ["Bracket 1", "Bracket 2", "Bracket 3"]
        node.bracket_count = 5
        assert len(node.inputs) == 5
        inner = node.node_tree.name
        tree.nodes.remove(node)
        assert inner not in bpy.data.node_groups  # the node's private group goes with it
    finally:
        addon.unregister()
    assert registered_node("CompositorNodeHdrioMerge") is None
    assert registered_node("CompositorNodeHdrioReinhardGlobal") is None
    assert not registered_in_add_menu()
    assert "solve_response" not in dir(bpy.ops.hdrio)


def test_merge_node_matches_hdrio_linear_merge(registered, write_brackets, tmp_path):
    exposures = (1 / 16, 1 / 4, 1.0, 4.0)
    size = (40, 96)
    paths = write_brackets(exposures, size=size)
    response = gamma_camera_response()
    scene = bpy.context.scene
    tree = clean_compositor(scene)
    node = merge_node_with(tree, paths)
    # The tutorial's file names carry the exposures (bracket_1_16.png is 1/16 s).
    assert np.allclose(node.bracket_exposures(), exposures)
    node.set_response(bake_response(response))
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "node.exr", size)

    stack = read_brackets(paths)
    reference, _ = merge_brackets(stack, response, "Debevec1997", domain="linear")
    assert_matches_merge("known response", merged, reference)

    # Exposures are editable: twice every exposure time is half the radiance.
    node.exposures = [2.0 * t for t in node.exposures]
    halved = render_to_exr(scene, node.outputs[0], tmp_path / "edited.exr", size)
    # float32 arithmetic in both renders: 1e-5 relative covers its rounding.
    np.testing.assert_allclose(halved, merged / 2.0, rtol=1e-5)


def test_merge_node_says_when_exposures_cannot_be_read(registered, write_brackets):
    paths = write_brackets((1 / 4, 1.0), names=["dark.png", "bright.png"])
    node = merge_node_with(clean_compositor(bpy.context.scene), paths)
    assert "dark.png: no exposure time" in node.message
    assert node.bracket_exposures() == pytest.approx([1 / 16, 1 / 4])  # defaults kept
    assert all(node.inputs[i].links[0].from_node.image.colorspace_settings.name
               == "Non-Color" for i in range(2))
