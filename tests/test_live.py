"""Live mode (issue 20, item 2; blender/live.py) driven tick by tick in a bpy session, as the modal
operator's timer drives it in a window: strokes re-solved off the main thread from the prepared
model, a newer stroke superseding an older re-solve, and the changes it cannot follow pausing it."""
import os
import time

import numpy as np
import pytest

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
import bpy  # noqa: E402

from test_prepared import _clustered_polygons, _stroke  # noqa: E402
from relight_addon.pipeline import prepared  # noqa: E402
from relight_addon.engine.scene_light import scene_light, scene_light_excess  # noqa: E402
from relight_addon.engine.targets import PaintedRadiance  # noqa: E402

SAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "sample_blends")


def _run(s, until, timeout=300, pause=False):
    """Tick (as the modal operator's timer does, with Blender's depsgraph updates in between)
    until ``until()``; a pause fails unless ``pause``."""
    t0 = time.monotonic()
    while not until():
        assert time.monotonic() - t0 < timeout, (s.status, s.paused, s.updates)
        assert pause or not s.paused, s.paused
        bpy.context.view_layer.update()  # Blender evaluates the depsgraph: the update handler runs
        s.tick(bpy.context)
        time.sleep(0.02)


def _shown(scene):
    """The final configuration in the scene: the stored result's exitance of its final row."""
    from relight_addon.blender import results

    data = results.load_result(scene)
    return np.asarray(data.exitance[int(np.flatnonzero(data.point_index == int(data.final))[0])])


