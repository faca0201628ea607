"""Blender layer of Relight (bpy). Thin: operators and panels call relight_addon.pipeline.jobs.

Registers the preferences, the scene/object properties, the operators and the sidebar
panels (whose tab name comes from the preferences).
The add-on's own package is ``blender.ADDON_PACKAGE`` (found through ``__package__``,
never hard-coded).
"""

import bpy

from .. import ADDON_PACKAGE


class RelightPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_PACKAGE

    sidebar_tab: bpy.props.StringProperty(
        name="Sidebar Tab Name",
        description="Name of the 3D Viewport sidebar tab that shows the Relight panels",
        default="Relight",
        update=lambda self, context: self._retab(context),
    )
    threads: bpy.props.IntProperty(
        name="Threads",
        description="Worker threads for form factors and solves (0 = all cores)",
        default=0,
        min=0,
        soft_max=256,
    )

    def _retab(self, context):
        from . import display, panels

        display.unregister_panel()  # (a sub-panel of the Results panel: off before it, on after it)
        panels.unregister()
        panels.register(self.sidebar_tab or "Relight")
        display.register_panel(self.sidebar_tab or "Relight")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "sidebar_tab")
        layout.prop(self, "threads")


def preferences(context=None):
    """This add-on's preferences, or None when it is not enabled as an add-on."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_PACKAGE)
    return addon.preferences if addon is not None else None


_classes = (RelightPreferences,)


def register():
    from . import display, operators, panels, properties, render_settings, view_target_ops

    for cls in _classes:
        bpy.utils.register_class(cls)
    properties.register()
    operators.register()
    view_target_ops.register()
    render_settings.register()
    prefs = preferences()
    tab = prefs.sidebar_tab if prefs is not None and prefs.sidebar_tab else "Relight"
    panels.register(tab)
    display.register(tab)
    bpy.app.handlers.load_post.append(_sync_curve_on_load)


def unregister():
    from . import display, operators, panels, properties, render_settings, view_target_ops
    from .. import live

    live.stop()

    if _sync_curve_on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_sync_curve_on_load)
    display.unregister()
    panels.unregister()
    render_settings.unregister()
    view_target_ops.unregister()
    operators.unregister()
    properties.unregister()
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)


@bpy.app.handlers.persistent
def _sync_curve_on_load(*_args):
    """A file saved by the CLI carries the curve but not the UI list: fill it in. The prepared
    scenes of the file before are let go (preparation.PREPARED: another file's scenes)."""
    from . import operators
    from ..preparation import PREPARED, PREPARED_JOBS

    PREPARED.clear()
    PREPARED_JOBS.clear()
    from .. import live

    live.stop()  # Live follows the file it was turned on in

    for scene in bpy.data.scenes:
        try:
            operators.sync_curve_list(scene)
        except (KeyError, ValueError) as exc:
            print(f"Relight: cannot read the stored result of scene {scene.name!r}: {exc}")
