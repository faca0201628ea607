"""Generate Relight's sample scenes (deterministic).

    make samples                                     # = the line below, in the bpy 4.2 LTS venv
    .venv-bpy42/bin/python sample_blends/generate.py [OUTDIR]

The committed files are written by the oldest Blender the extension supports (bpy 4.2 LTS,
the `make compat-envs` venv): Blender reads files of older versions, never those of a newer
file format (Blender 4.2-4.5 cannot open a file saved by 5.0). Any bpy can generate scenes into
another OUTDIR (the tests do); writing this folder with bpy 5.0+ is refused.

Writes, into OUTDIR (default: this folder):

- cornell_box.blend: the published Cornell box data (metres; walls, floor and ceiling
  each an 8 x 8 grid of the published quad; Cornell's y-up data rotated
  +90 deg about X so Blender's Z is up), faces inward, blocks outward, the ceiling light a
  separate emissive quad 0.5 mm below the ceiling facing down. Reflectances white
  (0.725, 0.71, 0.68), red (0.63, 0.065, 0.05), green (0.14, 0.45, 0.091). The light's
  Principled Emission Color x Strength = radiance L_e = CORNELL_LIGHT_RADIANCE, so its
  exitance is e = pi * L_e (about (157, 134, 94) W/m^2). Camera at the standard
  position (278, 273, -800) mm looking in, 35 mm lens on a 25 mm film. Cycles.
- staircase.blend: a stairwell joining three floors (4 m x 8 m, floors at 0, 3 and 6 m,
  ceiling at 9 m, two flights of 16 open-rise steps, two landings). ~1500 faces; the
  walls, the ceiling and the landings' undersides (~690 faces) are candidate lights,
  everything else (floors, landing tops and edges, steps) has ``relight_forbidden`` = True.
  The scene sets ``relight_max_patch_size`` = 1.3 m so the default meshing keeps every
  face as one patch.
- staircase_targets.blend: the same scene with the paper's targets painted into
  ``relight_target`` (bright on the ground floor in front of the stairs and on the middle of
  the first steps, ~3% of the faces).
- ff_parallel_<X>.blend, ff_perpendicular_<W>.blend, ff_disks_<R>.blend: two faces each,
  for closed-form form factors (see CLOSED_FORM_CASES): the receiver "receiver" (grey,
  reflectance RECEIVER_REFLECTANCE, no emission) and the emitter "emitter" (black, emission
  radiance EMITTER_RADIANCE, exitance pi W/m^2). With a black emitter the receiver's
  radiosity is exactly B_r = rho_r * F(r->e) * e.
"""
from __future__ import annotations

import math
import os
import sys
import warnings

import bpy
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

WHITE = (0.725, 0.71, 0.68)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.091)
CORNELL_LIGHT_RADIANCE = (50.0, 42.5, 30.0)  # W/(m^2 sr); exitance = pi * this
RECEIVER_REFLECTANCE = 0.5
EMITTER_RADIANCE = 1.0  # exitance pi W/m^2

# (kind, parameter, label): parallel: a = b = X * c (c = 1 m); perpendicular: common edge l = 1 m,
# receiver width w = W * l, emitter height h = 1 m; disks: r_receiver = r_emitter = R * h (h = 1 m).
CLOSED_FORM_CASES = [
    ("parallel", 0.5), ("parallel", 1.0), ("parallel", 2.0),
    ("perpendicular", 0.5), ("perpendicular", 1.0), ("perpendicular", 2.0),
    ("disks", 0.5), ("disks", 1.0), ("disks", 2.0),
]
DISK_SIDES = 64


def closed_form_filename(kind, param):
    return f"ff_{kind}_{param:g}.blend"


# ---------------------------------------------------------------- helpers
def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 64
    scene.cycles.use_denoising = False
    scene.view_settings.view_transform = "Standard"
    return scene


def material(name, base_color, emission=None):
    m = bpy.data.materials.new(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        if not m.use_nodes:
            m.use_nodes = True
    p = next(n for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (*base_color, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Specular IOR Level"].default_value = 0.0
    m.diffuse_color = (*base_color, 1.0)
    if emission is not None:
        p.inputs["Emission Color"].default_value = (*emission, 1.0)
        p.inputs["Emission Strength"].default_value = 1.0
    return m


def mesh_object(name, verts, faces, mat=None, face_mats=None, mats=()):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, f)) for f in faces])
    me.validate()
    me.update()
    for m in ([mat] if mat is not None else list(mats)):
        me.materials.append(m)
    if face_mats is not None:
        me.polygons.foreach_set("material_index", np.asarray(face_mats, dtype=np.int32))
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def grid(origin, u, v, nu, nv):
    """Quad grid origin + i/nu u + j/nv v; face normal = u x v."""
    o, u, v = (np.asarray(x, dtype=np.float64) for x in (origin, u, v))
    verts = [o + (i / nu) * u + (j / nv) * v for j in range(nv + 1) for i in range(nu + 1)]
    faces = []
    for j in range(nv):
        for i in range(nu):
            a = j * (nu + 1) + i
            faces.append((a, a + 1, a + nu + 2, a + nu + 1))
    return verts, faces


