"""The compositor nodes: HDR Merge and Reinhard Global (custom group nodes).

Each is a ``CompositorNodeCustomGroup`` whose private node tree is rebuilt from native
nodes whenever its settings change, so it runs live on any image, render passes included.
"""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import EnumProperty, FloatVectorProperty, IntProperty, StringProperty

from hdrio.errors import HdrioError, InputError
from hdrio.merge.highlights import HIGHLIGHT_HELP, HIGHLIGHT_MODES

from .baking import BakedMerge, bake_merge, response_from_json, scene_linear_response
from .compat import show_status
from .exposures import (
    PLACEHOLDER,
    edited_sources,
    exposure_state,
    exposures_for_files,
    input_problems,
    placeholder_brackets,
)
from .merge_graph import build_merge_graph
from .reinhard_graph import DEFAULT_KEY, DEFAULT_SATURATION, build_reinhard_global_graph

MAX_BRACKETS = 16
# 1/16 s, 1/4 s, 1 s, 4 s, ...: distinct starting values two stops apart.
DEFAULT_EXPOSURES = tuple(4.0 ** (i - 2) for i in range(MAX_BRACKETS))
UNSOLVED_LABEL = "linear (not solved)"
DISPLAY_VIEW = "Standard"
"""The view under which a display-linear image (the Reinhard node's output) is shown as is."""

_FILLING: set[int] = set()  # nodes whose exposures the add-on is setting (not the user)

# Built here, not in the annotation: Blender evaluates a property's annotation where a
# comprehension does not see this module's names.
HIGHLIGHT_ITEMS = [(mode, mode.capitalize(), HIGHLIGHT_HELP[mode]) for mode in HIGHLIGHT_MODES]
RESOLVE_HIGHLIGHTS = "Highlights: Solve again to reconstruct them"


def linked_image(socket: bpy.types.NodeSocket) -> bpy.types.Image | None:
    """The image of the Image node linked into ``socket`` (through reroutes), if any."""
    while socket.is_linked:
        node = socket.links[0].from_node
        if node.bl_idname == "CompositorNodeImage":
            return node.image
        if node.bl_idname != "NodeReroute":
            return None
        socket = node.inputs[0]
    return None


def image_path(image: bpy.types.Image | None) -> str | None:
    """The absolute file path of a file-backed image, else ``None``."""
    if image is None or image.source not in {"FILE", "SEQUENCE"} or not image.filepath:
        return None
    return bpy.path.abspath(image.filepath, library=image.library)


def merge_node_name(node: bpy.types.Node) -> str:
    """How messages name a node: its label, else its name (``HDR Merge.001``)."""
    return node.label or node.name


class PrivateGroupMixin:
    """A group node whose tree is its own: a copied node gets a copy, a deleted node
    takes its tree along (not decided by ``users``: Blender 5.0 counts 2 users for a tree
    only this node holds)."""

    def copy(self, node) -> None:
        self.node_tree = node.node_tree.copy()

    def free(self) -> None:
        if self.node_tree is not None:
            bpy.data.node_groups.remove(self.node_tree)


def _exposures_changed(node: HdrioMergeNode, _context=None) -> None:
    if node.as_pointer() not in _FILLING:
        sources = edited_sources(node.sources(), node.last_exposures, node.exposures)
        node.exposure_sources = ",".join(sources)
    node.last_exposures = node.exposures
    node.rebuild()


def _highlights_changed(node: HdrioMergeNode, _context=None) -> None:
    node.rebuild()


def _resize_merge(node: HdrioMergeNode, _context=None) -> None:
    node.resize_interface()
    node.rebuild()


