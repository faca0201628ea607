"""The 3D Viewports' shading while Relight shows its predicted radiosity.

Showing the radiosity means Solid shading with Color: Attribute (the active colour attribute,
``relight_radiosity`` after a solve). The shading each viewport had before is remembered in
``scene.relight.view_restore`` (JSON, saved with the file) and given back by Hide Radiosity
and by Clear Results, so the artist's viewport is never left in Attribute colour; with it, the
scene's view transform a false-colour view replaced (display.py).
"""
from __future__ import annotations

import json

import bpy

from .. import layers
from . import display


def _key(window, screen, area_index):
    return f"{screen.name}/{area_index}"


def _views(context):
    """(key, SpaceView3D) of every 3D Viewport in the open windows."""
    wm = context.window_manager
    out = []
    for window in wm.windows if wm is not None else ():
        screen = window.screen
        for i, area in enumerate(screen.areas):
            if area.type == "VIEW_3D":
                out.append((_key(window, screen, i), area.spaces.active, area))
    return out


def _memory(scene) -> dict:
    try:
        return json.loads(scene.relight.view_restore or "{}")
    except ValueError:
        return {}


def is_shown(scene) -> bool:
    """Does Relight currently hold viewports in its radiosity display?"""
    return bool(_memory(scene))


def _activate_radiosity_layers(scene):
    for obj in scene.objects:
        if obj.type != "MESH":
            continue
        colors = obj.data.color_attributes
        layer = colors.get(layers.RADIOSITY_ATTRIBUTE)
        if layer is not None and colors.active_color_name != layer.name:
            colors.active_color = layer


def show_radiosity(context) -> int:
    """Remember each viewport's shading (once) and switch it to Solid + Attribute colour.
    Returns the number of viewports switched."""
    scene = context.scene
    memory = _memory(scene)
    n = 0
    for key, space, area in _views(context):
        shading = space.shading
        if key not in memory:
            memory[key] = {"type": shading.type, "color_type": shading.color_type}
        shading.type = "SOLID"
        shading.color_type = "VERTEX"
        area.tag_redraw()
        n += 1
    _activate_radiosity_layers(scene)
    if n:
        scene.relight.view_restore = json.dumps(memory)
        display.refresh(scene, held=True)  # the Results panel's View (its layer; a false colour's view transform)
    return n


def restore(context) -> int:
    """Give every remembered viewport its shading back and forget it. Returns how many."""
    scene = context.scene
    display.give_back(scene)  # the view transform a false-colour view replaced
    memory = _memory(scene)
    if not memory:
        return 0
    n = 0
    for key, space, area in _views(context):
        old = memory.get(key)
        if old is None:
            continue
        try:
            space.shading.type = old["type"]
            space.shading.color_type = old["color_type"]
        except (TypeError, KeyError):  # a value this Blender does not know: leave it
            continue
        area.tag_redraw()
        n += 1
    scene.relight.view_restore = ""
    return n
