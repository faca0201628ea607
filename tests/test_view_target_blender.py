"""The camera-view target in Blender (issue 40, items 2, 3 and 5): New View Target, Load Reference,
Solve & Reduce reading the scene's view-target image, and the predicted camera image it writes.

References: the working resolution from the camera's aspect (pipeline.view_targets.working_size);
a reference picture's box means at the working resolution computed here from its pixels; the
command line's ``solve --view-target FILE --view-prediction PRED.exr`` on the same image and file
(the add-on's solve must give the same rows, curve, pixel error and predicted image); the scene
snapshot of tests/test_hostile.py (a refused operator changes nothing)."""
import json

import numpy as np
import pytest

from test_hostile import snapshot

bpy = pytest.importorskip("bpy", reason="the add-on needs bpy (Blender as a Python module)")

import view_rooms as vr  # noqa: E402

RAYS = 256
PATCH = 0.3


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """The view room (tests/view_rooms.py: a 16:9 camera at 480 x 270) at a coarse patch size."""
    tmp = tmp_path_factory.mktemp("view_blender")
    vr.build(tmp / "room.blend", patch_size=PATCH)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return tmp


def _open(room, name="room.blend"):
    bpy.ops.wm.open_mainfile(filepath=str(room / name))
    return bpy.context.scene


def _pixels(img):
    from relight_addon.blender.camera_view import image_pixels

    return image_pixels(img)[0]


def _refused(run, message):
    """The operator refuses in one line naming ``message`` and the scene is as it was."""
    before = snapshot()
    with pytest.raises(RuntimeError) as info:
        run()
    text = str(info.value).strip()
    assert text.startswith("Error: ") and len(text.splitlines()) == 1 and message in text, text
    assert "Traceback" not in text
    assert snapshot() == before, "a refused operator changed the scene"


def test_new_view_target_is_a_free_image_of_the_cameras_aspect(addon, room, tmp_path):
    """480 x 270 for the 16:9 camera (the resolution a scene property: 240 -> 240 x 135), float, alpha
    0 everywhere, packed: saved and opened again, the file still holds it, painted pixels included."""
    scene = _open(room)
    assert bpy.ops.relight.new_view_target() == {"FINISHED"}
    img = scene.relight_camera_target.image
    assert img is not None and tuple(img.size) == (480, 270) and img.is_float and img.packed_file is not None
    rgba = _pixels(img)
    assert rgba.shape == (270, 480, 4) and np.all(rgba[..., 3] == 0)
    # the same camera and resolution: the image is opened again, not replaced
    assert bpy.ops.relight.new_view_target() == {"FINISHED"} and scene.relight_camera_target.image == img
    assert len(bpy.data.images) == 1
    # "painted" (as a brush leaves a float image: premultiplied) and saved: the file keeps what was painted
    px = np.zeros((270, 480, 4), dtype=np.float32)
    px[:10, :20] = (0.6, 0.3, 0.15, 0.5)  # straight (1.2, 0.6, 0.3) at alpha 0.5, row 0 at the bottom
    img.pixels.foreach_set(px.ravel())
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "painted.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "painted.blend"))
    img = bpy.context.scene.relight_camera_target.image
    assert img is not None and tuple(img.size) == (480, 270)
    rgba = _pixels(img)
    np.testing.assert_allclose(rgba[-10:, :20], np.tile([1.2, 0.6, 0.3, 0.5], (10, 20, 1)), rtol=1e-6)
    assert np.all(rgba[:-10, :, 3] == 0)
    # another working resolution: a new image; the earlier one stays in the file (nothing the user made is lost)
    bpy.context.scene.relight_camera_target.resolution = 240
    assert bpy.ops.relight.new_view_target() == {"FINISHED"}
    new = bpy.context.scene.relight_camera_target.image
    assert new != img and tuple(new.size) == (240, 135) and img.name in bpy.data.images and img.use_fake_user


def test_undo_of_new_view_target_leaves_no_orphan(addon, room):
    """The image made has users (the scene's pointer, a fake user: saved with the file, never an
    orphan); undone, it is gone."""
    scene = _open(room)
    assert bpy.ops.relight.new_view_target() == {"FINISHED"}
    img = scene.relight_camera_target.image
    assert img.users >= 2 and img.use_fake_user
    if not bpy.ops.ed.undo.poll():
        pytest.skip("Blender's undo stack does not exist in background mode (bpy.ops.ed.undo.poll() is False)")
    bpy.ops.ed.undo()
    assert bpy.context.scene.relight_camera_target.image is None and not bpy.data.images


