"""The extension's operators and the Reinhard Global node on the real ``bpy``.

Run by ``plugins/blender/ci/run_tests.sh``; the main suite has no ``bpy`` and skips this.
"""

from __future__ import annotations

from pathlib import Path

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
    relative_difference,
    render_to_exr,
    solved_merge_node,
)

import plugins.blender as addon  # noqa: E402
from hdrio.cli import main as hdrio_main  # noqa: E402
from hdrio.io.brackets import read_brackets  # noqa: E402
from hdrio.io.write import write_exr  # noqa: E402
from hdrio.job.options import MergeOptions  # noqa: E402
from hdrio.job.run import merge_stack  # noqa: E402
from hdrio.tonemap import TONEMAP_METHODS  # noqa: E402
from hdrio.tools.synthetic import demo_scene  # noqa: E402
from plugins.blender.compat import compositor_tree  # noqa: E402
from plugins.blender.nodes import refresh_curves, view_warning  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def registered():
    addon.register()
    yield
    addon.unregister()


def read_exr(path) -> tuple[np.ndarray, dict]:
    import OpenImageIO as oiio

    buffer = oiio.ImageBuf(str(path))
    spec = buffer.spec()
    attributes = {a.name: spec.getattribute(a.name) for a in spec.extra_attribs}
    return np.asarray(buffer.get_pixels(oiio.FLOAT)), attributes


def test_solve_operator_bakes_hdrio_response(write_brackets, tmp_path):
    size = (40, 96)
    paths = write_brackets(size=size)
    scene = bpy.context.scene
    tree = clean_compositor(scene)
    before = tree.nodes.new("CompositorNodeHdrioMerge").response_json
    node = solved_merge_node(tree, paths)
    assert node.response_json != before
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "solved.exr", size)

    # The node applies the saturation policy the Solve's merge decided (hdrio's default).
    reference = merge_stack(read_brackets(paths), MergeOptions()).radiance
    assert_matches_merge("solved", merged, reference)


def assert_matches_command(label: str, merged: np.ndarray, paths, tmp_path,
                           *options: str) -> None:
    """The node's render against the EXR ``hdrio merge`` writes with its defaults (and
    ``options``): half floats, and a power-of-two scale if its range needs one, so
    after one global scale. The issue's bound: p99 1e-3 (half's 11-bit mantissa is
    4.9e-4)."""
    command = tmp_path / f"{label}.exr"
    assert hdrio_main(["merge", *map(str, paths), "-o", str(command), "-q", *options]) == 0
    written, _ = read_exr(command)
    written = written[..., :3].astype(np.float64)
    scale = np.median(written / merged)
    difference = relative_difference(merged * scale, written)
    print(f"{label} against hdrio merge {' '.join(options)}: scale {scale:.6g}, "
          f"p99 {np.percentile(difference, 99):.1e}, max {difference.max():.1e}")
    assert np.percentile(difference, 99) <= 1e-3


def test_merge_node_matches_hdrio_merge_command_on_real_brackets(shared_data, tmp_path):
    # Real JPEGs: the solved response has codes no sample fell on (red code 83 here),
    # which hdrio's merge gives no weight; the node must reproduce these one-code notches.
    # A 5D Mark II mixes its channels after the clip: the Solve's merge tests partly
    # clipped observations and gives the window (clipped in every bracket) the neutral
    # lower bound, which the node must apply as hdrio merge does.
    paths = sorted(shared_data("frobisher_001").glob("*.jpg"))
    scene = bpy.context.scene
    node = solved_merge_node(clean_compositor(scene), paths)
    assert node.bracket_exposures() == pytest.approx([1 / 8, 1.0, 8.0])  # from EXIF
    result = merge_stack(read_brackets(paths), MergeOptions())
    assert not np.all(result.response.supported[1:-1])  # the case this test is about
    policy = result.statistics.policy
    assert policy.rule == "test" and policy.neutral
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "frobisher.exr",
                           result.radiance.shape[:2])
    assert_matches_merge("frobisher", merged, result.radiance)
    window = result.statistics.clipped_everywhere / result.statistics.pixels
    assert window > 0.04  # the window (4.6 %): neutral in the node as in the command
    assert_matches_command("frobisher", merged, paths, tmp_path)


