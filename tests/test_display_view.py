"""The Results panel's View (issue 36, item 2): exposure, false colours and their view transform,
in the installed add-on on a solved scene (blender/ui/display.py).

Scene: issue 17's gallery (tests/artist_scenes.py) with a crate linked from a library file, solved
once by the CLI (``--out``), opened with the add-on registered. Evidence: the ``relight_display``
colours on each face are the bpy-free view's (pipeline/false_colour.py) for that face, and its
illuminance on the painted floor averages to what the solve's report says there (report.py's
target_photometry, its own code); the predicted view at +2 EV is the radiosity layer x 4; the
scene's view transform is Standard while a false colour is shown in held viewports and exactly the
artist's (AgX, Punchy, exposure 1.5, gamma 1.2) after the predicted view, Hide Radiosity and Clear
Results; another row of the curve rewrites the layer; Clear Results removes it; the linked crate is
skipped and named.
"""
import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon import cli  # noqa: E402
from relight_addon.blender import layers, meshes, results  # noqa: E402
from relight_addon.pipeline import false_colour as fc  # noqa: E402

ARTIST = {"view_transform": "AgX", "look": "AgX - Punchy", "exposure": 1.5, "gamma": 1.2}


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    d = tmp_path_factory.mktemp("display")
    cr.reset_blender()
    s = 0.3  # a crate on the floor, in a library file
    v = [(x, y, z) for z in (0.0, 2 * s) for y in (-s, s) for x in (-s, s)]
    f = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    crate = cr.add_mesh_object("Crate", [(x + 1.5, y - 1.0, z) for x, y, z in v], f,
                               cr._material("CrateWood", (0.5, 0.4, 0.3), lambertian=True))
    crate["relight_no_lights"] = True
    lib = d / "lib.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(lib))
    cr.reset_blender()
    artist_scenes.gallery()
    with bpy.data.libraries.load(str(lib), link=True) as (_, dst):
        dst.objects = ["Crate"]
    bpy.context.scene.collection.objects.link(dst.objects[0])
    blend, out, rep = d / "gallery.blend", d / "out.blend", d / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["solve", str(blend), "--out", str(out), "--report", str(rep), "--quiet", "--seed", "1"]) == 0
    cr.reset_blender()
    return out, json.loads(rep.read_text())


@pytest.fixture
def scene(addon, solved):
    bpy.ops.wm.open_mainfile(filepath=str(solved[0]))
    sc = bpy.context.scene
    for k, value in ARTIST.items():
        setattr(sc.view_settings, k, value)
    assert _colour_management(sc) == pytest.approx(ARTIST)
    return sc


def _colour_management(sc):
    vs = sc.view_settings
    return {"view_transform": vs.view_transform, "look": vs.look, "exposure": vs.exposure, "gamma": vs.gamma}


def _hold(sc):
    """The viewports held by Relight, as viewport.show_radiosity remembers them (headless: no window)."""
    sc.relight.view_restore = json.dumps({"Layout/0": {"type": "SOLID", "color_type": "MATERIAL"}})


def _corners(ob, name):
    me = ob.data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    me.color_attributes[name].data.foreach_get("color", col.ravel())
    return col[:, :3]


def _per_face(ob, name):
    """(per polygon colour, whether all its corners agree)."""
    me = ob.data
    col = _corners(ob, name)
    loop_poly = meshes.loop_polygons(me)[0]
    first = meshes.loop_polygons(me)[1]
    return col[first], bool(np.all(np.abs(col - col[first][loop_poly]) <= 1e-6))


def _expected(sc, ob, mode):
    data = results.load_result(sc)
    view = fc.view(data, int(sc["relight_shown"]), mode)
    oi = data.objects.index(ob.name)
    off = data.polygon_offset
    return view, view.values[off[oi]:off[oi + 1]], view.shown[off[oi]:off[oi + 1]], \
        layers.srgb_to_linear(view.colours[off[oi]:off[oi + 1]])


