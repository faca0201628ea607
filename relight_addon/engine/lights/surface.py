"""What the surface kinds share (no bpy): a light that emits one exitance (W/m^2) uniformly
from a set of candidate patches, diffusely (Lambertian, one-sided, along the patches' normals),
shown in the scene by its patches' triangles (the emitters object) and made into area lights
one per patch by *Make Area Lights* (results.py, writer "surface")."""
from __future__ import annotations

from ..registry import LIGHT_KINDS
from .kind import LightKind


def register_surface_kind(name, label, description):
    """Register a surface kind (exitance source, strength in W/m^2, shown as its patches)."""
    kind = LightKind(name, label, description, source="exitance", strength_unit="W/m^2", shape="patches",
                     writer="surface")
    LIGHT_KINDS.register(name, label, description)(kind)
    return kind
