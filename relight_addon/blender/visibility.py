"""What a render of the view layer shows, and what Relight made (bpy).

An object is exported when a render shows it: not hidden from render (its ``hide_render``, or
``hide_render`` on every collection chain it is linked through) and in a collection the view layer
does not exclude. Hidden in the viewport (H, the eye, the monitor icon) it is still modelled, as
Cycles still renders it; one disabled in the viewports is enabled while it is evaluated
(``Evaluable``). Everything Relight creates carries its result id (``tag_owned``, ``owner_of``):
only that is ever removed, or left out of the scene's light.
"""
from __future__ import annotations

import bpy
import numpy as np

RELIGHT_OWNER_PROP = "relight_owner"  # on everything Relight creates (results.py): its result id
#: and the name it was made with: a copy (Shift-D, another data-block of a new name) is the user's
RELIGHT_NAME_PROP = "relight_owner_name"


def tag_owned(idb, rid) -> None:
    """Mark ``idb`` (an object, mesh, material, light or collection) as made by result ``rid``."""
    idb[RELIGHT_OWNER_PROP] = rid
    idb[RELIGHT_NAME_PROP] = idb.name


def owner_of(idb):
    """The result id that made ``idb``, or None when the user made it: never tagged, or a copy of
    something Relight made (its custom properties came along, its name did not: Blender names are
    unique, so a copy has another). Only what Relight made is ever removed or left out as ours."""
    rid = idb.get(RELIGHT_OWNER_PROP)
    made = idb.get(RELIGHT_NAME_PROP)
    return None if rid is None or (made is not None and made != idb.name) else rid


def render_visible_objects(context):
    """Names of the objects that a render of the view layer would see through the collection
    tree: every object linked to at least one collection of the layer that is not excluded from it
    and whose chain from the scene collection has no ``hide_render`` (the object's own
    ``hide_render`` is checked separately). Hiding in the viewport (H, the eye, the monitor icon)
    does not keep an object out of a render, so it does not keep it out of the model."""
    seen = set()

    def walk(lc, hidden):
        if lc.exclude:
            return
        hidden = hidden or bool(getattr(lc.collection, "hide_render", False))
        if not hidden:
            seen.update(ob.name for ob in lc.collection.objects)
        for child in lc.children:
            walk(child, hidden)

    walk(context.view_layer.layer_collection, False)
    return seen


def rendered(ob, renderable) -> bool:
    """Whether a render shows ``ob`` (``renderable``: render_visible_objects)."""
    return not ob.hide_render and ob.name in renderable


def exported_objects(context=None):
    """The scene's mesh objects that are exported: those a render shows (``rendered``), whether or
    not they are hidden in the viewport, and not made by Relight (its emitters object shows a
    result: a new solve does not count it as scene light)."""
    context = context or bpy.context
    renderable = render_visible_objects(context)
    return [ob for ob in context.scene.objects
            if ob.type == "MESH" and rendered(ob, renderable) and owner_of(ob) is None]


def hidden_in_viewport(context, objs) -> list:
    """The names of ``objs`` hidden in the viewport (H, the eye or the monitor icon) that renders
    show, and so Relight models."""
    return [ob.name for ob in objs if not ob.visible_get(view_layer=context.view_layer)]


class Evaluable:
    """While open, the objects ``objs`` and their collections are enabled in the viewports, so that
    the depsgraph evaluates their modifiers as a render would (an object disabled in the viewports,
    the monitor icon, is not evaluated); everything is set back as it was on close."""

    def __init__(self, context, objs):
        self.context, self.changed = context, []
        colls = {c for ob in objs for c in ob.users_collection}
        for idb in list(objs) + sorted(colls, key=lambda c: c.name):
            if getattr(idb, "hide_viewport", False) and getattr(idb, "library", None) is None:
                self.changed.append(idb)

    def __enter__(self):
        for idb in self.changed:
            idb.hide_viewport = False
        if self.changed:
            self.context.view_layer.update()
        return self

    def __exit__(self, *exc):
        for idb in self.changed:
            idb.hide_viewport = True
        if self.changed:
            self.context.view_layer.update()
        return False


def mesh_instances(context, renderable):
    """(name, evaluated object, world matrix) of every mesh instance of the depsgraph
    (collection instances, particle and geometry-nodes instances) whose instancer and
    source object are rendered. Only valid while the depsgraph is not re-evaluated."""
    depsgraph = context.evaluated_depsgraph_get()
    for inst in depsgraph.object_instances:
        if not inst.is_instance:
            continue
        ob, parent = inst.object, inst.parent
        if ob is None or ob.type != "MESH":
            continue
        src = ob.original
        host = parent.original if parent is not None else None
        if host is not None and (host.hide_render or host.name not in renderable):
            continue
        if src is not None and src != host and src.hide_render:
            continue
        name = f"{host.name if host is not None else '?'}/{src.name if src is not None else ob.name}"
        yield name, ob, np.array(inst.matrix_world, dtype=np.float64)