def test_false_colour_faces_are_the_views_values_and_the_floor_reads_the_reports_lux(scene, solved):
    sc, report = scene, solved[1]
    sc.relight_view.mode = "ILLUMINANCE"
    view = None
    for name in ("Floor", "Room", "Painting"):
        ob = sc.objects[name]
        assert ob.data.color_attributes.active_color_name == "relight_display"
        got, flat = _per_face(ob, "relight_display")
        view, lux, shown, want = _expected(sc, ob, "ILLUMINANCE")
        assert flat  # one colour per face
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        assert shown.all()  # every surface here reflects enough to read its light
    assert sc.relight_view.scale_used == view.vmax and view.auto
    # the painted floor strip: its faces' illuminance, area-weighted, is the report's mean there
    floor = sc.objects["Floor"]
    painted = layers.face_flags(floor, "target")
    _, lux, _, _ = _expected(sc, floor, "ILLUMINANCE")
    area = meshes.foreach_array(floor.data.polygons, "area", len(floor.data.polygons), np.float64)
    mean = float((lux[painted] * area[painted]).sum() / area[painted].sum())
    assert mean == pytest.approx(report["targets_photometric"]["Floor"]["illuminance_lx"]["mean"], rel=1e-4)
    # the colour of a face is the scale's colour at its lux, by the legend's rule
    k = int(np.flatnonzero(painted)[0])
    np.testing.assert_allclose(_per_face(floor, "relight_display")[0][k],
                               layers.srgb_to_linear(fc.colours(lux[k], view.vmax)), rtol=1e-5)
    # the linked crate is skipped and named; its mesh is untouched
    crate = sc.objects["Crate"]
    assert crate.data.library is not None and "relight_display" not in crate.data.color_attributes
    assert "Crate: its mesh is linked" in sc.relight_view.message


def test_luminance_difference_and_painted_views(scene):
    sc = scene
    painting = sc.objects["Painting"]
    for mode in ("LUMINANCE", "DIFFERENCE"):
        sc.relight_view.mode = mode
        for ob in (painting, sc.objects["Room"]):
            got, flat = _per_face(ob, "relight_display")
            view, values, shown, want = _expected(sc, ob, mode)
            assert flat
            np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        assert np.all(np.isfinite(values))
    # the difference: the painting is painted, the ceiling is not (grey)
    room = sc.objects["Room"]
    _, values, shown, want = _expected(sc, room, "DIFFERENCE")
    assert not shown[0] and np.allclose(want[0], layers.srgb_to_linear(np.array(fc.NOT_SHOWN)))
    assert sc.relight_view.scale_used > 0
    # the painted view: the painted radiance on painted faces, dark grey elsewhere
    sc.relight_view.mode = "PAINTED"
    got, _ = _per_face(painting, "relight_display")
    data = results.load_result(sc)
    view = fc.view(data, int(sc["relight_shown"]), "PAINTED")
    oi = data.objects.index("Painting")
    np.testing.assert_allclose(got, view.colours[data.polygon_offset[oi]:data.polygon_offset[oi + 1]], rtol=1e-5)
    assert _per_face(room, "relight_display")[0][0] == pytest.approx(fc.UNPAINTED)


def test_exposure_multiplies_the_radiosity_layer_by_two_to_the_ev(scene):
    sc = scene
    sc.relight_view.exposure = 2.0
    for name in ("Floor", "Room"):
        ob = sc.objects[name]
        assert ob.data.color_attributes.active_color_name == "relight_display"
        np.testing.assert_allclose(_corners(ob, "relight_display"), 4.0 * _corners(ob, "relight_radiosity"),
                                   rtol=1e-5, atol=1e-7)
    sc.relight_view.exposure = 0.0  # the radiosity layer itself again
    for name in ("Floor", "Room"):
        colors = sc.objects[name].data.color_attributes
        assert "relight_display" not in colors and colors.active_color_name == "relight_radiosity"


