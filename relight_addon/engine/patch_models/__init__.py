"""Patch models (see engine.registry): how a FaceSet becomes patches (the radiosity elements)
and candidate lights. Each module registers one class in PATCH_MODELS with

    model = Model(options, default_max_patch_size=None)
    patches = model.mesh(faces)                # PatchSet
    lights = model.lights(patches, mask)       # LightSet over the candidate patches ``mask``
"""
from . import adaptive, polygon  # noqa: F401  (registration order = UI order)
