"""Illuminance targets (issue 21, item 2): faces given an illuminance in lx (the Face attribute
``relight_target_lux``, Fill Selected (lx) in the sidebar) instead of a painted radiance.

Evidence: the export makes such a face a target of radiosity reflectance x lux / 683 (the
material's base colour read here, the constants of the units module: white light of that
illuminance); a face of both kinds, a negative value, or a face too dark to tell its illuminance
is refused with a message naming the object; the sidebar's Fill writes one kind per face; a solve
of issue 17's gallery whose floor strip asks for 300 lx predicts about that illuminance there
(within its own relative error), and the read-out gives the target next to it.
"""
import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon import cli  # noqa: E402
from relight_addon.blender import export, layers  # noqa: E402
from relight_addon.engine.scene import SceneError  # noqa: E402

WOOD = np.array([0.45, 0.3, 0.2])  # the gallery's floor (artist_scenes.gallery, Lambertian)


def _strip(floor):
    """The gallery's painted floor strip (its faces), its radiance paint removed."""
    me = floor.data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    me.color_attributes["relight_target"].data.foreach_get("color", col.ravel())
    starts = np.zeros(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_start", starts)
    painted = np.flatnonzero(col[starts, 3] >= 0.5)
    for p in painted:
        for li in me.polygons[int(p)].loop_indices:
            col[li] = 0.0
    me.color_attributes["relight_target"].data.foreach_set("color", col.ravel())
    return painted


def _set_lux(ob, faces, value):
    me = ob.data
    attr = me.attributes.get("relight_target_lux") or me.attributes.new("relight_target_lux", "FLOAT", "FACE")
    v = np.zeros(len(me.polygons))
    attr.data.foreach_get("value", v)
    v[faces] = value
    attr.data.foreach_set("value", v)


@pytest.fixture
def gallery():
    cr.reset_blender()
    obs = artist_scenes.gallery()
    yield obs
    cr.reset_blender()


def test_export_reads_lux_as_white_light_on_the_face(gallery):
    strip = _strip(gallery["Floor"])
    _set_lux(gallery["Floor"], strip, 300.0)
    f = export.export_scene().faces
    on = f.target_lux > 0
    assert on.sum() == len(strip) and np.all(f.target[on])
    np.testing.assert_allclose(f.target_radiosity[on], np.tile(WOOD * 300.0 / 683.0, (len(strip), 1)), rtol=1e-6)


def test_both_kinds_negative_and_dark_faces_refused(gallery):
    floor = gallery["Floor"]
    me = floor.data
    _set_lux(floor, [0], 0.0)
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    me.color_attributes["relight_target"].data.foreach_get("color", col.ravel())
    starts = np.zeros(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_start", starts)
    painted = int(np.flatnonzero(col[starts, 3] >= 0.5)[0])
    _set_lux(floor, [painted], 200.0)
    with pytest.raises(SceneError, match=r"Floor: 1 face\(s\) carry both a painted target .*relight_target_lux"):
        export.export_scene()
    _set_lux(floor, [painted], 0.0)
    _set_lux(floor, [painted + 1 if painted + 1 < len(me.polygons) else 0], -5.0)
    with pytest.raises(SceneError, match="Floor: 1 face.*negative, NaN or infinite illuminance"):
        export.export_scene()
    _set_lux(floor, list(range(len(me.polygons))), 0.0)
    black = cr._material("Black", (0.0, 0.0, 0.0), lambertian=True)
    room = gallery["Room"]
    room.data.materials[0] = black
    _set_lux(room, [0], 300.0)  # the ceiling, black
    with pytest.raises(SceneError, match="reflect less than 0.01 in a channel .*Room"):
        export.export_scene()


def test_fill_selected_writes_one_kind_per_face(addon, gallery):
    floor = gallery["Floor"]
    bpy.context.view_layer.objects.active = floor
    floor.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="DESELECT")
    bpy.ops.object.mode_set(mode="OBJECT")
    chosen = [0, 1, 2]
    for p in chosen:
        floor.data.polygons[p].select = True
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.scene.relight.paint_lux = 400.0
    assert bpy.ops.relight.fill_targets(unpaint=True) == {"FINISHED"}  # (an Unpaint first: not remembered)
    assert bpy.ops.relight.fill_targets(illuminance=True) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    lux = np.zeros(len(floor.data.polygons))
    floor.data.attributes["relight_target_lux"].data.foreach_get("value", lux)
    assert np.all(lux[chosen] == 400.0) and np.all(lux[3:] == 0.0)
    flags = layers.face_flags(floor, "target")
    assert np.all(flags[chosen])
    f = export.export_scene().faces
    rows = np.flatnonzero((f.face_object == f.object_names.index("Floor")) & np.isin(f.face_index, chosen))
    np.testing.assert_allclose(f.target_radiosity[rows], np.tile(WOOD * 400.0 / 683.0, (3, 1)), rtol=1e-6)
    bpy.ops.object.mode_set(mode="EDIT")
    assert bpy.ops.relight.fill_targets(illuminance=False) == {"FINISHED"}  # the colour: the lux goes
    bpy.ops.object.mode_set(mode="OBJECT")
    floor.data.attributes["relight_target_lux"].data.foreach_get("value", lux)
    assert np.all(lux[chosen] == 0.0)


def test_a_solve_meets_a_lux_target(gallery, tmp_path):
    """The floor strip at 300 lx (the painting and its band painted as before): the predicted mean
    illuminance there is 300 lx within the solve's relative error (twice it: the error is over
    every target), and the read-out gives the target beside it."""
    strip = _strip(gallery["Floor"])
    _set_lux(gallery["Floor"], strip, 300.0)
    blend = tmp_path / "lux.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    report = tmp_path / "r.json"
    assert cli.main(["solve", str(blend), "--report", str(report), "--quiet", "--seed", "1"]) == 0
    r = json.loads(report.read_text())
    rec = r["targets_photometric"]["Floor"]
    assert rec["target_lx"] == pytest.approx(300.0)
    err = r["final"]["relative_error"]
    assert abs(rec["illuminance_lx"]["mean"] / 300.0 - 1) <= max(2 * err, 0.05)


@pytest.mark.cycles
def test_cycles_agrees_on_the_predicted_illuminance(gallery, tmp_path):
    """The floor strip at 300 lx, `solve --out` (its lamps blackbody lights by the default, written
    with their Temperature), the written file's floor baked by Cycles (Lambertian, no World): the
    illuminance Cycles gives the strip, pi x baked radiance / reflectance through engine.units'
    luminance, is the report's predicted mean within 3 %."""
    strip = _strip(gallery["Floor"])
    _set_lux(gallery["Floor"], strip, 300.0)
    blend, out, report = tmp_path / "lux.blend", tmp_path / "out.blend", tmp_path / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["solve", str(blend), "--report", str(report), "--out", str(out), "--quiet", "--seed", "1"]) == 0
    r = json.loads(report.read_text())
    predicted = r["targets_photometric"]["Floor"]["illuminance_lx"]["mean"]
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        baked = cr.cycles_face_radiance(samples=512, seed=2, objects=[bpy.data.objects["Floor"]],
                                        faces={"Floor": [int(p) for p in strip]})
    finally:
        cr.reset_blender()
    from relight_addon.engine.units import illuminance_lux

    L = baked["Floor"].radiance[strip]  # (faces, 3) W/(m^2 sr); the strip's faces are of one area
    cycles = float(np.mean(illuminance_lux(np.pi * L / WOOD)))
    print(f"illuminance: predicted {predicted:.1f} lx, Cycles {cycles:.1f} lx, target 300")
    assert cycles == pytest.approx(predicted, rel=0.03)


