"""The view target's image (issue 40, item 2's command line): pipeline/view_targets.py on arrays
(the inverse of the view transform, the box resampling, the alpha mask, what is refused), Blender's
own PNG of a render read back against its OpenEXR, and the command line's one-line refusals."""
import numpy as np
import pytest

from relight_addon.engine.targets.view import Camera
from relight_addon.pipeline.view_targets import display_to_linear, resample, view_spec, working_size


def srgb_encode(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def cam(w=160, h=90):
    return Camera((0, 0, 0), np.eye(3), w, h, (0.8, 0.8 * h / w))


def test_standard_is_inverted():
    """Blender's display processor (exposure, the sRGB encoding, then Gamma) undone: the linear values."""
    lin = np.random.default_rng(0).uniform(0, 0.4, (5, 7, 3))
    view = {"transform": "Standard", "look": "None", "exposure": 0.7, "gamma": 1.3, "display": "sRGB"}
    shown = srgb_encode(lin * 2 ** 0.7) ** (1 / 1.3)
    np.testing.assert_allclose(display_to_linear(shown, view), lin, rtol=1e-12)
    raw = dict(view, transform="Raw")
    np.testing.assert_allclose(display_to_linear((lin * 2 ** 0.7) ** (1 / 1.3), raw), lin, rtol=1e-12)


@pytest.mark.parametrize("view,what", [({"transform": "AgX"}, "AgX"), ({"transform": "Filmic"}, "Filmic"),
                                       ({"transform": "Standard", "look": "Very High Contrast"}, "Look"),
                                       ({"transform": "Standard", "curves": True}, "RGB Curves")])
def test_tone_maps_are_refused(view, what):
    with pytest.raises(ValueError, match=what):
        display_to_linear(np.zeros((2, 2, 3)), view)


def test_box_resampling_keeps_block_means():
    x = np.random.default_rng(1).random((8, 12, 3))
    y = resample(x, 4, 6)
    np.testing.assert_allclose(y, x.reshape(4, 2, 6, 2, 3).mean(axis=(1, 3)))
    np.testing.assert_allclose(resample(x, 8, 12), x)


def test_alpha_marks_free_pixels_and_weights_the_mean():
    """A 320 x 180 image at a 160 x 90 camera: working 480 x 270 (the longer side 480); alpha 0 free;
    a working pixel half painted asks for its painted part's radiance."""
    assert working_size(16 / 9) == (480, 270) and working_size(0.5) == (240, 480)
    rgba = np.zeros((180, 320, 4))
    rgba[:, :160] = (0.2, 0.3, 0.4, 1.0)  # left half painted
    rgba[:, 160:, :3] = 5.0  # right half free (alpha 0): its colour is ignored
    spec = view_spec(cam(), rgba, True, {}, "t.exr", side=160)
    assert spec.radiance.shape == (90, 160, 3) and spec.painted[:, :80].all() and not spec.painted[:, 80:].any()
    np.testing.assert_allclose(spec.radiance[spec.painted], np.tile([0.2, 0.3, 0.4], (90 * 80, 1)))
    rgba2 = np.zeros((90, 160, 4))
    rgba2[:, 0::2] = (1.0, 1.0, 1.0, 1.0)  # every other column painted: at half the width, each pixel half
    spec2 = view_spec(cam(), rgba2, True, {}, "t.exr", side=80)
    assert spec2.painted.all()
    np.testing.assert_allclose(spec2.radiance, 1.0)


@pytest.mark.parametrize("change,match", [("aspect", "aspect"), ("alpha", "paints no pixel"),
                                          ("black", "nothing to light"), ("nan", "NaN"), ("negative", "negative")])
def test_bad_images_are_refused(change, match):
    rgba = np.ones((90, 160, 4))
    if change == "aspect":
        rgba = np.ones((100, 160, 4))
    elif change == "alpha":
        rgba[..., 3] = 0
    elif change == "black":
        rgba[..., :3] = 0
    elif change == "nan":
        rgba[3, 4, 0] = np.nan
    else:
        rgba[3, 4, 0] = -1.0
    with pytest.raises(ValueError, match=match):
        view_spec(cam(), rgba, True, {}, "t.exr")



def test_blenders_png_reads_back_as_its_exr(tmp_path):
    """Cycles renders a small scene once; Blender saves the render as an OpenEXR (linear) and as a PNG
    through the Standard view transform with Exposure 0.5 and Gamma 1.2: the PNG read through
    display_to_linear is the OpenEXR within 8-bit quantisation (camera_view.read_image reads both)."""
    bpy = pytest.importorskip("bpy")
    import view_rooms as vr
    from relight_addon.blender.camera_view import read_image, view_settings

    vr.build(tmp_path / "room.blend")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "room.blend"))
        scene = bpy.context.scene
        bpy.ops.object.light_add(type="POINT", location=(2.0, 1.5, 2.0))
        bpy.context.object.data.energy = 300.0
        scene.render.resolution_x, scene.render.resolution_y = 96, 54
        scene.cycles.samples, scene.cycles.use_denoising = 4, False
        scene.view_settings.view_transform, scene.view_settings.exposure, scene.view_settings.gamma = "Standard", 0.5, 1.2
        bpy.ops.render.render()
        result = bpy.data.images["Render Result"]
        for fmt, name in (("OPEN_EXR", "r.exr"), ("PNG", "r.png")):
            scene.render.image_settings.file_format = fmt
            result.save_render(filepath=str(tmp_path / name), scene=scene)
        view = view_settings(scene)
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    exr, lin = read_image(tmp_path / "r.exr")
    png, lin2 = read_image(tmp_path / "r.png")
    assert lin and not lin2 and exr.shape == png.shape == (54, 96, 4)
    got = display_to_linear(png[..., :3], view)
    ref = exr[..., :3]
    seen = (ref > 0.01) & (srgb_encode(ref * 2 ** 0.5) < 0.98)  # (not clipped by the display)
    print(f"{seen.mean():.3f} of the values compared; median ref {np.median(ref):.4f}")
    assert seen.sum() > 1000
    # an 8-bit step at display value s is 1/255; through the inverse, relative about 2.4 x gamma / (255 s)
    rel = np.abs(got[seen] / ref[seen] - 1)
    print(f"PNG read back vs EXR: median {np.median(rel):.4f}, 99th percentile {np.quantile(rel, 0.99):.4f}")
    assert np.median(rel) < 0.01 and np.quantile(rel, 0.99) < 0.05


