"""Child process of tests/test_addon_workflow.py (not a test module itself).

    python -S addon_scenario.py EXTENSION_ZIP SAMPLES_DIR

Installs the built extension zip into a bpy session whose user directories are temporary
(set by the parent), then drives the add-on through its operators the way an artist would:
open a sample scene, paint targets through the attribute, forbid faces with the operator,
Solve & Reduce, walk the curve, make area lights, clear, solve again after an edit.
Prints one line ``RESULT {json}`` with what it observed; the parent asserts on it.
"""
import json
import math
import os
import sys

import bpy
import numpy as np

zip_path, samples = sys.argv[1], sys.argv[2]
R = {}


def snapshot():
    """Everything Clear Results must restore: per mesh, slots, material indices, attributes,
    active colour; the scene's materials, lights, collections and custom properties."""
    snap = {"materials": sorted(m.name for m in bpy.data.materials),
            "lights": sorted(o.name for o in bpy.data.objects if o.type == "LIGHT"),
            "collections": sorted(c.name for c in bpy.data.collections),
            # the add-on's own settings groups ("relight", the View's "relight_view", the camera
            # view target's "relight_camera_target") appear in the ID properties of Blender 4.2 and
            # 4.5 on first access; they hold the panel's settings, not scene content (relight_view's
            # view transform to give back: checked empty below)
            "scene_keys": sorted(k for k in bpy.context.scene.keys()
                                 if k not in ("relight", "relight_view", "relight_camera_target"))}
    for ob in bpy.context.scene.objects:
        if ob.type != "MESH":
            continue
        me = ob.data
        idx = np.zeros(len(me.polygons), dtype=np.int32)
        me.polygons.foreach_get("material_index", idx)
        active = me.color_attributes.active_color
        snap[ob.name] = {"slots": [m.name if m else None for m in me.materials],
                         "material_index": idx.tolist(),
                         "attributes": sorted(a.name for a in me.attributes),
                         "active_color": active.name if active else None,
                         "keys": sorted(me.keys())}
    return snap


def op(fn, **kw):
    try:
        return sorted(fn(**kw)), None
    except RuntimeError as exc:  # an operator's ERROR report
        return ["CANCELLED"], str(exc)


ret = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
R["install"] = sorted(ret)
pkg = "bl_ext.user_default.relight"
R["enabled"] = pkg in bpy.context.preferences.addons
mod = sys.modules[pkg]
results = sys.modules[pkg + ".blender.results"]

# 1. a scene without targets: an error report, nothing changed
bpy.ops.wm.open_mainfile(filepath=os.path.join(samples, "staircase.blend"))
before = snapshot()
R["no_target"] = op(bpy.ops.relight.solve)
R["no_target_unchanged"] = snapshot() == before

# 2a. the target tools: Paint Targets creates the layer (alpha 0 = unpainted) and enters
# Vertex Paint; Fill Selected paints selected faces; Select Targets selects them; Clear removes
scene = bpy.context.scene
probe = next(o for o in scene.objects if o.type == "MESH" and o.name.startswith("ceiling"))
bpy.context.view_layer.objects.active = probe
for o in scene.objects:
    o.select_set(o == probe)
# another colour layer first, active: Paint Targets must switch to its own layer
other = probe.data.color_attributes.new("artist_colors", "BYTE_COLOR", "CORNER")
probe.data.color_attributes.active_color = other
R["paint_op"] = op(bpy.ops.relight.paint_targets)
R["paint_mode"] = bpy.context.mode
lay = probe.data.color_attributes.get("relight_target")
R["paint_layer"] = None if lay is None else [lay.domain, lay.data_type, probe.data.color_attributes.active_color.name]
alpha = np.zeros(len(probe.data.loops) * 4, dtype=np.float32)
if lay is not None:
    lay.data.foreach_get("color", alpha)
R["paint_alpha_max"] = float(alpha.reshape(-1, 4)[:, 3].max())
import bmesh  # noqa: E402


def edit_select(obj, faces):
    """In Edit Mode, select exactly these faces (face select mode)."""
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_mode(type="FACE")
    bpy.ops.mesh.select_all(action="DESELECT")
    bm = bmesh.from_edit_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    for f in faces:
        bm.faces[f].select_set(True)
    bm.select_flush_mode()
    bmesh.update_edit_mesh(obj.data)


