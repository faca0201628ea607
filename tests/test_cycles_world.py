"""The World against Cycles (issue 16): the map Cycles renders of it (blender/world.py) and its
conventions, then rooms with a window lit by a Sky Texture, an HDRI and a Sun, and an Area lamp,
each solved with `--out` and the written file baked by Cycles with its own World (closed loops),
and `radiosity` under a sky against Cycles. Lambertian materials (tests/cycles_reference.py)."""
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is needed to render with Cycles")

import cycles_reference as cr  # noqa: E402
from lit_rooms import (against_cycles, cut_window, lamp_room, light, relight, remove_lamps,  # noqa: E402
                       solve_closed_loop)

#: floor faces (4 x 4 grid, row-major from the south-west corner) painted as targets: the middle
#: two rows, the sun patch of the window rooms among them
TARGETS = [j * 4 + i for j in range(1, 3) for i in range(4)]


def _world_tree(name="sky"):
    world = bpy.data.worlds.new(name)
    bpy.context.scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    return world, nt, next(n for n in nt.nodes if n.type == "BACKGROUND")


def _sky_world(strength=0.06, sun_disc=True):
    """A Sky Texture World (Blender's default sky model) whose sun stands 35 degrees high in the
    south (-Y), shining through the south window."""
    world, nt, bg = _world_tree()
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sun_elevation, sky.sun_rotation = math.radians(35), math.radians(200)
    sky.sun_disc = sun_disc
    nt.links.new(sky.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    return world


def _hdri_world(path, sun=(0.0, -0.75, 0.66)):
    """An Environment Texture World on a 512 x 256 float image written to ``path`` (OpenEXR): a
    sky graded from the horizon to the zenith, a darker ground and a sun of 3 x 3 pixels."""
    W, H = 512, 256
    v = (np.arange(H) + 0.5) / H
    elev = (v - 0.5) * math.pi
    rgb = np.where(elev[:, None] > 0, np.array([0.5, 0.65, 1.0]) * (0.4 + 0.6 * np.sin(np.maximum(elev, 0)))[:, None],
                   np.array([0.15, 0.12, 0.1]))
    px = np.ones((H, W, 4), dtype=np.float32)
    px[..., :3] = rgb[:, None, :]
    # Cycles' equirectangular image lookup: u = (atan2(y, x) - pi) / -2 pi, v = 0.5 + elevation / pi
    d = np.asarray(sun) / np.linalg.norm(sun)
    u = (math.atan2(d[1], d[0]) - math.pi) / (-2 * math.pi)
    r, c = int((0.5 + math.asin(d[2]) / math.pi) * H), int(u * W) % W
    px[r - 1:r + 2, c - 1:c + 2, :3] = (4000.0, 3800.0, 3500.0)
    img = bpy.data.images.new("hdri", W, H, float_buffer=True, alpha=True)
    img.pixels.foreach_set(px.ravel())
    img.filepath_raw = str(path)
    img.file_format = "OPEN_EXR"
    img.save()
    world, nt, bg = _world_tree("hdri")
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(path))
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return world


def test_world_map_conventions_and_units():
    """The map of a World whose colour is its own view direction (Texture Coordinate > Generated,
    mapped to 0.5 + 0.5 d) is engine.world's texel directions, and a constant World rendered
    through a node (not read directly) comes back exactly as Color x Strength (no view transform)."""
    from relight_addon.blender.world import render_world_map, world_light
    from relight_addon.engine.world import EnvironmentMap

    try:
        cr.reset_blender()
        world, nt, bg = _world_tree()
        tc, vm = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeVectorMath")
        vm.operation = "MULTIPLY_ADD"
        vm.inputs[1].default_value = vm.inputs[2].default_value = (0.5, 0.5, 0.5)
        nt.links.new(tc.outputs["Generated"], vm.inputs[0])
        nt.links.new(vm.outputs[0], bg.inputs["Color"])
        m = render_world_map(world, width=64, samples=64).radiance
        n_before = (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras), len(bpy.data.worlds))
        rgb = nt.nodes.new("ShaderNodeRGB")
        rgb.outputs[0].default_value = (0.3, 0.6, 0.9, 1.0)
        nt.links.new(rgb.outputs[0], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = 2.5
        env, name, notes = world_light(bpy.context.scene)
        n_after = (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras), len(bpy.data.worlds))
    finally:
        cr.reset_blender()
    d = 2.0 * m - 1.0
    ref = EnvironmentMap(np.zeros((32, 64, 3))).directions()
    ang = np.degrees(np.arccos(np.clip(np.einsum("hwc,hwc->hw", d / np.linalg.norm(d, axis=-1, keepdims=True), ref),
                                       -1, 1)))
    assert ang.mean() < 0.5 and ang.max() < 3.0, (ang.mean(), ang.max())  # a texel is 5.6 degrees
    assert n_after == n_before  # nothing temporary left behind
    assert name == "sky" and notes == [] and env.shape == (128, 256)
    np.testing.assert_allclose(env.radiance, np.broadcast_to([0.75, 1.5, 2.25], env.radiance.shape), rtol=1e-5)


