"""The hdrio panel in the compositor's sidebar (N panel, tab "hdrio")."""

from __future__ import annotations

import bpy

from .nodes import HdrioMergeNode
from .warmup import WARMUP


class HDRIO_PT_compositor(bpy.types.Panel):
    bl_label = "hdrio"
    bl_space_type = "NODE_EDITOR"
    bl_region_type = "UI"
    bl_category = "hdrio"

    @classmethod
    def poll(cls, context):
        return getattr(context.space_data, "tree_type", "") == "CompositorNodeTree"

    def draw(self, context):
        layout = self.layout
        if WARMUP.running or WARMUP.error:
            layout.label(text=WARMUP.status(), icon="ERROR" if WARMUP.error else "TIME")
        column = layout.column(align=True)
        column.operator("hdrio.add_node", text="HDR Merge").node_type = (
            "CompositorNodeHdrioMerge")
        column.operator("hdrio.add_node", text="Reinhard Global").node_type = (
            "CompositorNodeHdrioReinhardGlobal")
        layout.operator("hdrio.merge_to_exr", icon="IMAGE_DATA")
        layout.operator("hdrio.tonemap_local", icon="IMAGE_RGB")
        node = context.active_node
        if isinstance(node, HdrioMergeNode):
            box = layout.box()
            box.label(text=node.name)
            node.draw_buttons(context, box)


def draw_add_menu(menu, context) -> None:
    """hdrio's nodes at the end of the compositor's Add > Color menu."""
    layout = menu.layout
    layout.separator()
    for idname, label in (("CompositorNodeHdrioMerge", "HDR Merge"),
                          ("CompositorNodeHdrioReinhardGlobal", "Reinhard Global")):
        operator = layout.operator("node.add_node", text=label)
        operator.type = idname
        operator.use_transform = True


ADD_MENU = "NODE_MT_category_compositor_color"  # in Blender 4.2 to 5.0

CLASSES = (HDRIO_PT_compositor,)


def register_menus() -> None:
    getattr(bpy.types, ADD_MENU).append(draw_add_menu)


def unregister_menus() -> None:
    getattr(bpy.types, ADD_MENU).remove(draw_add_menu)