def merge(parts):
    verts, faces, tags = [], [], []
    for tag, (v, f) in parts:
        base = len(verts)
        verts.extend(v)
        faces.extend(tuple(base + k for k in face) for face in f)
        tags.extend([tag] * len(f))
    return verts, faces, tags


def box(lo, hi):
    """Closed box, faces outward."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return v, f


def save(path):
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
    print("wrote", path)


# ---------------------------------------------------------------- Cornell box
_MM = {
    "floor": [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)],
    "ceiling": [(556.0, 548.8, 0), (556.0, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)],
    "back_wall": [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556.0, 548.8, 559.2)],
    "green_wall": [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)],
    "red_wall": [(552.8, 0, 0), (549.6, 0, 559.2), (556.0, 548.8, 559.2), (556.0, 548.8, 0)],
    "light": [(343.0, 548.3, 227.0), (343.0, 548.3, 332.0), (213.0, 548.3, 332.0), (213.0, 548.3, 227.0)],
}
_SHORT = [(130.0, 65.0), (82.0, 225.0), (240.0, 272.0), (290.0, 114.0)]  # (x, z) footprint, h 165
_TALL = [(423.0, 247.0), (265.0, 296.0), (314.0, 456.0), (472.0, 406.0)]  # h 330


def _cornell_to_blender(p):
    """Cornell mm, y up -> Blender m, z up (rotation +90 deg about X: (x, y, z) -> (x, -z, y))."""
    x, y, z = p
    return (x / 1000.0, -z / 1000.0, y / 1000.0)


def _orient(verts, faces, inside_point, inward):
    """Flip faces so that normals point towards (inward) / away from inside_point."""
    V = np.asarray(verts)
    out = []
    for f in faces:
        p = V[list(f)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        towards = np.dot(n, np.asarray(inside_point) - p.mean(axis=0)) > 0
        out.append(tuple(f) if towards == inward else tuple(reversed(f)))
    return out


def _block(footprint, h):
    bottom = [(x, 0.0, z) for x, z in footprint]
    top = [(x, h, z) for x, z in footprint]
    verts = [_cornell_to_blender(p) for p in bottom + top]
    faces = [(4, 5, 6, 7)] + [(i, (i + 1) % 4, 4 + (i + 1) % 4, 4 + i) for i in range(4)]
    center = np.mean(verts, axis=0)
    return verts, _orient(verts, faces, center, inward=False)


CORNELL_GRID = 8  # walls, floor and ceiling are 8 x 8 grids of the published quads


def _bilinear_grid(quad, n):
    """n x n grid of quads over the (planar) quad p0..p3, in the quad's vertex order."""
    p = np.asarray(quad, dtype=np.float64)
    verts = []
    for j in range(n + 1):
        for i in range(n + 1):
            u, v = i / n, j / n
            verts.append(tuple((1 - u) * (1 - v) * p[0] + u * (1 - v) * p[1] + u * v * p[2] + (1 - u) * v * p[3]))
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    return verts, faces


def make_cornell(outdir):
    scene = reset()
    room_center = _cornell_to_blender((278.0, 274.4, 279.6))
    white = material("white", WHITE)
    mats = {"white": white, "red": material("red", RED), "green": material("green", GREEN)}
    for name in ("floor", "ceiling", "back_wall", "green_wall", "red_wall"):
        verts, faces = _bilinear_grid([_cornell_to_blender(p) for p in _MM[name]], CORNELL_GRID)
        faces = _orient(verts, faces, room_center, inward=True)
        color = name.split("_")[0] if name in ("red_wall", "green_wall") else "white"
        mesh_object(name, verts, faces, mats[color])
    light = material("light", (0.78, 0.78, 0.78), emission=CORNELL_LIGHT_RADIANCE)
    verts = [_cornell_to_blender(p) for p in _MM["light"]]
    below = np.mean(verts, axis=0) - np.array([0, 0, 1.0])
    mesh_object("light", verts, _orient(verts, [(0, 1, 2, 3)], below, inward=True), light)
    mesh_object("short_block", *_block(_SHORT, 165.0), white)
    mesh_object("tall_block", *_block(_TALL, 330.0), white)

    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 35.0
    cam_data.sensor_fit = "VERTICAL"
    cam_data.sensor_height = 25.0
    cam_data.sensor_width = 25.0
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = _cornell_to_blender((278.0, 273.0, -800.0))
    cam.rotation_euler = (math.pi / 2, 0.0, math.pi)  # looks along -Y (Cornell +z), Z up
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x = 256
    scene.render.resolution_y = 256
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    save(os.path.join(outdir, "cornell_box.blend"))