def test_least_power_with_a_uniformity_goal(gallery, tmp_path):
    """The floor strip at 300 lx, least power within +-30 % and U0 >= 0.6: the report's predicted
    uniformity on the strip (from its radiosity, not the programme's rows) meets the goal, or the
    report says which U0 is reachable and the answer has that."""
    strip = _strip(gallery["Floor"])
    _set_lux(gallery["Floor"], strip, 300.0)
    blend, report = tmp_path / "lux.blend", tmp_path / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["solve", str(blend), "--report", str(report), "--quiet", "--seed", "1",
                     "--selection", "least-power", "--tolerance", "0.3", "--uniformity", "0.6"]) == 0
    r = json.loads(report.read_text())
    u0 = r["targets_photometric"]["Floor"]["illuminance_lx"]["u0"]
    said = " ".join(r["warnings"])
    print(f"U0 {u0:.3f}: {said[:300]}")
    if "is reachable" in said:
        reach = float(said.split("U0 >= ")[2].split(" is reachable")[0])
        assert u0 >= reach - 1e-3
    else:
        assert "U0 >= 0.6 met" in said and u0 >= 0.6 - 1e-6


def _work_plane(path):
    """The gallery with a 1.6 x 1 m work plane 0.75 m above its floor (4 x 3 faces, a grey material
    the solve does not use), 500 lx on every face, and no other target on the floor."""
    cr.reset_blender()
    obs = artist_scenes.gallery()
    _strip(obs["Floor"])
    v, f = cr.grid_quads((-0.8, 0.2, 0.75), (1.6, 0, 0), (0, 1.0, 0), 4, 3)  # facing up
    plane = cr.add_mesh_object("WorkPlane", v, f, cr._material("Desk", (0.5, 0.5, 0.5), lambertian=True))
    plane["relight_work_plane"] = True
    _set_lux(plane, list(range(12)), 500.0)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    cr.reset_blender()


