"""The scene's lamps as Relight changes them, and gives them back (bpy).

In direct-lighting mode ("reduce") a configuration is shown by the scene's own lamps: a kept lamp
gets its new Power (a Sun: Strength) and colour (its Exposure, Temperature and Normalize are kept:
results.plan_lamps' Power and colour emit the solved power through them), the others are disabled for render and in the
viewports (``hide_render``, ``hide_viewport``). Before the first change, what the lamp was is kept
on its object (custom property ``relight_lamp_original``: Power, colour, the two switches and the
id of the result that changed it), and when its Light data-block is shared with other objects it
gets a copy of its own (the original kept in ``relight_lamp_original_data``, by identity), so
that no other lamp changes with it. ``restore`` gives the lamp back exactly; ``before`` is what the
lamp is without Relight's changes (what a new solve sees: every new result replaces the shown one).
"""
from __future__ import annotations

import bpy
import numpy as np

__all__ = ["STATE_PROP", "DATA_PROP", "before", "world_matrix", "visible_before", "set_power", "disable", "restore",
           "animated", "check_not_animated"]

STATE_PROP = "relight_lamp_original"
DATA_PROP = "relight_lamp_original_data"
#: the owner property of everything Relight makes (visibility.RELIGHT_OWNER_PROP)
OWNER_PROP = "relight_owner"


#: what Relight writes on a lamp (set_power, disable): on its object, and on its Light
WRITTEN_OBJECT = ("hide_render", "hide_viewport")
WRITTEN_LIGHT = ("energy", "color")
_LABELS = {"energy": "Power", "color": "Color", "hide_render": "Disable in Renders",
           "hide_viewport": "Disable in Viewports"}


def _fcurves(action, slot):
    """The F-curves of ``action`` that animate the data-block of ``slot`` (Blender 4.4 on: slotted
    actions; before: the action's own F-curves)."""
    if action is None:
        return []
    if hasattr(action, "fcurves"):
        return list(action.fcurves)
    from bpy_extras import anim_utils

    bag = anim_utils.action_get_channelbag_for_slot(action, slot) if slot is not None else None
    return list(bag.fcurves) if bag is not None else []


def animated(idb, props) -> list:
    """The properties of ``props`` on ``idb`` that animation sets when the file is opened, the frame
    changes or it renders -- a driver, or keyframes (its action's F-curves, or an unmuted NLA strip's)
    -- each as "Power (a driver)", "Color (keyframes)": what Relight writes there would be overridden."""
    ad = getattr(idb, "animation_data", None)
    if ad is None:
        return []
    found = {}
    for fc in ad.drivers:
        if fc.data_path in props and not fc.mute:
            found.setdefault(fc.data_path, "a driver")
    actions = [(ad.action, getattr(ad, "action_slot", None))]
    actions += [(strip.action, getattr(strip, "action_slot", None)) for track in ad.nla_tracks if not track.mute
                for strip in track.strips if not strip.mute]
    for action, slot in actions:
        for fc in _fcurves(action, slot):
            if fc.data_path in props and not fc.mute:
                found.setdefault(fc.data_path, "keyframes")
    return [f"{_LABELS.get(p, p)} ({found[p]})" for p in props if p in found]


def check_not_animated(ob, power=True) -> None:
    """SceneError, before anything is written, when animation would override what Relight writes on
    the lamp ``ob`` (issue 35, case 8): its Disable in Renders/Viewports, and with ``power`` its
    Power and Color. Refused, not warned: the copy or the scene would render another light than
    the configuration shown and reported, whatever the warning said."""
    from ..engine.scene import SceneError

    what = animated(ob, WRITTEN_OBJECT) + (animated(ob.data, WRITTEN_LIGHT) if power and ob.data else [])
    if what:
        raise SceneError(f"lamp {ob.name!r}: {', '.join(what)} would override what Relight sets there: nothing "
                         "written; remove them (right-click the property: Delete Driver / Clear Keyframes) or "
                         "leave the lamp out")


