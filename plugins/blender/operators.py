"""Operators: solve the camera response into an HDR Merge node, merge brackets to an EXR,
tone-map an image with hdrio's local operator, add the nodes.

Every hdrio error (bad input, unsolvable response) is reported in Blender's UI as one
line naming the file and the problem, and the operator is cancelled: no traceback.
"""

from __future__ import annotations

import os
import re
from dataclasses import replace
from pathlib import Path

import bpy
import numpy as np
from bpy.props import CollectionProperty, EnumProperty, StringProperty

from hdrio.errors import HdrioError, InputError
from hdrio.io.brackets import read_brackets
from hdrio.io.exposure import split_exposures
from hdrio.io.write import EXR_COMPRESSIONS
from hdrio.job.options import MergeOptions
from hdrio.job.run import merge_files, merge_stack
from hdrio.tonemap import TONEMAP_METHODS

from .baking import highlight_gain, response_to_json
from .compat import active_compositor_tree, compositor_tree, find_node_tree
from .nodes import DISPLAY_VIEW, HIGHLIGHT_ITEMS, HdrioMergeNode, image_path, merge_node_name
from .warmup import WARMUP


def kernels_ready(operator: bpy.types.Operator) -> bool:
    """True once hdrio's kernels are compiled (:mod:`.warmup`). In the background (no UI
    to freeze) wait for them; with a UI, say so and let the user retry."""
    if not WARMUP.running:
        return True
    if bpy.app.background:
        WARMUP.wait()
        return True
    operator.report({"WARNING"}, f"{WARMUP.status()}: try again in a few seconds")
    return False


def _merge_node(context, tree_name: str, node_name: str) -> HdrioMergeNode | None:
    if tree_name and node_name:
        tree = find_node_tree(tree_name)
        node = tree.nodes.get(node_name) if tree is not None else None
    else:
        node = getattr(context, "node", None) or getattr(context, "active_node", None)
    return node if isinstance(node, HdrioMergeNode) else None


PANEL_EXPOSURES = "typed in Exposures"
"""Where Merge Brackets to EXR's exposures come from, in its side panel's words."""
NODE_EXPOSURES = "in the node's Bracket fields"
"""Where the HDR Merge node's Solve takes its exposures from."""


COMMAND_ONLY = re.compile(r"(?<![\w-])(--nd|--response-from|--response linear)\b")
"""hdrio merge's options that neither the panel nor the node has: a message naming one
names the command."""


def in_panel_words(text: str, exposures: str = PANEL_EXPOSURES) -> str:
    """``text`` (hdrio's message) with the merge options in Blender's words: exposures
    given by ``--exposures`` are ``exposures`` (the panel's or the node's),
    ``--exposures-from-data`` is the panel's Exposures From Data, and the options only
    the command has (:data:`COMMAND_ONLY`) are ``hdrio merge``'s."""
    text = text.replace("given by --exposures", exposures).replace(
        "--exposures-from-data", "Exposures From Data")
    return COMMAND_ONLY.sub(r"hdrio merge \1", text)


def exposure_warnings(result) -> list[str]:
    """What ``hdrio merge`` warns of a merge's exposures (a bracket whose metadata the data
    contradict), in this operator's words."""
    check = result.exposures
    lines = [] if check is None else check.warnings(result.stack.exposure_sources[0])
    return [in_panel_words(line) for line in lines]


