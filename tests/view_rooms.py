"""A room seen by a camera, for the view-target tests (issue 40; bpy): a 4 x 3 x 2.5 m room, matte
walls, ceiling and floor (Lambertian: Specular IOR Level 0), a glossy table (a default Principled
BSDF of Roughness 0.25) in front of the north wall, a perspective camera looking at the table and
the wall; lights allowed on the ceiling only; no World. Images are written and read with bpy
(OpenEXR, linear), and Cycles renders the camera's image of a file."""
import math
import os

import bpy
import numpy as np

import cycles_reference as cr

ROOM = (4.0, 3.0, 2.5)
CAMERA = dict(location=(2.0, 0.25, 1.5), look_at=(2.0, 2.2, 0.6), lens=24.0)
WIDTH, HEIGHT = 480, 270
TABLE_ROUGHNESS = 0.25


def _principled(name, colour, roughness=0.5, lambertian=False):
    mat = cr._material(name, colour, lambertian=lambertian)
    p = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    p.inputs["Roughness"].default_value = roughness
    return mat


def _box(name, lo, hi, mat, n=(1, 1, 1)):
    """An axis-aligned box facing outwards, its top split n[0] x n[1]."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    quads = [((x0, y0, z1), (x1 - x0, 0, 0), (0, y1 - y0, 0), n[0], n[1]),  # top, +z
             ((x0, y0, z0), (0, y1 - y0, 0), (x1 - x0, 0, 0), 1, 1),  # bottom, -z
             ((x0, y0, z0), (x1 - x0, 0, 0), (0, 0, z1 - z0), 1, 1),  # -y
             ((x0, y1, z0), (0, 0, z1 - z0), (x1 - x0, 0, 0), 1, 1),  # +y
             ((x0, y0, z0), (0, 0, z1 - z0), (0, y1 - y0, 0), 1, 1),  # -x
             ((x1, y0, z0), (0, y1 - y0, 0), (0, 0, z1 - z0), 1, 1)]  # +x
    verts, faces = [], []
    for o, du, dv, nu, nv in quads:
        v, f = cr.grid_quads(o, du, dv, nu, nv)
        faces += [tuple(k + len(verts) for k in face) for face in f]
        verts += list(v)
    return cr.add_mesh_object(name, verts, faces, mat)


def build(path, patch_size=0.15, emitters=(), lamps=(), lights_on=("ceiling",)):
    """The room, saved to ``path``. ``emitters``: [(i, j, strength)]: polygon (column i from the west,
    row j from the north) of the ceiling's 8 x 8 grid emitting white, Emission Strength ``strength``
    (a known configuration of lights: a reference image's). ``lamps``: [dict(type="SPOT" / "POINT" /
    "AREA", location, aim (the point it looks at), energy (W), radius (m, a point or spot), size
    (deg, a spot's cone; m, an area lamp's side), blend)]: the scene's own lamps (fixed light), not
    seen by the camera (only their light). ``lights_on``: the surfaces that may hold lights."""
    cr.reset_blender()
    scene = bpy.context.scene
    scene.world = cr.black_world()
    walls = _principled("walls", (0.7, 0.7, 0.7), lambertian=True)
    floor_m = _principled("floor", (0.45, 0.4, 0.35), lambertian=True)
    table_m = _principled("table", (0.25, 0.2, 0.15), roughness=TABLE_ROUGHNESS)
    W, D, H = ROOM
    n = 8
    quads = [("floor", (0, 0, 0), (W, 0, 0), (0, D, 0), floor_m),
             ("ceiling", (0, D, H), (W, 0, 0), (0, -D, 0), walls),
             ("wall_s", (0, 0, 0), (0, 0, H), (W, 0, 0), walls),
             ("wall_n", (0, D, 0), (W, 0, 0), (0, 0, H), walls),
             ("wall_w", (0, 0, 0), (0, D, 0), (0, 0, H), walls),
             ("wall_e", (W, 0, 0), (0, 0, H), (0, D, 0), walls)]
    for name, o, du, dv, m in quads:
        v, f = cr.grid_quads(o, du, dv, n, n)
        ob = cr.add_mesh_object(name, v, f, m)
        if name not in lights_on:
            ob["relight_no_lights"] = True
        else:
            for k, (i, j, strength) in enumerate(emitters):
                ob.data.materials.append(cr._material(f"emitter{k}", (0.7, 0.7, 0.7), (1.0, 1.0, 1.0), strength,
                                                      lambertian=True))
                ob.data.polygons[j * n + i].material_index = k + 1
    for k, spec in enumerate(lamps):
        _lamp(scene, f"lamp{k}", **spec)
    table = _box("table", (1.2, 1.5, 0.7), (2.8, 2.4, 0.75), table_m, n=(8, 4))
    table["relight_no_lights"] = True
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = CAMERA["lens"]
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = CAMERA["location"]
    d = np.subtract(CAMERA["look_at"], CAMERA["location"])
    cam.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0.0, math.atan2(d[1], d[0]) - math.pi / 2)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = WIDTH, HEIGHT, 100
    scene.render.engine = "CYCLES"
    scene.view_settings.view_transform = "Standard"
    scene["relight_max_patch_size"] = patch_size
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def _lamp(scene, name, type, location, aim, energy, radius=0.02, size=45.0, blend=0.15):
    light = bpy.data.lights.new(name, type)
    light.energy = energy
    if type in ("POINT", "SPOT"):
        light.shadow_soft_size = radius
    if type == "SPOT":
        light.spot_size, light.spot_blend = math.radians(size), blend
    if type == "AREA":
        light.size = size
    ob = bpy.data.objects.new(name, light)
    scene.collection.objects.link(ob)
    ob.location = location
    d = np.subtract(aim, location)  # (the lamp shines along its -Z)
    ob.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0.0, math.atan2(d[1], d[0]) - math.pi / 2)
    ob.visible_camera = False
    return ob


def write_exr(path, rgba):
    """(h, w, 4) floats, row 0 at the top -> an OpenEXR (bpy)."""
    from relight_addon.blender.camera_view import write_image
    write_image(str(path), rgba)


def read_exr(path):
    from relight_addon.blender.camera_view import read_image
    return read_image(str(path))[0]


def render(blend, path, samples, seed=0, size=None, border=None):
    """Cycles' camera image of ``blend`` as the file has it (its light paths, materials), linear:
    (h, w, 4), row 0 at the top. No denoising, no adaptive sampling, the Standard view transform.
    ``size``: (width, height) at 100 % instead of the file's resolution (the same aspect).
    ``border``: (x0, x1, y0, y1) pixels (row 0 at the top) of the image rendered alone, cropped."""
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
        scene = bpy.context.scene
        if size is not None:
            scene.render.resolution_x, scene.render.resolution_y = size
            scene.render.resolution_percentage = 100
        scene.render.engine = "CYCLES"
        c = scene.cycles
        c.device, c.samples, c.seed = "CPU", int(samples), int(seed)
        c.use_adaptive_sampling = c.use_denoising = False
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = str(path)
        scene.render.film_transparent = True
        if border is not None:
            w, h = scene.render.resolution_x, scene.render.resolution_y
            x0, x1, y0, y1 = border
            r = scene.render
            r.use_border, r.use_crop_to_border = True, True
            r.border_min_x, r.border_max_x = x0 / w, x1 / w
            r.border_min_y, r.border_max_y = 1 - y1 / h, 1 - y0 / h
        bpy.ops.render.render(write_still=True)
    finally:
        cr.reset_blender()
    return read_exr(path)


def relight_cli(*args):
    """`python -m relight_addon ARGS` (the real command line): (exit code, stderr)."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    proc = subprocess.run([sys.executable, "-m", "relight_addon", *map(str, args)], cwd=root, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": root})
    return proc.returncode, proc.stderr


