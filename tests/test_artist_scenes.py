"""Relight on a scene modelled the way artists model (tests/artist_scenes.py): walls and ceiling
as one cube of big quads, dense props with modifiers, default Principled materials, Cycles'
default settings. Through the real command line (in-process), with the adaptive patch model:
the report's contract (issue 7, part 4), lights smaller than the artist's polygons that lie on
the candidate surfaces, a model much smaller than the mesh, and re-solving a solved file."""
import math

import numpy as np
import pytest

from conftest import file_digest

bpy = pytest.importorskip("bpy", reason="needs bpy (Blender as a Python module)")

import artist_scenes  # noqa: E402


@pytest.fixture(scope="module")
def room_file(tmp_path_factory):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    artist_scenes.living_room(detail=1)
    tris = artist_scenes.triangle_count()
    path = tmp_path_factory.mktemp("artist") / "living_room.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return path, tris


@pytest.fixture(scope="module")
def solved(room_file, tmp_path_factory):
    from relight_addon import cli

    path, tris = room_file
    tmp = tmp_path_factory.mktemp("solved")
    before = file_digest(path)
    report, out = tmp / "r.json", tmp / "out.blend"
    code = cli.main(["solve", str(path), "--report", str(report), "--out", str(out), "--patch-model", "adaptive",
                     "--rays-per-patch", "1024", "--selection", "nnls-greedy"])
    assert code == 0
    import json

    r = json.loads(report.read_text())
    assert file_digest(path) == before  # the input is never written
    return r, out, tris


def test_report_contract(solved):
    r, _, tris = solved
    assert r["scene"]["triangles"] >= 0.9 * tris and r["scene"]["patches"] > 0
    assert r["inverse"]["n_candidates"] >= 100  # cells, groups and whole polygons on 5 quads
    from relight_addon.engine.registry import LIGHT_KINDS

    kinds = set(LIGHT_KINDS.names())
    assert {"cell", "group", "polygon", "lamp", "sun", "spot", "area", "point"} <= kinds
    assert set(r["model"]["lights_by_kind"]) == kinds  # every registered kind listed
    assert r["model"]["lights_by_kind"]["lamp"] == r["model"]["lights_by_kind"]["sun"] == 0  # the scene's: reduce only
    assert r["model"]["lights_by_kind"]["spot"] > 0  # candidate lamps beside the cells (issue 17)
    fin = r["final"]
    assert 1 <= len(fin["lights"]) <= 3
    for li in fin["lights"]:
        assert set(li) >= {"object", "polygons", "center", "normal", "area", "exitance", "power", "kind"}
        if li["kind"] in ("spot", "area", "point"):  # a lamp placed in front of the walls or the ceiling
            assert li["exitance"] is None and min(li["strength"]) >= 0 and li["power"] == pytest.approx(
                sum(li["strength"]))
            assert set(li) >= {"location", "direction", "color", "energy"}
            continue
        assert li["object"] == "Room"  # only the walls and the ceiling may emit
        assert li["polygons"] and all(0 <= p < 5 for p in li["polygons"])
        assert np.linalg.norm(li["normal"]) == pytest.approx(1.0)
        assert li["area"] > 0 and min(li["exitance"]) >= 0
        assert li["power"] == pytest.approx(sum(li["exitance"]) * li["area"], rel=1e-9)
    for name, o in r["objects"].items():
        assert len(o["radiosity"]) == len(o["target"]) == len(o["exitance"])
        assert all(all(math.isfinite(x) for x in row) for row in o["radiosity"])


def test_model_smaller_than_the_mesh_and_lights_smaller_than_polygons(solved):
    r, _, tris = solved
    assert r["scene"]["patches"] < r["scene"]["triangles"] / 3
    # a wall is 5 x 2.7 m: cells (and 2 x 2 groups) are far smaller than the polygon they lie on
    assert min(li["area"] for li in r["final"]["lights"]) < 5.0


def test_out_file_shows_the_lights_and_resolves_without_counting_them(solved, tmp_path):
    from relight_addon import cli
    from relight_addon.blender import blend_files
    from relight_scene import emitted, emitted_power

    r, out, _ = solved
    blend_files.open_blend(str(out))
    em = emitted(bpy.context.scene)
    cells = [li for li in r["final"]["lights"] if li["exitance"] is not None]
    assert (em is not None) == bool(cells)
    if cells:
        power = np.sum([np.asarray(li["exitance"]) * li["area"] for li in cells], axis=0)
        np.testing.assert_allclose(emitted_power(bpy.context.scene), power, rtol=1e-4)
    lamps = {o.name for o in bpy.data.objects if o.type == "LIGHT" and o.get("relight_owner")}
    assert lamps == {li["object"] for li in r["final"]["lights"] if li["exitance"] is None}
    # the artist's Room mesh is untouched: its 5 polygons, no Relight material on it
    room = bpy.data.objects["Room"]
    assert len(room.data.polygons) == 5 and all(not m.get("relight_owner") for m in room.data.materials)
    # solving the solved file again: Relight's emitters are not scene light, nor exported
    code = cli.main(["solve", str(out), "--report", str(tmp_path / "r2.json"), "--patch-model", "adaptive",
                     "--rays-per-patch", "1024", "--selection", "nnls-greedy"])
    assert code == 0
    import json

    r2 = json.loads((tmp_path / "r2.json").read_text())
    assert "Relight Emitters" not in r2["objects"]
    assert not any("background light" in w for w in r2["warnings"])  # nor its lamps (issue 17)
    assert not [row for row in r2["fixed_light"] if row["kind"] != "emission"]
    assert r2["scene"]["patches"] == r["scene"]["patches"]