class HDRIO_OT_solve_response(bpy.types.Operator):
    """Solve the camera response (Debevec 1997) from the node's bracket images and bake it
    into the node's curves"""

    bl_idname = "hdrio.solve_response"
    bl_label = "Solve Camera Response"
    bl_options = {"REGISTER", "UNDO"}

    tree_name: StringProperty(options={"SKIP_SAVE"})  # type: ignore[valid-type]
    node_name: StringProperty(options={"SKIP_SAVE"})  # type: ignore[valid-type]

    def execute(self, context):
        node = _merge_node(context, self.tree_name, self.node_name)
        if node is None:
            self.report({"ERROR"}, "no HDR Merge node selected")
            return {"CANCELLED"}
        name = merge_node_name(node)
        paths = [image_path(image) for image in node.bracket_images()]
        if not all(paths):
            missing = next(i for i, path in enumerate(paths, start=1) if not path)
            self.report({"ERROR"}, f"HDR Merge \"{name}\": bracket {missing} is not linked to "
                                   "an image file; the solve reads the brackets' files")
            return {"CANCELLED"}
        placeholders = node.placeholder_brackets()
        if placeholders:
            first = placeholders[0]
            which = ", ".join(str(n) for n in placeholders)
            self.report({"ERROR"}, f"HDR Merge \"{name}\": no exposure for bracket {which} "
                                   f"(no EXIF, no time in the file name): type it in the "
                                   f"node's \"Bracket {first} (s)\" field, then Solve again")
            return {"CANCELLED"}
        if not kernels_ready(self):
            return {"CANCELLED"}
        # hdrio merge's defaults, so the baked node merges as `hdrio merge` does.
        options = MergeOptions()
        try:
            # As stored, as Blender loads the node's images (it ignores EXIF orientation):
            # the highlight gain below is an image the node lays over them.
            stack = read_brackets(paths, exposures=node.bracket_exposures(), upright=False)
            result = merge_stack(stack, options)
            gain = None
            if node.highlights == "reconstruct":  # hdrio's own, as `--highlights reconstruct`
                rebuilt = merge_stack(stack, replace(options, highlights="reconstruct"),
                                      response=result.response)
                gain = highlight_gain(result.radiance, rebuilt.radiance)
        except HdrioError as error:
            self.report({"ERROR"}, in_panel_words(str(error), NODE_EXPOSURES))
            return {"CANCELLED"}
        node.set_response(response_to_json(
            result.response, f"{result.response.method} from {len(paths)} brackets",
            result.noise, result.statistics.policy), gain)
        self.report({"INFO"}, f"response solved from {len(paths)} brackets")
        return {"FINISHED"}


class HDRIO_OT_merge_to_exr(bpy.types.Operator):
    """Merge bracketed images into a scene-linear OpenEXR with hdrio (as `hdrio merge`)
    and add it to the compositor as an Image node"""

    bl_idname = "hdrio.merge_to_exr"
    bl_label = "Merge Brackets to EXR"
    bl_options = {"REGISTER", "UNDO"}

    files: CollectionProperty(type=bpy.types.OperatorFileListElement)  # type: ignore[valid-type]
    directory: StringProperty(subtype="DIR_PATH")  # type: ignore[valid-type]
    output: StringProperty(  # type: ignore[valid-type]
        name="Output", subtype="FILE_PATH",
        description="EXR to write (default: merged.exr beside the brackets)")
    exposures: StringProperty(  # type: ignore[valid-type]
        name="Exposures",
        description="Exposure of each selected file in seconds, or each one's step in EV, "
                    "in the order of the file names, as `hdrio merge --exposures` (e.g. "
                    "1/8 1 8, or -3EV 0EV +3EV); empty: from the files' EXIF or names")
    exposures_from_data: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Exposures From Data", default=False,
        description="Merge with each bracket's exposure estimated from the pixels, as "
                    "`hdrio merge --exposures-from-data`: corrects EXIF that is off, and "
                    "infers the exposures of files with none (relative, step found)")
    overwrite: bpy.props.BoolProperty(  # type: ignore[valid-type]
        name="Overwrite", default=False, options={"SKIP_SAVE"},
        description="Replace the output EXR if it exists")
    highlights: EnumProperty(  # type: ignore[valid-type]
        name="Highlights", default="clip",
        description="Pixels with channels clipped in every bracket, as `hdrio merge "
                    "--highlights`",
        items=HIGHLIGHT_ITEMS)
    data_type: EnumProperty(  # type: ignore[valid-type]
        name="Pixel Type", default="half",
        description="EXR pixel type, as `hdrio merge -d`",
        items=[("half", "Half", "16-bit float"), ("float", "Float", "32-bit float")])
    compression: EnumProperty(  # type: ignore[valid-type]
        name="Compression", default="zip",
        description="EXR compression, as `hdrio merge --compression`",
        items=[(name, name.upper(), f"`hdrio merge --compression {name}`")
               for name in EXR_COMPRESSIONS])
    filter_image: bpy.props.BoolProperty(default=True, options={"HIDDEN"})  # type: ignore

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        paths = sorted(os.path.join(self.directory, item.name)
                       for item in self.files if item.name)
        if len(paths) < 2:
            self.report({"ERROR"}, "select at least two bracketed images")
            return {"CANCELLED"}
        output = Path(bpy.path.abspath(self.output) if self.output
                      else os.path.join(self.directory, "merged.exr"))
        if output.suffix.lower() != ".exr":
            self.report({"ERROR"}, f"{output}: the output must be an .exr file")
            return {"CANCELLED"}
        if output.exists() and not self.overwrite:
            self.report({"ERROR"}, f"{output} exists: tick Overwrite (in the file browser's "
                                   "side panel) to replace it, or choose another Output")
            return {"CANCELLED"}
        if not kernels_ready(self):
            return {"CANCELLED"}
        exposures = split_exposures(self.exposures) if self.exposures.strip() else None
        try:
            result = merge_files(paths, output, exposures=exposures,
                                 options=MergeOptions(highlights=self.highlights,
                                                      exposures_from_data=self.exposures_from_data),
                                 pixel_type=self.data_type, compression=self.compression)
        except InputError as error:
            if "no exposure time" in error.problem:  # hdrio's words name a CLI option
                self.report({"ERROR"}, f"{error.path}: no exposure time (no EXIF, no time "
                                       "in the file name): type them in Exposures, in the "
                                       "file browser's side panel (e.g. 1/8 1 8), or tick "
                                       "Exposures From Data")
            else:
                self.report({"ERROR"}, in_panel_words(str(error)))
            return {"CANCELLED"}
        except HdrioError as error:
            self.report({"ERROR"}, in_panel_words(str(error)))
            return {"CANCELLED"}
        for line in exposure_warnings(result):
            self.report({"WARNING"}, line)
        image = bpy.data.images.load(str(output), check_existing=False)
        tree = active_compositor_tree(context) or compositor_tree(context.scene)
        node = tree.nodes.new("CompositorNodeImage")
        node.image = image
        self.report({"INFO"}, f"wrote {output}")
        return {"FINISHED"}


