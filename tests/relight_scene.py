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


def lamps(data) -> dict:
    """{lamp object: (its Light data-block's name, Power, colour, hide_render, hide_viewport, its
    Relight custom properties)} of ``data`` (bpy.data), rounded to 5 digits (float32 storage)."""
    return {o.name: (o.data.name, round(o.data.energy, 5), tuple(round(c, 5) for c in o.data.color), o.hide_render,
                     o.hide_viewport, sorted(k for k in o.keys() if k.startswith("relight")))
            for o in data.objects if o.type == "LIGHT"}


def reduce_built(build, folder, *args):
    """Build a scene with ``build(path)`` (bpy, from factory settings), then run `reduce --out` on
    it in-process with ``args``: (report, the written copy's path, the lamps as built)."""
    import json

    import bpy

    from relight_addon import cli

    blend, report, out = folder / "built.blend", folder / "r.json", folder / "out.blend"
    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        build(blend)
        built = lamps(bpy.data)
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    code = cli.main(["reduce", str(blend), "--report", str(report), "--out", str(out), *map(str, args)])
    assert code == 0
    return json.loads(report.read_text()), out, built