def before(ob) -> dict | None:
    """The lamp ``ob`` (a LIGHT object) as it was before Relight changed it: {"energy", "color",
    "hide_render", "hide_viewport", "data" (its own Light data-block)}, or None when unchanged."""
    state = ob.get(STATE_PROP)
    if state is None:
        return None
    data = ob.get(DATA_PROP)
    return {"energy": float(state["energy"]), "color": tuple(float(x) for x in state["color"]),
            "hide_render": bool(state["hide_render"]), "hide_viewport": bool(state["hide_viewport"]),
            "owner": str(state.get("owner", "")),
            "data": data if isinstance(data, bpy.types.Light) else ob.data}


def world_matrix(ob) -> np.ndarray:
    """(4, 4) world matrix of ``ob``. An object disabled in the viewports is not evaluated (a file
    opened with it disabled has no ``matrix_world``): its own transform and its parents' are
    composed instead (their constraints and drivers are not evaluated then)."""
    if not ob.hide_viewport:
        return np.array(ob.matrix_world, dtype=np.float64)
    M = np.array(ob.matrix_parent_inverse, dtype=np.float64) @ np.array(ob.matrix_basis, dtype=np.float64)
    return M if ob.parent is None else world_matrix(ob.parent) @ M


def visible_before(ob, view_layer, was) -> bool:
    """Whether ``ob`` was visible in ``view_layer`` before Relight disabled it: hidden now only by
    Relight's ``hide_viewport``, it is visible when its own view-layer switch and one of its
    collections in the layer are."""
    if ob.visible_get(view_layer=view_layer) or was["hide_viewport"] or not ob.hide_viewport:
        return ob.visible_get(view_layer=view_layer)
    if ob.hide_get(view_layer=view_layer):
        return False

    def visible(lc):
        if lc.exclude:
            return False
        if ob.name in lc.collection.objects and lc.is_visible:
            return True
        return any(visible(child) for child in lc.children)

    return visible(view_layer.layer_collection)


def _remember(ob, rid):
    """Keep what the lamp is before its first change (and give it a Light of its own if shared)."""
    if STATE_PROP in ob.keys():
        return
    ld = ob.data
    ob[STATE_PROP] = {"owner": rid or "", "energy": float(ld.energy), "color": [float(x) for x in ld.color],
                      "hide_render": bool(ob.hide_render), "hide_viewport": bool(ob.hide_viewport)}
    if ld.users > 1:
        own = ld.copy()
        own.name = f"{ld.name} (Relight)"
        own[OWNER_PROP] = rid or ""
        ob[DATA_PROP] = ld
        ob.data = own


def set_power(ob, rid, energy, color):
    """Show the lamp with Power (Sun: Strength) ``energy`` and ``color``, enabled as it was."""
    _remember(ob, rid)
    was = before(ob)
    ob.data.energy = float(energy)
    ob.data.color = tuple(float(x) for x in color)
    ob.hide_render, ob.hide_viewport = was["hide_render"], was["hide_viewport"]


def disable(ob, rid):
    """Switch the lamp off for render and in the viewports (its Power and colour kept)."""
    _remember(ob, rid)
    ob.hide_render = True
    ob.hide_viewport = True


def restore(ob) -> bool:
    """Give the lamp back exactly as it was before Relight changed it; False when unchanged."""
    was = before(ob)
    if was is None:
        return False
    own = ob.data
    if DATA_PROP in ob.keys():
        original = ob.get(DATA_PROP)
        del ob[DATA_PROP]
        if isinstance(original, bpy.types.Light) and original is not own:
            ob.data = original
            if own.get(OWNER_PROP) is not None and own.users == 0:
                bpy.data.lights.remove(own)
    if ob.data is own:  # its own data-block was changed: its values back
        own.energy = was["energy"]
        own.color = was["color"]
    ob.hide_render, ob.hide_viewport = was["hide_render"], was["hide_viewport"]
    del ob[STATE_PROP]
    return True
