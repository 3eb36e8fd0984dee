"""The compositor nodes: HDR Merge and Reinhard Global (custom group nodes).

Each is a ``CompositorNodeCustomGroup`` whose private node tree is rebuilt from native
nodes whenever its settings change, so it runs live on any image, render passes included.
"""

from __future__ import annotations

import bpy
from bpy.props import FloatVectorProperty, IntProperty, StringProperty

from hdrio.errors import HdrioError

from .baking import BakedResponse, bake_response, linear_response
from .exposures import exposures_for_files
from .merge_graph import build_merge_graph
from .reinhard_graph import DEFAULT_KEY, DEFAULT_SATURATION, build_reinhard_global_graph

MAX_BRACKETS = 16
# 1/16 s, 1/4 s, 1 s, 4 s, ...: distinct starting values two stops apart.
DEFAULT_EXPOSURES = tuple(4.0 ** (i - 2) for i in range(MAX_BRACKETS))


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


class PrivateGroupMixin:
    """A group node whose tree is its own: a copied node gets a copy, a deleted node
    takes its tree along (not decided by ``users``: Blender 5.0 counts 2 users for a tree
    only this node holds)."""

    def copy(self, node) -> None:
        self.node_tree = node.node_tree.copy()

    def free(self) -> None:
        if self.node_tree is not None:
            bpy.data.node_groups.remove(self.node_tree)


def _rebuild_merge(node: HdrioMergeNode, _context=None) -> None:
    node.rebuild()


def _resize_merge(node: HdrioMergeNode, _context=None) -> None:
    node.resize_interface()
    node.rebuild()


class HdrioMergeNode(PrivateGroupMixin, bpy.types.CompositorNodeCustomGroup):
    """Merge bracketed exposures into scene-linear radiance (hdrio's linear merge)."""

    bl_idname = "CompositorNodeHdrioMerge"
    bl_label = "HDR Merge"
    bl_description = ("Merge bracketed exposures into scene-linear radiance with a baked "
                      "camera response (hdrio)")
    bl_width_default = 260

    bracket_count: IntProperty(  # type: ignore[valid-type]
        name="Brackets", description="Number of bracket inputs", default=3, min=2,
        max=MAX_BRACKETS, update=_resize_merge)
    exposures: FloatVectorProperty(  # type: ignore[valid-type]
        name="Exposures", description="Exposure of each input (seconds, or relative)",
        size=MAX_BRACKETS, default=DEFAULT_EXPOSURES, min=1e-9, precision=6,
        update=_rebuild_merge)
    response_json: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]
    linked_files: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]
    message: StringProperty(options={"HIDDEN"})  # type: ignore[valid-type]

    def init(self, context) -> None:
        tree = bpy.data.node_groups.new(".hdrio HDR Merge", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        self.node_tree = tree
        self.resize_interface()
        self.rebuild()

    @property
    def baked(self) -> BakedResponse:
        if self.response_json:
            return BakedResponse.from_json(self.response_json)
        return bake_response(linear_response(), label="linear (not solved)")

    def set_response(self, baked: BakedResponse) -> None:
        self.response_json = baked.to_json()
        self.rebuild()

    def bracket_exposures(self) -> list[float]:
        return [float(v) for v in self.exposures[: self.bracket_count]]

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
        build_merge_graph(self.node_tree, self.baked, self.bracket_exposures())

    def bracket_images(self) -> list[bpy.types.Image | None]:
        return [linked_image(socket) for socket in self.inputs[: self.bracket_count]]

    def update(self) -> None:
        """On new links: read the brackets as code values and fill their exposures."""
        images = self.bracket_images()
        for image in images:
            if image is not None and image.colorspace_settings.name != "Non-Color":
                image.colorspace_settings.name = "Non-Color"
        paths = [image_path(image) for image in images]
        signature = "\n".join(path or "" for path in paths)
        if signature == self.linked_files or not all(paths):
            return
        self.linked_files = signature
        try:
            values = exposures_for_files(paths)
        except HdrioError as error:
            self.message = f"exposures not read: {error}"
            return
        self.message = ""
        exposures = list(self.exposures)
        exposures[: len(values)] = values
        self.exposures = exposures  # rebuilds

    def draw_buttons(self, context, layout) -> None:
        layout.prop(self, "bracket_count")
        column = layout.column(align=True)
        for index in range(self.bracket_count):
            column.prop(self, "exposures", index=index, text=f"Bracket {index + 1} (s)")
        layout.label(text=f"Response: {self.baked.label}")
        if self.message:
            layout.label(text=self.message, icon="ERROR")
        layout.context_pointer_set("node", self)
        layout.operator("hdrio.solve_response", icon="GRAPH")


def _rebuild_reinhard(node: HdrioReinhardGlobalNode, _context=None) -> None:
    build_reinhard_global_graph(node.node_tree)


class HdrioReinhardGlobalNode(PrivateGroupMixin, bpy.types.CompositorNodeCustomGroup):
    """Reinhard et al. (2002) global operator from native nodes (key from Levels' mean)."""

    bl_idname = "CompositorNodeHdrioReinhardGlobal"
    bl_label = "Reinhard Global"
    bl_description = ("Reinhard 2002 global tone mapping (log-average key from the "
                      "compositor's image statistics); display-linear output in [0, 1]")
    bl_width_default = 200

    def init(self, context) -> None:
        tree = bpy.data.node_groups.new(".hdrio Reinhard Global", "CompositorNodeTree")
        self.node_tree = tree
        build_reinhard_global_graph(tree)
        # A new node's sockets start at 0, not at the interface's defaults.
        self.inputs["Key"].default_value = DEFAULT_KEY
        self.inputs["Saturation"].default_value = DEFAULT_SATURATION


CLASSES = (HdrioMergeNode, HdrioReinhardGlobalNode)
