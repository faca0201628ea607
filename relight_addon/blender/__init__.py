"""The Blender layer (bpy): the scene in (export.py, materials.py), the results out (results.py,
light_paths.py), the one preparation step of a solve (preparation.py) and the sidebar (ui/).
Thin: the physics is in ``engine/`` and the stages in ``pipeline/``, neither of which imports bpy.

``ADDON_PACKAGE``: the add-on's own package, the parent of this one (``bl_ext.<repo>.relight``
when installed as an extension, ``relight_addon`` from the repository); never hard-coded.
"""
ADDON_PACKAGE = __package__.rpartition(".")[0]