# ---------------------------------------------------------------- staircase
STAIR_W, STAIR_L, STAIR_H = 4.0, 8.0, 9.0
FLOOR_Z = (0.0, 3.0, 6.0)
SLAB = 0.2
N_STEPS = 16
STEP_WIDTH = 1.2


def _staircase_parts():
    """Return [(name, verts, faces, forbidden_per_face)] of the stairwell."""
    W, L, H = STAIR_W, STAIR_L, STAIR_H
    objs = []
    # room shell, faces inward: (origin, u, v) with u x v pointing inside
    walls = [
        ("wall_west", (0, 0, 0), (0, L, 0), (0, 0, H), 13, 14),   # x = 0, normal +x
        ("wall_east", (W, L, 0), (0, -L, 0), (0, 0, H), 13, 14),  # x = W, normal -x
        ("wall_south", (W, 0, 0), (-W, 0, 0), (0, 0, H), 7, 14),  # y = 0, normal +y
        ("wall_north", (0, L, 0), (W, 0, 0), (0, 0, H), 7, 14),   # y = L, normal -y
        ("ceiling", (0, 0, H), (0, L, 0), (W, 0, 0), 13, 7),      # normal -z
    ]
    for name, o, u, v, nu, nv in walls:
        vs, fs = grid(o, u, v, nu, nv)
        objs.append((name, vs, fs, [False] * len(fs)))
    vs, fs = grid((0, 0, 0), (W, 0, 0), (0, L, 0), 13, 26)  # ground floor, normal +z
    objs.append(("floor_0", vs, fs, [True] * len(fs)))
    # landings: slab tops (floors, forbidden), undersides (ceilings, candidates), front edges (forbidden)
    for name, z, y0, y1, front_y, front_dir in (("landing_1", FLOOR_Z[1], 6.0, L, 6.0, -1),
                                                ("landing_2", FLOOR_Z[2], 0.0, 2.0, 2.0, +1)):
        top = grid((0, y0, z), (W, 0, 0), (0, y1 - y0, 0), 13, 6)
        under = grid((0, y0, z - SLAB), (0, y1 - y0, 0), (W, 0, 0), 3, 7)
        if front_dir < 0:
            edge = grid((0, front_y, z - SLAB), (W, 0, 0), (0, 0, SLAB), 4, 1)
        else:
            edge = grid((W, front_y, z - SLAB), (-W, 0, 0), (0, 0, SLAB), 4, 1)
        vs, fs, tags = merge([(True, top), (False, under), (True, edge)])
        objs.append((name, vs, fs, tags))
    # two flights of open-rise steps (each step a box: tread split in 3 across the width)
    rise = 3.0 / N_STEPS
    for name, x0, y_start, z0, going in (("flight_1", 0.0, 1.5, 0.0, 0.28125),
                                          ("flight_2", W - STEP_WIDTH, 6.0, 3.0, -0.25)):
        parts = []
        for k in range(N_STEPS):
            ya, yb = sorted((y_start + k * going, y_start + (k + 1) * going))
            zt = z0 + (k + 1) * rise
            vs, fs = box((x0, ya, zt - 0.06), (x0 + STEP_WIDTH, yb, zt))
            fs = [f for i, f in enumerate(fs) if i != 1]  # drop the one-piece top...
            parts.append((True, (vs, fs)))
            top = grid((x0, ya, zt), (STEP_WIDTH, 0, 0), (0, yb - ya, 0), 3, 1)  # ...use a 3-piece tread
            parts.append((True, top))
        vs, fs, tags = merge(parts)
        objs.append((name, vs, fs, tags))
    return objs


def make_staircase(outdir, with_targets=False):
    scene = reset()
    scene["relight_max_patch_size"] = 1.3
    scene["relight_target_scale"] = 1.0
    mats = {
        "plaster": material("plaster", (0.7, 0.68, 0.65)),
        "floor": material("floor", (0.35, 0.25, 0.18)),
        "stone": material("stone", (0.5, 0.5, 0.48)),
    }
    for name, vs, fs, forbidden in _staircase_parts():
        kind = "floor" if name.startswith("floor") else "stone" if name.startswith(("flight", "landing")) else "plaster"
        ob = mesh_object(name, vs, fs, mats[kind])
        attr = ob.data.attributes.new("relight_forbidden", "BOOLEAN", "FACE")
        attr.data.foreach_set("value", np.asarray(forbidden, dtype=bool))
        if with_targets:
            paint_staircase_targets(ob)
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 16.0
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (STAIR_W / 2, 0.3, 4.5)
    cam.rotation_euler = (math.radians(80), 0.0, 0.0)  # looks along +Y, slightly down
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x = 256
    scene.render.resolution_y = 384
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    save(os.path.join(outdir, "staircase_targets.blend" if with_targets else "staircase.blend"))


