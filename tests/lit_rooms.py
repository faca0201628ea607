"""Rooms lit by lamps and Worlds, built with bpy for the Cycles comparisons (tests/test_cycles_lamps.py,
tests/test_cycles_world.py), and the command line run on them: `python -m relight_addon ...` and
the report against Cycles' bake of the same file."""
import json
import math
import os
import subprocess
import sys

import bpy
import numpy as np

import cycles_reference as cr

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def light(kind, location, rotation=(0.0, 0.0, 0.0), name=None, data=None, **props):
    """A lamp object (named ``name``, default lamp_<kind>; ``data``: an existing Light to share)."""
    ld = data or bpy.data.lights.new(name or f"lamp_{kind.lower()}", kind)
    for k, v in props.items():
        setattr(ld, k, v)
    ob = bpy.data.objects.new(name or ld.name, ld)
    bpy.context.scene.collection.objects.link(ob)
    ob.location, ob.rotation_euler = location, rotation
    return ob


def relight(command, blend, report_path, *extra):
    """`python -m relight_addon COMMAND BLEND --report R ...` (the real command line): its report."""
    proc = subprocess.run([sys.executable, "-m", "relight_addon", command, str(blend), "--report", str(report_path),
                           "--quiet", *map(str, extra)], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(report_path.read_text())


def against_cycles(report, baked):
    """Per face (every baked object), the report's radiosity / pi against Cycles' radiance, channels
    summed: (relative errors, signed errors, a summary printed and returned)."""
    rel, signed, lines = [], [], []
    for name, cyc in baked.items():
        ours = np.asarray(report["objects"][name]["radiosity"], dtype=np.float64) / math.pi
        lum = cyc.radiance.sum(axis=1)
        rel.append(np.abs(ours.sum(axis=1) - lum) / lum)
        signed.append((ours.sum(axis=1) - lum) / lum)
        lines.append(f"{name}: mean {rel[-1].mean():.4f} max {rel[-1].max():.4f} signed {signed[-1].mean():+.4f}")
    rel, signed = np.concatenate(rel), np.concatenate(signed)
    summary = f"{len(rel)} faces: mean {rel.mean():.4f} max {rel.max():.4f} signed {signed.mean():+.4f}\n" + \
        "\n".join(lines)
    print(summary)
    return rel, signed, summary


def radiosity_against_cycles(blend, report_path, samples=1024, seed=1):
    """`radiosity` on ``blend``, and every face of it against Cycles baking the same file with its
    World: (relative errors, signed errors, a summary; against_cycles)."""
    report = relight("radiosity", blend, report_path)
    try:
        baked = cr.cycles_face_radiance(samples=samples, seed=seed, blend_path=str(blend), keep_world=True)
    finally:
        cr.reset_blender()
    return against_cycles(report, baked)


def lamp_room(path, lambertian=True):
    """A closed 4 x 3 x 2.5 m room (walls and ceiling 0.6, floor (0.4, 0.35, 0.3); Lambertian, or
    default Principled BSDFs of that Base Color), 4 x 4 faces a side, no World, lit by a Point and
    a Spot lamp; saved to ``path``."""
    cr.reset_blender()
    bpy.context.scene.world = None
    walls = cr._material("walls", (0.6, 0.6, 0.6), lambertian=lambertian)
    floor_m = cr._material("floor", (0.4, 0.35, 0.3), lambertian=lambertian)
    W, D, H, n = 4.0, 3.0, 2.5, 4
    quads = [  # inward-facing walls and ceiling, a floor
        ("floor", (0, 0, 0), (W, 0, 0), (0, D, 0), floor_m),
        ("ceiling", (0, D, H), (W, 0, 0), (0, -D, 0), walls),
        ("wall_s", (0, 0, 0), (0, 0, H), (W, 0, 0), walls),
        ("wall_n", (0, D, 0), (W, 0, 0), (0, 0, H), walls),
        ("wall_w", (0, 0, 0), (0, D, 0), (0, 0, H), walls),
        ("wall_e", (W, 0, 0), (0, 0, H), (0, D, 0), walls),
    ]
    for name, o, du, dv, m in quads:
        v, f = cr.grid_quads(o, du, dv, n, n)
        cr.add_mesh_object(name, v, f, m)
    light("POINT", (1.2, 1.5, 2.0), energy=150.0, shadow_soft_size=0.1)
    light("SPOT", (3.2, 1.0, 2.3), (0.4, 0.3, 0.0), energy=400.0, spot_size=math.radians(60), spot_blend=0.2)
    bpy.context.scene["relight_max_patch_size"] = 0.5
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def floor_with_blocker(albedo, n):
    """A 4 m grey floor of n x n faces (Lambertian ``albedo``), a black tile floating 0.5 m over it
    to cast a shadow, no World: the scene of the lamp kinds' direct light against Cycles."""
    cr.reset_blender()
    bpy.context.scene.world = None  # no World light: only the lamp
    grey = cr._material("grey", (albedo,) * 3, lambertian=True)
    v, f = cr.grid_quads((-2.0, -2.0, 0.0), (4.0, 0, 0), (0, 4.0, 0), n, n)
    floor = cr.add_mesh_object("floor", v, f, grey)
    black = cr._material("black", (0.0,) * 3, lambertian=True)
    v, f = cr.grid_quads((-0.9, -0.3, 0.5), (0.6, 0, 0), (0, 0.6, 0), 1, 1)  # a tile floating at 0.5 m
    cr.add_mesh_object("blocker", v, f, black)
    return floor


def floor_irradiance_against_cycles(name, floor, exp, lamps, albedo, samples, min_lit, dark=False):
    """``lamps``' direct irradiance on the floor of floor_with_blocker (lamp_irradiance on the exported
    patches, per floor face) against Cycles' bake of that floor, per channel (a Temperature's colour
    has its own power in each): the lamps' power on the lit faces within 1 %, the mean per face within
    2 %, each face within 8 % or 2 % of the peak (a cone's or a shadow's edge crosses it, sampled)
    plus 4 x the bake's noise; ``dark``: no more than 2 % of the peak where Cycles has under 0.5 % of it
    (a distribution's zero, a fixture's back)."""
    from relight_addon.engine.lamps import lamp_irradiance
    from relight_addon.engine.scene import mesh_patches

    try:
        patches = mesh_patches(exp.faces, 10.0)
        H = lamp_irradiance(patches, lamps, seed=0)[:, 0, :]
        on_floor = patches.object == exp.faces.object_names.index("floor")
        ours_rgb = np.zeros((len(floor.data.polygons), 3))
        ours_rgb[exp.faces.face_index[patches.face[on_floor]]] = H[on_floor]
        baked = cr.cycles_face_radiance(samples=samples, seed=1, objects=[floor], threads=2)["floor"]
    finally:
        cr.reset_blender()
    for c in range(3):
        ours = ours_rgb[:, c]
        E = math.pi * baked.radiance[:, c] / albedo
        noise = math.pi * baked.std_error[:, c] / albedo
        lit = E > 0.05 * E.max()
        rel = np.abs(ours[lit] - E[lit]) / E[lit]
        total = abs(ours[lit].sum() / E[lit].sum() - 1)
        worst = np.argsort(-rel)[:3]
        summary = (f"{name} ({'RGB'[c]}): {lit.sum()} lit faces, mean {rel.mean():.4f} max {rel.max():.4f}, total "
                   f"{total:.4f} (ours {ours[lit].sum():.4g}, Cycles {E[lit].sum():.4g}); Cycles noise "
                   f"{np.mean(noise[lit] / E[lit]):.4f}; worst faces (ours, Cycles, peak): "
                   + ", ".join(f"({ours[lit][i]:.3g}, {E[lit][i]:.3g})" for i in worst) + f", {E.max():.3g}")
        print(summary)
        assert lit.sum() >= min_lit, summary
        assert total < 0.01, summary
        assert rel.mean() < 0.02, summary
        assert np.all(np.abs(ours[lit] - E[lit]) <= 0.08 * E[lit] + 0.02 * E.max() + 4 * noise[lit]), summary
        if dark:
            assert np.all(ours[E < 0.005 * E.max()] <= 0.02 * E.max()), summary


def targets_against_cycles(report, baked, names, own_materials=False):
    """Each painted face of the objects ``names``: the report's prediction (its radiosity / pi, or with
    the file's own materials its radiance along the normal, which a bake with them shows) against
    Cycles' bake, channels summed: (signed relative errors per object, one line per object)."""
    signed, lines = [], []
    for name in names:
        rows = report["objects"][name]
        target = np.array([t is not None for t in rows["target"]])
        ours = (np.array([r if r is not None else [np.nan] * 3 for r in rows["radiance_normal"]], dtype=np.float64)
                if own_materials else np.asarray(rows["radiosity"], dtype=np.float64) / math.pi)[target].sum(axis=1)
        got = baked[name].radiance[target].sum(axis=1)
        signed.append((ours - got) / got)
        lines.append(f"{name}: {target.sum()} targets, mean {np.abs(signed[-1]).mean():.4f} signed "
                     f"{signed[-1].mean():+.4f}, Cycles noise {baked[name].rel_noise[target].mean():.4f}")
    return signed, lines


def paint(ob, polygons, rgb):
    me = ob.data
    layer = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    for p in polygons:
        poly = me.polygons[p]
        col[poly.loop_start:poly.loop_start + poly.loop_total] = (*rgb, 1.0)
    layer.data.foreach_set("color", col.ravel())


def uniform_world(color, strength=1.0):
    world, _, bg = world_tree()
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
    return world


def cut_window(wall="wall_s", faces=(5, 6, 9, 10)):
    """Delete faces of a wall of lamp_room (the default: a 2 x 1.25 m window in the south wall)."""
    import bmesh

    me = bpy.data.objects[wall].data
    bm = bmesh.new()
    bm.from_mesh(me)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[i] for i in faces], context="FACES_ONLY")
    bm.to_mesh(me)
    bm.free()