def test_live_mode_follows_strokes_from_the_prepared_model(addon):
    from relight_addon.blender import live, preparation, results
    from relight_addon.blender.ui import operators

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    _run(s, lambda: s.updates == 1)  # no prepared model: Live's first answer is a full solve
    state = preparation.PREPARED[scene.name]
    assert state.solves == 1 and state.live_solves == 0 and len(scene.relight.curve)
    first = _shown(scene)
    avoid = _clustered_polygons(state, "flight_1")

    # a stroke in Vertex Paint on the target layer: re-solved live, without a full solve, and the
    # brush keeps its layer (the radiosity layer is written, not made active)
    stairs = bpy.data.objects["flight_1"]
    bpy.context.view_layer.objects.active = stairs
    stairs.data.color_attributes.active_color = stairs.data.color_attributes["relight_target"]
    bpy.ops.object.mode_set(mode="VERTEX_PAINT")
    _stroke(12, "flight_1", avoid)
    _run(s, lambda: s.updates == 2)
    assert stairs.data.color_attributes.active_color_name == "relight_target"
    assert "relight_radiosity" in stairs.data.color_attributes
    # Fill Selected in Edit Mode: followed too (the edit mesh read), and the user left in Edit Mode
    import bmesh

    from relight_addon.blender import export, layers

    taken = set(np.flatnonzero(layers.face_flags(stairs, "target")).tolist()) | set(avoid)
    bpy.ops.object.mode_set(mode="EDIT")
    bm = bmesh.from_edit_mesh(stairs.data)
    for f in bm.faces:
        f.select_set(False)
    free = [f for f in bm.faces if f.index not in taken][-3:]
    for f in free:
        f.select_set(True)
    bmesh.update_edit_mesh(stairs.data)
    assert bpy.ops.relight.fill_targets() == {"FINISHED"}
    _run(s, lambda: s.updates == 3)
    assert bpy.context.mode == "EDIT_MESH" and s.paused is None
    # its later answers wait for the artist's pause (live.LATER_PAUSE): a stroke that comes sooner
    # finds the worker idle, not busy with an answer it would cancel
    shown = time.monotonic()
    _run(s, lambda: s.worker is not None or time.monotonic() - shown > live.LATER_PAUSE / 2)
    assert s.worker is None and s.to_refine is not None and s.to_refine[3] == 0
    # then its later answers (prepared.REFINE_STEPS), each written when better than the one shown
    _run(s, lambda: s.worker is None and s.to_refine is None)
    # (the first stroke's, if the Fill came while they ran, were dropped: cancelled)
    assert state.refined_solves >= s.refined + s.kept_quick >= len(prepared.REFINE_STEPS)
    bpy.ops.object.mode_set(mode="OBJECT")
    assert state.solves == 1 and state.live_solves == 2 and s.status == "up to date"
    second = _shown(scene)
    assert first.shape != second.shape or not np.allclose(first, second), "the lights did not change"
    assert "live answer from the prepared transport" in scene.relight.last_warnings
    # the answer shown is the prepared state's live re-solve of the scene's paint, or a later one
    # better than it
    counts = preparation.PREPARED_JOBS[scene.name].inputs["polygon_counts"]
    answer = state.live(s._faces, counts, key=state.key)
    for step in range(len(prepared.REFINE_STEPS)):
        answer = state.refine_live(answer, step, counts) or answer
    np.testing.assert_allclose(answer.stored.exitance[answer.final_index], second, rtol=1e-6, atol=1e-9)
    assert float(scene.relight.curve[scene.relight.curve_index].relative_error) == pytest.approx(
        answer.report["final"]["relative_error"], rel=1e-6)
    assert "live" in live.status_text(s).lower() and "updated" in live.status_text(s)
    # the later answers written are counted on the sidebar's line (none written: not said)
    assert (f"{s.refined} improved later" in live.status_text(s)) == (s.refined > 0), live.status_text(s)

    # a newer stroke while a re-solve runs supersedes it: only the newest answer is written
    _stroke(6, "flight_1", avoid)
    _run(s, lambda: s.worker is not None)
    painted = s.solving
    _stroke(6, "flight_1", avoid)
    _run(s, lambda: s.updates == 4)
    assert s.superseded == 1 and not np.array_equal(painted[0], s.shown[0])
    assert np.array_equal(s.shown[0], s.paint[0])
    # each tick reads again only the objects the depsgraph updated: what it holds is the paint of
    # every object, as a full read has it
    full = export.repaint(preparation.PREPARED_JOBS[scene.name].exp)
    assert np.array_equal(s.paint[0], full.target) and np.array_equal(s.paint[1], full.target_radiosity)
    written = results.result_id(scene)

    # an object moved: Live cannot follow it; it pauses, says why, and leaves the scene as it was
    bpy.data.objects["ceiling"].location.z += 0.05
    _run(s, lambda: s.paused is not None, timeout=10, pause=True)
    assert "object 'ceiling'" in s.paused and "Solve & Reduce" in s.paused
    _stroke(4, "flight_1", avoid)
    for _ in range(10):
        bpy.context.view_layer.update()
        s.tick(bpy.context)
    _run(s, lambda: s.worker is None, timeout=30, pause=True)  # (a later answer running: cancelled)
    assert results.result_id(scene) == written and s.updates == 4
    # Solve & Reduce prepares again: Live follows the new model
    assert bpy.ops.relight.solve() == {"FINISHED"}
    _run(s, lambda: s.paused is None and s.status == "up to date", timeout=30, pause=True)
    live.stop(scene.name)
    assert live.session(scene) is None and s.status == "off"


def test_stopping_live_drops_a_running_re_solve(addon):
    """ESC or the toggle while a re-solve runs: its answer is never written."""
    from relight_addon.blender import live, preparation, results
    from relight_addon.blender.ui import operators

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    _run(s, lambda: s.updates == 1)
    written = results.result_id(scene)
    _stroke(12, "flight_1", _clustered_polygons(preparation.PREPARED[scene.name], "flight_1"))
    _run(s, lambda: s.worker is not None)
    live.stop(scene.name)
    s.worker.join()
    s.tick(bpy.context)  # a stopped session writes nothing, even if ticked
    assert results.result_id(scene) == written and s.updates == 1


