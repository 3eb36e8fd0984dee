"""What differs between the Blender versions the extension supports (4.5 and 5.0), and
the status bar.

Facts checked on the PyPI ``bpy`` 4.5.15 and 5.0.1:

* 5.0 dropped the compositor's own Math and Value nodes; compositor trees use the shader
  ``ShaderNodeMath``. 4.5 has ``CompositorNodeMath``.
* 5.0's compositor is ``scene.compositing_node_group`` (a ``CompositorNodeTree`` whose
  Group Output is the result; ``CompositorNodeComposite`` is gone). In 4.5 it is
  ``scene.node_tree`` after ``scene.use_nodes = True``, ending in a Composite node.
"""

from __future__ import annotations

import bpy

IS_5 = bpy.app.version >= (5, 0, 0)
MATH_NODE = "ShaderNodeMath" if IS_5 else "CompositorNodeMath"


def compositor_tree(scene: bpy.types.Scene, create: bool = True) -> bpy.types.NodeTree | None:
    """The scene's compositor node tree (made, with its output node, when ``create``)."""
    if IS_5:
        tree = scene.compositing_node_group
        if tree is None and create:
            tree = bpy.data.node_groups.new(f"{scene.name} Compositing", "CompositorNodeTree")
            tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
            tree.nodes.new("NodeGroupOutput")
            scene.compositing_node_group = tree
        return tree
    if create and not scene.use_nodes:
        scene.use_nodes = True
    return scene.node_tree


def compositor_result_socket(tree: bpy.types.NodeTree) -> bpy.types.NodeSocket:
    """The input socket whose image is the composited (rendered) result."""
    kind = "NodeGroupOutput" if IS_5 else "CompositorNodeComposite"
    node = next((n for n in tree.nodes if n.bl_idname == kind), None)
    if node is None:
        node = tree.nodes.new(kind)
        if IS_5 and not tree.interface.items_tree:
            tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    return node.inputs[0]


def active_compositor_tree(context: bpy.types.Context) -> bpy.types.NodeTree | None:
    """The compositor tree shown in the node editor, else the scene's (or ``None``)."""
    space = getattr(context, "space_data", None)
    tree = getattr(space, "edit_tree", None)
    if tree is not None and tree.bl_idname == "CompositorNodeTree":
        return tree
    return compositor_tree(context.scene, create=False)


def find_node_tree(name: str) -> bpy.types.NodeTree | None:
    """A node tree by name: a node group, or (4.x) a scene's embedded compositor tree."""
    tree = bpy.data.node_groups.get(name)
    if tree is not None:
        return tree
    return next((scene.node_tree for scene in bpy.data.scenes
                 if getattr(scene, "node_tree", None) is not None
                 and scene.node_tree.name == name), None)


_status_owner: int | None = None


def show_status(text: str, owner: int = 0) -> None:
    """Show ``text`` in every window's status bar; ``""`` clears it, but only the text
    the same ``owner`` (a node's pointer, say) put there. No-op without windows."""
    global _status_owner
    if not text and _status_owner != owner:
        return
    _status_owner = owner if text else None
    manager = getattr(bpy.context, "window_manager", None)
    for window in getattr(manager, "windows", ()):
        if window.workspace is not None:
            window.workspace.status_text_set(text or None)
