"""The scene's lamps and World, read as Cycles renders them (bpy): Blender Light objects ->
engine.lamps.Lamp, and a warning for every part of the scene's light that is not modelled.

Read: Point (power, colour, radius = soft size), Spot (and its cone: size and blend), Area
(square, rectangle, disk, ellipse; the object's scale scales the sizes, as in Cycles; its Spread,
which Cycles takes as it is: ``light->set_spread(b_area_light.spread())``,
intern/cycles/blender/light.cpp) and Sun (strength, angle) lamps that render (visible in the
view layer, not disabled for rendering, diffuse visibility on), in world space; their shadows
(Cast Shadow); a Point or Spot lamp whose node tree is an IES Texture node feeding its Emission
(blender/ies_nodes.py: a photometric lamp). Named in a warning, and not modelled: other light node
trees (an IES node on an Area lamp among them), light and shadow
linking, a point or spot lamp with soft falloff off (modelled as a point of the same intensity:
exact where the whole sphere is seen) and instanced lamps. As Cycles renders them (issue 35): a
lamp of negative Power is negative light (named; fixed light), an area lamp of size 0 gives none
(named, left out: ``Light::has_contribution``, intern/cycles/scene/light.cpp). The World:
blender/world.py.

What a lamp emits (``cycles_gain``, the one place Blender's light values become the engine's
Lamp.power, and through Lamp.gain back: engine.lights.lamp.blender_values): Cycles'
``BlenderSync::sync_light`` (intern/cycles/blender/light.cpp, Blender 4.5 on) sets the strength
colour x Power x 2^Exposure, times the Light's ``temperature_color`` (its blackbody colour) when
Use Temperature is on, and ``normalize``; ``intern/cycles/scene/light.cpp`` divides the strength by
``Light::area`` only when Normalize is on, so a Light with it off emits ``Light::area`` times its
Power: a point or spot 4 pi r^2 (4 at radius 0), an area lamp its area (its object's scale
included; a disk or ellipse pi/4 of the rectangle), a sun pi sin^2(angle / 2) (1 at angle 0). Blender
4.2 has none of the three (its lights emit colour x Power): read with their defaults.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..engine.lamps import Lamp
from ..engine.registry import LIGHT_KINDS
from ..engine.scene import SceneError
from . import ies_nodes, lamp_state

#: W: a lamp of more power is refused (an infinite Power, stored as 3.4e38)
MAX_LAMP_POWER = 1e15

__all__ = ["export_lamps", "cycles_gain", "make_plain", "KIND_OF_TYPE"]

#: the lamp kind (engine/lights/, its LIGHT_KINDS name) of each Blender Light type Relight reads:
#: the one place a Light's ``type`` becomes a kind (the kind reads the rest: LampKind.blender_settings)
KIND_OF_TYPE = {"POINT": "point", "SPOT": "spot", "AREA": "area", "SUN": "sun"}

#: the values of the Light settings Cycles multiplies colour x Power by, at which it emits colour x
#: Power (what Relight writes on the lamps it makes); Blender 4.2 lacks them
PLAIN = {"exposure": 0.0, "use_temperature": False, "normalize": True}


def _cycles(ld, name, default):
    c = getattr(ld, "cycles", None)
    return getattr(c, name, getattr(ld, name, default)) if c is not None else getattr(ld, name, default)


def make_plain(ld) -> None:
    """Give the Light ``ld`` the PLAIN settings (where this Blender has them): it emits colour x Power."""
    for k, v in PLAIN.items():
        if hasattr(ld, k):
            setattr(ld, k, v)


def lamp_kind(ld):
    """The lamp kind (engine.lights.LampKind) of the Blender Light ``ld`` (KIND_OF_TYPE)."""
    return LIGHT_KINDS[KIND_OF_TYPE[ld.type]].impl


def cycles_gain(ld, M) -> np.ndarray:
    """(3,) what Cycles multiplies the Light ``ld``'s colour x Power (a sun's Strength) by, ``M``
    its object's world matrix (4, 4): 2^Exposure, the blackbody colour with Use Temperature on, and
    ``Light::area`` with Normalize off (the module's docstring). 1 where this Blender lacks them."""
    gain = np.full(3, 2.0 ** float(getattr(ld, "exposure", 0.0)))
    if getattr(ld, "use_temperature", False):
        gain = gain * np.array(ld.temperature_color, dtype=np.float64)[:3]
    if not getattr(ld, "normalize", True):
        gain = gain * lamp_kind(ld).cycles_area(ld, M)
    return gain


def uses_nodes(idblock) -> bool:
    """Whether a World's or a light's node tree is what renders (``use_nodes`` is always on, and
    deprecated, from Blender 5.0)."""
    if getattr(idblock, "node_tree", None) is None:
        return False
    return bpy.app.version >= (5, 0, 0) or bool(getattr(idblock, "use_nodes", False))


def _default_light_nodes(ld) -> bool:
    """True when the light has no node tree, or only the default Emission (strength 1, white)."""
    if not uses_nodes(ld):
        return True
    kinds = sorted(n.type for n in ld.node_tree.nodes)
    if kinds != ["EMISSION", "OUTPUT_LIGHT"]:
        return False
    em = next(n for n in ld.node_tree.nodes if n.type == "EMISSION")
    col, strength = em.inputs["Color"], em.inputs["Strength"]
    return (not col.is_linked and not strength.is_linked and abs(strength.default_value - 1.0) < 1e-6
            and all(abs(v - 1.0) < 1e-6 for v in tuple(col.default_value)[:3]))


def _light_linking(ob) -> bool:
    ll = getattr(ob, "light_linking", None)
    return ll is not None and (getattr(ll, "receiver_collection", None) is not None
                               or getattr(ll, "blocker_collection", None) is not None)


def _read_lamp(ob, ld, was, warnings, dark):
    """The engine.lamps.Lamp of the lamp object ``ob`` (its Light ``ld``; ``was``: what a shown
    reduction keeps of it, lamp_state.before), None when it gives no light (``dark`` gets why, and
    ``warnings`` what is not modelled, as export_lamps says)."""
    name = ob.name
    color = np.array(ld.color if was is None else was["color"], dtype=np.float64)[:3]
    energy = float(ld.energy if was is None else was["energy"])
    if not (np.all(np.isfinite(color)) and np.isfinite(energy)):
        raise SceneError(f"lamp {name!r} has a NaN or infinite Power or Color: give it finite values")
    if not np.any(color * energy != 0):
        dark.append(f"{name!r} ({'0 W' if energy == 0 else 'colour black'})")
        return None
    M = lamp_state.world_matrix(ob)  # (a lamp disabled in the viewports has no matrix_world)
    X, Y, Z = M[:3, 0], M[:3, 1], M[:3, 2]
    sx, sy, sz = (float(np.linalg.norm(v)) for v in (X, Y, Z))
    if min(sx, sy, sz) <= 0:
        warnings.append(f"lamp {name!r} is scaled to zero: left out")
        dark.append(f"{name!r} (scaled to zero)")
        return None
    ies = None if _default_light_nodes(ld) else ies_nodes.photometric(ld, name)
    kind = lamp_kind(ld) if ies is None else ies.kind
    no_light = kind.blender_dark(ld, M)
    if no_light is not None:
        warnings.append(f"lamp {name!r} {no_light[0]}")
        dark.append(f"{name!r} ({no_light[1]})")
        return None
    gain = cycles_gain(ld, M) if ies is None else cycles_gain(ld, M) * ies.gain
    power = color * energy * gain  # what Cycles emits
    if not np.all(np.isfinite(power)) or float(np.max(np.abs(power))) > MAX_LAMP_POWER:
        raise SceneError(f"lamp {name!r} has a power of {energy:.3g} W and colour {tuple(color)}: a NaN or "
                         "infinite value? (Blender stores infinity as its largest number, 3.4e+38); give it "
                         "finite values")
    if not np.any(power != 0):
        dark.append(f"{name!r} (0 W after its Exposure, Temperature or Normalize)")
        return None
    if energy < 0:
        warnings.append(f"lamp {name!r} has a negative Power ({energy:.3g} W): Cycles renders it as negative "
                        "light (it takes light away where it shines); modelled so, as the scene's fixed light (a "
                        "reduction leaves it as it is)")
    kw = dict(name=name, kind=kind, position=M[:3, 3], direction=-Z / sz, axis_u=X / sx, axis_v=Y / sy,
              power=power, energy=energy, color=color, gain=gain,
              cast_shadow=bool(_cycles(ld, "cast_shadow", getattr(ld, "use_shadow", True))))
    own, notes = kind.blender_settings(ld, M)
    kw.update(own)
    if ies is not None:  # a measured distribution (blender/ies_nodes.py)
        kw["profile"] = ies.profile
        notes.extend(ies.notes)
    elif not _default_light_nodes(ld):
        notes.append("its light nodes (textures, IES, a changed Emission) are not modelled: read as a plain lamp")
    if _light_linking(ob):
        notes.append("light or shadow linking is not modelled: it lights and is shadowed by every object")
    warnings.extend(f"lamp {name!r}: {n}" for n in notes)
    return Lamp(**kw)


def export_lamps(context, renderable, owner_of, dark=None) -> tuple:
    """(lamps, warnings): the scene's lamps as engine.lamps.Lamp, and what is not modelled.
    ``renderable``: the names of the objects that render (visibility.render_visible_objects);
    ``owner_of(ob)``: the result that made ``ob`` (visibility.owner_of: its lamps are not scene light).
    ``dark``: a list that gets, for each lamp that renders but emits nothing in Cycles, its name
    and why ("'Key' (0 W)"): a lamp of Power 0 or a black colour, an area lamp of size 0
    (``Light::has_contribution``, intern/cycles/scene/light.cpp: "Area light with a size of zero
    does not contribute to the scene"), a lamp scaled to zero.

    A lamp of negative Power is kept, negative: Cycles renders it so (``has_contribution`` only
    leaves out a strength of exactly 0; the kernel adds its negative light), so its light is
    taken away where it shines; named in a warning (a solve keeps it as fixed light, a reduction
    leaves it as it is)."""
    scene, view_layer = context.scene, context.view_layer
    lamps, warnings, hidden = [], [], []
    dark = [] if dark is None else dark
    for ob in scene.objects:
        if ob.type != "LIGHT":
            continue
        # a lamp that a shown reduction changed is read as the user set it (a new result replaces that one)
        was = lamp_state.before(ob)
        if (ob.hide_render if was is None else was["hide_render"]) or ob.name not in renderable:
            continue
        if owner_of(ob) is not None:
            continue
        if not (ob.visible_get(view_layer=view_layer) if was is None
                else lamp_state.visible_before(ob, view_layer, was)):
            hidden.append(ob.name)  # hidden in the viewport only: Cycles renders it
        ld = ob.data if was is None else was["data"]
        if not getattr(ob, "visible_diffuse", True):
            warnings.append(f"lamp {ob.name!r} does not light diffuse surfaces (Object > Visibility > Diffuse off): "
                            "left out, as Cycles leaves it out of their light")
            continue
        lamp = _read_lamp(ob, ld, was, warnings, dark)
        if lamp is not None:
            lamps.append(lamp)
    n_inst = 0
    depsgraph = context.evaluated_depsgraph_get()
    for inst in depsgraph.object_instances:
        if inst.is_instance and inst.object.type == "LIGHT":
            n_inst += 1
    if n_inst:
        warnings.append(f"{n_inst} instanced lamp(s) (in collection instances or particle systems) are not "
                        "modelled: Cycles renders their light, the prediction leaves it out")
    if hidden:
        warnings.append(hidden_warning(hidden, "lamp"))
    return lamps, warnings


def hidden_warning(names, what="object") -> str:
    """The warning naming what is hidden in the viewport and modelled (docs/reliability.md)."""
    return (f"{len(names)} {what}(s) hidden in the viewport are modelled, because Cycles renders them: "
            f"{', '.join(map(repr, names[:10]))}{' ...' if len(names) > 10 else ''}; to leave one out, hide it "
            "from render too (the camera icon in the Outliner)")