def test_kept_lamps_stay_and_the_next_solve_finds_the_rest(addon):
    """Keep Lamps (issue 20, item 3): the shown lamps become the scene's own (Clear Results and the
    next solve leave them), the next solve keeps them at their place and power (its fixed light)
    and finds Max Lights more around them, its error never below the certificate of the rest."""
    from relight_addon.blender import preparation

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    with pytest.raises(RuntimeError, match="no placed lamp to keep"):  # nothing solved: refused, said
        bpy.ops.relight.keep_lamps()
    assert bpy.ops.relight.solve() == {"FINISHED"}
    placed = {o.name: (tuple(o.matrix_world.translation), o.data.energy, tuple(o.data.color))
              for o in scene.objects if o.type == "LIGHT" and "relight_owner" in o}
    assert placed, "the solve placed no lamp"
    assert bpy.ops.relight.keep_lamps() == {"FINISHED"}
    kept = {n + " (kept)": v for n, v in placed.items()}
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    for name, (loc, energy, color) in kept.items():
        ob = bpy.data.objects[name]
        assert "relight_owner" not in ob and ob.name in scene.collection.objects
        assert np.allclose(ob.matrix_world.translation, loc) and ob.data.energy == energy
    assert bpy.ops.relight.solve() == {"FINISHED"}
    from relight_addon.blender import results

    data = results.load_result(scene)
    fixed = scene.relight.last_fixed_light
    for name, (loc, energy, color) in kept.items():
        ob = bpy.data.objects[name]  # unchanged by the solve, and counted as the scene's light
        assert np.allclose(ob.matrix_world.translation, loc) and ob.data.energy == energy and name in fixed
    # the certificate is of the rest (the candidates, the kept lamps on): the final configuration is
    # never below it, unless its lamps were refined off the candidates (and then the note says so)
    i = int(data.final)
    rel, bound = float(data.curve_relative_error[i]), float(data.curve_bound_relative_error[i])
    assert bound > 0 and (rel >= bound * (1 - 1e-6) or "were refined" in scene.relight.last_warnings), (rel, bound)
    assert f"no {int(data.curve_n_lights[i])} non-negative lights can go below {bound:.3g}" in \
        scene.relight.last_warnings


def test_live_follows_a_kept_lamp_moved_by_hand(addon):
    """A kept lamp moved or set to another power with Live on (issue 20, item 3): the error and the
    layer follow from the prepared transport, with the rest re-solved around it, and no new full
    solve: the kept model's fixed light is the lamp's new direct light, through its factorisation."""
    from relight_addon.blender import live, preparation
    from relight_addon.blender.ui import operators
    from relight_addon.engine.inverse import InverseProblem

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    assert bpy.ops.relight.solve() == {"FINISHED"}
    assert bpy.ops.relight.keep_lamps() == {"FINISHED"}
    kept = next(o for o in scene.objects if o.type == "LIGHT" and o.name.endswith("(kept)"))
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    _run(s, lambda: s.updates == 1)  # the scene as it is now: the kept lamp is the scene's light
    state = preparation.PREPARED[scene.name]
    solves = state.solves
    bg0 = state.model.problem.background_radiosity.copy()
    assert np.any(bg0 > 0) and kept.name in scene.relight.last_fixed_light

    kept.location.x -= 0.3
    _run(s, lambda: s.updates == 2)
    assert state.solves == solves and state.live_solves == 1 and s.paused is None
    model = state.model
    bg1 = model.problem.background_radiosity.copy()
    assert not np.allclose(bg0, bg1)
    # against the fixed light of a problem built anew (the constructor's route) on the same patches
    H, _ = scene_light(model.faces, model.patches, model.form_factors, state.options.seed)
    p = model.patches
    fresh = InverseProblem(model.form_factors, p.area, p.reflectance,
                           [PaintedRadiance.masked(p.target, p.target_radiosity)],
                           model.problem.candidate_mask, p.center, p.normal, lights=model.lights,
                           background=model.background, background_irradiance=H.sum(axis=1),
                           background_excess=scene_light_excess(model.faces, p, H))
    np.testing.assert_allclose(bg1, fresh.background_radiosity, rtol=1e-9, atol=1e-12 * np.abs(bg1).max())

    kept.data.energy *= 2.0  # linear in the lamp's power (the scene has no World light)
    _run(s, lambda: s.updates == 3)
    assert state.solves == solves and state.live_solves == 2
    assert scene.world is None or state.model.faces.world_radiance is None
    np.testing.assert_allclose(state.model.problem.background_radiosity, 2.0 * bg1, rtol=1e-6,
                               atol=1e-9 * np.abs(bg1).max())
    assert "relight_owner" not in kept and kept.name in scene.objects
    live.stop(scene.name)


