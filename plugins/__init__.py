"""Front ends that live inside host applications (``blender/``: the Blender extension).

``hdrio`` never imports this package; these adapters import ``hdrio``.
"""
