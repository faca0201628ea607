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

__all__ = ["STATE_PROP", "DATA_PROP", "before", "world_matrix", "visible_before", "set_power", "disable", "restore"]

STATE_PROP = "relight_lamp_original"
DATA_PROP = "relight_lamp_original_data"
#: the owner property of everything Relight makes (export.RELIGHT_OWNER_PROP)
OWNER_PROP = "relight_owner"


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