def test_merge_node_merges_a_repeated_exposure_as_hdrio_merge(write_brackets, tmp_path):
    # A ladder capped by the shutter: two frames named for 1/16 s (rendered 1 % apart, so
    # that they are two frames, not one image twice). The node wires them side by side,
    # shortest first, ties in the order linked, and merges as `hdrio merge` does.
    size = (40, 96)
    paths = write_brackets((1 / 16, 1.01 / 16, 1 / 4, 1.0), size=size,
                           names=["c_1_16.png", "d_1_16.png", "e_1_4.png", "f_1_1.png"])
    scene = bpy.context.scene
    node = solved_merge_node(clean_compositor(scene), paths)
    assert node.bracket_exposures() == pytest.approx([1 / 16, 1 / 16, 1 / 4, 1.0])
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "repeat.exr", size)
    assert_matches_merge("repeat", merged,
                         merge_stack(read_brackets(paths), MergeOptions()).radiance)
    assert_matches_command("repeat", merged, paths, tmp_path)


def test_merge_node_reconstructs_highlights_as_hdrio_merge(shared_data, tmp_path):
    # Highlights: Reconstruct is `hdrio merge --highlights reconstruct`, hdrio's own
    # (baked by the Solve), multiplied into the node's merge.
    paths = sorted(shared_data("frobisher_001").glob("*.jpg"))
    scene = bpy.context.scene
    tree = clean_compositor(scene)
    node = merge_node_with(tree, paths)
    node.highlights = "reconstruct"
    assert node.highlight_gain() is None  # nothing until solved
    assert bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name) == {
        "FINISHED"}
    assert node.highlight_gain() is not None
    result = merge_stack(read_brackets(paths), MergeOptions(highlights="reconstruct"))
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "rebuilt.exr",
                           result.radiance.shape[:2])
    assert_matches_command("reconstruct", merged, paths, tmp_path,
                           "--highlights", "reconstruct")
    node.highlights = "clip"  # back to the lower bound, without a new Solve
    clipped = render_to_exr(scene, node.outputs[0], tmp_path / "clip.exr",
                            result.radiance.shape[:2])
    assert_matches_command("clip", clipped, paths, tmp_path)


def test_merge_node_reads_brackets_as_blender_loads_them(shared_data, tmp_path):
    # A portrait set as a phone writes it: landscape pixels tagged "turned 90 degrees
    # clockwise" (EXIF orientation 6). Blender loads them as stored; `hdrio merge` turns
    # them upright. The node's Solve reads them as Blender does, so its highlight gain
    # (an image laid over the node's inputs) has their size and place.
    import OpenImageIO as oiio

    paths = []
    for source in sorted(shared_data("frobisher_001").glob("*.jpg")):
        buffer = oiio.ImageBuf(str(source))
        buffer.specmod().attribute("Orientation", 6)
        paths.append(tmp_path / f"{source.stem}.tif")  # lossless: the same codes
        assert buffer.write(str(paths[-1]), "uint8")
    image = bpy.data.images.load(str(paths[0]), check_existing=False)
    stored = (image.size[1], image.size[0])
    assert stored == (426, 640)  # as stored: Blender ignores the orientation
    scene = bpy.context.scene
    tree = clean_compositor(scene)
    node = merge_node_with(tree, paths)
    node.highlights = "reconstruct"
    assert bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name) == {
        "FINISHED"}
    gain = node.highlight_gain()
    assert (gain.size[1], gain.size[0]) == stored
    result = merge_stack(read_brackets(paths, upright=False),
                         MergeOptions(highlights="reconstruct"))
    merged = render_to_exr(scene, node.outputs[0], tmp_path / "stored.exr", stored)
    difference = relative_difference(merged, result.radiance)
    print(f"as stored, reconstructed: p99 {np.percentile(difference, 99):.1e}")
    assert np.percentile(difference, 99) <= 1e-3  # the parity bound of the tests above
    upright = read_brackets(paths)
    assert upright.codes.shape[1:3] == stored[::-1]  # hdrio merge's, for comparison


