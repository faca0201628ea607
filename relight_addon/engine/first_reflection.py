"""The first reflection of a scene's lights at the albedo of its incidence, from its faces'
materials (engine.incidence's D and excess, for a FaceSet meshed into a PatchSet; no bpy).

``incidence_of`` reads the faces' materials once per call: (per-patch material, incidence tables),
None when the scene has no direction-dependent material (then every function here gives None:
the transport reflects rho of every light).
"""
from __future__ import annotations

import numpy as np

from .incidence import first_bounce_matrices, incidence_tables, lamp_albedo_excess, lamp_excess
from .scene import FaceSet, PatchSet

__all__ = ["incidence_of", "first_bounce", "lights_excess", "lamp_excess_of"]


def incidence_of(faces: FaceSet, patches: PatchSet):
    """(per-patch material, incidence tables) of the faces' materials, None without any."""
    if faces.face_material is None or not faces.material_lobes:
        return None
    return np.asarray(faces.face_material, dtype=np.int64)[patches.face], incidence_tables(faces.material_lobes)


def first_bounce(faces: FaceSet, patches: PatchSet, F, sources):
    """engine.incidence's D per channel for the light leaving ``sources`` (a patch mask), from the
    faces' materials; None when the FaceSet has none or none depends on the incidence."""
    inc = incidence_of(faces, patches)
    return None if inc is None else first_bounce_matrices(F, patches.center, patches.normal, *inc,
                                                          np.flatnonzero(sources))


def lights_excess(faces: FaceSet, patches: PatchSet, lights, lamps=None, H=None):
    """engine.incidence.lamp_excess of the lights of irradiance kinds (their Lamp in
    ``lights.lamps``; or of ``lamps`` with irradiance ``H``): their first reflection with the albedo
    of its incidence; None without lamps or without a direction-dependent material."""
    inc = incidence_of(faces, patches)
    if lamps is None:
        if lights is None or lights.irradiance is None or lights.lamps is None:
            return None
        lamps, H = lights.lamps, lights.irradiance
    return None if inc is None else lamp_excess(lamps, H, patches.center, patches.normal, *inc)


def lamp_excess_of(faces: FaceSet, patches: PatchSet):
    """(lamp -> (P,) its first reflection's albedo excess per unit of its irradiance), or None
    without a direction-dependent material: a refined lamp's (engine.lamp_refinement.Transport)."""
    inc = incidence_of(faces, patches)
    return None if inc is None else (lambda lamp: lamp_albedo_excess(lamp, patches.center, patches.normal, *inc))