@pytest.fixture(scope="module")
def room_files(tmp_path_factory):
    """The view room (with its camera), the same without a camera, and images: a right one (480 x 270
    OpenEXR), one of another aspect, a PNG, a file that is no image."""
    bpy = pytest.importorskip("bpy")
    import view_rooms as vr

    tmp = tmp_path_factory.mktemp("view_input")
    vr.build(tmp / "room.blend")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(tmp / "room.blend"))
        bpy.context.scene.camera = None
        bpy.data.objects.remove(bpy.data.objects["camera"])
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "no_camera.blend"))
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    vr.write_exr(tmp / "ok.exr", np.ones((270, 480, 4)))
    vr.write_exr(tmp / "square.exr", np.ones((100, 100, 4)))
    vr.write_exr(tmp / "ok.png", np.full((270, 480, 4), 0.5))
    (tmp / "text.exr").write_text("not an image")
    return tmp


@pytest.mark.parametrize("scene,image,match", [
    ("no_camera.blend", "ok.exr", "no camera: a view target is the image of the scene's camera"),
    ("room.blend", "square.exr", r"is 100 x 100 \(aspect 1\), the camera.s image has aspect 1.778"),
    ("room.blend", "text.exr", "the view target .*text.exr cannot be read"),
    ("room.blend", "missing.exr", "the view target .*missing.exr does not exist"),
])
def test_the_command_line_refuses_in_one_line(room_files, scene, image, match):
    import re

    import view_rooms as vr

    tmp = room_files
    code, err = vr.relight_cli("solve", tmp / scene, "--report", tmp / "r.json", "--view-target", tmp / image)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("relight: error: "), err
    assert re.search(match, lines[0]), lines[0]


def test_a_png_through_agx_is_refused(room_files):
    """The room's view transform set to AgX: a PNG cannot be read back (an OpenEXR still can)."""
    bpy = pytest.importorskip("bpy")
    import view_rooms as vr

    tmp = room_files
    try:
        bpy.ops.wm.open_mainfile(filepath=str(tmp / "room.blend"))
        bpy.context.scene.view_settings.view_transform = "AgX"
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "agx.blend"))
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    code, err = vr.relight_cli("solve", tmp / "agx.blend", "--report", tmp / "r.json", "--view-target", tmp / "ok.png")
    assert code == 2 and "AgX tone maps (not invertible)" in err and len(err.strip().splitlines()) == 1, err
    code, err = vr.relight_cli("solve", tmp / "agx.blend", "--report", tmp / "r.json", "--view-prediction",
                               tmp / "p.exr")
    assert code == 2 and "--view-prediction needs --view-target" in err, err