def test_view_transform_is_standard_in_false_colour_and_the_artists_after(scene):
    sc = scene
    v = sc.relight_view
    # not in held viewports: the layer, but the artist's view transform stays
    v.mode = "ILLUMINANCE"
    assert _colour_management(sc) == pytest.approx(ARTIST) and not v.transform_restore
    _hold(sc)
    v.mode = "LUMINANCE"
    assert _colour_management(sc) == pytest.approx({"view_transform": "Standard", "look": "None", "exposure": 0.0,
                                                    "gamma": 1.0})
    v.mode = "DIFFERENCE"  # (another false colour: still the artist's remembered)
    v.mode = "PREDICTED"
    assert _colour_management(sc) == pytest.approx(ARTIST) and not v.transform_restore
    # Hide Radiosity gives it back
    v.mode = "ILLUMINANCE"
    assert sc.view_settings.view_transform == "Standard"
    assert bpy.ops.relight.show_radiosity(action="HIDE") == {"FINISHED"}
    assert _colour_management(sc) == pytest.approx(ARTIST)
    # the artist sets another transform while a false colour is shown: theirs stays
    _hold(sc)
    v.mode = "LUMINANCE"
    sc.view_settings.view_transform = "Filmic"
    v.mode = "PAINTED"
    assert sc.view_settings.view_transform == "Filmic" and not v.transform_restore
    for k, value in ARTIST.items():
        setattr(sc.view_settings, k, value)
    # Clear Results gives it back, and removes the layer: the active colour is the artist's again
    _hold(sc)
    v.mode = "DIFFERENCE"
    assert sc.view_settings.view_transform == "Standard"
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert _colour_management(sc) == pytest.approx(ARTIST)
    for ob in sc.objects:
        if ob.type == "MESH" and ob.data.library is None:
            names = [a.name for a in ob.data.color_attributes]
            assert "relight_display" not in names and "relight_radiosity" not in names, ob.name
            assert ob.data.color_attributes.active_color_name in (None, "", "relight_target"), ob.name


def test_another_row_rewrites_the_layer(scene):
    sc = scene
    sc.relight_view.mode = "ILLUMINANCE"
    floor = sc.objects["Floor"]
    before = _per_face(floor, "relight_display")[0]
    first = int(sc["relight_shown"])
    other = next(k for k in range(len(sc.relight.curve)) if k != sc.relight.curve_index)
    sc.relight.curve_index = other  # a click on another row of the list
    assert int(sc["relight_shown"]) != first and not sc.relight.apply_error
    after, flat = _per_face(floor, "relight_display")
    _, _, _, want = _expected(sc, floor, "ILLUMINANCE")
    assert flat and floor.data.color_attributes.active_color_name == "relight_display"
    np.testing.assert_allclose(after, want, rtol=1e-5, atol=1e-6)
    assert np.abs(after - before).max() > 1e-3  # another configuration lights the floor otherwise


def test_a_view_that_cannot_be_shown_says_why_and_writes_nothing(scene):
    import dataclasses

    import bmesh

    sc = scene
    # a result stored before the reflectance was kept: no illuminance, the other views still
    data = results.load_result(sc)
    sc[results.RESULT_PROP] = dataclasses.replace(data, patch_reflectance=None).pack()
    results._cache.clear()
    sc.relight_view.mode = "ILLUMINANCE"
    assert "Illuminance (lx) not shown" in sc.relight_view.message and "solve again" in sc.relight_view.message
    assert not any("relight_display" in ob.data.color_attributes for ob in sc.objects if ob.type == "MESH")
    sc.relight_view.mode = "LUMINANCE"
    assert "not shown:" not in sc.relight_view.message and "relight_display" in sc.objects["Floor"].data.color_attributes
    # a mesh changed since the solve: named, every layer off, nothing half written
    me = sc.objects["Painting"].data
    bm = bmesh.new()
    bm.from_mesh(me)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context="FACES")
    bm.to_mesh(me)
    bm.free()
    sc.relight_view.mode = "DIFFERENCE"
    assert "Painting has changed since the solve" in sc.relight_view.message
    assert not any("relight_display" in ob.data.color_attributes for ob in sc.objects if ob.type == "MESH")