bpy.ops.object.mode_set(mode="OBJECT")
edit_select(probe, [0, 2])
R["fill_op"] = op(bpy.ops.relight.fill_targets, unpaint=False)
bpy.ops.object.mode_set(mode="OBJECT")
R["select_op"] = op(bpy.ops.relight.select_faces, kind="TARGET")
bpy.ops.object.mode_set(mode="OBJECT")
got = np.zeros(len(probe.data.polygons), dtype=bool)
probe.data.polygons.foreach_get("select", got)
R["selected_targets"] = np.flatnonzero(got).tolist()
R["clear_targets_op"] = op(bpy.ops.relight.clear_targets)
R["target_layer_after_clear"] = "relight_target" in probe.data.attributes
probe.data.color_attributes.remove(probe.data.color_attributes["artist_colors"])

# 2b. paint targets through the attribute: the floor of the first storey, bright warm light
settings = scene.relight
settings.rays_per_patch = 512
settings.target_scale = 1.0
floor = scene.objects["floor_0"] if "floor_0" in scene.objects else \
    next(o for o in scene.objects if o.type == "MESH" and o.name.startswith("floor"))
me = floor.data
attr = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
col = np.zeros((len(me.loops), 4), dtype=np.float32)
n_paint = max(4, len(me.polygons) // 4)
paint = np.arange(n_paint)
loop_start = np.zeros(len(me.polygons), dtype=np.int64)
loop_total = np.zeros(len(me.polygons), dtype=np.int64)
me.polygons.foreach_get("loop_start", loop_start)
me.polygons.foreach_get("loop_total", loop_total)
target_radiance = np.array([0.9, 0.8, 0.6])
for p in paint:
    col[loop_start[p]:loop_start[p] + loop_total[p]] = (*target_radiance, 1.0)
attr.data.foreach_set("color", col.ravel())
R["floor"] = floor.name
R["painted"] = int(n_paint)

# 3. forbid faces through the operator: the first 10 faces of a wall, in Edit Mode
wall = next(o for o in scene.objects if o.type == "MESH" and o.name.startswith("wall"))
bpy.context.view_layer.objects.active = wall
for o in scene.objects:
    o.select_set(o == wall)
fb0 = wall.data.attributes.get("relight_forbidden")
before_vals = np.zeros(len(wall.data.polygons), dtype=bool)
if fb0 is not None:
    fb0.data.foreach_get("value", before_vals)
R["forbidden_before"] = np.flatnonzero(before_vals).tolist()
edit_select(wall, range(10))
R["forbid"] = op(bpy.ops.relight.forbid_faces, allow=False)
bpy.ops.object.mode_set(mode="OBJECT")
fb = wall.data.attributes["relight_forbidden"]
vals = np.zeros(len(wall.data.polygons), dtype=bool)
fb.data.foreach_get("value", vals)
R["forbidden_faces"] = np.flatnonzero(vals).tolist()
R["wall"] = wall.name

# 4. Solve & Reduce (synchronous path: execute(), as in blender -b and scripts)
before = snapshot()
R["solve"] = op(bpy.ops.relight.solve)
data = results.load_result(scene)
R["curve_rows"] = len(settings.curve)
R["curve_index"] = settings.curve_index
R["rows"] = [[c.n_lights, c.relative_error, c.n_negative, c.curve_index] for c in settings.curve]
R["stored_n_lights"] = data.n_lights.tolist()
R["e_x_relative_error"] = float(data.relative_error[0])
R["whole_curve_points"] = int(len(data.curve_n_lights))


def emitting_state():
    """What Relight's emitters object emits: [total power per channel (W) = sum of pi x
    radiance x area over its faces, emitting area (m^2), number of faces]."""
    ob = next((o for o in scene.objects if o.get("relight_owner") and o.type == "MESH"), None)
    if ob is None:
        return [[0.0, 0.0, 0.0], 0.0, 0]
    me = ob.data
    n = len(me.polygons)
    em = np.zeros(n * 4, dtype=np.float32)
    me.attributes["relight_emission"].data.foreach_get("color", em)
    area = np.zeros(n)
    me.polygons.foreach_get("area", area)
    em = em.reshape(-1, 4)[:, :3]
    return [(math.pi * em * area[:, None]).sum(axis=0).tolist(), float(area.sum()), n]


def expected_lights(k):
    """From the stored curve: the power per channel and the area of configuration k's positive
    surface lights (the emitters object shows them), their number and the number of lamps on
    (Light objects of Relight's)."""
    e = data.exitance[k].astype(float)
    pos = np.any(e > 0, axis=1) & ~np.any(e < 0, axis=1)
    lamp = np.asarray(data.light_lamp) >= 0
    cells = pos & ~lamp
    a = data.light_area.astype(float)
    return [(e[cells] * a[cells, None]).sum(axis=0).tolist(), float(a[cells].sum()), int(cells.sum()),
            int((pos & lamp).sum())]


def target_check(k):
    """Radiosity layer (radiance) on the painted faces vs pi x painted colour, configuration k."""
    me = floor.data
    rad = np.zeros(len(me.loops) * 4, dtype=np.float32)
    me.color_attributes["relight_radiosity"].data.foreach_get("color", rad)
    rad = rad.reshape(-1, 4)[:, :3]
    rows = results.polygon_rows(data, data.radiosity[k].astype(float))
    off = data.polygon_offset[data.objects.index(floor.name)]
    return {"stored_target_radiance": (rows[off + paint] / math.pi).tolist(),
            "layer_corner_radiance_mean": float(rad.mean())}


k_final = settings.curve_index
R["final_state"] = emitting_state()
R["final_lights"] = [[li_obj, li_polys] for li_obj, li_polys in (
    (data.objects[data.light_object[j]],
     (data.light_polygons[data.light_polygons_indptr[j]:data.light_polygons_indptr[j + 1]]
      - data.polygon_offset[data.light_object[j]]).tolist())
    for j in np.flatnonzero(np.any(data.exitance[settings.curve_index] > 0, axis=1) & (data.light_object >= 0)))]
# Select Light Faces selects exactly the polygons under the lights shown, on the selected objects
lit_obj = bpy.data.objects[R["final_lights"][0][0]] if R["final_lights"] else floor
bpy.context.view_layer.objects.active = lit_obj
for o in scene.objects:
    o.select_set(o == lit_obj)
R["select_lights_op"] = op(bpy.ops.relight.select_faces, kind="LIGHT")
bpy.ops.object.mode_set(mode="OBJECT")
got = np.zeros(len(lit_obj.data.polygons), dtype=bool)
lit_obj.data.polygons.foreach_get("select", got)
R["selected_lights"] = [lit_obj.name, np.flatnonzero(got).tolist()]
R["final_expected"] = expected_lights(k_final)
R["final_row"] = [settings.curve[k_final].n_lights, settings.curve[k_final].n_negative]
R["final_targets"] = target_check(k_final)["stored_target_radiance"]
R["final_relative_error"] = float(settings.curve[k_final].relative_error)
# Eq. 1 from what the file stores: the final configuration's radiosity on the painted patches
b_k = data.radiosity[k_final][data.target_patch].astype(float)
want_b = data.target_value.astype(float)
R["stored_eq1_relative"] = float(np.linalg.norm(b_k - want_b) / np.linalg.norm(want_b))
R["active_color"] = floor.data.color_attributes.active_color.name
R["target_radiance"] = target_radiance.tolist()

# 5. apply configuration k through the operator and through the list (update callback)
k = min(3, len(settings.curve) - 1)
R["apply_k"] = op(bpy.ops.relight.apply_configuration, index=k)
R["k"] = k
R["k_state"] = emitting_state()
R["k_expected"] = expected_lights(k)
R["k_row"] = [settings.curve[k].n_lights, settings.curve[k].n_negative]
settings.curve_index = k_final  # clicking a row in the list applies it
R["back_to_final_state"] = emitting_state()

# the chart the Results panel draws, with the shown configuration marked
panels = sys.modules[pkg + ".blender.ui.panels"]
drawn = panels.chart_pixels(scene, 240, 204)
R["chart"] = None if drawn is None else {
    "shape": list(drawn[0].shape), "marker": drawn[1]["marker"] is not None,
    "current": results.chart_data(scene)["current"], "final_curve_index": int(data.point_index[k_final])}
R["summary"] = [settings.last_summary, settings.last_warnings]
# the automatic options' labels give the value the solve used (issue 36 item 5)
params = sys.modules[pkg + ".engine.options"].PARAMS
R["auto"] = {"stored": {k: data.meta["options"].get(k) for k in ("max_patch_size", "rays_per_patch")},
             "labels": {k: panels.auto_label(settings, params[k]) for k in ("max_patch_size", "rays_per_patch")},
             "settings": [settings.max_patch_size, settings.rays_per_patch]}

# 6. area lights (one per emitting cell, the same power), then clear: the area lights stay (they
# are the artist's, as the button says), so do the artist's own objects in a collection that
# happens to be called "Relight Lights"; the rest is exactly as before the solve
R["area_lights"] = op(bpy.ops.relight.make_area_lights)
# Relight's own lights of the row are gone (issue 36, item 6): the new lights alone render it
R["relight_lights_left"] = [emitting_state()[2],
                            len([o for o in scene.objects if o.type == "LIGHT" and o.get("relight_owner")])]
made = next(c for c in bpy.data.collections if c.get("relight_area_lights") is not None)
area_objs = [o for o in made.objects if o.type == "LIGHT"]  # (Relight's own lamps are elsewhere)
R["n_area_lights"] = len(area_objs)
# per channel: Cycles emits colour x Power (W) in each; the lamps shown are copied with their power
R["area_light_power"] = np.sum([np.array(o.data.color) * o.data.energy for o in area_objs], axis=0).tolist()
e_final = data.exitance[k_final].astype(float)
lamp_on = (np.asarray(data.light_lamp) >= 0) & np.any(e_final > 0, axis=1)
R["emitted_power"] = (np.asarray(R["final_state"][0]) + e_final[lamp_on].sum(axis=0)).tolist()
mine = bpy.data.collections.new("Relight Lights")  # the artist's own collection of that name
scene.collection.children.link(mine)
cube = bpy.data.objects.new("artist_empty", None)
mine.objects.link(cube)
R["clear"] = op(bpy.ops.relight.clear_results)
R["area_lights_kept"] = len([o for o in scene.objects if o.type == "LIGHT"]) == len(area_objs)
R["artist_collection_kept"] = "artist_empty" in bpy.data.objects and cube.name in mine.objects
R["emitters_after_clear"] = emitting_state()[2]
for o in [o for o in scene.objects if o.type == "LIGHT"]:  # the artist deletes them
    d = o.data
    bpy.data.objects.remove(o)
    bpy.data.lights.remove(d)
for c in [c for c in bpy.data.collections if c.get("relight_area_lights") is not None]:
    bpy.data.collections.remove(c)
bpy.data.objects.remove(cube)
bpy.data.collections.remove(mine)
R["clear_restores"] = snapshot() == before
R["view_transform_to_restore"] = scene.relight_view.transform_restore  # (nothing left to give back)
if not R["clear_restores"]:
    a, b = snapshot(), before
    R["clear_diff"] = {k2: [a.get(k2), b.get(k2)] for k2 in set(a) | set(b) if a.get(k2) != b.get(k2)}

# 7. two solves in a row, then an edit (more targets) and a third solve
R["solve2"] = op(bpy.ops.relight.solve)
R["solve3"] = op(bpy.ops.relight.solve)
R["materials_after_two"] = sorted(m.name for m in bpy.data.materials)
col2 = np.zeros(len(me.loops) * 4, dtype=np.float32)
attr = me.color_attributes["relight_target"]
attr.data.foreach_get("color", col2)
col2 = col2.reshape(-1, 4)
extra = np.arange(n_paint, min(len(me.polygons), 2 * n_paint))
for p in extra:
    col2[loop_start[p]:loop_start[p] + loop_total[p]] = (0.2, 0.2, 0.2, 1.0)
attr.data.foreach_set("color", col2.ravel())
R["solve_after_edit"] = op(bpy.ops.relight.solve)
data2 = results.load_result(scene)
R["targets_before_edit"] = int(R["painted"])
R["targets_after_edit"] = int(n_paint + len(extra))
R["target_norm_before"] = float(data.target_norm)
R["target_norm_after"] = float(data2.target_norm)
R["clear2"] = op(bpy.ops.relight.clear_results)
R["clear2_restores"] = snapshot() == before

print("RESULT " + json.dumps(R), flush=True)
