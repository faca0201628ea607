"""The scene's materials as the engine reads them (bpy): per face a reflectance and an exitance.

Materials (per face, through ``material_index`` and the object's material slots): materials.py
- reflectance = the material's white-furnace albedo as Cycles renders it (a Principled BSDF's
  specular layer included: engine/principled.py), emitted radiance L_e (linear RGB);
  Principled BSDF, Diffuse BSDF, Emission, Mix Shader and Add Shader are read, the
  approximations (metallic, transmission, coat, sheen, subsurface, alpha) and anything not
  read (other shaders and node groups, linked colours: the viewport colour
  ``Material.diffuse_color``) are named in a warning.
- No material: reflectance 0.8 grey.
- Exitance e = pi * L_e (W/m^2). Reflectance is clamped to [0, MAX_REFLECTANCE] and
  negative emission to 0, with a warning.
- Linked emission (a texture, a procedural, an attribute... on an Emission Color / Strength, or
  a Mix Shader's linked factor over an emitting branch: materials.Closure.linked_emission): each
  face's mean emitted radiance over its area, from a Cycles EMIT bake of temporary copies
  (emission_bake.py; nothing of the user's data changes), then e = pi * L_e as above. Nothing
  is baked in a scene without linked emission. Instanced objects are not baked, and a bake that
  fails keeps the unlinked part: both named in a warning with the material and its linked input.


What Cycles renders and Relight does not model is named in a warning (``not_modelled``):
materials whose Volume output is linked, volume objects (the light is taken as passing through;
a World volume: world.py), objects with Shadow Catcher or Holdout on (lit and reported as
ordinary surfaces).
"""
from __future__ import annotations

import bpy
import numpy as np

from ..engine.scene import SceneError
from .visibility import rendered

DEFAULT_REFLECTANCE = 0.8
#: W/m^2/sr: a material emitting more is refused (the Sun's surface is about 2e7)
MAX_RADIANCE = 1e12


def material_properties(mat):
    """(reflectance (3,), radiance (3,), note or None) of a material: its white-furnace albedo
    and emitted radiance as Cycles renders it (materials.py; see the module docstring). A linked
    emission is not in ``radiance``: export_scene bakes it per face."""
    reflectance, radiance, notes = material_closure(mat)[:3]
    return reflectance, radiance, (f"material {scene_material(mat).name!r}: " + "; ".join(notes) if notes else None)


def scene_material(mat):
    """The scene's own material behind ``mat``: a Relight variant shown by an earlier solve has
    its source as the scene's material (the variant's emission is Relight's result, not the
    scene's light); None stays None."""
    if mat is not None and mat.get("relight_generated"):
        return bpy.data.materials.get(mat.get("relight_source", "")) or None
    return mat


def material_closure(mat):
    """``material_properties`` and the material's BSDFs (materials.Closure.lobes, for
    view-dependent radiance) and linked emission (materials.Closure.linked_emission, baked by
    export_scene): (reflectance, radiance, notes (list), lobes, linked_emission)."""
    from .materials import surface_closure

    mat = scene_material(mat)
    if mat is None:
        grey = np.full(3, DEFAULT_REFLECTANCE)
        return grey, np.zeros(3), [], [(1.0, "diffuse", (grey, 0.0))], []
    c = surface_closure(mat)
    for part, v in (("colour (its reflectance)", c.reflectance), ("emission (colour x strength)", c.radiance)):
        if not np.all(np.isfinite(v)):
            raise SceneError(f"material {mat.name!r} has a NaN or infinite {part}: give it finite values")
    if float(np.max(c.radiance, initial=0.0)) > MAX_RADIANCE:
        raise SceneError(f"material {mat.name!r} emits a radiance of {float(np.max(c.radiance)):.3g} W/m^2/sr: an "
                         "infinite Emission Strength? (Blender stores infinity as its largest number, 3.4e+38); "
                         "give it a finite strength")
    return c.reflectance, c.radiance, list(c.notes), c.lobes, c.linked_emission


#: a note shared by many materials names this many of them
NAMED_MATERIALS = 3


def material_warnings(noted: dict) -> list:
    """One warning per note (what a material's model leaves out), naming the materials that
    have it: ``noted`` maps material name -> its notes."""
    by_note = {}
    for name, notes in noted.items():
        for note in notes:
            by_note.setdefault(note, []).append(name)
    out = []
    for note, names in by_note.items():
        shown = ", ".join(repr(n) for n in names[:NAMED_MATERIALS])
        if len(names) == 1:
            out.append(f"material {shown}: {note}")
        else:
            more = f" and {len(names) - NAMED_MATERIALS} more" if len(names) > NAMED_MATERIALS else ""
            out.append(f"{len(names)} materials ({shown}{more}): {note}")
    return out


def _volume_output(mat) -> bool:
    """Whether the material's active output (All or Cycles) has its Volume input linked."""
    from .materials import active_output

    out = active_output(mat)
    return out is not None and "Volume" in out.inputs and any(not l.is_muted for l in out.inputs["Volume"].links)


def not_modelled(context, objs, b, renderable) -> list:
    """Warnings naming what Cycles renders and Relight does not model: volumes (materials with a
    Volume output, volume objects; a World volume: world.py), shadow catchers and holdouts."""
    out = []
    vol = sorted(n for n, m in b.materials_used.items() if _volume_output(m))
    if vol:
        out.append(f"material(s) {', '.join(map(repr, vol))}: a volume shader is linked to the Volume output; volumes "
                   "(absorption, scattering, emission) are not modelled: Relight treats the light as passing through "
                   "and reads only the surface")
    volumes = [ob.name for ob in context.scene.objects if ob.type == "VOLUME" and rendered(ob, renderable)]
    if volumes:
        out.append(f"volume object(s) {', '.join(map(repr, volumes[:10]))}{' ...' if len(volumes) > 10 else ''}: "
                   "volumes are not modelled (Relight treats light as passing through them)")
    catchers = [ob.name for ob in objs if getattr(ob, "is_shadow_catcher", False)]
    if catchers:
        out.append(f"object(s) {', '.join(map(repr, catchers))}: Shadow Catcher (Object > Visibility) is not modelled: "
                   "Relight lights and reports them as ordinary surfaces (their material reflects and occludes)")
    holdouts = [ob.name for ob in objs if getattr(ob, "is_holdout", False)]
    if holdouts:
        out.append(f"object(s) {', '.join(map(repr, holdouts))}: Holdout (Object > Visibility) is not modelled: "
                   "Relight treats them as ordinary surfaces (their material reflects and occludes)")
    return out