def _window_room(path, world_builder, sun_lamp=False):
    try:
        lamp_room(path)
        bpy.ops.wm.open_mainfile(filepath=str(path))
        remove_lamps()
        cut_window()
        world_builder()
        if sun_lamp:
            # shining in through the south window: its -Z axis tilted 55 degrees towards +Y
            light("SUN", (0, 0, 5), (math.radians(55), 0.0, 0.0), energy=3.0, angle=math.radians(1))
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        cr.reset_blender()


def test_radiosity_under_a_sky_texture_against_cycles(tmp_path):
    """`radiosity` in the window room lit only by a Sky Texture World with its sun disc: every
    face against Cycles baking the same file with its World."""
    blend, report_path = tmp_path / "sky.blend", tmp_path / "r.json"
    _window_room(blend, _sky_world)
    report = relight("radiosity", blend, report_path)
    try:
        baked = cr.cycles_face_radiance(samples=1024, seed=1, blend_path=str(blend), keep_world=True)
    finally:
        cr.reset_blender()
    rel, signed, summary = against_cycles(report, baked)
    assert rel.mean() < 0.02 and abs(signed.mean()) < 0.01, summary
    assert rel.max() < 0.10, summary


@pytest.mark.parametrize("scene", ["sun and sky", "hdri", "area lamp"])
def test_solve_counts_the_world_closed_loop(scene, tmp_path):
    """The window room under a Sun lamp and a Sky Texture World (no sun disc: the Sun lamp is the
    sun), under an HDRI World with a sun, and the closed room lit by an Area lamp: targets on the
    floor, lights only on the ceiling, `solve --out`, the written file baked by Cycles with its
    own World. The scene's light is a large share of the targets, and Cycles shows what the
    report predicts."""
    blend = tmp_path / "room.blend"
    if scene == "sun and sky":
        _window_room(blend, lambda: _sky_world(strength=0.5, sun_disc=False), sun_lamp=True)
        kinds, rgb = {"sun", "world"}, (0.6, 0.55, 0.5)
    elif scene == "hdri":
        _window_room(blend, lambda: _hdri_world(tmp_path / "sky.exr"))
        kinds, rgb = {"world"}, (0.4, 0.37, 0.34)
    else:
        try:
            lamp_room(blend)
            bpy.ops.wm.open_mainfile(filepath=str(blend))
            remove_lamps()
            light("AREA", (2.0, 1.5, 2.3), (0.15, 0.0, 0.0), energy=50.0, shape="RECTANGLE", size=1.0, size_y=0.5)
            bpy.ops.wm.save_as_mainfile(filepath=str(blend))
        finally:
            cr.reset_blender()
        kinds, rgb = {"area"}, (0.6, 0.55, 0.5)
    report, e, signed, share, summary = solve_closed_loop(blend, tmp_path, TARGETS, rgb)
    assert {r["kind"] for r in report["fixed_light"]} >= kinds, report["fixed_light"]
    assert 0.25 < share < 0.95, summary  # a large share of the painted light, not all of it
    assert e.mean() < 0.02 and e.max() < 0.06, summary
