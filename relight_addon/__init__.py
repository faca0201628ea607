"""Relight: inverse lighting for Blender (Contensin, "Redistributing Light").

This file stays importable without bpy so that ``relight_addon.engine`` can be
used and tested on its own; the Blender layer is imported in ``register()``.
An installed extension is imported as ``bl_ext.<repo>.<this package>``: code
refers to its own package through ``__package__``, never by name.
"""


def register():
    from .blender import ui

    ui.register()


def unregister():
    from .blender import ui

    ui.unregister()