class HdrioMergeNode(PrivateGroupMixin, bpy.types.CompositorNodeCustomGroup):
    """Merge bracketed exposures into scene-linear radiance (hdrio's default merge)."""

    bl_idname = "CompositorNodeHdrioMerge"
    bl_label = "HDR Merge"
    bl_description = ("Merge bracketed exposures into scene-linear radiance as `hdrio merge` "
                      "does, with a baked camera response")
    bl_width_default = 260

    bracket_count: IntProperty(  # type: ignore[valid-type]
        name="Brackets", description="Number of bracket inputs", default=3, min=2,
        max=MAX_BRACKETS, update=_resize_merge)
    exposures: FloatVectorProperty(  # type: ignore[valid-type]
        name="Exposures", description="Exposure of each input (seconds, or relative)",
        size=MAX_BRACKETS, default=DEFAULT_EXPOSURES, min=1e-9, precision=6,
        update=_exposures_changed)
    last_exposures: FloatVectorProperty(  # type: ignore[valid-type]
        size=MAX_BRACKETS, default=DEFAULT_EXPOSURES, options={"HIDDEN"})
    # Where each exposure came from (exposures.PLACEHOLDER, TYPED, or hdrio's source).
    exposure_sources: StringProperty(  # type: ignore[valid-type]
        default=",".join([PLACEHOLDER] * MAX_BRACKETS), options={"HIDDEN"})
    response_json: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]
    highlights: EnumProperty(  # type: ignore[valid-type]
        name="Highlights", default="clip", items=HIGHLIGHT_ITEMS, update=_highlights_changed,
        description="Pixels with channels clipped in every bracket, as `hdrio merge "
                    "--highlights`; Reconstruct is computed by the Solve")
    # The packed image of hdrio's reconstruction over its clip merge (1 but at clipped
    # pixels), made by the Solve when Highlights is Reconstruct.
    highlight_image: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]
    linked_files: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]
    message: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]

    def init(self, context) -> None:
        tree = bpy.data.node_groups.new(".hdrio HDR Merge", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        self.node_tree = tree
        self.resize_interface()
        self.rebuild()

    def sources(self) -> list[str]:
        return self.exposure_sources.split(",")

    def response_label(self) -> str:
        if not self.response_json:
            return UNSOLVED_LABEL
        return response_from_json(self.response_json).label

    def baked(self) -> BakedMerge:
        """hdrio's merge tables for this node's response and exposures (shortest first)."""
        if not self.response_json:
            return bake_merge(scene_linear_response(), sorted(self.bracket_exposures()))
        solved = response_from_json(self.response_json)
        return bake_merge(solved.response, sorted(self.bracket_exposures()),
                          noise=solved.noise, policy=solved.policy)

    def set_response(self, response_json: str, gain: np.ndarray | None = None) -> None:
        """Store a Solve: the response and policy ``response_json``, and ``gain`` ``(H, W,
        3)``, hdrio's ``--highlights reconstruct`` over its clip merge (``None``: none)."""
        self.response_json = response_json
        old = bpy.data.images.get(self.highlight_image) if self.highlight_image else None
        if old is not None:
            bpy.data.images.remove(old)
        self.highlight_image = ""
        if gain is not None:
            height, width = gain.shape[:2]
            image = bpy.data.images.new(f".hdrio highlights {self.name}", width, height,
                                        alpha=True, float_buffer=True)
            image.colorspace_settings.name = "Non-Color"
            rgba = np.concatenate([gain, np.ones_like(gain[..., :1])], axis=-1)
            image.pixels.foreach_set(rgba[::-1].astype(np.float32).reshape(-1))  # bottom-up
            image.file_format = "OPEN_EXR"
            image.pack()
            self.highlight_image = image.name
        self.rebuild()

    def free(self) -> None:
        image = bpy.data.images.get(self.highlight_image) if self.highlight_image else None
        if image is not None:
            bpy.data.images.remove(image)
        super().free()

    def highlight_gain(self) -> bpy.types.Image | None:
        """The Solve's reconstruction image, when Highlights is Reconstruct."""
        if self.highlights != "reconstruct" or not self.highlight_image:
            return None
        return bpy.data.images.get(self.highlight_image)

    def bracket_exposures(self) -> list[float]:
        return [float(v) for v in self.exposures[: self.bracket_count]]

    def set_exposures(self, values: list[float], source: str) -> None:
        """Exposures of the first ``len(values)`` brackets, found by the add-on."""
        exposures, sources = list(self.exposures), self.sources()
        exposures[: len(values)] = values
        sources[: len(values)] = [source] * len(values)
        self.exposure_sources = ",".join(sources)
        _FILLING.add(self.as_pointer())
        try:
            self.exposures = exposures  # rebuilds
        finally:
            _FILLING.discard(self.as_pointer())

    def placeholder_brackets(self) -> list[int]:
        return placeholder_brackets(self.sources()[: self.bracket_count])

    def resize_interface(self) -> None:
        """Give the group exactly ``bracket_count`` inputs (links to kept ones stay)."""
        interface = self.node_tree.interface
        inputs = [item for item in interface.items_tree
                  if item.item_type == "SOCKET" and item.in_out == "INPUT"]
        for item in inputs[self.bracket_count:]:
            interface.remove(item)
        for number in range(len(inputs) + 1, self.bracket_count + 1):
            interface.new_socket(f"Bracket {number}", in_out="INPUT",
                                 socket_type="NodeSocketColor")

    def rebuild(self) -> None:
        build_merge_graph(self.node_tree, self.baked(), self.bracket_exposures(),
                          self.highlight_gain())

    def bracket_images(self) -> list[bpy.types.Image | None]:
        return [linked_image(socket) for socket in self.inputs[: self.bracket_count]]

    def check_inputs(self) -> str:
        """The first problem with the linked inputs (on the node and the status bar)."""
        sizes = [None if image is None else tuple(image.size)
                 for image in self.bracket_images()]
        linked = [socket.is_linked for socket in self.inputs[: self.bracket_count]]
        return input_problems(sizes, linked)

    def update(self) -> None:
        """On new links: read the brackets as code values, fill their exposures, and say
        what is wrong with the inputs."""
        images = self.bracket_images()
        for image in images:
            if image is not None and image.colorspace_settings.name != "Non-Color":
                image.colorspace_settings.name = "Non-Color"
        problem = self.check_inputs()
        self.message = problem
        show_status(f"HDR Merge \"{merge_node_name(self)}\": {problem}" if problem else "",
                    owner=self.as_pointer())
        paths = [image_path(image) for image in images]
        signature = "\n".join(path or "" for path in paths)
        if problem or signature == self.linked_files or not all(paths):
            return
        self.linked_files = signature
        try:
            values, source = exposures_for_files(paths)
        except InputError as error:
            if "no exposure time" not in error.problem:
                self.message = f"{bpy.path.basename(error.path)}: {error.problem}"
            return
        except HdrioError as error:
            self.message = str(error)
            return
        self.set_exposures(values, source)

    def draw_buttons(self, context, layout) -> None:
        layout.prop(self, "bracket_count")
        missing = set(self.placeholder_brackets())
        column = layout.column(align=True)
        for index in range(self.bracket_count):
            row = column.row(align=True)
            row.alert = index + 1 in missing
            row.prop(self, "exposures", index=index, text=f"Bracket {index + 1} (s)")
        state = exposure_state(self.sources()[: self.bracket_count])
        layout.label(text=state, icon="ERROR" if missing else "CHECKMARK")
        layout.label(text=f"Response: {self.response_label()}")
        layout.prop(self, "highlights")
        if self.highlights == "reconstruct" and self.highlight_gain() is None:
            layout.label(text=RESOLVE_HIGHLIGHTS, icon="ERROR")
        if self.message:
            layout.label(text=self.message, icon="ERROR")
        layout.context_pointer_set("node", self)
        layout.operator("hdrio.solve_response", icon="GRAPH")


def view_warning(scene: bpy.types.Scene) -> str:
    """What is wrong with showing the Reinhard node's output under ``scene``'s view."""
    view = scene.view_settings.view_transform
    if view == DISPLAY_VIEW:
        return ""
    return f"{view} view tone-maps it again"


@bpy.app.handlers.persistent
def refresh_curves(*_arguments) -> None:
    """After a file is loaded (``load_post``): recompute the hdrio nodes' curve tables.

    Blender rebuilds a curve's table from its points lazily; a file saved and opened
    again must not render with stale tables (Blender 4.2 did, from the second open).
    """
    for tree in bpy.data.node_groups:
        if tree.name.startswith(".hdrio"):
            for node in tree.nodes:
                if node.bl_idname == "CompositorNodeCurveRGB":
                    node.mapping.update()


class HdrioReinhardGlobalNode(PrivateGroupMixin, bpy.types.CompositorNodeCustomGroup):
    """Reinhard et al. (2002) global operator from native nodes (key from Levels' mean)."""

    bl_idname = "CompositorNodeHdrioReinhardGlobal"
    bl_label = "Reinhard Global"
    bl_description = ("Reinhard 2002 global tone mapping (log-average key from the "
                      "compositor's image statistics); display-linear output in [0, 1], "
                      "to be viewed with the Standard view")
    bl_width_default = 200

    def init(self, context) -> None:
        tree = bpy.data.node_groups.new(".hdrio Reinhard Global", "CompositorNodeTree")
        self.node_tree = tree
        build_reinhard_global_graph(tree)
        # A new node's sockets start at 0, not at the interface's defaults.
        self.inputs["Key"].default_value = DEFAULT_KEY
        self.inputs["Saturation"].default_value = DEFAULT_SATURATION

    def draw_buttons(self, context, layout) -> None:
        warning = view_warning(context.scene)
        if warning:
            layout.label(text=warning, icon="ERROR")
            layout.operator("hdrio.use_standard_view", icon="CHECKMARK")


CLASSES = (HdrioMergeNode, HdrioReinhardGlobalNode)
