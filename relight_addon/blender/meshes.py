"""Mesh building (bpy): evaluated meshes as numpy arrays, their faces gathered with their
materials into chunks (engine.face_chunks), and the fingerprints a stored result must match.

Every exported object is evaluated with its modifiers (depsgraph ``evaluated_get`` /
``to_mesh``) and placed in world space (``matrix_world``, parent chain included); a
negative-determinant transform (negative scale) reverses the winding so normals keep pointing the
same way as in Blender's viewport. One engine face per polygon of the evaluated mesh, triangulated
with ``mesh.loop_triangles`` (concave n-gons are fine). ``face_index`` is the polygon index in
the object's BASE mesh: without modifiers it is the polygon itself; with modifiers a temporary
INT face attribute (``_relight_face_index``) is written on the base mesh, carried through the
modifier stack and removed right after (the user's mesh ends as it was). Faces that a modifier
creates without that attribute (or of linked, read-only meshes) get ``face_index`` -1.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..engine.face_chunks import FaceChunks, check_near
from ..engine.scene import SceneError
from ..engine.units import exitance_from_radiance
from .exported_materials import material_closure, scene_material

_FACE_INDEX_ATTRIBUTE = "_relight_face_index"


def foreach_array(seq, attr, n, dtype, width=1):
    """``seq.foreach_get(attr)`` into a new (n,) or (n, width) array."""
    a = np.zeros(n * width, dtype=dtype)
    if n:
        seq.foreach_get(attr, a)
    return a.reshape(n, width) if width > 1 else a


def loop_polygons(mesh):
    """(polygon of each loop, loop_start, loop_total) of a mesh."""
    n = len(mesh.polygons)
    starts = foreach_array(mesh.polygons, "loop_start", n, np.int64)
    totals = foreach_array(mesh.polygons, "loop_total", n, np.int64)
    return np.repeat(np.arange(n), totals), starts, totals


#: positions are compared within this fraction of the object's size (times sqrt(vertices))
FINGERPRINT_TOLERANCE = 1e-6


def _vertex_weights(n):
    """Two fixed pseudo-random weights in [-0.5, 0.5) per vertex index (a Weyl sequence)."""
    i = np.arange(n, dtype=np.float64)
    return np.stack([(i * 0.6180339887498949) % 1.0, (i * 0.7548776662466927 + 0.5) % 1.0], axis=1) - 0.5


def mesh_fingerprint(ob) -> dict:
    """What a stored result must still match: the base mesh's topology and the evaluated one's
    (exact: a hash of their polygons' vertex loops; a modifier that adds faces changes it) and
    the evaluated mesh's world-space vertex positions (two weighted sums per axis and the
    bounding box, compared within a tolerance: a shape key or a modifier that moves vertices
    changes them)."""

    def loops(me):
        nv, nl, npoly = len(me.vertices), len(me.loops), len(me.polygons)
        return [[nv, nl, npoly], foreach_array(me.polygons, "loop_total", npoly, np.int64),
                foreach_array(me.loops, "vertex_index", nl, np.int64)]

    ob_eval = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ob_eval.to_mesh()
    try:
        nv = len(me.vertices)
        return _fingerprint(ob, loops(me), foreach_array(me.vertices, "co", nv, np.float64, 3).reshape(nv, 3),
                            np.array(ob_eval.matrix_world, dtype=np.float64))
    finally:
        ob_eval.to_mesh_clear()


def geometry_fingerprint(ob, geo, M) -> dict:
    """``mesh_fingerprint(ob)`` from the export's own reading of its evaluated mesh (``geo``, from
    ``mesh_geometry``, at world matrix ``M``): the same arrays, the mesh not evaluated again."""
    V = geo["V"]
    counts = [len(V), len(geo["loop_vert"]), len(geo["loop_total"])]
    return _fingerprint(ob, [counts, geo["loop_total"], geo["loop_vert"]], V.reshape(-1, 3), M)


def _fingerprint(ob, evaluated_loops, co, M) -> dict:
    import hashlib

    def loops(me):
        nv, nl, npoly = len(me.vertices), len(me.loops), len(me.polygons)
        return [[nv, nl, npoly], foreach_array(me.polygons, "loop_total", npoly, np.int64),
                foreach_array(me.loops, "vertex_index", nl, np.int64)]

    nv = len(co)
    topo = hashlib.blake2b(np.concatenate(loops(ob.data) + list(evaluated_loops)).astype(np.int64).tobytes(),
                           digest_size=16)
    W = co @ M[:3, :3].T + M[:3, 3]
    sig = (_vertex_weights(nv).T @ W).ravel() if nv else np.zeros(6)
    box = np.concatenate([W.min(axis=0), W.max(axis=0)]) if nv else np.zeros(6)
    return {"topology": topo.hexdigest(), "vertices": nv, "signature": sig.tolist(), "box": box.tolist()}


def fingerprint_change(ob, fp) -> str | None:
    """None when ``ob`` still matches fingerprint ``fp``, else what changed (for the message)."""
    now = mesh_fingerprint(ob)
    if now["topology"] != fp.get("topology"):
        return "its polygons or their vertex order changed"
    box = np.asarray(fp["box"])
    size = float(np.max(box[3:] - box[:3])) if len(box) == 6 else 1.0
    tol = FINGERPRINT_TOLERANCE * max(size, 1e-6) * (1.0 + np.sqrt(now["vertices"]))
    d = max(np.max(np.abs(np.asarray(now["signature"]) - np.asarray(fp["signature"])), initial=0.0),
            np.max(np.abs(np.asarray(now["box"]) - box), initial=0.0))
    if d > tol:
        return "it moved or its vertices moved (in its mesh, by a shape key or a modifier)"
    return None


def evaluated_mesh(ob, context):
    """(evaluated object, mesh, face_index per evaluated polygon or None when identity)."""
    base = ob.data
    has_modifiers = any(m.show_viewport for m in ob.modifiers)
    tagged = False
    if has_modifiers and base.library is None and _FACE_INDEX_ATTRIBUTE not in base.attributes:
        a = base.attributes.new(_FACE_INDEX_ATTRIBUTE, "INT", "FACE")
        a.data.foreach_set("value", np.arange(len(base.polygons), dtype=np.int32))
        base.update()
        tagged = True
    try:
        depsgraph = context.evaluated_depsgraph_get()
        ob_eval = ob.evaluated_get(depsgraph)
        me = ob_eval.to_mesh()
        n = len(me.polygons)
        if not has_modifiers:
            mapping = None
        else:
            a = me.attributes.get(_FACE_INDEX_ATTRIBUTE) if tagged else None
            if a is not None and a.domain == "FACE":
                mapping = foreach_array(a.data, "value", n, np.int64)
                mapping[(mapping < 0) | (mapping >= len(base.polygons))] = -1
            elif n == len(base.polygons):
                mapping = None  # same polygon count, assume same order
            else:
                mapping = np.full(n, -1, dtype=np.int64)
    finally:
        if tagged:
            base.attributes.remove(base.attributes[_FACE_INDEX_ATTRIBUTE])
            base.update()
    return ob_eval, me, mapping


def mesh_geometry(ob_eval, me, name):
    """Local-space arrays of an evaluated mesh: vertices, loop triangles, their polygons,
    polygon loops (vertex indices) and material indices."""
    V = foreach_array(me.vertices, "co", len(me.vertices), np.float64, 3)
    if not np.all(np.isfinite(V)):
        raise SceneError(f"object {name!r} has NaN or infinite vertex coordinates")
    check_near(V, name, "its origin")
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    lt = foreach_array(me.loop_triangles, "vertices", nt, np.int64, 3).reshape(nt, 3)
    lt_poly = foreach_array(me.loop_triangles, "polygon_index", nt, np.int64)
    npoly = len(me.polygons)
    loop_vert = foreach_array(me.loops, "vertex_index", len(me.loops), np.int64)
    loop_poly, starts, totals = loop_polygons(me)
    mat_index = foreach_array(me.polygons, "material_index", npoly, np.int64)
    slots = [getattr(s.material, "original", s.material) for s in ob_eval.material_slots]
    loop_edge = foreach_array(me.loops, "edge_index", len(me.loops), np.int64)
    return {"V": V, "lt": lt, "lt_poly": lt_poly, "loop_vert": loop_vert, "loop_poly": loop_poly,
            "loop_start": starts, "loop_total": totals, "mat_index": mat_index, "slots": slots,
            "loop_edge": loop_edge, "n_edges": len(me.edges)}


def no_area(geo, M) -> bool:
    """True when the object's triangles have no area in world space (but some in its own)."""
    A = np.asarray(M, dtype=np.float64)[:3, :3]
    # a triangle's world area is at least s_min s_mid (the matrix's two smallest singular values)
    # times its own: far above the 1e-12 below, every triangle need not be measured (on the 1M
    # room, 2.4 s of the export)
    if not np.isfinite(A).all():  # (named by the chunks' own check: face_chunks' "NaN or infinite transform")
        return False
    s = np.linalg.svd(A, compute_uv=False)
    if s[1] * s[2] > 1e-9:
        return False
    V = geo["V"]
    T = V[geo["lt"]]
    local = np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum()
    W = T @ np.asarray(M, dtype=np.float64)[:3, :3].T
    world = np.linalg.norm(np.cross(W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]), axis=1).sum()
    return bool(local > 0 and not world > 1e-12 * local)


