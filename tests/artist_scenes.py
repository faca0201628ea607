"""Scenes modelled the way artists model them, built with bpy (tests and benchmarks).

``living_room(detail)``: a 5 x 4 x 2.7 m room whose walls and ceiling are ONE cube mesh (5 big
quads; its floor face deleted), a floor grid of 0.5 m faces for painting, a sofa of boxes with a
Bevel modifier, a table, a Subdivision-Surface Suzanne, a 64 x 32 UV sphere and a torus, all
with default Principled BSDF materials (Base Color only changed) and Cycles' default render
settings. Targets are painted (relight_target) on part of the floor and on the table top; only
the walls and the ceiling may emit (every other object has relight_no_lights).

``detail`` raises the Suzanne's subdivision levels: 2 -> about 23k triangles in all, 4 ->
about 260k, 5 -> about 1M.
"""
from __future__ import annotations

import bmesh
import bpy
import numpy as np

ROOM = (5.0, 4.0, 2.7)


def principled(name, color):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    mat.diffuse_color = (*color, 1.0)
    return mat


def _link(ob, mat):
    ob.data.materials.append(mat)
    return ob


def _mesh_object(name, build):
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    build(bm)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _uv_sphere(name, radius, location):
    """A UV sphere of 64 segments and 32 rings (primitive_uv_sphere_add's vertices), its faces in
    a fixed order: Blender 5.0's operator (and bmesh.ops.create_uvsphere) gives its polygons in a
    different order in each process, which moved the adaptive model's clusters and the answer
    between runs. Each polygon starts at its lowest vertex (its orientation kept), the polygons sorted."""
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=64, v_segments=32, radius=radius)
    bm.verts.index_update()
    verts = [tuple(v.co) for v in bm.verts]
    polys = []
    for f in bm.faces:
        idx = [v.index for v in f.verts]
        k = idx.index(min(idx))
        polys.append(tuple(idx[k:] + idx[:k]))
    bm.free()
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], sorted(polys))
    me.update()
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def paint(ob, faces, rgb):
    """Paint target colour (radiance) ``rgb`` on polygons ``faces`` of ``ob`` (relight_target, alpha 1)."""
    me = ob.data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)  # a new layer: unpainted (alpha 0)
    attr = me.color_attributes.get("relight_target")
    if attr is None:
        attr = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
    else:
        attr.data.foreach_get("color", col.ravel())
    starts = np.zeros(len(me.polygons), dtype=np.int64)
    totals = np.zeros(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_start", starts)
    me.polygons.foreach_get("loop_total", totals)
    for f in faces:
        col[starts[f]:starts[f] + totals[f]] = (*rgb, 1.0)
    attr.data.foreach_set("color", col.ravel())


def forbid(ob, faces):
    """Forbid lights on polygons ``faces`` of ``ob`` (relight_forbidden, a new Face BOOLEAN layer)."""
    me = ob.data
    values = np.zeros(len(me.polygons), dtype=bool)
    values[np.asarray(faces, dtype=np.int64)] = True
    me.attributes.new("relight_forbidden", "BOOLEAN", "FACE").data.foreach_set("value", values)


def living_room(detail=2, target=(0.35, 0.33, 0.3)):
    """Build the living room in the current (empty) scene; returns {name: object}."""
    W, D, H = ROOM
    scene = bpy.context.scene
    obs = {}

    def room(bm):  # walls and ceiling: one cube, 5 big quads facing inwards, no floor face
        bmesh.ops.create_cube(bm, size=1.0)
        for v in bm.verts:
            v.co.x *= W
            v.co.y *= D
            v.co.z = (v.co.z + 0.5) * H
        bmesh.ops.delete(bm, geom=[f for f in bm.faces if f.normal.z < -0.5], context="FACES")
        bmesh.ops.reverse_faces(bm, faces=list(bm.faces))
    obs["Room"] = _link(_mesh_object("Room", room), principled("Walls", (0.8, 0.78, 0.72)))

    def floor(bm):
        bmesh.ops.create_grid(bm, x_segments=10, y_segments=8, size=0.5)
        bmesh.ops.scale(bm, vec=(W, D, 1.0), verts=bm.verts)
    fl = _link(_mesh_object("Floor", floor), principled("Wood", (0.45, 0.3, 0.2)))
    obs["Floor"] = fl

    def box(bm, sx, sy, sz, x, y, z):
        r = bmesh.ops.create_cube(bm, size=1.0)
        bmesh.ops.scale(bm, vec=(sx, sy, sz), verts=r["verts"])
        bmesh.ops.translate(bm, vec=(x, y, z + sz / 2), verts=r["verts"])

    def sofa(bm):
        box(bm, 2.0, 0.9, 0.45, 0.0, -1.4, 0.0)  # seat
        box(bm, 2.0, 0.2, 0.5, 0.0, -1.75, 0.45)  # back
        box(bm, 0.2, 0.9, 0.3, -1.1, -1.4, 0.45)  # arms
        box(bm, 0.2, 0.9, 0.3, 1.1, -1.4, 0.45)
    so = _link(_mesh_object("Sofa", sofa), principled("Fabric", (0.25, 0.3, 0.45)))
    bev = so.modifiers.new("Bevel", "BEVEL")
    bev.width = 0.03
    bev.segments = 3
    obs["Sofa"] = so

    def table(bm):
        box(bm, 1.2, 0.7, 0.04, 0.5, 0.6, 0.7)  # top (its upper face is painted)
        for x in (-0.05, 1.05):
            for y in (0.3, 0.9):
                box(bm, 0.05, 0.05, 0.7, x, y, 0.0)
    tb = _link(_mesh_object("Table", table), principled("Oak", (0.5, 0.35, 0.2)))
    obs["Table"] = tb

    bpy.ops.mesh.primitive_monkey_add(size=0.5, location=(0.5, 0.6, 0.95))
    suz = bpy.context.active_object
    suz.name = "Suzanne"
    sub = suz.modifiers.new("Subdivision", "SUBSURF")
    sub.levels = sub.render_levels = detail
    suz.data.materials.append(principled("Clay", (0.7, 0.6, 0.5)))
    obs["Suzanne"] = suz
    obs["Sphere"] = _uv_sphere("Sphere", 0.3, (-1.6, 1.2, 0.3))
    obs["Sphere"].data.materials.append(principled("Ceramic", (0.9, 0.9, 0.9)))
    bpy.ops.mesh.primitive_torus_add(location=(1.8, 1.3, 0.15), major_radius=0.35, minor_radius=0.12)
    obs["Torus"] = bpy.context.active_object
    obs["Torus"].data.materials.append(principled("Red", (0.7, 0.15, 0.1)))
    for name in ("Floor", "Sofa", "Table", "Suzanne", "Sphere", "Torus"):
        obs[name]["relight_no_lights"] = True  # the custom property export reads (add-on or not)
    # targets: a 2 x 1.5 m area of the floor in front of the sofa, and the table top
    fme = fl.data
    cen = np.zeros(3 * len(fme.polygons))
    fme.polygons.foreach_get("center", cen)
    cen = cen.reshape(-1, 3)
    sel = np.flatnonzero((np.abs(cen[:, 0]) < 1.0) & (cen[:, 1] > -1.0) & (cen[:, 1] < 0.5))
    paint(fl, sel, target)
    tme = tb.data
    tc = np.zeros(3 * len(tme.polygons))
    tme.polygons.foreach_get("center", tc)
    tn = np.zeros(3 * len(tme.polygons))
    tme.polygons.foreach_get("normal", tn)
    tc, tn = tc.reshape(-1, 3), tn.reshape(-1, 3)
    top = np.flatnonzero((tn[:, 2] > 0.9) & (tc[:, 2] > 0.73))
    paint(tb, top, tuple(1.3 * np.asarray(target)))
    scene.render.engine = "CYCLES"
    return obs


def triangle_count(context=None):
    """Triangles of the evaluated scene (modifiers applied)."""
    context = context or bpy.context
    dg = context.evaluated_depsgraph_get()
    n = 0
    for ob in context.scene.objects:
        if ob.type == "MESH":
            me = ob.evaluated_get(dg).to_mesh()
            me.calc_loop_triangles()
            n += len(me.loop_triangles)
            ob.evaluated_get(dg).to_mesh_clear()
    return n


GALLERY = (6.0, 5.0, 3.2)
#: the painting: its size (m), its centre's height (m) and the painted radiances
PAINTING = (1.0, 0.7, 1.6)
BAND = 0.6


def gallery(painting=1.2, band=0.08, floor=0.1):
    """Issue 17's gallery, in the current (empty) scene: a 6 x 5 x 3.2 m room whose walls and
    ceiling are one mesh ("Room": the ceiling and three walls one quad each, the north wall (+Y)
    cut into a 5 x 5 grid so that a 0.6 m band around the painting is faces of its own), a 1.0 x
    0.7 m painting ("Painting", 2 cm in front of the north wall, its centre 1.6 m high) and a
    floor of 0.5 m faces ("Floor"); Lambertian materials (Principled, Specular IOR Level 0), no
    World. Painted radiance (relight_target): the painting ``painting`` (grey), the band around
    it ``band``, a 3 x 1 m floor strip in front of the wall ``floor``. Only the ceiling may hold
    lights (the walls' faces relight_forbidden; the floor and the painting relight_no_lights).
    Returns {name: object}."""
    import cycles_reference as cr

    W, D, H = GALLERY
    pw, ph, pz = PAINTING
    x0, y0 = -W / 2, -D / 2
    walls = cr._material("Walls", (0.8, 0.78, 0.72), lambertian=True)
    verts, faces = [], []

    def quad(corners):
        k = len(verts)
        verts.extend(corners)
        faces.append((k, k + 1, k + 2, k + 3))

    # inward-facing: the ceiling, the south, west and east walls, each one quad
    quad([(x0, y0, H), (x0, -y0, H), (-x0, -y0, H), (-x0, y0, H)])
    quad([(x0, y0, 0), (x0, y0, H), (-x0, y0, H), (-x0, y0, 0)])
    quad([(x0, y0, 0), (x0, -y0, 0), (x0, -y0, H), (x0, y0, H)])
    quad([(-x0, y0, 0), (-x0, y0, H), (-x0, -y0, H), (-x0, -y0, 0)])
    xs = [x0, -pw / 2 - BAND, -pw / 2, pw / 2, pw / 2 + BAND, -x0]
    zs = [0.0, pz - ph / 2 - BAND, pz - ph / 2, pz + ph / 2, pz + ph / 2 + BAND, H]
    north = []  # (column, row) of each north-wall face
    for j in range(5):
        for i in range(5):
            quad([(xs[i], -y0, zs[j]), (xs[i + 1], -y0, zs[j]), (xs[i + 1], -y0, zs[j + 1]), (xs[i], -y0, zs[j + 1])])
            north.append((i, j))
    room = cr.add_mesh_object("Room", verts, faces, walls)
    me = room.data
    forbidden = me.attributes.new("relight_forbidden", "BOOLEAN", "FACE")
    forbidden.data.foreach_set("value", [k > 0 for k in range(len(faces))])  # all but the ceiling
    band_faces = [4 + k for k, (i, j) in enumerate(north) if 1 <= i <= 3 and 1 <= j <= 3 and (i, j) != (2, 2)]
    paint(room, band_faces, (band,) * 3)
    v, f = cr.grid_quads((-pw / 2, -y0 - 0.02, pz - ph / 2), (pw, 0, 0), (0, 0, ph), 1, 1)  # facing -Y
    pic = cr.add_mesh_object("Painting", v, f, cr._material("Canvas", (0.6, 0.55, 0.5), lambertian=True))
    paint(pic, [0], (painting,) * 3)
    v, f = cr.grid_quads((x0, y0, 0.0), (W, 0, 0), (0, D, 0), 12, 10)
    fl = cr.add_mesh_object("Floor", v, f, cr._material("Wood", (0.45, 0.3, 0.2), lambertian=True))
    cen = np.array([fl.data.polygons[k].center[:] for k in range(len(fl.data.polygons))])
    paint(fl, np.flatnonzero((np.abs(cen[:, 0]) < 1.5) & (cen[:, 1] > -y0 - 1.0)), (floor,) * 3)
    for ob in (pic, fl):
        ob["relight_no_lights"] = True
    bpy.context.scene.world = None
    bpy.context.scene.render.engine = "CYCLES"
    return {"Room": room, "Painting": pic, "Floor": fl}


def scale_scene(scale):
    """Scale every top-level object of the scene about the origin by ``scale`` (the same scene in
    other units: tests/test_scale.py, benchmarks/bench_extent.py)."""
    import mathutils

    S = mathutils.Matrix.Scale(scale, 4)
    for ob in bpy.data.objects:
        if ob.parent is None:
            ob.matrix_world = S @ ob.matrix_world
    bpy.context.view_layer.update()