def test_solve_refuses_placeholder_exposures_in_one_line(write_brackets):
    # PNGs without EXIF and names without times: the node's exposures are placeholders.
    paths = write_brackets((1 / 4, 1.0, 4.0), names=["a.png", "b.png", "c.png"])
    tree = clean_compositor(bpy.context.scene)
    node = merge_node_with(tree, paths)
    node.label = "Church"
    before = node.response_json
    with pytest.raises(RuntimeError) as refused:
        bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name)
    message = str(refused.value).strip()
    print(message)
    assert "\n" not in message
    assert ('HDR Merge "Church": no exposure for bracket 1, 2, 3 (no EXIF, no time in the '
            'file name): type it in the node\'s "Bracket 1 (s)" field') in message
    assert node.response_json == before
    node.exposures[0], node.exposures[1] = 0.25, 1.0
    with pytest.raises(RuntimeError, match="no exposure for bracket 3 "):
        bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name)
    node.exposures[2] = 4.0
    assert node.placeholder_brackets() == []
    assert bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name) == {
        "FINISHED"}
    # Typed the other way round: refused before the solve, in the node's words.
    node.exposures[0], node.exposures[2] = 4.0, 0.25
    with pytest.raises(RuntimeError, match="b.png: exposure 1 in the node's Bracket fields, "
                                           "2.00 stops longer than c.png's 1/4"):
        bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name)


def test_saved_file_reopened_twice_renders_the_same_pixels(write_brackets, tmp_path):
    size = (40, 96)
    paths = write_brackets(size=size)
    scene = bpy.context.scene
    node = solved_merge_node(clean_compositor(scene), paths)
    name = node.name
    first = render_to_exr(scene, node.outputs[0], tmp_path / "before.exr", size)
    blend = tmp_path / "merge.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    for attempt in range(2):
        bpy.ops.wm.open_mainfile(filepath=str(blend))
        assert refresh_curves in bpy.app.handlers.load_post  # persistent: kept
        scene = bpy.context.scene
        node = compositor_tree(scene).nodes[name]
        again = render_to_exr(scene, node.outputs[0], tmp_path / f"reopened{attempt}.exr",
                              size)
        assert np.array_equal(again, first), f"open {attempt + 1}"


def test_solve_without_linked_images_reports_an_error():
    tree = clean_compositor(bpy.context.scene)
    node = tree.nodes.new("CompositorNodeHdrioMerge")
    with pytest.raises(RuntimeError, match="bracket 1 is not linked to an image file"):
        bpy.ops.hdrio.solve_response(tree_name=tree.name, node_name=node.name)


def test_reinhard_global_node_matches_hdrio(tmp_path):
    size = (60, 90)
    radiance = demo_scene(*size)
    source = write_exr(tmp_path / "scene.exr", radiance, pixel_type="float")
    scene = bpy.context.scene
    tree = clean_compositor(scene)
    node = tree.nodes.new("CompositorNodeHdrioReinhardGlobal")
    tree.links.new(image_node(tree, source).outputs["Image"], node.inputs["Image"])
    display = render_to_exr(scene, node.outputs[0], tmp_path / "reinhard.exr", size)

    reference = TONEMAP_METHODS["reinhard-global"](radiance)
    difference = relative_difference(display, reference)
    # Its output is display-linear: under AgX it would be tone-mapped twice.
    scene.view_settings.view_transform = "AgX"
    assert view_warning(scene) == "AgX view tone-maps it again"
    assert bpy.ops.hdrio.use_standard_view() == {"FINISHED"}
    assert scene.view_settings.view_transform == "Standard"
    assert view_warning(scene) == ""
    print(f"reinhard: median {np.median(difference):.2e} p99 "
          f"{np.percentile(difference, 99):.2e}")
    # The bound; float32 statistics and Blender's luminance path differ from
    # hdrio's only by rounding, so the median is far below it.
    assert np.median(difference) <= 0.01


