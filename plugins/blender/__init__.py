"""hdrio for Blender: merge bracketed exposures and tone-map them in the compositor.

A thin front end over hdrio's public API (``hdrio.job.run`` and the core modules):

* ``HDR Merge`` node: hdrio's default merge in native compositor nodes, its tables baked
  into RGB Curves (``nodes.py``, ``merge_graph.py``, ``baking.py``);
* ``Reinhard Global`` node from native nodes (``reinhard_graph.py``);
* operators: Solve Camera Response, Merge Brackets to EXR, Reinhard Local through hdrio,
  Use Standard View (``operators.py``); the sidebar panel (``panel.py``);
* hdrio's kernels compiled in a background thread when the extension is enabled
  (``warmup.py``), with the progress in the status bar.

``bpy`` is imported only when Blender registers the extension, so the modules that need
no Blender (``baking``, ``exposures``, ``warmup``) are importable and tested without it.
"""

from __future__ import annotations

_PROGRESS_SECONDS = 0.5


def _classes() -> tuple:
    from . import nodes, operators, panel

    return (*nodes.CLASSES, *operators.CLASSES, *panel.CLASSES)


def _show_warmup_progress() -> float | None:
    """Timer: the kernel warm-up's progress in the window manager and the status bar."""
    import bpy

    from .compat import show_status
    from .warmup import WARMUP

    manager = bpy.context.window_manager
    if WARMUP.finished:
        if manager is not None:
            manager.progress_end()
        # A failure stays in the status bar; success clears the progress line.
        show_status(WARMUP.status() if WARMUP.error else "", owner=id(WARMUP))
        return None
    if manager is not None:
        manager.progress_begin(0, len(WARMUP.steps))
        manager.progress_update(WARMUP.done)
    show_status(WARMUP.status(), owner=id(WARMUP))
    return _PROGRESS_SECONDS


def register() -> None:
    import bpy

    from . import nodes, panel
    from .warmup import WARMUP

    for cls in _classes():
        bpy.utils.register_class(cls)
    panel.register_menus()
    bpy.app.handlers.load_post.append(nodes.refresh_curves)
    WARMUP.start()
    if not bpy.app.background:
        bpy.app.timers.register(_show_warmup_progress, first_interval=_PROGRESS_SECONDS)


def unregister() -> None:
    import bpy

    from . import nodes, panel

    if bpy.app.timers.is_registered(_show_warmup_progress):
        bpy.app.timers.unregister(_show_warmup_progress)
    if nodes.refresh_curves in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(nodes.refresh_curves)
    panel.unregister_menus()
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