def test_new_view_target_without_a_usable_camera_changes_nothing(addon, room):
    scene = _open(room)
    cam = scene.camera
    scene.camera = None
    before = snapshot()
    assert not bpy.ops.relight.new_view_target.poll()
    assert snapshot() == before
    scene.camera = cam
    cam.data.type = "ORTHO"
    _refused(bpy.ops.relight.new_view_target, "is ortho: a view target needs a perspective camera")


def _write_png(path, rgba):
    from relight_addon.blender.camera_view import write_image

    write_image(str(path), rgba)


def test_a_reference_picture_becomes_the_targets_scaled_and_masked(addon, room, tmp_path):
    """A 960 x 540 OpenEXR at Exposure +1 with a mask (alpha 0 on its left quarter): at 480 x 270 each
    pixel asks 2 x the mean of its 2 x 2 pixels, the masked quarter is free; a PNG through the
    Standard view transform reads back as its linear values."""
    rng = np.random.default_rng(3)
    ref = np.ones((540, 960, 4))
    ref[..., :3] = rng.uniform(0.05, 0.8, (540, 960, 3))
    vr.write_exr(tmp_path / "ref.exr", ref)
    mask = np.ones((270, 480, 4))
    mask[:, :120, 3] = 0.0  # its left quarter free (the mask at half the picture's resolution)
    vr.write_exr(tmp_path / "mask.exr", mask)
    scene = _open(room)
    assert bpy.ops.relight.load_view_reference(filepath=str(tmp_path / "ref.exr"), exposure=1.0,
                                               mask=str(tmp_path / "mask.exr")) == {"FINISHED"}
    img = scene.relight_camera_target.image
    assert tuple(img.size) == (480, 270) and img.packed_file is not None
    got = _pixels(img)
    want = 2.0 * ref[..., :3].reshape(270, 2, 480, 2, 3).mean(axis=(1, 3))
    assert np.all(got[:, :120, 3] == 0) and np.all(got[:, 120:, 3] == 1)
    np.testing.assert_allclose(got[:, 120:, :3], want[:, 120:], rtol=1e-5)
    # a PNG (display values through the scene's Standard view transform, Exposure 0): its linear values
    lin = np.full((270, 480, 3), 0.2)
    shown = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    _write_png(tmp_path / "ref.png", np.concatenate([shown, np.ones((270, 480, 1))], axis=2))
    assert bpy.ops.relight.load_view_reference(filepath=str(tmp_path / "ref.png")) == {"FINISHED"}
    got = _pixels(scene.relight_camera_target.image)
    np.testing.assert_allclose(got[..., :3], 0.2, rtol=0.01)  # (8-bit quantisation)
    assert img.name in bpy.data.images  # the earlier view target stays in the file


@pytest.mark.parametrize("case,message", [
    ("aspect", "the camera's image has aspect 1.778"),
    ("agx", "AgX tone maps (not invertible)"),
    ("mask_aspect", "give a mask of the reference's aspect"),
    ("missing", "does not exist"),
    ("masked_out", "paints no pixel"),
])
def test_a_bad_reference_is_refused_in_one_line(addon, room, tmp_path, case, message):
    vr.write_exr(tmp_path / "ok.exr", np.ones((270, 480, 4)))
    vr.write_exr(tmp_path / "square.exr", np.ones((100, 100, 4)))
    _write_png(tmp_path / "ok.png", np.full((270, 480, 4), 0.5))
    vr.write_exr(tmp_path / "zero.exr", np.zeros((27, 48, 4)))
    scene = _open(room)
    args = {"aspect": dict(filepath=str(tmp_path / "square.exr")),
            "agx": dict(filepath=str(tmp_path / "ok.png")),
            "mask_aspect": dict(filepath=str(tmp_path / "ok.exr"), mask=str(tmp_path / "square.exr")),
            "missing": dict(filepath=str(tmp_path / "missing.exr")),
            "masked_out": dict(filepath=str(tmp_path / "ok.exr"), mask=str(tmp_path / "zero.exr"))}[case]
    if case == "agx":
        scene.view_settings.view_transform = "AgX"
    _refused(lambda: bpy.ops.relight.load_view_reference(**args), message)


def _target_image(tmp_path):
    """A view target: a bright patch of the north wall and a dimmer one on the table, the rest free."""
    rgba = np.zeros((270, 480, 4))
    rgba[20:90, 150:330] = (0.30, 0.28, 0.25, 1.0)  # the wall above the table
    rgba[170:230, 170:310] = (0.05, 0.045, 0.04, 1.0)  # the table top
    vr.write_exr(tmp_path / "target.exr", rgba)
    return rgba


