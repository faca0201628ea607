"""`reduce` with the scene's lamps as the emitters (issue 16, item 3): what the written copy holds
and how it is given back (bpy, no render).

A room with a window, a grey World, an emissive panel and lamps of every case: two Point lamps
sharing one Light data-block, a coloured Point lamp, a Spot, a Sun through the window, and a
lamp behind a wall that lights no face. Evidence: the files themselves, reopened -- the lamps'
Power, colour and switches as the report says, the user's values back after Clear Results
(exactly, the shared data-block shared again), a lamp moved after the solve refused before
anything is written, and a new job on the written copy seeing the lamps as the user set them.
"""
import contextlib
import json
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import cycles_reference as cr  # noqa: E402
import lit_rooms  # noqa: E402
import relight_scene  # noqa: E402

FAST = ["--rays-per-patch", "512", "--quiet"]
#: the red lamp's Power and Exposure (Blender 4.5 on; 4.2 lacks them): Cycles emits colour x Power x 2^Exposure
EXPOSURE = "exposure" in bpy.types.Light.bl_rna.properties
RED_POWER = dict(energy=20.0, exposure=1.0) if EXPOSURE else dict(energy=40.0)


def build(path):
    lit_rooms.uniform_world((0.3, 0.3, 0.3))
    walls = cr._material("walls", (0.6, 0.6, 0.6), lambertian=True)
    W, D, H, n = 3.0, 3.0, 2.5, 3
    for name, o, du, dv in [("floor", (0, 0, 0), (W, 0, 0), (0, D, 0)), ("ceiling", (0, D, H), (W, 0, 0), (0, -D, 0)),
                            ("wall_s", (0, 0, 0), (0, 0, H), (W, 0, 0)), ("wall_n", (0, D, 0), (W, 0, 0), (0, 0, H)),
                            ("wall_w", (0, 0, 0), (0, D, 0), (0, 0, H)), ("wall_e", (W, 0, 0), (0, 0, H), (0, D, 0))]:
        v, f = cr.grid_quads(o, du, dv, n, n)
        if name == "wall_s":
            f = [q for k, q in enumerate(f) if k != 4]  # a window in the middle of the south wall
        cr.add_mesh_object(name, v, f, walls)
    panel = cr._material("panel", (0.5, 0.5, 0.5), emission=(1.0, 1.0, 1.0), strength=3.0, lambertian=True)
    v, f = cr.grid_quads((2.2, 2.2, H - 0.01), (0.4, 0, 0), (0, 0.4, 0), 1, 1)
    cr.add_mesh_object("panel", v, [tuple(reversed(q)) for q in f], panel)  # facing down
    shared = bpy.data.lights.new("shared", "POINT")
    shared.energy, shared.shadow_soft_size = 60.0, 0.05
    light = lit_rooms.light
    light("POINT", (0.7, 0.7, 2.0), name="twin_a", data=shared)
    light("POINT", (2.3, 0.8, 2.0), name="twin_b", data=shared)
    light("POINT", (0.8, 2.2, 1.8), name="red", color=(1.0, 0.3, 0.2), shadow_soft_size=0.05,
          **RED_POWER)  # 40 W emitted in red, from 20 W at Exposure 1 where Blender has it
    light("SPOT", (1.5, 1.5, 2.3), name="spot", energy=150.0, spot_size=math.radians(70), shadow_soft_size=0.0)
    light("SUN", (0, -3, 4), (math.radians(50), 0.0, 0.0), name="sun", energy=2.0, angle=math.radians(1))
    light("POINT", (1.5, 4.0, 1.2), name="outside", energy=100.0)  # behind the north wall: lights no face
    bpy.context.scene["relight_max_patch_size"] = 0.5
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def lamps_now():
    return relight_scene.lamps(bpy.data)


@contextlib.contextmanager
def opened(path):
    """The Blender file ``path`` open (its scene); factory settings again afterwards."""
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path))
        yield bpy.context.scene
    finally:
        cr.reset_blender()


@pytest.fixture(scope="module")
def reduced(tmp_path_factory):
    report, out, original = relight_scene.reduce_built(build, tmp_path_factory.mktemp("reduce_lamps"),
                                                       "--max-lights", "3", *FAST)
    return None, report, out, original


