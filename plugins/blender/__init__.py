"""hdrio for Blender: merge bracketed exposures and tone-map them in the compositor.

A thin front end over hdrio's public API (``hdrio.pipeline`` and the core modules):

* ``HDR Merge`` node: hdrio's linear merge in native compositor nodes, with the camera
  response baked into RGB Curves (``nodes.py``, ``merge_graph.py``, ``baking.py``);
* ``Reinhard Global`` node from native nodes (``reinhard_graph.py``);
* operators: Solve Camera Response, Merge Brackets to EXR, Reinhard Local through hdrio
  (``operators.py``); the sidebar panel (``panel.py``).

``bpy`` is imported only when Blender registers the extension, so the modules that need
no Blender (``baking``, ``exposures``) are importable and tested without it.
"""

from __future__ import annotations


def _classes() -> tuple:
    from . import nodes, operators, panel

    return (*nodes.CLASSES, *operators.CLASSES, *panel.CLASSES)


def register() -> None:
    import bpy

    from . import panel

    for cls in _classes():
        bpy.utils.register_class(cls)
    panel.register_menus()


def unregister() -> None:
    import bpy

    from . import panel

    panel.unregister_menus()
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