def test_merge_to_exr_matches_hdrio_merge_command(shared_data, tmp_path):
    folder = shared_data("frobisher_001")
    names = sorted(p.name for p in folder.glob("*.jpg"))
    assert len(names) == 3, f"expected the 3 Frobisher brackets in {folder}"
    paths = [str(folder / name) for name in names]
    cli_output = tmp_path / "cli.exr"
    assert hdrio_main(["merge", *paths, "-o", str(cli_output), "-q"]) == 0

    blender_output = tmp_path / "blender.exr"
    tree = clean_compositor(bpy.context.scene)
    result = bpy.ops.hdrio.merge_to_exr(
        directory=str(folder), files=[{"name": name} for name in names],
        output=str(blender_output))
    assert result == {"FINISHED"}
    cli_pixels, cli_attributes = read_exr(cli_output)
    pixels, attributes = read_exr(blender_output)
    assert np.array_equal(pixels, cli_pixels)
    # Everything in the header but the time of writing (OpenImageIO stamps DateTime).
    assert attributes.pop("DateTime") and cli_attributes.pop("DateTime")
    assert attributes == cli_attributes
    assert attributes["hdrio:sourceFiles"] == tuple(str(Path(p).resolve()) for p in paths)
    loaded = [n for n in tree.nodes if n.bl_idname == "CompositorNodeImage"]
    assert [bpy.path.abspath(n.image.filepath) for n in loaded] == [str(blender_output)]

    # Asked again, it does not overwrite silently.
    stamp = blender_output.stat().st_mtime_ns
    with pytest.raises(RuntimeError, match="blender.exr exists: tick Overwrite"):
        bpy.ops.hdrio.merge_to_exr(
            directory=str(folder), files=[{"name": name} for name in names],
            output=str(blender_output))
    assert blender_output.stat().st_mtime_ns == stamp
    assert bpy.ops.hdrio.merge_to_exr(
        directory=str(folder), files=[{"name": name} for name in names],
        output=str(blender_output), overwrite=True) == {"FINISHED"}


def test_merge_to_exr_pixel_type_and_compression_are_hdrio_merges(shared_data, tmp_path):
    # Pixel Type and Compression are `hdrio merge -d` and `--compression`: the same file.
    import OpenImageIO as oiio

    folder = shared_data("frobisher_001")
    names = sorted(p.name for p in folder.glob("*.jpg"))
    paths = [str(folder / name) for name in names]
    cli_output = tmp_path / "cli.exr"
    assert hdrio_main(["merge", *paths, "-o", str(cli_output), "-q", "-d", "float",
                       "--compression", "piz"]) == 0
    blender_output = tmp_path / "blender.exr"
    assert bpy.ops.hdrio.merge_to_exr(
        directory=str(folder), files=[{"name": name} for name in names],
        output=str(blender_output), data_type="float", compression="piz") == {"FINISHED"}
    cli_pixels, cli_attributes = read_exr(cli_output)
    pixels, attributes = read_exr(blender_output)
    assert np.array_equal(pixels, cli_pixels)
    assert attributes.pop("DateTime") and cli_attributes.pop("DateTime")
    assert attributes == cli_attributes and attributes["compression"] == "piz"
    image = oiio.ImageInput.open(str(blender_output))
    assert str(image.spec().format) == "float"
    image.close()


