"""Test helpers: what Relight shows in a Blender scene, read back independently of results.py's
own bookkeeping (the emitters object's faces and attributes, the stored per-polygon radiosity)."""
from __future__ import annotations

import numpy as np


def emitted(scene):
    """The faces of Relight's emitters object: world-space triangles (n, 3, 3), radiance (n, 3)
    (W/m^2/sr, from the relight_emission face attribute), area (n,) m^2; None when there is none."""
    ob = next((o for o in scene.objects if o.get("relight_owner") and o.type == "MESH"), None)
    if ob is None:
        return None
    me = ob.data
    n = len(me.polygons)
    co = np.zeros(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    M = np.array(ob.matrix_world)
    co = co @ M[:3, :3].T + M[:3, 3]
    lv = np.zeros(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", lv)
    tri = co[lv].reshape(n, 3, 3)
    em = np.zeros(4 * n, dtype=np.float32)
    me.attributes["relight_emission"].data.foreach_get("color", em)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return {"object": ob, "triangles": tri, "radiance": em.reshape(n, 4)[:, :3].astype(np.float64), "area": area}


def emitted_power(scene):
    """Total power (W) per channel emitted by Relight's emitters object: sum of pi x radiance x area."""
    e = emitted(scene)
    if e is None:
        return np.zeros(3)
    return np.pi * (e["radiance"] * e["area"][:, None]).sum(axis=0)


def stored_polygon_radiosity(data, k):
    """{object: (n_polygons, 3) W/m^2} of stored configuration ``k`` (patch radiosity through the
    stored polygon weights)."""
    from relight_addon.blender import results

    rows = results.polygon_rows(data, np.asarray(data.radiosity[k], dtype=np.float64))
    off = data.polygon_offset
    return {name: rows[off[i]:off[i + 1]] for i, name in enumerate(data.objects)}