STAIR_TARGET_RADIANCE = (0.8, 0.8, 0.75)  # painted colour; target radiosity = pi * colour * scale


def paint_staircase_targets(ob):
    """Paint the paper's targets into the FLOAT_COLOR corner attribute ``relight_target``.

    Targets: the ground floor in front of the first flight (x in [0.3, 3.4] m, y in
    [0.2, 1.5] m) and the middle third of the treads of the first four steps.
    """
    me = ob.data
    n = len(me.polygons)
    centers = np.zeros(n * 3)
    me.polygons.foreach_get("center", centers)
    c = centers.reshape(-1, 3)
    normals = np.zeros(n * 3)
    me.polygons.foreach_get("normal", normals)
    up = normals.reshape(-1, 3)[:, 2] > 0.9
    if ob.name == "floor_0":
        sel = (c[:, 0] > 0.3) & (c[:, 0] < 3.4) & (c[:, 1] > 0.2) & (c[:, 1] < 1.5)
    elif ob.name == "flight_1":
        first = c[:, 1] < 1.5 + 4 * 0.28125
        middle = (c[:, 0] > 0.4) & (c[:, 0] < 0.8)
        sel = up & first & middle
    else:
        return
    attr = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
    loop_poly = np.zeros(len(me.loops), dtype=np.int64)
    starts = np.zeros(n, dtype=np.int64)
    totals = np.zeros(n, dtype=np.int64)
    me.polygons.foreach_get("loop_start", starts)
    me.polygons.foreach_get("loop_total", totals)
    for p in range(n):
        loop_poly[starts[p]:starts[p] + totals[p]] = p
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    col[sel[loop_poly]] = (*STAIR_TARGET_RADIANCE, 1.0)
    attr.data.foreach_set("color", col.ravel())


# ---------------------------------------------------------------- closed forms
def closed_form_geometry(kind, param):
    """(receiver polygon, emitter polygon), each (n, 3) in metres, facing each other."""
    if kind == "parallel":  # a = b = param * c, c = 1
        a = param
        rec = np.array([(0, 0, 0), (a, 0, 0), (a, a, 0), (0, a, 0)], dtype=float)  # normal +z
        emi = np.array([(0, 0, 1), (0, a, 1), (a, a, 1), (a, 0, 1)], dtype=float)  # normal -z
    elif kind == "perpendicular":  # common edge l = 1 along x; receiver width w = param, emitter height 1
        w = param
        rec = np.array([(0, 0, 0), (1, 0, 0), (1, w, 0), (0, w, 0)], dtype=float)  # y in [0, w], normal +z
        emi = np.array([(0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0)], dtype=float)  # xz plane, normal +y
    elif kind == "disks":  # r1 = r2 = param, h = 1
        t = 2 * np.pi * np.arange(DISK_SIDES) / DISK_SIDES
        ring = np.stack([param * np.cos(t), param * np.sin(t), np.zeros_like(t)], axis=1)
        rec = ring.copy()  # counter-clockwise seen from +z: normal +z
        emi = ring[::-1] + np.array([0, 0, 1.0])  # normal -z
    else:
        raise ValueError(kind)
    return rec, emi


def make_closed_form(outdir, kind, param):
    reset()
    rec, emi = closed_form_geometry(kind, param)
    grey = material("grey", (RECEIVER_REFLECTANCE,) * 3)
    black = material("black_emitter", (0.0, 0.0, 0.0), emission=(EMITTER_RADIANCE,) * 3)
    mesh_object("receiver", rec, [tuple(range(len(rec)))], grey)
    mesh_object("emitter", emi, [tuple(range(len(emi)))], black)
    save(os.path.join(outdir, closed_form_filename(kind, param)))


def main(outdir=HERE):
    if os.path.abspath(outdir) == HERE and bpy.app.version >= (5, 0, 0):
        sys.exit(f"generate.py: Blender {bpy.app.version_string} would write the shipped samples in a format "
                 "Blender 4.2-4.5 cannot read; run `make samples` (bpy 4.2 LTS) instead")
    os.makedirs(outdir, exist_ok=True)
    make_cornell(outdir)
    make_staircase(outdir)
    make_staircase(outdir, with_targets=True)
    for kind, param in CLOSED_FORM_CASES:
        make_closed_form(outdir, kind, param)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else HERE)