@pytest.mark.cycles
def test_a_work_plane_neither_occludes_nor_reflects_and_cycles_agrees(tmp_path):
    """A work plane at 0.75 m, 500 lx, least power within +-30 % and U0 >= 0.6: the solve meets it
    or says the U0 it reaches; the --out copy has the plane's Ray Visibility off (light passes
    through it in Cycles too), and Cycles, baking the plane there, gives the predicted mean
    illuminance within 3 %."""
    blend, out, report = tmp_path / "wp.blend", tmp_path / "out.blend", tmp_path / "r.json"
    _work_plane(blend)
    assert cli.main(["solve", str(blend), "--report", str(report), "--out", str(out), "--quiet", "--seed", "1",
                     "--selection", "least-power", "--tolerance", "0.3", "--uniformity", "0.6"]) == 0
    r = json.loads(report.read_text())
    said = " ".join(r["warnings"])
    assert "work plane(s) 'WorkPlane': light passes through them" in said
    rec = r["targets_photometric"]["WorkPlane"]
    lx = rec["illuminance_lx"]
    if "is reachable" in said:
        assert lx["u0"] >= float(said.split("U0 >= ")[2].split(" is reachable")[0]) - 1e-3
    else:
        assert "U0 >= 0.6 met" in said and lx["u0"] >= 0.6 - 1e-6
    assert abs(lx["mean"] / 500.0 - 1) <= 0.3 + 1e-6 or "the closest is" in said
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        plane = bpy.data.objects["WorkPlane"]
        assert not plane.visible_shadow and not plane.visible_diffuse and plane.visible_camera
        floor = bpy.data.objects["Floor"]
        cen = np.array([p.center[:] for p in floor.data.polygons])
        under = np.flatnonzero((np.abs(cen[:, 0]) < 0.8) & (cen[:, 1] > 0.2) & (cen[:, 1] < 1.2))
        baked = cr.cycles_face_radiance(samples=512, seed=2, objects=[plane, floor])
    finally:
        cr.reset_blender()
    from relight_addon.engine.units import illuminance_lux

    cycles = float(np.mean(illuminance_lux(np.pi * baked["WorkPlane"].radiance / 0.5)))
    print(f"work plane: predicted {lx['mean']:.1f} lx (U0 {lx['u0']:.2f}), Cycles {cycles:.1f} lx, target 500")
    assert cycles == pytest.approx(lx["mean"], rel=0.03)
    # the floor under the plane is lit as if the plane were not there, in both (it casts no shadow):
    # under it against the rest of the floor, Relight's ratio is Cycles' (a shadow would halve it;
    # the floor is no target, its coarse patches 7-12 % off in both parts alike)
    ours = np.asarray(r["objects"]["Floor"]["radiosity"], dtype=np.float64).sum(axis=1)
    theirs = baked["Floor"].radiance.sum(axis=1)
    rest = np.setdiff1d(np.arange(len(cen)), under)
    ratio_ours, ratio_cycles = ours[under].mean() / ours[rest].mean(), theirs[under].mean() / theirs[rest].mean()
    print(f"floor under the plane / the rest: predicted {ratio_ours:.3f}, Cycles {ratio_cycles:.3f}")
    assert ratio_ours == pytest.approx(ratio_cycles, rel=0.1)