def test_merge_to_exr_reports_bad_input_in_blender_words(write_brackets, tmp_path):
    # Names without exposures, and PNGs without EXIF: nothing gives the exposures.
    paths = write_brackets((1 / 4, 1.0, 4.0), names=["a.png", "b.png", "c.png"])
    arguments = dict(directory=str(paths[0].parent), files=[{"name": p.name} for p in paths],
                     output=str(tmp_path / "out.exr"))
    with pytest.raises(RuntimeError, match="a.png: no exposure time .*type them in "
                                           "Exposures") as refused:
        bpy.ops.hdrio.merge_to_exr(**arguments)
    assert "--exposures" not in str(refused.value)
    assert not (tmp_path / "out.exr").exists()
    # The same option as `hdrio merge --exposures`, in the same words.
    assert bpy.ops.hdrio.merge_to_exr(**arguments, exposures="1/4, 1 4") == {"FINISHED"}
    _, attributes = read_exr(tmp_path / "out.exr")
    assert attributes["hdrio:exposures"] == ("0.25", "1", "4")  # exact short decimals
    assert attributes["hdrio:exposureSource"] == "explicit"
    # Steps in EV, as `hdrio merge --exposures -2EV,0EV,+2EV`: the same ratios, the same
    # pixels; units mixed are refused in the panel's words.
    pixels, _ = read_exr(tmp_path / "out.exr")
    (tmp_path / "out.exr").unlink()
    assert bpy.ops.hdrio.merge_to_exr(**arguments, exposures="-2EV 0EV +2EV") == {"FINISHED"}
    ev_pixels, attributes = read_exr(tmp_path / "out.exr")
    assert attributes["hdrio:exposureSource"] == "EV steps"
    assert np.array_equal(ev_pixels, pixels)
    (tmp_path / "out.exr").unlink()
    with pytest.raises(RuntimeError, match="typed in Exposures: '1' beside '-2EV'"):
        bpy.ops.hdrio.merge_to_exr(**arguments, exposures="-2EV 1 +2EV")


def test_merge_to_exr_exposures_from_data_is_hdrio_merges(write_brackets, tmp_path):
    # Exposures From Data is `hdrio merge --exposures-from-data`: files with no exposure
    # anywhere are merged with inferred, relative exposures; the same EXR either way.
    paths = write_brackets((1 / 4, 1.0, 4.0), names=["a.png", "b.png", "c.png"])
    cli_output = tmp_path / "cli.exr"
    assert hdrio_main(["merge", *map(str, paths), "-o", str(cli_output), "-q",
                       "--exposures-from-data"]) == 0
    blender_output = tmp_path / "blender.exr"
    assert bpy.ops.hdrio.merge_to_exr(
        directory=str(paths[0].parent), files=[{"name": p.name} for p in paths],
        output=str(blender_output), exposures_from_data=True) == {"FINISHED"}
    cli_pixels, cli_attributes = read_exr(cli_output)
    pixels, attributes = read_exr(blender_output)
    assert np.array_equal(pixels, cli_pixels)
    assert attributes["hdrio:exposuresInferred"] == cli_attributes["hdrio:exposuresInferred"]


def test_merge_to_exr_warns_of_an_exposure_the_data_contradict(write_brackets, tmp_path,
                                                               capsys):
    # `hdrio merge` names a bracket whose exposure the data contradict (here b.png, shot
    # at 1 s, typed as 2); the operator reports the same line as a warning, in the words
    # of its panel, and merges as the command does.
    from hdrio.job.run import merge_paths
    from plugins.blender.operators import exposure_warnings

    paths = write_brackets((1 / 4, 1.0, 4.0), names=["a.png", "b.png", "c.png"])
    assert hdrio_main(["merge", *map(str, paths), "--exposures", "1/4,2,4", "-o",
                       str(tmp_path / "cli.exr"), "-q"]) == 0
    said = capsys.readouterr().err
    assert "b.png: exposure 2 given by --exposures, the data say 1.001 (-1.00 stop); " \
        "--exposures-from-data uses the data's" in said, said
    (line,) = exposure_warnings(merge_paths(paths, exposures=["1/4", "2", "4"]))
    assert line == ("b.png: exposure 2 typed in Exposures, the data say 1.001 (-1.00 "
                    "stop); Exposures From Data uses the data's")
    assert bpy.ops.hdrio.merge_to_exr(
        directory=str(paths[0].parent), files=[{"name": p.name} for p in paths],
        output=str(tmp_path / "blender.exr"), exposures="1/4 2 4") == {"FINISHED"}
    assert np.array_equal(read_exr(tmp_path / "blender.exr")[0],
                          read_exr(tmp_path / "cli.exr")[0])
    # Exposures typed in another order than the files': refused, in the same words.
    with pytest.raises(RuntimeError, match="b.png: exposure 1 typed in Exposures, 2.00 "
                                           "stops longer than c.png's 1/4, yet its codes "
                                           "are lower") as refused:
        bpy.ops.hdrio.merge_to_exr(
            directory=str(paths[0].parent), files=[{"name": p.name} for p in paths],
            output=str(tmp_path / "reversed.exr"), exposures="4 1 1/4")
    assert "--exposures" not in str(refused.value)
    assert not (tmp_path / "reversed.exr").exists()