def test_the_report_lists_the_lamps_and_the_world(reduced):
    _, r, _, _ = reduced
    assert r["model"]["lights_by_kind"]["lamp"] == 4 and r["model"]["lights_by_kind"]["sun"] == 1
    assert r["model"]["lights_by_kind"]["polygon"] == 1  # the panel
    lamps = {x["name"]: x for x in r["lamps"]}
    assert set(lamps) == {"twin_a", "twin_b", "red", "spot", "sun"}  # "outside" lights no face
    assert any("outside" in w and "light no face" in w for w in r["warnings"])
    assert lamps["red"]["power_before"] == pytest.approx([40.0, 12.0, 8.0])  # what Cycles emits (Exposure 1)
    assert lamps["red"]["energy_before"] == pytest.approx(RED_POWER["energy"])
    assert lamps["sun"]["unit"] == "W/m^2" and lamps["twin_a"]["unit"] == "W"
    assert sum(x["kept"] for x in lamps.values()) <= 3 and r["final"]["n_lights"] <= 3
    assert lamps["red"]["kept"]
    for x in lamps.values():  # what is written gives each channel its predicted power, through the lamp's gain
        assert x["gain"] == pytest.approx([2.0] * 3 if x["name"] == "red" and EXPOSURE else [1.0] * 3)
        if x["kept"]:
            np.testing.assert_allclose(np.array(x["color_after"]) * x["energy_after"] * np.array(x["gain"]),
                                       x["power_after"], rtol=1e-9)
    fixed = {x["name"]: x for x in r["fixed_light"]}
    assert set(fixed) == {"sky"} and fixed["sky"]["kind"] == "world" and 0 < fixed["sky"]["share"] < 1
    assert any("sky" in w and "fixed light" in w for w in r["warnings"])
    assert min(c["relative_error"] for c in r["curve"] if c["n_lights"] == 6) < 1e-9  # the scene: its six lights


def test_the_written_copy_sets_the_kept_lamps_and_disables_the_others(reduced):
    _, r, out, original = reduced
    lamps = {x["name"]: x for x in r["lamps"]}
    with opened(out):
        now = lamps_now()
        assert now["outside"] == original["outside"]  # not in the reduction: untouched
        for name, x in lamps.items():
            data, energy, color, hide_render, hide_viewport, props = now[name]
            assert "relight_lamp_original" in props
            if x["kept"]:
                assert energy == pytest.approx(x["energy_after"], rel=1e-5) and not hide_render and not hide_viewport
                np.testing.assert_allclose(color, x["color_after"], atol=1e-5)
                # with the user's Exposure kept, Cycles emits colour x Power x 2^Exposure: the solved power
                ld = bpy.data.objects[name].data
                emitted = np.array(ld.color) * ld.energy * 2.0 ** getattr(ld, "exposure", 0.0)
                np.testing.assert_allclose(emitted, x["power_after"], rtol=1e-5)
                if name == "red" and EXPOSURE:
                    assert ld.exposure == 1.0
            else:
                assert (energy, color) == original[name][1:3] and hide_render and hide_viewport
        if lamps["twin_a"]["kept"] or lamps["twin_b"]["kept"]:  # the shared data-block is not changed for both
            assert now["twin_a"][0] != now["twin_b"][0] or now["twin_a"][1:3] == original["twin_a"][1:3]
        assert bpy.data.lights["shared"].energy == pytest.approx(60.0)
        # the panel's own emission is switched off (the emitters object shows it if kept)
        assert "relight_original_slots" in bpy.data.objects["panel"].data.keys()


def test_clear_results_gives_every_lamp_back(reduced):
    from relight_addon.blender import results

    _, _, out, original = reduced
    with opened(out) as scene:
        results.clear_results(scene)
        assert lamps_now() == original
        assert bpy.data.objects["twin_a"].data is bpy.data.objects["twin_b"].data
        assert not [ld for ld in bpy.data.lights if ld.get("relight_owner") is not None]  # the copies removed


def test_every_row_of_the_curve_applies_and_a_moved_lamp_is_refused(reduced):
    from relight_addon.blender import results
    from relight_addon.pipeline.stored import StoredResult

    _, r, out, _ = reduced
    with opened(out) as scene:
        data = results.load_result(scene)
        again = StoredResult.unpack(data.pack())  # the lamps survive the round trip
        assert again.lamps == data.lamps and np.array_equal(again.light_lamp, data.light_lamp)
        assert [x["name"] for x in data.lamps] == [x["name"] for x in r["lamps"]]
        for row in range(len(data.n_lights)):  # the add-on's list: each row shows its lamps
            results.apply_stored_point(scene, row)
            lit = np.any(data.exitance[row] > 0, axis=1)
            on = {o.name for o in bpy.data.objects if o.type == "LIGHT" and not o.hide_render} - {"outside"}
            assert on == {data.lamps[data.light_lamp[j]]["name"] for j in np.flatnonzero(lit & (data.light_lamp >= 0))}
        before = lamps_now()
        bpy.data.objects["red"].location.x += 0.3
        with pytest.raises(results.StaleResult, match="lamp 'red' has changed since the solve .it moved"):
            results.apply_stored_point(scene, 0)
        assert lamps_now() == before  # nothing written
        bpy.data.objects["red"].location.x -= 0.3
        if EXPOSURE:  # what it emits changed: its Exposure
            bpy.data.objects["red"].data.exposure = 2.0
            with pytest.raises(results.StaleResult, match=r"lamp 'red' has changed since the solve .it emits \[80"):
                results.apply_stored_point(scene, 0)
            assert lamps_now() == before
            bpy.data.objects["red"].data.exposure = 1.0
        results.clear_shown(scene)  # every lamp as the user set it
        bpy.data.objects["spot"].hide_render = True  # the user's own switch, after the solve
        with pytest.raises(results.StaleResult, match="lamp 'spot' has changed since the solve .it is disabled"):
            results.apply_stored_point(scene, 0)


