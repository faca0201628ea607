"""Cycles as the independent reference for per-face radiosity (test helpers, bpy).

``cycles_face_radiance`` bakes Cycles' COMBINED outgoing radiance of every
mesh face in the current Blender file and returns per-face means, with an
estimate of Cycles' own Monte-Carlo noise on each mean.

How a per-face mean is measured without edge bias:
- each mesh gets a new UV map in which every polygon has its own square cell
  of a grid (``cell_px`` texels, one texel of padding on each side). The
  polygon is laid out in its own plane by a *similarity* (rotation + uniform
  scale; a face too narrow for it, stretched along its narrow axis: still an
  affine map), so texel centres inside it sample the face uniformly by area;
- the bake target is a float image pre-filled with a negative sentinel, baked
  with margin 0 and without clearing: exactly the texels Cycles rasterised
  (their centres lie inside the polygon) hold values, every other texel keeps
  the sentinel. Nothing bleeds across faces, unlike a vertex-colour bake;
- the face mean is the mean of its written texels (a stratified area average).

Noise: Cycles' per-texel noise is estimated from differences of horizontally
adjacent written texels (var(noise) ~ mean(d^2)/2, which removes the smooth
true variation), and the standard error of a face mean is that sigma over
sqrt(texel count). ``FaceRadiance.rel_noise`` is that error relative to the mean.

Units: Blender's emission Color x Strength is radiance L (W m^-2 sr^-1); a
COMBINED bake of a diffuse surface is its outgoing radiance, i.e. radiosity/pi.

By default the Cycles scene is made Lambertian to match the radiosity model
(``make_lambertian``; ``keep_materials`` and ``keep_light_paths`` bake the file as an artist
renders it instead): Principled BSDFs get Specular IOR Level, Metallic, Coat,
Sheen, Transmission and Diffuse Roughness 0 (the Principled diffuse lobe is then
Lambert with albedo Base Color); Principled emission one-sided
(``one_sided_emission``); world black; no clamping, no glossy filter,
no adaptive sampling, 64 bounces.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

import bpy

SENTINEL = -1.0
UV_NAME = "relight_face_cells"


@dataclass
class FaceRadiance:
    """Per-face Cycles result for one object (faces in base-mesh polygon order)."""

    radiance: np.ndarray  # (F, 3) mean outgoing radiance, W m^-2 sr^-1
    std_error: np.ndarray  # (F, 3) Monte-Carlo standard error of that mean
    n_texels: np.ndarray  # (F,) texels averaged

    @property
    def rel_noise(self) -> np.ndarray:
        """(F, 3) standard error / mean (0 where the mean is 0)."""
        m = np.abs(self.radiance)
        return np.where(m > 0, self.std_error / np.where(m > 0, m, 1.0), 0.0)


def configure_cycles(scene, samples: int, seed: int = 0, threads: int = 0, keep_light_paths: bool = False,
                     keep_world: bool = False):
    """Cycles CPU settings for an unbiased, unclamped, Lambertian-comparable bake.

    ``keep_light_paths``: leave the scene's own clamping, bounce limits, caustics, glossy
    filter and light threshold as they are (what an artist renders with); only the device,
    samples, seed, denoising/adaptive sampling, view transform and the black world are set.
    ``keep_world``: the World lights the bake as the file has it (else it is made black)."""
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = int(samples)
    c.seed = int(seed)
    c.use_animated_seed = False
    c.use_adaptive_sampling = False
    c.use_denoising = False
    if not keep_light_paths:
        _unbiased_light_paths(c)
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = int(threads)
    if keep_world:
        return
    # No world light.
    world = scene.world or bpy.data.worlds.new("relight_black_world")
    scene.world = world
    with warnings.catch_warnings():  # use_nodes is deprecated (always on) in Blender 5
        warnings.simplefilter("ignore", DeprecationWarning)
        world.use_nodes = True
    bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None)
    if bg is not None:
        bg.inputs["Strength"].default_value = 0.0
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    world.color = (0.0, 0.0, 0.0)


def black_world(name="World"):
    """A World that gives no light (black background): for scenes lit by their emitters alone.
    Relight counts the World's light (engine.lamps.world_irradiance), as Cycles does."""
    world = bpy.data.worlds.new(name)
    world.color = (0.0, 0.0, 0.0)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    bg = next((n for n in world.node_tree.nodes if n.type == "BACKGROUND"), None) if world.node_tree else None
    if bg is not None:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    return world