def test_the_paint_is_read_once_the_stroke_ends():
    """Live reads the paint at the first tick after a stroke (no wait) and never while a brush's
    modal operator runs; where Blender cannot list the modal operators, after QUIET seconds."""
    from types import SimpleNamespace as NS

    from relight_addon.blender import live

    def context(*windows):
        return NS(window_manager=NS(windows=list(windows)))

    def window(*idnames):
        return NS(modal_operators=[NS(bl_idname=i) for i in idnames])

    now = time.monotonic()
    assert not live.stroke_running(context(), now)  # headless: no window, no stroke
    assert not live.stroke_running(context(window("RELIGHT_OT_live")), now)  # Live's own timer
    assert live.stroke_running(context(window("RELIGHT_OT_live", "PAINT_OT_vertex_paint")), now)
    assert live.stroke_running(context(window(), window("SCULPT_OT_brush_stroke")), now)  # another window
    assert not live.stroke_running(context(window("TRANSFORM_OT_translate")), now)
    old = NS(windows=[NS()])  # a Blender without Window.modal_operators: the brush at rest after QUIET
    assert live.stroke_running(NS(window_manager=old), now)
    assert not live.stroke_running(NS(window_manager=old), now - 2 * live.QUIET)


def test_live_pauses_naming_an_object_deleted_or_hidden_and_follows_lamps(addon):
    """Issue 35, cases 13 and 14: an exported object deleted (no ReferenceError) or hidden from
    renders (its own hide_render, its collection excluded) pauses Live naming it, the scene as last
    written; a lamp added, hidden from renders or deleted is followed (counted, then not)."""
    from relight_addon.blender import live, preparation, results
    from relight_addon.blender.ui import operators

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    _run(s, lambda: s.status == "up to date" and s.updates == 1)
    state = preparation.PREPARED[scene.name]
    avoid = _clustered_polygons(state, "flight_1")

    # a lamp added with Live on: counted (the scene's light), followed without a full solve
    ld = bpy.data.lights.new("desk lamp", "POINT")
    ld.energy = 60.0
    lamp = bpy.data.objects.new("desk lamp", ld)
    lamp.location = (2.0, 6.0, 8.5)  # (under the ceiling, z = 9, of the 4 x 8 m stairwell)
    scene.collection.objects.link(lamp)
    _run(s, lambda: s.updates == 2)
    assert "desk lamp" in scene.relight.last_fixed_light and state.live_solves == 1
    bg = state.model.problem.background_radiosity.copy()
    assert np.any(bg > 0)
    lamp.hide_render = True  # hidden from renders: no longer counted
    _run(s, lambda: s.updates == 3)
    assert "desk lamp" not in scene.relight.last_fixed_light
    assert not np.any(state.model.problem.background_radiosity > 0)
    lamp.hide_render = False
    _run(s, lambda: s.updates == 4)
    assert "desk lamp" in scene.relight.last_fixed_light
    bpy.data.objects.remove(lamp)  # deleted: no longer counted
    _run(s, lambda: s.updates == 5)
    assert "desk lamp" not in scene.relight.last_fixed_light and s.paused is None
    assert not np.any(state.model.problem.background_radiosity > 0)

    # the ceiling hidden from renders: Live pauses naming it, writes nothing
    written = results.result_id(scene)
    ceiling = bpy.data.objects["ceiling"]
    ceiling.hide_render = True
    _stroke(4, "flight_1", avoid)
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert s.paused == "object 'ceiling' hidden from renders: Solve & Reduce prepares again", s.paused
    # (a later answer running when the pause came is cancelled at its next check: let it end)
    _run(s, lambda: s.worker is None, timeout=60, pause=True)
    for _ in range(5):
        bpy.context.view_layer.update()
        s.tick(bpy.context)
    assert s.worker is None and results.result_id(scene) == written
    ceiling.hide_render = False
    assert bpy.ops.relight.solve() == {"FINISHED"}
    _run(s, lambda: s.paused is None and s.status == "up to date", timeout=60, pause=True)

    # a wall deleted: paused, named, no ReferenceError (bpy.data.objects.remove, as Delete does)
    written = results.result_id(scene)
    bpy.data.objects.remove(bpy.data.objects["wall_west"])
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert s.paused == "object 'wall_west' deleted: Solve & Reduce prepares again", s.paused
    assert results.result_id(scene) == written
    assert bpy.ops.relight.solve() == {"FINISHED"}
    _run(s, lambda: s.paused is None and s.status == "up to date", timeout=60, pause=True)

    # a collection excluded from the view layer: its meshes named
    coll = bpy.data.collections.new("stairs")
    scene.collection.children.link(coll)
    coll.objects.link(bpy.data.objects["flight_2"])
    scene.collection.objects.unlink(bpy.data.objects["flight_2"])
    _run(s, lambda: s.status == "up to date", timeout=60)
    bpy.context.view_layer.layer_collection.children["stairs"].exclude = True
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert "object 'flight_2' hidden from renders" in s.paused, s.paused
    live.stop(scene.name)


