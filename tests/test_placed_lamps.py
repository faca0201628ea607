"""Lamps as answers (issue 17): issue 17's gallery solved with the default candidates, and the lamps
the solve placed written back as real Blender lights (bpy, no render; Cycles: test_cycles_lamps.py).

The gallery (tests/artist_scenes.gallery): a painting painted bright, a band of wall around it dim,
a floor strip; only the ceiling may hold lights. Evidence: the two solves' reports (with and without
candidate lamps), and the written copy reopened -- Light objects of Relight's in a collection of its
own, as the report lists them (their power per channel, cone, orientation); every row of the curve
applied shows its own lamps; Clear Results leaves the user's scene as it was; Make Area Lights
copies them for keeps, and the export then reads those copies as the lamps the solve placed; a new
solve of the written copy does not count Relight's own lamps as the scene's light.
"""
import contextlib
import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon import cli  # noqa: E402
from relight_addon.blender.lamps import cycles_gain  # noqa: E402
from relight_addon.engine.light_colour import blackbody_rec709  # noqa: E402

FAST = ["--quiet", "--seed", "1"]
NO_LAMPS = ["--no-spot-lamps"]  # (area and point lamps are off by default)
OWNER = "relight_owner"


def _solve(blend, folder, name, *extra):
    report, out = folder / f"{name}.json", folder / f"{name}.blend"
    code = cli.main(["solve", str(blend), "--report", str(report), "--out", str(out), *FAST, *extra])
    assert code == 0
    return json.loads(report.read_text()), out