def _unbiased_light_paths(c):
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.max_bounces = 64
    c.diffuse_bounces = 64
    c.glossy_bounces = 64
    c.transmission_bounces = 64
    c.transparent_max_bounces = 64
    c.min_light_bounces = 0
    c.light_sampling_threshold = 0.0


def make_lambertian(materials=None):
    """Turn every Principled BSDF into a pure Lambert diffuse + emission."""
    zero = ("Specular IOR Level", "Metallic", "Coat Weight", "Sheen Weight",
            "Transmission Weight", "Subsurface Weight", "Diffuse Roughness")
    for mat in (materials if materials is not None else bpy.data.materials):
        if mat.node_tree is None:
            continue
        for node in mat.node_tree.nodes:
            if node.type == "BSDF_PRINCIPLED":
                for name in zero:
                    if name in node.inputs:
                        node.inputs[name].default_value = 0.0
                node.inputs["Roughness"].default_value = 1.0


#: a face whose narrow side would span fewer texels than this, laid out by a similarity, is
#: stretched across its cell instead (an affine map: texel centres still sample it uniformly by area)
MIN_SPAN_PX = 6


def _face_cells(obj, cell_px: int, pad: int = 1, faces=None):
    """Give ``obj`` a UV map with one square cell per polygon (or per polygon of ``faces``).

    Returns (resolution, grid columns, cell of each polygon (-1: not baked)). Cell k occupies
    texels [col*cell_px, (col+1)*cell_px) x [row*cell_px, (row+1)*cell_px) with col = k % n,
    row = k // n. A polygon is laid out in its own plane by a similarity; one too narrow for
    that (a bevel's strip, a sliver) is stretched along its narrow axis (MIN_SPAN_PX). Polygons
    not in ``faces`` are collapsed to a point outside the image: Cycles bakes no texel of them.
    """
    me = obj.data
    F = len(me.polygons)
    chosen = np.arange(F) if faces is None else np.unique(np.asarray(faces, dtype=np.int64))
    cell_of = np.full(F, -1, dtype=np.int64)
    cell_of[chosen] = np.arange(len(chosen))
    n = max(1, math.ceil(math.sqrt(max(len(chosen), 1))))
    res = n * cell_px
    uv = me.uv_layers.get(UV_NAME) or me.uv_layers.new(name=UV_NAME)
    me.uv_layers.active = uv
    mw = np.array(obj.matrix_world)
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
    loop_vert = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", loop_vert)
    uvs = np.full((len(me.loops), 2), 2.0)  # outside the image
    inner = cell_px - 2 * pad
    for f in chosen:
        poly = me.polygons[int(f)]
        ls = np.arange(poly.loop_start, poly.loop_start + poly.loop_total)
        p = co[loop_vert[ls]]
        # Newell normal, in-plane orthonormal basis: a similarity onto the plane.
        nrm = np.sum(np.cross(p, np.roll(p, -1, axis=0)), axis=0)
        nrm /= np.linalg.norm(nrm) or 1.0
        e = p[1] - p[0]
        u = e / (np.linalg.norm(e) or 1.0)
        v = np.cross(nrm, u)
        q = np.stack([(p - p[0]) @ u, (p - p[0]) @ v], axis=1)
        lo, hi = q.min(axis=0), q.max(axis=0)
        ext = np.maximum(hi - lo, 1e-30)
        scale = np.full(2, inner / float(ext.max()))
        if float(ext.min() * scale[0]) < MIN_SPAN_PX:  # too narrow: along its principal axes, stretched
            _, vec = np.linalg.eigh(np.cov((q - q.mean(axis=0)).T))
            q = q @ vec
            lo, hi = q.min(axis=0), q.max(axis=0)
            ext = np.maximum(hi - lo, 1e-30)
            scale = inner / ext
        q = (q - lo) * scale + (inner - ext * scale) / 2 + pad  # centred in the cell, texels
        k = cell_of[f]
        col, row = k % n, k // n
        uvs[ls] = (q + np.array([col * cell_px, row * cell_px])) / res
    uv.data.foreach_set("uv", uvs.ravel())
    return res, n, cell_of