class Builder(FaceChunks):
    """The chunks of the exported meshes (engine.face_chunks.FaceChunks) with their materials:
    each material read once (``material_closure``), its BSDFs kept (``lobes``)."""

    def __init__(self):
        super().__init__()
        self.mat_cache = {}
        self.mat_ids = {}  # material name (None: no material) -> index into self.lobes
        self.materials_used = {}  # material name -> the material (the exported ones)
        self.material_notes = {}  # material name -> what its model leaves out (material_warnings)
        self.lobes = []

    def materials(self, slots, mat_index):
        """(reflectance, exitance, linked emission, material index) per face of one mesh, from its slots."""
        props, ids = [], []
        for mi in range(max(len(slots), 1)):
            mat = slots[mi] if mi < len(slots) else None
            key = mat.name if mat is not None else None
            if key not in self.mat_cache:
                self.mat_cache[key] = material_closure(mat)
                self.mat_ids[key] = len(self.lobes)
                self.lobes.append(self.mat_cache[key][3])
                if mat is not None:
                    self.materials_used[key] = mat
                if self.mat_cache[key][2]:
                    self.material_notes[scene_material(mat).name] = self.mat_cache[key][2]
            props.append(self.mat_cache[key])
            ids.append(self.mat_ids[key])
        mi = np.clip(mat_index, 0, len(props) - 1)
        material = np.asarray(ids, dtype=np.int64)[mi]
        linked = np.array([bool(p[4]) for p in props])[mi]
        return (np.array([p[0] for p in props])[mi], exitance_from_radiance(np.array([p[1] for p in props]))[mi],
                linked, material)

    def add(self, geo, matrix, name, oi, face_index, target, target_b, forbidden, lux=None):
        """Add the evaluated mesh ``geo`` (``mesh_geometry``) of object ``name`` (index ``oi``) at
        world matrix ``matrix``, with its faces' base-mesh polygons and paint."""
        self.add_geometry(geo, matrix, name)
        rho, e, linked, material = self.materials(geo["slots"], geo["mat_index"])
        self.add_faces(oi, face_index, target, target_b, forbidden, lux, rho, e, linked, material)
