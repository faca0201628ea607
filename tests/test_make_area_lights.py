"""Make Area Lights converts (issue 36, item 6): the configuration shown becomes the artist's own
lights, and Relight's emitters of it (the emitters object, the lamps it placed) stop rendering, so
a render shows the row's light once, not twice; the new lights are named what and where
("Relight Area Room 1", "Relight Spot Room 2"), never taking an artist's object's name.

Scenes: issue 17's gallery (tests/artist_scenes.gallery) solved by the CLI with its default
candidates (its final row: emitting cells on the ceiling of the one mesh "Room" and spot lamps),
and tests/test_hostile_ownership.py's room_camera solved in the add-on with point lamps only (a
"ceiling" above a "floor"). Reference for the power: the row's power the solve reported
(``curve_power``, W summed over the channels), against what a render of the scene emits counted
here independently of Relight's writers: every Light not hidden from render (Cycles: colour x Power
x its Exposure / Temperature / Normalize gain) and every mesh face carrying Relight's emission
attribute (one-sided Lambertian: pi x radiance x area).
"""
import json
import re

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon import cli  # noqa: E402
from relight_addon.blender.lamps import cycles_gain  # noqa: E402
from test_hostile import assert_scene_finite, snapshot  # noqa: E402
from test_hostile_ownership import _open_placed, scenes  # noqa: E402,F401  (fixture)

NAME = re.compile(r"^Relight (Area|Spot|Point) (\S+) (\d+)$")