def test_a_new_job_on_the_written_copy_sees_the_lamps_as_the_user_set_them(reduced, tmp_path):
    """Every new result replaces the shown one (Clear first), so the export reads a lamp the shown
    reduction changed as it was: reduce again on the copy starts from the user's six lights."""
    from relight_addon import cli

    _, r, out, _ = reduced
    rep = tmp_path / "again.json"
    assert cli.main(["reduce", str(out), "--report", str(rep), "--max-lights", "2", *FAST]) == 0
    again = json.loads(rep.read_text())
    before = {x["name"]: x["power_before"] for x in r["lamps"]}
    assert {x["name"]: x["power_before"] for x in again["lamps"]} == before


def test_a_scene_whose_lamps_light_nothing_is_refused(tmp_path, run_cli):
    cr.reset_blender()
    v, f = cr.grid_quads((0, 0, 0), (1, 0, 0), (0, 1, 0), 2, 2)
    cr.add_mesh_object("floor", v, f, cr._material("grey", (0.5, 0.5, 0.5), lambertian=True))
    lit_rooms.light("POINT", (0.5, 0.5, -1.0), name="below", energy=100.0)  # under the one-sided floor
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "dark.blend"))
    code, _, err = run_cli(["reduce", tmp_path / "dark.blend", "--report", tmp_path / "r.json", *FAST])
    assert code == 2 and "no lamp lights any face (below)" in err, err


def test_the_lamp_state_marks_its_copies_as_relight_made():
    from relight_addon.blender import lamp_state, visibility

    assert lamp_state.OWNER_PROP == visibility.RELIGHT_OWNER_PROP



def test_the_add_on_clicks_through_the_curve_and_clears(reduced):
    """With the add-on registered: the curve list is rebuilt from the written copy; selecting a
    row (the list's click) shows its lamps; the Clear Results operator gives every lamp back."""
    import relight_addon
    from relight_addon.blender import results

    _, _, out, original = reduced
    relight_addon.register()
    try:
        with opened(out) as scene:
            settings = scene.relight
            data = results.load_result(scene)
            assert len(settings.curve) == len(data.n_lights)
            for k in range(len(settings.curve)):
                settings.curve_index = k  # what a click in the list does (its update callback applies it)
                on = {o.name for o in bpy.data.objects if o.type == "LIGHT" and not o.hide_render} - {"outside"}
                kept = np.flatnonzero(np.any(data.exitance[k] > 0, axis=1) & (data.light_lamp >= 0))
                assert on == {data.lamps[data.light_lamp[j]]["name"] for j in kept}, k
                assert len(kept) <= settings.curve[k].n_lights
            assert bpy.ops.relight.clear_results() == {"FINISHED"}
            assert lamps_now() == original
    finally:
        relight_addon.unregister()


def test_a_result_stored_before_lamps_were_lights_reads_as_without_lamps(reduced):
    """A stored result of the earlier layout (no lamps_json, no light_lamp) reads back with no
    lamp; one that lacks anything else is still refused."""
    import base64
    import io
    import zlib

    from relight_addon.blender import results
    from relight_addon.pipeline.stored import StoredResult

    def without(text, *keys):
        with np.load(io.BytesIO(zlib.decompress(base64.b64decode(text)))) as z:
            arrays = {k: z[k] for k in z.files if k not in keys}
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        return base64.b64encode(zlib.compress(buf.getvalue())).decode("ascii")

    _, _, out, _ = reduced
    with opened(out) as scene:
        text = results.load_result(scene).pack()
    old = StoredResult.unpack(without(text, "lamps_json", "light_lamp"))
    assert old.lamps == [] and np.all(old.light_lamp == -1)
    with pytest.raises(ValueError, match="lacks objects"):
        StoredResult.unpack(without(text, "objects_json"))
