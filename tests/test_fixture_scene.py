"""Catalogue fixtures in the add-on (issue 39, item 5): a solve offered the built-in library (the sidebar's
Fixtures field) writes its fixtures as Point Lights with an IES Texture node holding the fixture's LM-63
(an internal text, owned by the result); the sidebar lists the fixture schedule; the curve's rows, Clear,
Keep Lamps and a kept fixture read back by the next export work for them as for the spots; --keep makes
them from a report.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_hostile import _reset, _room, _save, addon, assert_scene_finite  # noqa: E402,F401

from relight_addon.engine.photometry import library as lib  # noqa: E402
from relight_addon.pipeline.report import SCHEDULE_LINE  # noqa: E402

LM63 = {f.name: f.lm63 for f in lib.load_library(lib.BUILTIN)}


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    _reset()
    _room()
    path = _save(tmp_path_factory.mktemp("fixtures") / "room.blend")
    _reset()
    return path


def _solve(room):
    bpy.ops.wm.open_mainfile(filepath=room)
    s = bpy.context.scene.relight
    s.rays_per_patch, s.surface_lights, s.spot_lamps, s.fixtures = 256, False, False, "builtin"
    assert bpy.ops.relight.solve() == {"FINISHED"}
    return bpy.context.scene


def _fixtures(scene):
    return [o for o in scene.objects if o.type == "LIGHT" and o.data.node_tree is not None
            and any(n.type == "TEX_IES" for n in o.data.node_tree.nodes)]


def _check_ies(ob):
    """Its node tree is the one blender/ies_nodes reads, holding a built-in fixture's LM-63."""
    from relight_addon.blender import ies_nodes

    got = ies_nodes.photometric(ob.data, ob.name)
    assert got is not None and np.allclose(got.gain, 1.0)
    node = next(n for n in ob.data.node_tree.nodes if n.type == "TEX_IES")
    assert node.mode == "INTERNAL" and node.ies.as_string() in LM63.values()


def test_the_fixtures_are_written_with_their_ies_nodes_and_listed(addon, room):
    scene = _solve(room)
    placed = _fixtures(scene)
    assert placed and all("relight_owner" in o and "relight_owner" in o.data for o in placed)
    for ob in placed:
        _check_ies(ob)
        assert "relight_owner" in ob.data.node_tree.nodes["IES Texture"].ies
    schedule = [ln for ln in scene.relight.last_lights.split("\n") if ln.startswith(SCHEDULE_LINE + "\t")]
    assert schedule and schedule[-1].startswith(f"{SCHEDULE_LINE}\tin all {len(placed)} fixtures: ")
    texts = len(bpy.data.texts)
    assert texts == len(placed)
    # every row of the curve: its own fixtures, the previous ones and their texts gone
    for k in range(len(scene.relight.curve)):
        assert bpy.ops.relight.apply_configuration(index=k) == {"FINISHED"}
        shown = _fixtures(scene)
        assert len(shown) == scene.relight.curve[k].n_lights
        assert len(bpy.data.texts) == len(shown)
        for ob in shown:
            _check_ies(ob)
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert not [o for o in scene.objects if o.type == "LIGHT"] and not len(bpy.data.texts)
    assert_scene_finite()


def test_kept_fixtures_keep_their_node_and_are_the_scenes_light(addon, room):
    from relight_addon.blender import export

    scene = _solve(room)
    placed = _fixtures(scene)
    power = sorted(o.data.energy for o in placed)
    assert bpy.ops.relight.keep_lamps() == {"FINISHED"}
    kept = _fixtures(scene)
    assert len(kept) == len(placed) and all(o.name.endswith(" (kept)") for o in kept)
    assert sorted(o.data.energy for o in kept) == pytest.approx(power)
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    kept = _fixtures(scene)  # Clear keeps them, and their texts
    assert len(kept) == len(placed) and len(bpy.data.texts) == len(kept)
    for ob in kept:
        _check_ies(ob)
    faces = export.export_scene(bpy.context).faces
    assert sorted(lamp.name for lamp in faces.lamps) == sorted(o.name for o in kept)
    assert {lamp.kind.name for lamp in faces.lamps} == {"photometric"}  # a scene fixture: fixed light
    assert_scene_finite()


def test_keep_from_a_report_writes_the_fixture(addon, room, tmp_path):
    """A report's fixtures kept (pipeline.kept: --keep's records, each with its LM-63): results.new_lamp
    writes them with their IES node at the report's Power."""
    from lit_rooms import relight

    from relight_addon.blender import results
    from relight_addon.pipeline.kept import kept_lamps

    report = relight("solve", room, tmp_path / "r.json", "--rays-per-patch", "256", "--fixtures", "builtin",
                     "--no-spot-lamps", "--no-surface-lights")
    mine = [li for li in report["final"]["lights"] if li["kind"] == "fixture"]
    assert mine and report["fixture_schedule"]
    records, notes = kept_lamps(report)
    assert not notes and [r["fixture"] for r in records] == [li["fixture"] for li in mine]
    bpy.ops.wm.open_mainfile(filepath=room)
    names = results.add_kept_lamps(bpy.context.scene, records)
    for name, li in zip(names, mine):
        ob = bpy.data.objects[name]
        _check_ies(ob)
        assert ob.data.energy == pytest.approx(li["energy"], rel=1e-6)
        assert next(n for n in ob.data.node_tree.nodes if n.type == "TEX_IES").ies.as_string() == li["ies_lm63"]


def test_live_follows_a_stroke_with_fixtures(addon, tmp_path):
    """Live with the fixtures offered (issue 20's Live, issue 37's later answers): its first answer (a
    full solve) and a stroke's answers are written as fixtures with their IES nodes, no text left behind
    by the answers they replace."""
    from test_hostile import _grid, _mesh, _paint
    from test_live import _run
    from test_prepared import _stroke

    from relight_addon.blender import live, preparation
    from relight_addon.blender.ui import operators

    _reset()
    fv, ff = _grid(4, size=2.0)
    floor = _mesh("floor", fv, ff)
    floor["relight_no_lights"] = True
    _paint(floor, polys=[0, 1, 4, 5])
    cv, cf = _grid(2, size=2.0, z=1.5, flip=True)
    _mesh("ceiling", cv, cf)
    path = _save(tmp_path / "live.blend")
    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    st = scene.relight
    st.rays_per_patch, st.surface_lights, st.spot_lamps, st.fixtures = 256, False, False, "builtin"
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    try:
        _run(s, lambda: s.updates == 1)
        first = _fixtures(scene)
        assert first and len(bpy.data.texts) == len(first)
        _stroke(4, "floor")
        _run(s, lambda: s.updates == 2)
        _run(s, lambda: s.worker is None and s.to_refine is None)
        shown = _fixtures(scene)
        assert shown and len(bpy.data.texts) == len(shown)
        for ob in shown:
            _check_ies(ob)
        assert any(ln.startswith(SCHEDULE_LINE + "\t") for ln in st.last_lights.split("\n"))
    finally:
        live.stop(scene.name)
    assert_scene_finite()