def remove_lamps():
    for ob in [o for o in bpy.data.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(ob)


def solve_closed_loop(blend, tmp_path, targets, rgb, samples=1024, seed=2, own_materials=False):
    """Paint ``targets`` (floor face indices) of the file's floor ``rgb``, forbid lights on the floor
    and walls (only the ceiling may hold them), `solve --out`, and bake the floor of the written
    file with its own World (``own_materials``: and its own materials and light paths, against the
    report's radiance_normal): (report, per-target relative errors, signed errors, the scene's
    light's share of the targets, a summary)."""
    report_path, out = tmp_path / "r.json", tmp_path / "out.blend"
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
        objs = bpy.data.objects
        paint(objs["floor"], targets, rgb)
        for name in ("floor", "wall_s", "wall_n", "wall_w", "wall_e"):
            objs[name]["relight_no_lights"] = True
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        cr.reset_blender()
    report = relight("solve", blend, report_path, "--out", out, "--seed", "1")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        baked = cr.cycles_face_radiance(samples=samples, seed=seed, objects=[bpy.data.objects["floor"]],
                                        keep_world=True, keep_materials=own_materials,
                                        keep_light_paths=own_materials)
    finally:
        cr.reset_blender()
    signed = targets_against_cycles(report, baked, ["floor"], own_materials)[0][0]
    e = np.abs(signed)
    fixed = [r for r in report["fixed_light"] if r["kind"] != "emission"]
    share = sum(r["share"] for r in fixed)
    summary = (f"fixed light {[(r['name'], round(r['share'], 3)) for r in fixed]} (share {share:.2f}); "
               f"{report['final']['n_lights']} lights, relative error {report['final']['relative_error']:.3f}; "
               f"targets: mean {e.mean():.4f} max {e.max():.4f} signed {signed.mean():+.4f}")
    print(summary)
    return report, e, signed, share, summary


def world_tree(name="sky"):
    world = bpy.data.worlds.new(name)
    bpy.context.scene.world = world
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nt = world.node_tree
    return world, nt, next(n for n in nt.nodes if n.type == "BACKGROUND")


def sky_world(strength=0.06, sun_disc=True):
    """A Sky Texture World (Blender's default sky model) whose sun stands 35 degrees high in the
    south (-Y), shining through the south window."""
    world, nt, bg = world_tree()
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sun_elevation, sky.sun_rotation = math.radians(35), math.radians(200)
    sky.sun_disc = sun_disc
    nt.links.new(sky.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    return world


def hdri_world(path, sun=(0.0, -0.75, 0.66)):
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
    world, nt, bg = world_tree("hdri")
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(path))
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return world