@pytest.mark.slow  # (three solves of the room: 69 s at load 12 on 2 cores)
def test_the_add_ons_solve_is_the_command_lines(addon, room, tmp_path, run_cli):
    """Solve & Reduce with the scene's view-target image (loaded as a reference, Exposure 0) equals
    ``solve --view-target`` of the same picture on the same file: the same rows, curve, final
    configuration, pixel error and predicted image. The prediction is owned by the result (Clear
    Results removes it; a new solve replaces it) and the Results panel's line is the report's."""
    from relight_addon.blender.ui import view_target_ops

    _target_image(tmp_path)
    code, report, err = run_cli(["solve", room / "room.blend", "--report", tmp_path / "r.json",
                                 "--rays-per-patch", RAYS, "--view-target", tmp_path / "target.exr",
                                 "--view-prediction", tmp_path / "pred.exr"])
    assert code == 0, err
    from relight_addon.blender.camera_view import read_image

    cli_pred = read_image(str(tmp_path / "pred.exr"))[0]
    scene = _open(room)
    scene.relight.rays_per_patch = RAYS
    assert bpy.ops.relight.load_view_reference(filepath=str(tmp_path / "target.exr")) == {"FINISHED"}
    painted = scene.relight_camera_target.image
    assert bpy.ops.relight.solve() == {"FINISHED"}
    from relight_addon.blender import results

    data = results.load_result(scene)
    # (the stored curve keeps float32: 6e-8 relative)
    np.testing.assert_allclose(data.relative_error, [p["relative_error"] for p in report["curve"]], rtol=1e-6)
    assert list(data.n_lights) == [p["n_lights"] for p in report["curve"]]
    pred = view_target_ops.prediction_image(scene)
    assert pred is not None and tuple(pred.size) == (480, 270) and pred.packed_file is not None
    block = json.loads(pred[view_target_ops.ERROR_PROP])
    cli = report["view_target"]
    assert block["rows"] == cli["rows"] and block["painted"] == cli["painted"] == 180 * 70 + 140 * 60
    assert block["mean_relative_error"] == pytest.approx(cli["mean_relative_error"], rel=1e-9)
    print(f"view target: {cli['rows']} rows, {cli['seen']} of {cli['painted']} pixels seen, mean error "
          f"{100 * cli['mean_relative_error']:.2f} %, final {report['final']['n_lights']} lights")
    np.testing.assert_allclose(_pixels(pred), cli_pred, rtol=1e-6, atol=1e-9)
    # the prediction belongs to the result: a new solve replaces it, Clear Results removes it
    assert bpy.ops.relight.solve() == {"FINISHED"}
    preds = [i for i in bpy.data.images if view_target_ops.ERROR_PROP in i.keys()]
    assert len(preds) == 1 and preds[0] == view_target_ops.prediction_image(scene)
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert not [i for i in bpy.data.images if view_target_ops.ERROR_PROP in i.keys()]
    assert scene.relight_camera_target.image == painted and painted.name in bpy.data.images  # the artist's stays


def test_use_in_solve_off_solves_without_it(addon, room, tmp_path):
    """With Use in Solve off (or no camera then) the image stays and the solve does not read it; with
    it on and no camera, the solve is refused in one line naming both ways out."""
    from relight_addon.blender import camera_view

    _target_image(tmp_path)
    scene = _open(room)
    assert bpy.ops.relight.load_view_reference(filepath=str(tmp_path / "target.exr")) == {"FINISHED"}
    scene.camera = None
    _refused(bpy.ops.relight.solve, "or turn the View Target's Use in Solve off")
    scene.relight_camera_target.use = False
    assert camera_view.scene_view_target(scene) is None