@pytest.fixture(scope="module")
def gallery(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gallery")
    blend = folder / "gallery.blend"
    cr.reset_blender()
    try:
        artist_scenes.gallery()
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
        objects = sorted(o.name for o in bpy.data.objects)
    finally:
        cr.reset_blender()
    cells, _ = _solve(blend, folder, "cells", *NO_LAMPS)
    report, out = _solve(blend, folder, "lamps")
    return {"blend": blend, "cells": cells, "report": report, "out": out, "objects": objects, "folder": folder}


@contextlib.contextmanager
def written(gallery):
    """The written copy open: (its scene, {lamp object: the report's record of it})."""
    lamps = {li["object"]: li for li in gallery["report"]["final"]["lights"] if li["exitance"] is None}
    try:
        bpy.ops.wm.open_mainfile(filepath=str(gallery["out"]))
        yield bpy.context.scene, lamps
    finally:
        cr.reset_blender()


def _lamps_of_row(data, row):
    """The names of the placed lamps on in stored configuration ``row``, sorted."""
    from relight_addon.engine.registry import LIGHT_KINDS

    names = LIGHT_KINDS.names()
    on = np.flatnonzero(np.any(data.exitance[row] > 0, axis=1))
    return sorted(data.lamps[int(data.light_lamp[j])]["name"] for j in on
                  if names[data.light_kind[j]] in ("spot", "area", "point"))


def _placed(scene):
    rid = scene["relight_result_id"]
    return {o.name: o for o in scene.objects if o.type == "LIGHT" and o.get(OWNER) == rid}


def test_the_gallery_answers_with_a_spot_well_below_what_cells_allow(gallery):
    cells, r = gallery["cells"], gallery["report"]
    assert cells["final"]["n_lights"] <= 3 and r["final"]["n_lights"] == 3
    assert all(li["kind"] in ("cell", "group", "polygon") for li in cells["final"]["lights"])
    kinds = [li["kind"] for li in r["final"]["lights"]]
    assert "spot" in kinds, kinds
    print(f"gallery, 3 lights: cells only {cells['final']['relative_error']:.3f} (certificate "
          f"{cells['final']['bound_relative_error']:.3f}), with candidate lamps {r['final']['relative_error']:.3f} "
          f"({kinds}); lights by kind {r['model']['lights_by_kind']}")
    assert cells["final"]["relative_error"] > 0.8  # diffuse ceiling light cannot tell the painting from the wall
    assert r["final"]["relative_error"] < 0.4 * cells["final"]["relative_error"]
    from relight_addon.pipeline.report import kinds_text

    assert "spot" in kinds_text(r).split("chose")[1] and f"{r['model']['lights_by_kind']['spot']} spot" in kinds_text(r)
    by_kind = r["model"]["lights_by_kind"]
    assert by_kind["spot"] > 0 and by_kind["cell"] == cells["model"]["lights_by_kind"]["cell"]
    assert sum(by_kind[k] for k in ("spot", "area", "point")) <= 96  # --max-lamps' default
    painting = np.array(r["objects"]["Painting"]["radiosity"])[0]
    # the painting gets (nearly) what was painted: grey 1.2 on the canvas (0.6, 0.55, 0.5) is that
    # luminance on the canvas' own colour (engine/paint.py), 1.2 pi (1.08, 0.99, 0.90) W/m^2
    from relight_addon.engine.paint import neutral_as_brightness

    asked = neutral_as_brightness([True], [[1.2 * np.pi] * 3], [[0.6, 0.55, 0.5]])[0]
    assert np.all(np.abs(painting / asked - 1) < 0.15), (painting, asked)
    # Lambertian materials: the view along the normal shows B / pi, the spots' light included
    for name in ("Painting", "Room", "Floor"):
        o = r["objects"][name]
        for b, lv, t in zip(o["radiosity"], o["radiance_normal"], o["target"]):
            if t is not None:
                np.testing.assert_allclose(lv, np.asarray(b) / np.pi, rtol=0.02, atol=1e-4)
    for li in r["final"]["lights"]:
        if li["kind"] == "spot":  # a cone that just covers the painting or a part of it: a narrow one
            assert 2 < li["cone_angle_deg"] < 40 and li["location"][2] < artist_scenes.GALLERY[2]
            assert np.allclose(np.linalg.norm(li["direction"]), 1) and li["direction"][1] > 0  # toward the north wall
            # Cycles emits colour x Power, times the Temperature's colour for a blackbody light
            gain = blackbody_rec709(li["temperature_K"]) if "temperature_K" in li else 1.0
            np.testing.assert_allclose(np.array(li["color"]) * li["energy"] * gain, li["strength"], rtol=1e-9)
            assert li["power"] == pytest.approx(sum(li["strength"]))


def test_the_written_copy_holds_the_lamps_as_reported(gallery):
    with written(gallery) as (scene, lamps):
        placed = _placed(scene)
        assert sorted(placed) == sorted(lamps)
        coll = next(c for c in bpy.data.collections if c.get(OWNER) == scene["relight_result_id"])
        assert coll.name.startswith("Relight Lamps") and sorted(o.name for o in coll.objects) == sorted(lamps)
        for name, li in lamps.items():
            ob, ld = placed[name], placed[name].data
            assert ld.type == li["type"].upper() and ld.get(OWNER) == scene["relight_result_id"]
            M = np.array(ob.matrix_world)
            # what Cycles emits: colour x Power x the Light's gain (its Temperature's colour, for a blackbody light)
            np.testing.assert_allclose(np.array(ld.color) * ld.energy * cycles_gain(ld, M), li["strength"], rtol=1e-5)
            np.testing.assert_allclose(M[:3, 3], li["location"], atol=1e-5)
            np.testing.assert_allclose(-M[:3, 2], li["direction"], atol=1e-5)
            if ld.type == "SPOT":
                assert ld.spot_size == pytest.approx(li["spot_size"], rel=1e-6)
                assert ld.spot_blend == pytest.approx(li["spot_blend"], abs=1e-6) and ld.shadow_soft_size == 0
            if ld.type == "AREA":
                assert ld.shape == li["shape"] and ld.size == pytest.approx(li["size"][0], rel=1e-6)


def test_every_row_shows_its_own_lamps_and_clear_gives_the_scene_back(gallery):
    from relight_addon.blender import results

    with written(gallery) as (scene, _):
        data = results.load_result(scene)
        for row in range(len(data.n_lights)):
            shown = results.apply_stored_point(scene, row)
            want = _lamps_of_row(data, row)
            assert sorted(_placed(scene)) == want, row
            assert shown["lights"] == int(np.any(data.exitance[row] > 0, axis=1).sum())
            owned = [c for c in bpy.data.collections if c.get(OWNER) is not None]
            assert len(owned) == (1 if want else 0)  # one collection of lamps at a time, none when there are none
        results.clear_results(scene)
        assert sorted(o.name for o in bpy.data.objects) == gallery["objects"]
        assert not [c for c in bpy.data.collections if c.get(OWNER) is not None]
        assert not [ld for ld in bpy.data.lights if ld.get(OWNER) is not None]


def test_make_area_lights_copies_the_lamps_for_keeps_and_the_export_reads_them(gallery):
    from relight_addon.blender import export, results

    r = gallery["report"]
    with written(gallery) as (scene, lamps):
        assert export.export_scene().faces.lamps == []  # Relight's own lamps are not the scene's light
        n_cells = sum(li["exitance"] is not None for li in r["final"]["lights"])
        made = results.make_area_lights(scene, int(scene["relight_shown"]))["names"]
        results.clear_results(scene)
        kept = {o.name: o for o in bpy.data.objects if o.type == "LIGHT"}
        assert sorted(kept) == sorted(made) and len(made) >= len(lamps) + n_cells
        assert not any(o.get(OWNER) for o in kept.values())
        exported = export.export_scene().faces.lamps  # now the user's lamps
        assert len(exported) == len(made)
        got = {}  # each lamp's copy, found by its type and place (it is named after the surface it hangs from)
        for name, li in lamps.items():
            got[name] = next(v for v in exported if v.kind.blender_type == li["type"].upper()
                             and np.allclose(v.position, li["location"], atol=1e-5))
        assert len({id(v) for v in got.values()}) == len(lamps)
        for name, li in lamps.items():
            lamp = got[name]
            np.testing.assert_allclose(lamp.position, li["location"], atol=1e-5)
            np.testing.assert_allclose(lamp.direction, li["direction"], atol=1e-5)
            np.testing.assert_allclose(lamp.power, li["strength"], rtol=1e-5)
            if lamp.kind.blender_type == "SPOT":
                assert lamp.spot_size == pytest.approx(li["spot_size"], rel=1e-6) and lamp.radius == 0
                assert lamp.spot_blend == pytest.approx(li["spot_blend"], abs=1e-6)


def test_a_new_solve_of_the_written_copy_does_not_count_relights_lamps(gallery):
    again, _ = _solve(gallery["out"], gallery["folder"], "again")
    assert not [row for row in again["fixed_light"] if row["kind"] != "emission"]
    assert again["final"]["relative_error"] == pytest.approx(gallery["report"]["final"]["relative_error"], rel=0.02)


def test_the_add_on_clicks_through_the_curve_and_clears(gallery):
    """With the add-on registered: selecting a row of the list (its update callback applies it)
    shows that row's lamps; the Clear Results operator removes them all."""
    import relight_addon
    from relight_addon.blender import results

    relight_addon.register()
    try:
        with written(gallery) as (scene, _):
            settings = scene.relight
            data = results.load_result(scene)
            assert len(settings.curve) == len(data.n_lights)
            for k in reversed(range(len(settings.curve))):
                settings.curve_index = k
                assert sorted(_placed(scene)) == _lamps_of_row(data, k), k
            assert bpy.ops.relight.clear_results() == {"FINISHED"}
            assert sorted(o.name for o in bpy.data.objects) == gallery["objects"]
    finally:
        relight_addon.unregister()