def against_cycles(pred, renders, painted_alpha, size):
    """The predicted image ``pred`` (H, W, 4) box-filtered to ``size`` (w, h) against the mean of two
    Cycles ``renders`` at that size, over the pixels wholly painted (``painted_alpha`` (H, W, 1) at the
    working resolution) that Cycles sees lit: (the relative luminance differences, the renders'
    relative noise (half their difference), the pixels compared (h, w) bool, the painted ones)."""
    from relight_addon.pipeline.view_targets import resample

    w, h = size
    a, b = renders
    painted = resample(painted_alpha, h, w)[..., 0] >= 1 - 1e-9
    lum_p = resample(pred[..., :3], h, w).sum(axis=2)
    lum_c = ((a[..., :3] + b[..., :3]) / 2).sum(axis=2)
    ok = painted & (lum_c > 0)
    rel = np.abs(lum_p - lum_c)[ok] / lum_c[ok]
    noise = (np.abs(a[..., :3] - b[..., :3]).sum(axis=2) / 2)[ok] / lum_c[ok]
    return rel, noise, ok, painted


def cycles_summary(report, rel, noise, ok, samples, size) -> str:
    """One line: the report's view target block and lights, Cycles' noise, the differences."""
    return (f"view target: {report['view_target']}; {report['final']['n_lights']} lights; Cycles {2 * samples} "
            f"samples: pixel noise {noise.mean():.4f} (mean, relative) at {size[0]} x {size[1]}; predicted vs Cycles "
            f"over {ok.sum()} painted pixels: mean {rel.mean():.4f}, median {np.median(rel):.4f}, 95th percentile "
            f"{np.quantile(rel, 0.95):.4f}")


def lower_image_target(radiance, free_rows=40):
    """(HEIGHT, WIDTH, 4) a view target painted ``radiance`` (W m^-2 sr^-1, grey) below its top
    ``free_rows`` rows (free: alpha 0)."""
    rgba = np.zeros((HEIGHT, WIDTH, 4))
    rgba[..., :3] = radiance
    rgba[free_rows:, :, 3] = 1.0
    return rgba


def solve_view(tmp, rgba, *options):
    """`solve --view-target` of tmp/room.blend with the view target ``rgba`` (written to
    tmp/target.exr) and ``options``, the result to tmp/out.blend: (the report, the predicted image)."""
    import json

    write_exr(tmp / "target.exr", rgba)
    code, err = relight_cli("solve", tmp / "room.blend", "--report", tmp / "r.json", "--out", tmp / "out.blend",
                            "--view-target", tmp / "target.exr", "--view-prediction", tmp / "pred.exr", "--quiet",
                            *options)
    assert code == 0, err[-2000:]
    return json.loads((tmp / "r.json").read_text()), read_exr(tmp / "pred.exr")