class HDRIO_OT_tonemap_local(bpy.types.Operator):
    """Tone-map a scene-linear image with hdrio's Reinhard 2002 local operator into a new
    image (display-linear)"""

    bl_idname = "hdrio.tonemap_local"
    bl_label = "Reinhard Local (hdrio)"
    bl_options = {"REGISTER", "UNDO"}

    image_name: StringProperty(name="Image")  # type: ignore[valid-type]

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)

    def draw(self, context):
        self.layout.prop_search(self, "image_name", bpy.data, "images")

    def execute(self, context):
        image = bpy.data.images.get(self.image_name)
        if image is None:
            self.report({"ERROR"}, f"no image named {self.image_name!r}")
            return {"CANCELLED"}
        width, height = image.size
        if width * height == 0:
            self.report({"ERROR"}, f"{image.filepath or image.name}: image has no pixels")
            return {"CANCELLED"}
        if not kernels_ready(self):
            return {"CANCELLED"}
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        rgba = pixels.reshape(height, width, 4)
        display = TONEMAP_METHODS["reinhard-local"](rgba[..., :3])
        result = bpy.data.images.new(f"{image.name} Reinhard local", width, height,
                                     float_buffer=True)
        out = np.concatenate([display, np.ones_like(display[..., :1])], axis=-1)
        result.pixels.foreach_set(out.astype(np.float32).reshape(-1))
        result.update()
        self.report({"INFO"}, f"tone-mapped {image.name} into {result.name}")
        return {"FINISHED"}


class HDRIO_OT_use_standard_view(bpy.types.Operator):
    """Show the compositor's result with the Standard view: the Reinhard node's output is
    already tone-mapped (display-linear), and the default AgX view would tone-map it again"""

    bl_idname = "hdrio.use_standard_view"
    bl_label = "Use Standard View"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        settings = context.scene.view_settings
        previous = settings.view_transform
        settings.view_transform = DISPLAY_VIEW
        settings.look = "None"
        self.report({"INFO"}, f"view transform {previous} -> {DISPLAY_VIEW}")
        return {"FINISHED"}


class HDRIO_OT_add_node(bpy.types.Operator):
    """Add an hdrio node to the compositor"""

    bl_idname = "hdrio.add_node"
    bl_label = "Add hdrio Node"
    bl_options = {"REGISTER", "UNDO"}

    node_type: EnumProperty(items=[  # type: ignore[valid-type]
        ("CompositorNodeHdrioMerge", "HDR Merge", ""),
        ("CompositorNodeHdrioReinhardGlobal", "Reinhard Global", ""),
    ])

    def execute(self, context):
        tree = active_compositor_tree(context) or compositor_tree(context.scene)
        for node in tree.nodes:
            node.select = False
        node = tree.nodes.new(self.node_type)
        node.select = True
        tree.nodes.active = node
        return {"FINISHED"}


CLASSES = (HDRIO_OT_solve_response, HDRIO_OT_merge_to_exr, HDRIO_OT_tonemap_local,
           HDRIO_OT_use_standard_view, HDRIO_OT_add_node)