def test_live_follows_or_pauses_on_the_scenes_switches(addon):
    """What Live did not read before: Forbid Selected Faces changes the lights the model may offer,
    which the prepared state cannot follow: Live pauses naming the object (before, it went on
    answering with lights on the forbidden faces and said "up to date"); Solve & Reduce prepares
    again, from scratch, with the ceiling's faces forbidden, and Live follows it. The target scale
    changed is followed (the paint read again with it); an object's work plane switch and the
    scene's patch size pause it, named."""
    from relight_addon.blender import live, preparation
    from relight_addon.blender.ui import operators

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    _run(s, lambda: s.status == "up to date" and s.updates == 1)
    ceiling = bpy.data.objects["ceiling"]
    faces = preparation.PREPARED_JOBS[scene.name].exp.faces
    assert not faces.forbidden[faces.face_object == list(faces.object_names).index("ceiling")].any()
    bpy.context.view_layer.objects.active = ceiling
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    assert bpy.ops.relight.forbid_faces() == {"FINISHED"}
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)  # (in Edit Mode: its edit mesh read)
    assert s.paused == "object 'ceiling': faces forbidden or allowed: Solve & Reduce prepares again", s.paused
    bpy.ops.object.mode_set(mode="OBJECT")
    assert s.updates == 1
    assert bpy.ops.relight.solve() == {"FINISHED"}
    assert "solved from scratch: the forbidden faces changed" in scene.relight.last_warnings
    _run(s, lambda: s.paused is None and s.status == "up to date", timeout=60, pause=True)
    faces = preparation.PREPARED_JOBS[scene.name].exp.faces
    assert faces.forbidden[faces.face_object == list(faces.object_names).index("ceiling")].all()

    # the target scale (a scene custom property) doubled: followed, every object's paint read again
    n, asked = s.updates, s.paint[1].copy()
    scene["relight_target_scale"] = 2.0 * float(scene.get("relight_target_scale", 1.0))
    _run(s, lambda: s.updates == n + 1)
    assert np.allclose(s.paint[1], 2.0 * asked) and np.any(asked > 0)
    # a wall made a work plane (light passes through it): the model's, paused naming it
    bpy.data.objects["wall_east"]["relight_work_plane"] = True
    bpy.data.objects["wall_east"].update_tag()
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert s.paused == "object 'wall_east': its work plane switch changed: Solve & Reduce prepares again", s.paused
    del bpy.data.objects["wall_east"]["relight_work_plane"]
    assert bpy.ops.relight.solve() == {"FINISHED"}
    _run(s, lambda: s.paused is None and s.status == "up to date", timeout=60, pause=True)
    scene["relight_max_patch_size"] = 0.5  # the patch model's: paused
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert s.paused == "the patch size (relight_max_patch_size) changed: Solve & Reduce prepares again", s.paused


