"""Blender layer of Relight (bpy). Thin: operators and panels call relight_addon.jobs.

For now this registers the add-on preferences only; the UI module extends it.
The add-on's own package is the parent of this one (``bl_ext.<repo>.relight`` when
installed as an extension, ``relight_addon`` when used from the repository); it is
found through ``__package__``, never hard-coded.
"""

import bpy

ADDON_PACKAGE = __package__.rpartition(".")[0]


class RelightPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_PACKAGE

    sidebar_tab: bpy.props.StringProperty(
        name="Sidebar Tab Name",
        description="Name of the 3D Viewport sidebar tab that shows the Relight panels",
        default="Relight",
    )
    threads: bpy.props.IntProperty(
        name="Threads",
        description="Worker threads for form factors and solves (0 = all cores)",
        default=0,
        min=0,
        soft_max=256,
    )

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
    for cls in _classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