def test_merge_to_exr_names_the_command_for_an_option_blender_lacks(write_brackets,
                                                                     tmp_path):
    # Frames that all share one exposure (a burst) merge only through a known response,
    # which only `hdrio merge` takes: the report names the command's options as its own.
    # (Rendered 1 % apart, so that the two frames are not one image twice.)
    paths = write_brackets((1 / 4, 1.01 / 4), names=["a.png", "b.png"])
    with pytest.raises(RuntimeError, match="same exposure") as refused:
        bpy.ops.hdrio.merge_to_exr(
            directory=str(paths[0].parent), files=[{"name": p.name} for p in paths],
            output=str(tmp_path / "burst.exr"), exposures="1/4 1/4")
    said = str(refused.value)
    assert "hdrio merge --response-from EXR" in said and "hdrio merge --response linear" \
        in said, said
    assert not (tmp_path / "burst.exr").exists()


def test_tonemap_local_operator_matches_hdrio(tmp_path):
    radiance = demo_scene(48, 64)
    source = write_exr(tmp_path / "scene.exr", radiance, pixel_type="float")
    image = bpy.data.images.load(str(source), check_existing=False)
    assert bpy.ops.hdrio.tonemap_local(image_name=image.name) == {"FINISHED"}
    result = bpy.data.images[f"{image.name} Reinhard local"]
    pixels = np.empty(64 * 48 * 4, dtype=np.float32)
    result.pixels.foreach_get(pixels)
    # Blender stores rows bottom-up.
    display = pixels.reshape(48, 64, 4)[::-1, :, :3]
    reference = TONEMAP_METHODS["reinhard-local"](radiance)
    # Same function on the same float32 pixels: only float32 rounding may differ.
    assert np.allclose(display, reference, rtol=1e-5, atol=1e-6)


def test_merge_to_exr_highlights_option_is_hdrio_merges(shared_data, tmp_path):
    # The add-on's Highlights is `hdrio merge --highlights`: same name, same EXR.
    folder = shared_data("frobisher_001")
    names = sorted(p.name for p in folder.glob("*.jpg"))
    paths = [str(folder / name) for name in names]
    cli_output = tmp_path / "cli.exr"
    assert hdrio_main(["merge", *paths, "-o", str(cli_output), "-q",
                       "--highlights", "reconstruct"]) == 0
    blender_output = tmp_path / "blender.exr"
    clean_compositor(bpy.context.scene)
    assert bpy.ops.hdrio.merge_to_exr(
        directory=str(folder), files=[{"name": name} for name in names],
        output=str(blender_output), highlights="reconstruct") == {"FINISHED"}
    cli_pixels, cli_attributes = read_exr(cli_output)
    pixels, attributes = read_exr(blender_output)
    assert np.array_equal(pixels, cli_pixels)
    assert attributes["hdrio:highlights"] == "reconstruct"
    assert "reconstructed" in attributes["hdrio:highlightsReconstructed"]