@pytest.fixture(scope="module")
def gallery(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gallery")
    blend, out, report = folder / "gallery.blend", folder / "solved.blend", folder / "report.json"
    cr.reset_blender()
    try:
        artist_scenes.gallery()
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        cr.reset_blender()
    assert cli.main(["solve", str(blend), "--report", str(report), "--out", str(out), "--quiet", "--seed", "1"]) == 0
    return out, json.loads(report.read_text())


def _hidden(ob):
    return ob.hide_render or any(c.hide_render for c in ob.users_collection)


def rendered_power(scene) -> np.ndarray:
    """(3,) W per channel that a render of ``scene`` emits (see the module's docstring)."""
    total = np.zeros(3)
    for ob in scene.objects:
        if _hidden(ob):
            continue
        if ob.type == "LIGHT":
            M = np.array(ob.matrix_world)
            total += np.array(ob.data.color)[:3] * ob.data.energy * cycles_gain(ob.data, M)
        elif ob.type == "MESH" and "relight_emission" in ob.data.attributes:
            me, M = ob.data, np.array(ob.matrix_world)
            co = np.array([M[:3, :3] @ v.co + M[:3, 3] for v in me.vertices])
            radiance = np.zeros((len(me.polygons), 4), dtype=np.float32)
            me.attributes["relight_emission"].data.foreach_get("color", radiance.ravel())
            for p, L in zip(me.polygons, radiance[:, :3]):
                v = co[list(p.vertices)]
                area = 0.5 * sum(np.linalg.norm(np.cross(v[i] - v[0], v[i + 1] - v[0])) for i in range(1, len(v) - 1))
                total += np.pi * L * area
    return total


def _row_power(scene, row):
    from relight_addon.blender import results

    data = results.load_result(scene)
    return float(data.curve_power[int(data.point_index[row])])


def _converted(scene):
    """The lights Make Area Lights made and still marks as its own (object name -> object)."""
    return {o.name: o for o in scene.objects if o.type == "LIGHT" and o.get("relight_area_lights") is not None}


def _relights(scene):
    """Relight's own objects showing a row (the emitters object, the placed lamps)."""
    return sorted(o.name for o in scene.objects if o.get("relight_owner") is not None
                  and o.get("relight_owner_name") == o.name)


def _open_gallery(gallery):
    bpy.ops.wm.open_mainfile(filepath=str(gallery[0]))
    scene = bpy.context.scene
    k = int(scene["relight_shown"])
    assert scene.relight.curve_index == k and scene.relight.curve[k].n_negative == 0
    return scene, k


def test_make_area_lights_renders_the_row_once(addon, gallery, capfd):
    """Before the fix the emitters object and the placed lamps kept emitting beside the new lights:
    twice the row's power. Now the render emits the row's power once, as before the click."""
    scene, k = _open_gallery(gallery)
    power = _row_power(scene, k)
    before = rendered_power(scene)
    assert before.sum() == pytest.approx(power, rel=1e-4)  # (the reference counts the row as shown)
    assert any(o.type == "LIGHT" for o in scene.objects) and any(o.type == "MESH" for o in scene.objects
                                                                 if o.get("relight_owner"))
    capfd.readouterr()
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    said = capfd.readouterr().out
    after = rendered_power(scene)
    np.testing.assert_allclose(after, before, rtol=1e-4)  # the same light, not twice
    assert after.sum() == pytest.approx(power, rel=1e-4)
    assert _relights(scene) == []  # nothing of Relight's renders beside the artist's lights
    assert "beside" in said and "row" in said, said  # the report says what a row click does now
    assert int(scene["relight_shown"]) == k and len(scene.relight.curve) > 1  # the result stays
    assert_scene_finite()


def test_rows_show_again_beside_the_converted_lights_and_clear_keeps_them(addon, gallery):
    """The result stays: another row shows Relight's emitters again, beside the converted lights
    (both render); the row shown again and converted again makes the same lights under the same
    names (no doubling); Clear Results never removes them."""
    scene, k = _open_gallery(gallery)
    power = _row_power(scene, k)
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    names = sorted(_converted(scene))
    other = next(r for r in range(len(scene.relight.curve)) if r != k and scene.relight.curve[r].n_negative == 0)
    scene.relight.curve_index = other  # a click on the list
    assert scene.relight.apply_error == "" and int(scene["relight_shown"]) == other and _relights(scene)
    assert rendered_power(scene).sum() == pytest.approx(power + _row_power(scene, other), rel=1e-4)
    scene.relight.curve_index = k
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    assert sorted(_converted(scene)) == names  # replaced, stable names
    assert rendered_power(scene).sum() == pytest.approx(power, rel=1e-4)
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert sorted(o.name for o in scene.objects if o.type == "LIGHT") == names
    assert not any(o.get("relight_owner") for o in scene.objects)
    assert rendered_power(scene).sum() == pytest.approx(power, rel=1e-4)
    assert_scene_finite()


def test_make_area_lights_twice_refuses_and_changes_nothing(addon, gallery):
    """The row shown is already the artist's lights: a second click has nothing to convert (it
    would have replaced the lamps' copies by nothing, their Relight originals being gone)."""
    scene, _ = _open_gallery(gallery)
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    before = snapshot()
    with pytest.raises(RuntimeError, match="already your lights"):
        bpy.ops.relight.make_area_lights()
    assert snapshot() == before


def test_another_row_than_the_one_shown_is_refused(addon, gallery):
    from relight_addon.blender import results
    from relight_addon.engine.scene import SceneError

    scene, k = _open_gallery(gallery)
    before = snapshot()
    with pytest.raises(SceneError, match="not the one shown"):
        results.make_area_lights(scene, 0 if k else 1)
    assert snapshot() == before


def test_names_say_what_and_where_and_never_take_the_artists(addon, gallery):
    """Names "Relight <Kind> <object> <n>": the kind of the light, the mesh it sits on or hangs
    from, a number; an artist's object already called that keeps its name and stays itself (the
    next free number is taken)."""
    scene, k = _open_gallery(gallery)
    mine = bpy.data.objects.new("Relight Area Room 1", None)  # the artist's empty of that very name
    scene.collection.objects.link(mine)
    pointer = mine.as_pointer()
    data_mine = bpy.data.lights.new("Relight Spot Room 1", "POINT")  # and a light datablock
    data_mine.use_fake_user = True
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    made = _converted(scene)
    parsed = {n: NAME.match(n) for n in made}
    assert all(parsed.values()), sorted(made)
    kinds = {n: m.group(1) for n, m in parsed.items()}
    assert {m.group(2) for m in parsed.values()} == {"Room"}  # the gallery's lights all hang from its ceiling
    for n, ob in made.items():
        assert ob.data.type == kinds[n].upper()
    spots = sorted(int(m.group(3)) for m in parsed.values() if m.group(1) == "Spot")
    areas = sorted(int(m.group(3)) for m in parsed.values() if m.group(1) == "Area")
    assert len(spots) >= 1 and len(areas) >= 1
    assert spots == list(range(1, len(spots) + 1))
    assert areas == list(range(2, len(areas) + 2))  # 1 is the artist's
    assert mine.name == "Relight Area Room 1" and mine.type == "EMPTY" and mine.as_pointer() == pointer
    assert bpy.data.objects["Relight Area Room 1"] == mine and data_mine.name == "Relight Spot Room 1"


def test_lamps_are_named_after_the_surface_they_hang_from(addon, scenes):
    """room_camera, point lamps only: the lamps hang under the "ceiling", above the "floor"."""
    scene, placed = _open_placed(scenes)
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    names = sorted(_converted(scene))
    assert names == [f"Relight Point ceiling {i + 1}" for i in range(len(placed))]
    assert sorted(o.name for o in scene.objects if o.type == "LIGHT") == names  # Relight's own lamps are gone


def test_a_surface_without_evaluated_mesh_is_passed_over(bpy_clean):
    """The object a lamp hangs from: the nearest surface; an object Blender has not evaluated (not
    in the view layer: closest_point_on_mesh raises) is passed over, not a traceback."""
    from relight_addon.blender.results import _nearest_object

    def quad(name, z, link=True):
        me = bpy.data.meshes.new(name)
        me.from_pydata([(0, 0, z), (1, 0, z), (1, 1, z), (0, 1, z)], [], [(0, 1, 2, 3)])
        ob = bpy.data.objects.new(name, me)
        if link:
            bpy.context.scene.collection.objects.link(ob)
        return ob

    floor, ceiling, loose = quad("floor", 0.0), quad("ceiling", 1.0), quad("loose", 0.95, link=False)
    assert _nearest_object([floor, ceiling, loose], (0.5, 0.5, 0.9)) == "ceiling"
    assert _nearest_object([floor, ceiling], (0.5, 0.5, 0.2)) == "floor"
    assert _nearest_object([loose], (0.5, 0.5, 0.9)) == ""


def _baked_targets():
    """Cycles' mean outgoing radiance (W m^-2 sr^-1, per channel) of the gallery's painting and of
    its painted floor strip, as the open file renders them (cycles_reference's face bake)."""
    floor = bpy.data.objects["Floor"]
    centre = np.array([p.center[:] for p in floor.data.polygons])
    strip = np.flatnonzero((np.abs(centre[:, 0]) < 1.5) & (centre[:, 1] > artist_scenes.GALLERY[1] / 2 - 1.0))
    baked = cr.cycles_face_radiance(samples=64, seed=1, cell_px=8, threads=2,
                                    objects=[bpy.data.objects["Painting"], floor],
                                    faces={"Painting": [0], "Floor": strip.tolist()})
    return np.concatenate([baked["Painting"].radiance[0], baked["Floor"].radiance[strip].mean(axis=0)])


def test_cycles_renders_the_same_light_after_make_area_lights(addon, gallery):
    """Closed loop in Cycles: the painting and the floor strip baked as the written copy shows the
    row (the emitters object, the placed spots) and after Make Area Lights (the area light, the
    spots' copies) agree within a few per cent (64 samples, the same seed); twice the light
    before the fix."""
    bpy.ops.wm.open_mainfile(filepath=str(gallery[0]))
    shown = _baked_targets()
    bpy.ops.wm.open_mainfile(filepath=str(gallery[0]))
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    converted = _baked_targets()
    assert np.all(shown > 0)
    np.testing.assert_allclose(converted, shown, rtol=0.05)


def test_undo_gives_the_state_before(addon, gallery):
    """Ctrl+Z after Make Area Lights: the operator is undoable (bl_options UNDO); its writes all
    happen inside one execute, so Blender's undo step holds the state before."""
    if not bpy.ops.ed.undo.poll():
        pytest.skip("Blender's undo stack does not exist in background mode (bpy.ops.ed.undo.poll() is False "
                    "headless): Undo cannot be driven here")
    scene, _ = _open_gallery(gallery)
    before = snapshot()
    bpy.ops.ed.undo_push(message="before")
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    bpy.ops.ed.undo()
    assert snapshot() == before


def _reduced(folder, build, name):
    """Scene ``name`` of ``build`` reduced by the CLI (--out): the path of the written copy."""
    src, out = build(name, str(folder)), folder / f"{name}_reduced.blend"
    assert cli.main(["reduce", src, "--report", str(folder / f"{name}.json"), "--out", str(out),
                     "--rays-per-patch", "256", "--quiet"]) == 0
    return str(out)


def test_a_reduction_converts_and_says_clear_gives_the_scenes_emitters_back(addon, tmp_path, capfd):
    """Reduce of an emissive ceiling: its own faces are switched off while the result is shown and
    the emitters object shows the reduced light. Converted, the light renders once (the ceiling
    stays off), and the report says that Clear Results gives the ceiling's emission back, beside
    the converted lights, as it then does."""
    from test_hostile import build

    bpy.ops.wm.open_mainfile(filepath=_reduced(tmp_path, build, "lamp_room"))
    scene = bpy.context.scene
    ceiling = bpy.data.objects["ceiling"]
    assert any(m.name.endswith("(Relight, off)") for m in ceiling.data.materials)  # the ceiling is off
    before = rendered_power(scene)
    assert before.sum() == pytest.approx(_row_power(scene, int(scene["relight_shown"])), rel=1e-4)
    capfd.readouterr()
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    assert "Clear Results gives them back" in capfd.readouterr().out
    np.testing.assert_allclose(rendered_power(scene), before, rtol=1e-4)
    assert _relights(scene) == [] and any(m.name.endswith("(Relight, off)") for m in ceiling.data.materials)
    names = sorted(_converted(scene))
    assert names == ["Relight Area ceiling 1"]
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert [m.name for m in ceiling.data.materials] == ["lamp"] and sorted(_converted(scene)) == names


def test_a_reduction_of_lamps_has_nothing_to_convert(addon, tmp_path):
    """Reduce of two lamps: the configuration's lights are the scene's own lamps (their Power set):
    nothing of Relight's to make the artist's; refused, nothing written (no empty collection)."""
    from test_hostile_ownership import build

    bpy.ops.wm.open_mainfile(filepath=_reduced(tmp_path, build, "lamps"))
    before = snapshot()
    with pytest.raises(RuntimeError, match="no light of Relight.s to make yours"):
        bpy.ops.relight.make_area_lights()
    assert snapshot() == before
