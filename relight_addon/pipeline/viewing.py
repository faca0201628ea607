"""What a bake (a view along each face's normal) shows, for the reports (no bpy).

``normal_radiance(...)``: per base-mesh polygon, the radiance seen along the polygon's normal
(engine/view_radiance.py: the radiosity's incident light through the material's BSDF), for
the chosen patches' polygons;
written in the reports as ``objects.<name>.radiance_normal`` (W m^-2 sr^-1, None where not
computed; not computed above MAX_PATCHES patches). For Lambertian materials it is B/pi; for
glossy ones it predicts what a Cycles COMBINED bake shows, while B/pi is the Lambertian
model's average over view directions.
"""
from __future__ import annotations

import numpy as np

from ..engine.view_radiance import view_radiance
from ..engine.units import TINY

#: above this many chosen patches it is not computed (work: chosen patches x all patches)
MAX_PATCHES = 20000


def normal_radiance(faces, patches, F, B, face_material, material_lobes, polygon_counts, mask=None,
                    exitance=None, scene_light=None, placed=None, emission_share=None,
                    direct_correction=None) -> dict:
    """{object name: [rgb or None per polygon]}: the normal-view radiance of every polygon with
    a patch in ``mask`` (default: all), its patches' area-weighted mean. ``exitance`` (P, 3):
    the emitters' (view_radiance's). ``scene_light``: (H (P, n, 3) W/m^2, the direct light of
    ``faces.lamps`` and then of the World: jobs.scene_light), reflected through each patch's BSDF
    at the lamp's direction (from the patch's centre; the World's as the radiosity model does).
    ``placed``: [(engine.lamps.Lamp, H (P, 3) W/m^2)], the direct light of the lamps the solve placed
    (jobs.placed_light_at), reflected the same way. ``emission_share``: view_radiance's (default:
    formfactors.FormFactors.emission_share). ``direct_correction``: view_radiance's (the kernel's
    direct light of the configuration's emitters beyond F's gather)."""
    from .polygons import PolygonMap

    P = patches.n_patches
    mask = np.ones(P, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    sel = np.flatnonzero(mask)
    material = np.asarray(face_material)[patches.face]
    L = np.zeros((P, 3))
    lamp_light = []
    if scene_light is not None:
        H = np.asarray(scene_light, dtype=np.float64)
        for k in range(H.shape[1]):
            lamp = faces.lamps[k] if k < len(faces.lamps) else None  # the columns after the lamps: the World
            if lamp is None:
                towards = None
            else:
                towards = lamp.kind.towards(lamp, patches.center)
            lamp_light.append((towards, H[:, k]))
    for lamp, H in placed or ():
        d = lamp.position[None, :] - patches.center
        lamp_light.append((d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), TINY),
                           np.asarray(H, dtype=np.float64)))
    if emission_share is None:
        emission_share = getattr(F, "emission_share", None)
    L[sel] = view_radiance(F, B, patches.reflectance, patches.center, patches.normal, sel, material, material_lobes,
                           exitance=exitance, lamp_light=lamp_light, emission_share=emission_share,
                           direct_correction=direct_correction)
    pmap = PolygonMap(faces, patches, polygon_counts)
    W = pmap.weights
    covered = np.asarray(W @ mask.astype(np.float64)).reshape(-1)
    full = np.asarray(W @ np.ones(P)).reshape(-1)
    vals = np.asarray(W @ L)
    ok = (full > 0) & (covered >= full - 1e-9)  # every patch of the polygon was computed
    out = {}
    for oi, name in enumerate(pmap.names):
        a, b = pmap.offset[oi], pmap.offset[oi + 1]
        out[name] = [vals[k].tolist() if ok[k] else None for k in range(a, b)]
    return out