def test_live_follows_undo_by_name(addon):
    """Issue 35, case 14: Undo or Redo with Live on (Blender reads the scene back; the undo_post
    handler): the exported objects found again by name, Live goes on; one that Undo takes away
    pauses it, named (never an exception)."""
    from relight_addon.blender import live, preparation
    from relight_addon.blender.ui import operators

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    _run(s, lambda: s.status == "up to date" and s.updates == 1)
    job = preparation.PREPARED_JOBS[scene.name]
    # the scene read back with the same data-blocks (what Undo does to the ones it keeps)
    live._on_undo(scene)
    _run(s, lambda: s.updates == 2)
    assert s.paused is None and all(ob.name for ob in job.exp.objects)
    # Undo of what paused Live (a wall hidden from renders): Live goes on, and says nothing stale
    wall = bpy.data.objects["wall_north"]
    wall.hide_render = True
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert "object 'wall_north' hidden from renders" in s.paused
    wall.hide_render = False
    live._on_undo(scene)
    _run(s, lambda: s.updates == 3 and s.worker is None and s.to_refine is None, pause=True)  # (its later answers too)
    assert s.paused is None and s.status == "up to date"
    # a wall deleted (Live pauses), then brought back by Undo: another data-block of that name,
    # the same mesh in the same place (what Undo reads back): followed, Live goes on
    old = bpy.data.objects["wall_east"]
    me = old.data
    bpy.data.objects.remove(old)
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert s.paused == "object 'wall_east' deleted: Solve & Reduce prepares again", s.paused
    new = bpy.data.objects.new("wall_east", me)
    scene.collection.objects.link(new)
    live._on_undo(scene)
    _run(s, lambda: s.updates == 4, pause=True)
    assert s.paused is None and job.exp.objects[job.exp.faces.object_names.index("wall_east")] == new
    # brought back elsewhere: the geometry digest pauses Live; as something else than a mesh: named
    new.location.x += 0.5
    live._on_undo(scene)
    _run(s, lambda: s.paused is not None, timeout=30, pause=True)
    assert s.paused == "object 'wall_east' moved or edited: Solve & Reduce prepares again", s.paused
    bpy.data.objects.remove(new)
    scene.collection.objects.link(bpy.data.objects.new("wall_east", None))
    live._on_undo(scene)
    _run(s, lambda: s.paused is not None and "replaced" in s.paused, timeout=30, pause=True)
    assert s.paused == "object 'wall_east' replaced: Solve & Reduce prepares again", s.paused
    live.stop(scene.name)


def test_the_sidebar_keeps_as_many_status_rows_whatever_live_says(addon, monkeypatch):
    """Live's status grows from "starting" to an update's times and a pause's reason between two
    redraws; a panel that grew between redraws drew its last line under the next sub-panel's header
    (the window test's screenshot). The sidebar draws STATUS_ROWS rows whatever it says, and every
    part of a short status is on them."""
    from types import SimpleNamespace

    from relight_addon.blender import live
    from relight_addon.blender.ui import panels

    class Column:
        def __init__(self):
            self.labels = []

        def label(self, text=""):
            self.labels.append(text)

    class Layout:
        def __init__(self):
            self.columns = []

        def row(self, **kw):
            return SimpleNamespace(operator=lambda *a, **k: None)

        def column(self, **kw):
            self.columns.append(Column())
            return self.columns[-1]

    base = dict(paused=None, status="starting", last_update="", last_seconds=(0.0, 0.0), updates=0, refined=0)
    sessions = [SimpleNamespace(**base),
                SimpleNamespace(**{**base, "status": "improving the answer (full search)", "last_update": "14:06:03",
                                   "last_seconds": (4.7, 0.05), "updates": 12, "refined": 3}),
                SimpleNamespace(**{**base, "paused": "object 'ceiling' hidden from renders: Solve & Reduce "
                                                     "prepares again " + "and more words " * 20})]
    for s in sessions:
        monkeypatch.setattr(live, "session", lambda scene, s=s: s)
        layout = Layout()
        panels.draw_live(layout, bpy.context)
        (col,) = layout.columns
        assert len(col.labels) == panels.STATUS_ROWS, col.labels
        assert all(len(t) <= 44 for t in col.labels), col.labels
        if s.refined:  # the whole status, each part from a row of its own
            assert col.labels[0].startswith("Live: improving") and "3 improved later" in " ".join(col.labels)
            assert col.labels[1].startswith("updated 14:06:03"), col.labels
        if s.paused:
            assert col.labels[-1].endswith("..."), col.labels