@pytest.mark.slow  # (a full solve and a stroke of the room: ~40 s at load 12)
def test_live_solves_with_the_view_target(addon, room, tmp_path):
    """Live's first answer (a full solve, no prepared model) reads the view target as Solve & Reduce
    does (camera_view.scene_view_target) and writes the prediction; a stroke on a wall is re-solved
    with the pixels' rows, the very target the model holds (Target.serves: not made again), and,
    its lights new, the earlier prediction goes with its result (a stroke's answer writes none:
    Solve & Reduce does). The view target itself is followed as a stroke, never paused: pixels
    painted (the answer's rows are of the new pixels: as many rows as the target built anew), the
    camera moved (the rows of its new view), Use in Solve off (no view rows)."""
    from artist_scenes import paint
    from test_live import _run

    from relight_addon.blender import camera_view, live, preparation
    from relight_addon.blender.ui import operators, view_target_ops
    from relight_addon.engine.targets.view import ViewTarget

    preparation.PREPARED.clear()
    _target_image(tmp_path)
    scene = _open(room)
    scene.relight.rays_per_patch = RAYS
    wall = bpy.data.objects["wall_w"]
    paint(wall, [27, 28], (0.1, 0.1, 0.1))
    assert bpy.ops.relight.load_view_reference(filepath=str(tmp_path / "target.exr")) == {"FINISHED"}
    s = live.start(bpy.context, operators.job_options, operators.show_solve)

    def view_of(outcome):
        return next((t for t in outcome.problem.target_rows.targets if isinstance(t, ViewTarget)), None)

    try:
        _run(s, lambda: s.updates == 1)
        state = preparation.PREPARED[scene.name]
        assert preparation.PREPARED_JOBS[scene.name].exp.faces.view_target is not None
        prepared = view_of(state.model)
        assert prepared is not None
        assert view_target_ops.prediction_image(scene) is not None
        answers, stroke = [], state.live
        state.live = lambda *a, **k: (lambda out: answers.append(out) or out)(stroke(*a, **k))
        paint(wall, [19, 20, 35, 36], (0.1, 0.1, 0.1))
        _run(s, lambda: s.updates == 2)
        assert answers and view_of(answers[-1]) is prepared  # (kept: its rows not made again)
        assert view_target_ops.prediction_image(scene) is None
        assert not [i for i in bpy.data.images if view_target_ops.ERROR_PROP in i.keys()]
        # the view target painted again (half its pixels freed, as Erase Alpha does): followed
        img = scene.relight_camera_target.image
        px = np.asarray(img.pixels[:], dtype=np.float32).reshape(img.size[1], img.size[0], 4)
        px[: img.size[1] // 2, :, 3] = 0.0
        img.pixels.foreach_set(px.ravel())
        img.update_tag()  # (as a brush stroke in the Image Editor: the depsgraph updates the image)
        n = len(answers)
        _run(s, lambda: len(answers) > n, pause=True)
        assert s.paused is None, s.paused
        now = view_of(answers[-1])
        anew = camera_view.scene_view_target(scene)
        assert now is not prepared and now.pixels == int(anew.painted.sum()) < prepared.pixels
        # the camera moved: the rows of its new view (Live went on answering for the camera before)
        scene.camera.location.x += 0.2
        n = len(answers)
        _run(s, lambda: len(answers) > n, timeout=60, pause=True)
        assert s.paused is None, s.paused
        moved = view_of(answers[-1])
        assert moved is not now and not np.allclose(moved.spec.camera.origin, now.spec.camera.origin)
        # Use in Solve off (a scene setting): answered without the view rows
        scene.relight_camera_target.use = False
        n = len(answers)
        _run(s, lambda: len(answers) > n, timeout=60, pause=True)
        assert s.paused is None and view_of(answers[-1]) is None, s.paused
    finally:
        live.stop(scene.name)


class _Layout:
    """A UILayout stand-in that records what a draw function asks for."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        def call(*args, **kw):
            self.log.append((name, args, kw))
            return _Layout(self.log)  # (box, column, row; an operator's properties: set, unread)
        return call


def _drawn(fn, scene):
    import types

    log = []
    fn(_Layout(log), types.SimpleNamespace(scene=scene))
    for name, args, kw in log:  # every property and operator drawn exists
        if name in ("prop", "template_ID"):
            assert args[1] in args[0].bl_rna.properties, args[1]
        if name == "operator":
            getattr(bpy.ops.relight, args[0].split(".")[1]).get_rna_type()
    return [kw.get("text", "") for name, args, kw in log if name == "label"]


def test_the_prediction_is_the_results_and_the_panels_say_so(addon, room):
    """Without a solve (a result id and an owned image made here): the Results panel's line is the
    report block's numbers; Clear Results removes the prediction by its owner mark, and not a copy the
    artist made of it (another name) nor the view target."""
    from relight_addon.blender import results
    from relight_addon.blender.ui import view_target_ops as vt
    from relight_addon.blender.visibility import tag_owned

    scene = _open(room)
    assert bpy.ops.relight.new_view_target() == {"FINISHED"}
    labels = _drawn(vt.draw_view_target, scene)
    assert "480 x 270, scene-linear radiance" in labels
    assert _drawn(vt.draw_prediction, scene) == []  # no result: nothing drawn
    scene[results.RESULT_ID_PROP] = "r1"
    pred = bpy.data.images.new(vt.PREDICTION_NAME, 48, 27, float_buffer=True)
    tag_owned(pred, "r1")
    pred[vt.ERROR_PROP] = json.dumps({"painted": 12000, "seen": 11500, "mean_relative_error": 0.0423,
                                      "rms_error": 0.0125, "rows": 90})
    copy = pred.copy()  # the artist's copy: its name is another
    assert vt.prediction_image(scene) == pred
    labels = _drawn(vt.draw_prediction, scene)
    assert "4.2 % mean error over 11,500 of 12,000 painted pixels (RMS 0.0125 W/m\u00b2/sr)" in labels, labels
    painted = scene.relight_camera_target.image
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert vt.PREDICTION_NAME not in bpy.data.images and copy.name in bpy.data.images
    assert scene.relight_camera_target.image == painted
