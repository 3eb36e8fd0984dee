"""The extension on the real ``bpy`` (Blender as a Python module): nodes match hdrio.

Run by ``plugins/blender/ci/run_tests.sh`` in environments with bpy 4.5 and 5.0; the main
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
    image_node,
    merge_node_with,
    render_to_exr,
)

import plugins.blender as addon  # noqa: E402
from hdrio.io.brackets import read_brackets  # noqa: E402
from hdrio.io.write import write_exr  # noqa: E402
from hdrio.job.options import MergeOptions  # noqa: E402
from hdrio.merge import MERGE_METHODS  # noqa: E402
from hdrio.radiometry.curve import CameraResponse  # noqa: E402
from hdrio.radiometry.noise_fit import fit_noise  # noqa: E402
from hdrio.tools.synthetic import demo_scene  # noqa: E402
from plugins.blender.baking import response_to_json  # noqa: E402
from plugins.blender.warmup import WARMUP  # noqa: E402


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
    """``f^-1(Z) = (Z / code_max)^gamma``, the response hdrio.tools.synthetic renders with.

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


def test_merge_node_matches_hdrio_default_merge(registered, write_brackets, tmp_path):
    exposures = (1 / 16, 1 / 4, 1.0, 4.0)
    size = (40, 96)
    paths = write_brackets(exposures, size=size)
    response = gamma_camera_response()
    scene = bpy.context.scene
    tree = clean_compositor(scene)
    node = merge_node_with(tree, paths)
    # The tutorial's file names carry the exposures (bracket_1_16.png is 1/16 s).
    assert np.allclose(node.bracket_exposures(), exposures)
    stack = read_brackets(paths)
    noise = fit_noise(stack.codes, stack.exposures, response)  # as a Solve stores it
    node.set_response(response_to_json(response, "gamma 2.2", noise))
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "node.exr", size)

    # Whatever hdrio merge's defaults are: the node's tables are the core's (its
    # saturation policy as the node applies it: the pixel rule at the top code).
    options = MergeOptions(saturation="pixel")
    reference, _ = MERGE_METHODS[options.merge](stack, response, options.weighting,
                                                options.saturation, noise=noise)
    assert_matches_merge("known response", merged, reference)

    # Exposures are editable: twice every exposure time is half the radiance.
    node.exposures = [2.0 * t for t in node.exposures]
    halved = render_to_exr(scene, node.outputs[0], tmp_path / "edited.exr", size)
    # float32 arithmetic in both renders: 1e-5 relative covers its rounding.
    np.testing.assert_allclose(halved, merged / 2.0, rtol=1e-5)


def test_merge_node_shows_placeholder_exposures_until_typed(registered, write_brackets):
    paths = write_brackets((1 / 4, 1.0), names=["dark.png", "bright.png"])
    node = merge_node_with(clean_compositor(bpy.context.scene), paths)
    assert node.placeholder_brackets() == [1, 2]  # no EXIF, no time in the names
    assert node.message == ""  # not an input problem: the node's fields say it
    assert node.bracket_exposures() == pytest.approx([1 / 16, 1 / 4])  # defaults kept
    assert all(node.inputs[i].links[0].from_node.image.colorspace_settings.name
               == "Non-Color" for i in range(2))
    node.exposures[0] = 0.25
    assert node.placeholder_brackets() == [2]
    node.exposures[1] = 1.0
    assert node.placeholder_brackets() == []
    assert node.bracket_exposures() == pytest.approx([0.25, 1.0])


def test_merge_node_reports_incomplete_and_mismatched_inputs(registered, write_brackets):
    small = write_brackets((1 / 4, 1.0), size=(20, 30), names=["s_1_4.png", "s_1_1.png"])
    large = write_brackets((4.0,), size=(40, 60), names=["l_4_1.png"])
    tree = clean_compositor(bpy.context.scene)
    node = tree.nodes.new("CompositorNodeHdrioMerge")
    tree.links.new(image_node(tree, small[0]).outputs["Image"], node.inputs[0])
    node.update()
    assert node.message == "Bracket 2 is not linked"
    tree.links.new(image_node(tree, small[1]).outputs["Image"], node.inputs[1])
    tree.links.new(image_node(tree, large[0]).outputs["Image"], node.inputs[2])
    node.update()
    assert node.message == "Bracket 3 is 60x40, bracket 1 30x20"
    node.bracket_count = 2
    node.update()
    assert node.message == ""
    assert node.bracket_exposures() == pytest.approx([1 / 4, 1.0])  # read once complete


def test_render_pass_comes_back_at_its_own_scale(registered, tmp_path):
    # Scene-linear input (a render pass, an EXR) at exposures 1 and 4 (0.8 at most: not
    # saturated): an unsolved node must return the radiance itself, not 255/128 of it.
    size = (30, 40)
    radiance = np.clip(demo_scene(*size), 0.002, 0.2).astype(np.float32)
    tree = clean_compositor(bpy.context.scene)
    node = tree.nodes.new("CompositorNodeHdrioMerge")
    node.bracket_count = 2
    for index, exposure in enumerate((1.0, 4.0)):
        path = write_exr(tmp_path / f"pass_{index}.exr", radiance * exposure,
                         pixel_type="float")
        tree.links.new(image_node(tree, path).outputs["Image"], node.inputs[index])
    node.update()
    node.exposures[0], node.exposures[1] = 1.0, 4.0
    merged = render_to_exr(bpy.context.scene, node.outputs[0], tmp_path / "pass.exr", size)
    ratio = merged / radiance
    print(f"render pass: median scale {np.median(ratio):.6f}, "
          f"p99 |1 - scale| {np.percentile(np.abs(ratio - 1), 99):.1e}")
    # The acceptance bound, on every pixel: both brackets estimate the same radiance, so
    # any weights give it back, up to float32 rounding in the curves (measured 1e-6).
    assert np.abs(ratio - 1).max() <= 1e-3


def test_kernels_compile_in_the_background_when_enabled(registered):
    assert WARMUP.wait(600), "kernel warm-up did not finish"
    assert WARMUP.error == "" and WARMUP.done == len(WARMUP.steps)