def _bake_object(obj, res: int, pass_filter):
    """COMBINED bake of ``obj`` into a float image pre-filled with the sentinel."""
    img = bpy.data.images.new(f"relight_bake_{obj.name}", res, res, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    img.pixels.foreach_set(np.full(res * res * 4, SENTINEL, dtype=np.float32))
    saved = []
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or mat.node_tree is None:
            continue
        nt = mat.node_tree
        node = nt.nodes.new("ShaderNodeTexImage")
        node.image = img
        saved.append((nt, node, nt.nodes.active))
        nt.nodes.active = node
    if not saved:
        raise ValueError(f"object {obj.name!r} needs a node material to be baked")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    try:
        bpy.ops.object.bake(type="COMBINED", pass_filter=pass_filter, margin=0, use_clear=False,
                            target="IMAGE_TEXTURES", uv_layer=UV_NAME)
        px = np.empty(res * res * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
    finally:
        for nt, node, active in saved:
            nt.nodes.remove(node)
            if active is not None:
                nt.nodes.active = active
        bpy.data.images.remove(img)
    return px.reshape(res, res, 4)  # [row (v), col (u), rgba]


def _face_stats(px, F: int, n: int, cell_px: int, cell_of=None) -> FaceRadiance:
    """Each baked polygon's mean and standard error (NaN for the polygons not baked)."""
    cell_of = np.arange(F) if cell_of is None else np.asarray(cell_of)
    rad = np.full((F, 3), np.nan)
    se = np.full((F, 3), np.nan)
    cnt = np.zeros(F, dtype=np.int64)
    for f in np.flatnonzero(cell_of >= 0):
        col, row = cell_of[f] % n, cell_of[f] // n
        cell = px[row * cell_px:(row + 1) * cell_px, col * cell_px:(col + 1) * cell_px]
        written = cell[..., 3] > SENTINEL / 2
        rgb = cell[..., :3].astype(np.float64)
        cnt[f] = written.sum()
        if cnt[f] == 0:
            raise ValueError(f"face {f}: Cycles baked no texel (cell {cell_px} px too small?)")
        rad[f] = rgb[written].mean(axis=0)
        pair = written[:, 1:] & written[:, :-1]
        d = (rgb[:, 1:] - rgb[:, :-1])[pair]
        sigma = np.sqrt(0.5 * (d ** 2).mean(axis=0)) if len(d) else np.abs(rad[f])
        se[f] = sigma / np.sqrt(cnt[f])
    if not np.all(np.isfinite(rad[cell_of >= 0])):
        raise ValueError("Cycles bake produced non-finite values")
    return FaceRadiance(radiance=rad, std_error=se, n_texels=cnt)


def cycles_face_radiance(samples: int = 64, seed: int = 0, cell_px: int = 24, objects=None,
                         blend_path: str | None = None, threads: int = 0, keep_materials: bool = False,
                         keep_light_paths: bool = False, keep_world: bool = False, one_sided: bool = False,
                         faces: dict | None = None) -> dict:
    """Cycles' per-face mean outgoing radiance (W m^-2 sr^-1) of mesh objects.

    Works on the current Blender data, or opens ``blend_path`` first. Modifies
    the open file (UV maps, materials made Lambertian, Cycles settings): use
    it on a throw-away copy. Returns {object name: FaceRadiance}.

    ``keep_materials``: bake the file's materials as they are (not made Lambertian; the
    bake views each face along its normal, so a glossy layer shows its normal-view
    radiance); ``keep_light_paths``: keep the file's clamping and bounce limits
    (``configure_cycles``). Mesh emission is two-sided, as Cycles renders it and Relight models it
    (export.py: the back side of an open emitter is a face of its own); ``one_sided``: made
    one-sided first (``one_sided_emission``), for a comparison with a one-sided model.
    ``faces``: {object name: polygon indices}: only those polygons are baked (the others' rows
    are NaN), so a large object's few target faces bake in a small image.
    """
    if blend_path is not None:
        bpy.ops.wm.open_mainfile(filepath=str(blend_path))
    scene = bpy.context.scene
    configure_cycles(scene, samples, seed, threads, keep_light_paths=keep_light_paths, keep_world=keep_world)
    if not keep_materials:
        make_lambertian()
    if one_sided:
        one_sided_emission()
    if objects is None:
        objects = [o for o in scene.objects if o.type == "MESH" and not o.hide_render]
    # Direct + indirect, diffuse + emission (+ glossy, transmission when the materials are
    # kept): everything the surface sends out.
    pass_filter = {"EMIT", "DIRECT", "INDIRECT", "DIFFUSE"}
    if keep_materials:
        pass_filter |= {"GLOSSY", "TRANSMISSION"}
    out = {}
    for obj in objects:
        if len(obj.data.polygons) == 0:
            continue
        res, n, cell_of = _face_cells(obj, cell_px, faces=None if faces is None else faces[obj.name])
        px = _bake_object(obj, res, pass_filter)
        out[obj.name] = _face_stats(px, len(obj.data.polygons), n, cell_px, cell_of)
    return out


# ---------------------------------------------------------------------------
# Scenes built in Python (bpy), shared by the tests.

def _material(name, base_color, emission=(0.0, 0.0, 0.0), strength=0.0, lambertian=False):
    """A Principled BSDF (defaults but Base Color / emission); ``lambertian``: Specular IOR
    Level 0, so that it is Lambert with albedo Base Color for Relight as well as for Cycles."""
    mat = bpy.data.materials.new(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        mat.use_nodes = True
    p = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    p.inputs["Base Color"].default_value = (*base_color, 1.0)
    if lambertian:
        p.inputs["Specular IOR Level"].default_value = 0.0
    p.inputs["Emission Color"].default_value = (*emission, 1.0)
    p.inputs["Emission Strength"].default_value = strength
    return mat


def grid_quads(origin, du, dv, nu, nv):
    """Vertices and quad faces of an nu x nv grid spanning origin + [0,1]du + [0,1]dv.

    Faces wind so that the normal is du x dv.
    """
    origin, du, dv = (np.asarray(x, dtype=np.float64) for x in (origin, du, dv))
    verts = [origin + du * (i / nu) + dv * (j / nv) for j in range(nv + 1) for i in range(nu + 1)]
    faces = [(j * (nu + 1) + i, j * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i)
             for j in range(nv) for i in range(nu)]
    return verts, faces


def add_mesh_object(name, verts, faces, material):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in verts], [], faces)
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    obj.data.materials.append(material)
    return obj


def solve_cli(scene, report, out, *args) -> dict:
    """``python -m relight_addon solve SCENE --report REPORT --out OUT ARGS...`` (the real command
    line, in a child process); its report."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, "-m", "relight_addon", "solve", str(scene), "--report", str(report), "--out", str(out),
           *map(str, args)]
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(root)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(Path(report).read_text())


def built_and_solved(tmp_path_factory, name, build, *args) -> tuple:
    """The scene ``build()`` makes in an empty Blender, saved into a new temporary folder and
    solved by the command line (solve_cli, ``args``) with --out: (its report, the written copy)."""
    tmp = tmp_path_factory.mktemp(name)
    scene, out = tmp / "scene.blend", tmp / "scene_lit.blend"
    reset_blender()
    try:
        build()
        bpy.ops.wm.save_as_mainfile(filepath=str(scene))
    finally:
        reset_blender()
    return solve_cli(scene, tmp / "report.json", out, *args), out


def reset_blender():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def build_parallel_emitter_scene(side=1.0, height=0.5, n_recv=6, strength=2.0, albedo=0.6):
    """A black square emitter above a parallel grey receiver of the same size.

    The emitter (Base Color 0, emission radiance ``strength``) faces down at
    ``height``; the receiver (albedo ``albedo``) is split into n_recv x n_recv
    faces. No interreflection: the receiver's radiance is albedo * E / pi with
    E = pi * strength * (point-to-rectangle form factor), closed form.
    """
    reset_blender()
    if bpy.context.scene.world is None:
        bpy.context.scene.world = black_world()
    h = side / 2
    v, f = grid_quads((-h, -h, 0.0), (side, 0, 0), (0, side, 0), n_recv, n_recv)
    recv = add_mesh_object("Receiver", v, f, _material("grey", (albedo,) * 3))
    v, f = grid_quads((-h, -h, height), (0, side, 0), (side, 0, 0), 1, 1)  # normal -z
    add_mesh_object("Emitter", v, f, _material("lamp", (0.0,) * 3, (1.0, 1.0, 1.0), strength))
    return recv


def rect_point_form_factor(x, y, h, x0, x1, y0, y1):
    """Form factor from a point (x, y, 0) facing +z to the parallel rectangle
    [x0,x1] x [y0,y1] at height h (closed form, superposition of corner rectangles)."""

    def corner(a, b):  # rectangle with one corner above the point, sides a, b (signed)
        X, Y = np.abs(a) / h, np.abs(b) / h
        val = (X / np.sqrt(1 + X * X) * np.arctan(Y / np.sqrt(1 + X * X))
               + Y / np.sqrt(1 + Y * Y) * np.arctan(X / np.sqrt(1 + Y * Y))) / (2 * np.pi)
        return np.sign(a) * np.sign(b) * val

    return (corner(x1 - x, y1 - y) - corner(x0 - x, y1 - y)
            - corner(x1 - x, y0 - y) + corner(x0 - x, y0 - y))


def one_sided_emission(materials=None):
    """Make Principled emission one-sided (front only), as in the radiosity model.

    Cycles' mesh emission is two-sided; Emission Strength becomes
    strength * (1 - Backfacing).
    """
    for mat in (materials if materials is not None else bpy.data.materials):
        if mat.node_tree is None:
            continue
        nt = mat.node_tree
        for node in list(nt.nodes):
            if node.type != "BSDF_PRINCIPLED":
                continue
            sock = node.inputs["Emission Strength"]
            if sock.is_linked or sock.default_value == 0.0:
                continue
            geo = nt.nodes.new("ShaderNodeNewGeometry")
            front = nt.nodes.new("ShaderNodeMath")
            front.operation = "MULTIPLY_ADD"  # backfacing * (-s) + s
            front.inputs[1].default_value = -sock.default_value
            front.inputs[2].default_value = sock.default_value
            nt.links.new(geo.outputs["Backfacing"], front.inputs[0])
            nt.links.new(front.outputs["Value"], sock)


CORNELL_SIZE = 0.55
CORNELL_WHITE = (0.73, 0.71, 0.68)
CORNELL_RED = (0.63, 0.065, 0.05)
CORNELL_GREEN = (0.14, 0.45, 0.09)


def build_cornell_box(n=5, radiance=10.0):
    """A closed-top Cornell-like box (open front), built from quads, in metres.

    Walls (0.55 m) are n x n grids of quads; the ceiling's central cell
    (n odd) is the light, flush with the ceiling, Principled emission
    radiance ``radiance`` (W m^-2 sr^-1, exitance pi * radiance). Two
    axis-aligned white boxes stand on the floor. Returns the objects.
    """
    if n % 2 != 1:
        raise ValueError("n must be odd so that the light is the central ceiling cell")
    reset_blender()
    bpy.context.scene.world = black_world()
    L = CORNELL_SIZE
    white = _material("white", CORNELL_WHITE)
    objs = []
    # name, origin, du, dv (normal du x dv points into the room)
    walls = [("Floor", (0, 0, 0), (L, 0, 0), (0, L, 0), white),
             ("Back", (0, L, 0), (L, 0, 0), (0, 0, L), white),
             ("Left", (0, 0, 0), (0, L, 0), (0, 0, L), _material("red", CORNELL_RED)),
             ("Right", (L, 0, 0), (0, 0, L), (0, L, 0), _material("green", CORNELL_GREEN))]
    for name, o, du, dv, mat in walls:
        v, f = grid_quads(o, du, dv, n, n)
        objs.append(add_mesh_object(name, v, f, mat))
    v, f = grid_quads((0, 0, L), (0, L, 0), (L, 0, 0), n, n)
    ceiling = add_mesh_object("Ceiling", v, f, white)
    ceiling.data.materials.append(_material("light", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), radiance))
    centre = (n // 2) * n + n // 2
    ceiling.data.polygons[centre].material_index = 1
    objs.append(ceiling)

    def box(name, x0, y0, w, d, h):
        x1, y1 = x0 + w, y0 + d
        verts = [(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0),
                 (x0, y0, h), (x1, y0, h), (x1, y1, h), (x0, y1, h)]
        faces = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]  # outward
        return add_mesh_object(name, verts, faces, white)

    objs.append(box("ShortBox", 0.13, 0.065, 0.165, 0.165, 0.165))
    objs.append(box("TallBox", 0.29, 0.29, 0.165, 0.165, 0.33))
    return objs


def subdivide_quads(obj, cuts: int):
    """Split every quad of ``obj`` into a (cuts+1) x (cuts+1) grid of quads (bmesh)."""
    import bmesh

    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=int(cuts), use_grid_fill=True)
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()


def face_areas(obj) -> np.ndarray:
    """(F,) world-space polygon areas (m^2) of a mesh object without shear."""
    me = obj.data
    a = np.empty(len(me.polygons))
    me.polygons.foreach_get("area", a)
    s = np.abs(np.linalg.det(np.array(obj.matrix_world)[:3, :3])) ** (2.0 / 3.0)
    return a * s


# ---------------------------------------------------------------------------
# White furnace: a material's albedo as Cycles renders it.

@dataclass
class FurnaceResult:
    """Per material: what Cycles renders of a unit sphere in a uniform white world."""

    albedo: np.ndarray  # (3,) mean radiance over the projected disk = cosine-weighted hemispherical albedo
    normal: np.ndarray  # (3,) mean radiance of the pixels whose normal is within ~11 deg of the view
    std_error: np.ndarray  # (3,) Monte-Carlo standard error of ``albedo`` (adjacent-pixel differences)
    mu: np.ndarray  # (n,) cosine between the view and the normal at each covered pixel (perfect sphere)
    pixels: np.ndarray  # (n, 3) those pixels' radiance


def furnace_albedos(setups, px=48, samples=32, seed=0, threads=0, workdir=None) -> list:
    """Render every material of ``setups`` (callables ``setup(material)`` that build its node
    tree on a fresh node material) on its own unit sphere under a uniform white world of
    radiance 1, in ONE orthographic Cycles render, and return a FurnaceResult per material.

    Why this measures the white-furnace albedo: seen by an orthographic camera, the pixels of a
    sphere sample the cosine mu between view and normal with density 2 mu dmu (the projected
    area of a ring is 2 pi r dr = 2 pi mu dmu), so the mean pixel over the disk is
    2 int R(mu) mu dmu, the hemispherical (cosine-weighted) albedo the radiosity engine uses.
    Each sphere (UV sphere 128 x 64, smooth) is visible to camera rays only, so the spheres
    neither shadow nor light each other; film transparent (alpha = coverage), a 0.01 px pixel
    filter (each pixel samples its centre), no clamping, 8 bounces. Resets Blender first.
    """
    import os
    import tempfile

    import bmesh

    reset_blender()
    scene = bpy.context.scene
    n = len(setups)
    cols = max(1, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / cols)
    spacing, scale = 2.2, 2.2  # sphere centres 2.2 apart, each in a 2.2 x 2.2 square tile
    me = bpy.data.meshes.new("furnace_sphere")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=128, v_segments=64, radius=1.0)
    bm.to_mesh(me)
    bm.free()
    me.shade_smooth()
    centres = []
    for k, setup in enumerate(setups):
        mat = bpy.data.materials.new(f"furnace_{k}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            mat.use_nodes = True
        setup(mat)
        m = me.copy()
        m.materials.append(mat)
        ob = bpy.data.objects.new(f"sphere_{k}", m)
        r, c = divmod(k, cols)
        ob.location = (c * spacing, -r * spacing, 0.0)
        for attr in ("visible_diffuse", "visible_glossy", "visible_transmission", "visible_shadow",
                     "visible_volume_scatter"):
            setattr(ob, attr, False)
        scene.collection.objects.link(ob)
        centres.append((r, c))
    cam = bpy.data.cameras.new("furnace_cam")
    cam.type = "ORTHO"
    cam.ortho_scale = scale * max(cols, rows)
    cam_ob = bpy.data.objects.new("furnace_cam", cam)
    cam_ob.location = ((cols - 1) * spacing / 2, -(rows - 1) * spacing / 2, 10.0)
    scene.collection.objects.link(cam_ob)
    scene.camera = cam_ob
    configure_cycles(scene, samples, seed, threads)
    c = scene.cycles
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = 8
    c.filter_width = 0.01
    world = scene.world
    bg = next(nd for nd in world.node_tree.nodes if nd.type == "BACKGROUND")
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    r = scene.render
    r.film_transparent = True
    r.resolution_x, r.resolution_y = px * cols, px * rows
    if cols != rows:  # ortho_scale spans the larger side
        pass
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    d = workdir or tempfile.mkdtemp(prefix="relight_furnace_")
    path = os.path.join(d, "furnace.exr")
    r.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    try:
        W, H = img.size
        pix = np.array(img.pixels[:], dtype=np.float64).reshape(H, W, 4)[::-1]  # row 0 = top
    finally:
        bpy.data.images.remove(img)
    out = []
    tile = px * max(cols, rows) / max(cols, rows)  # pixels per 2.2 m tile
    for (rr, cc) in centres:
        cell = pix[rr * px:(rr + 1) * px, cc * px:(cc + 1) * px]
        a = cell[..., 3]
        rgb = cell[..., :3]
        x = ((np.arange(px) + 0.5) / tile - 0.5) * scale
        X, Y = np.meshgrid(x, x)
        rad = np.sqrt(X ** 2 + Y ** 2)
        inside = (a > 0.5) & (rad < 1.0)
        mu = np.sqrt(np.clip(1.0 - rad ** 2, 0.0, 1.0))
        pair = inside[:, 1:] & inside[:, :-1]
        diff = (rgb[:, 1:] - rgb[:, :-1])[pair]
        sigma = np.sqrt(0.5 * (diff ** 2).mean(axis=0))
        out.append(FurnaceResult(albedo=rgb[inside].mean(axis=0), normal=rgb[inside & (rad < 0.2)].mean(axis=0),
                                 std_error=sigma / np.sqrt(inside.sum()), mu=mu[inside], pixels=rgb[inside]))
    return out
