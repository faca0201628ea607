"""Blender -> engine: export the scene as an engine FaceSet (bpy). The way back is results.py.

What is exported
- Every object of type MESH that is visible in the view layer (``visible_get()``) and not
  hidden from render (its ``hide_render``, or ``hide_render`` on every collection chain it
  is linked through), evaluated with its modifiers (depsgraph ``evaluated_get`` /
  ``to_mesh``), in world space (``matrix_world``, parent chain included). A negative-determinant transform
  (negative scale) reverses the winding so normals keep pointing the same way as in
  Blender's viewport.
- One engine face per polygon of the evaluated mesh, triangulated with
  ``mesh.loop_triangles`` (concave n-gons are fine). ``face_index`` is the polygon index in
  the object's BASE mesh: without modifiers it is the polygon itself; with modifiers a
  temporary INT face attribute (``_relight_face_index``) is written on the base mesh,
  carried through the modifier stack and removed right after (the user's mesh ends as it
  was). Faces that a modifier creates without that attribute (or of linked, read-only
  meshes) get ``face_index`` -1 and a warning; they take part in the light transport but
  are not reported.
- Mesh instances of the evaluated depsgraph (``depsgraph.object_instances`` with
  ``is_instance``: collection instances, particle and geometry-nodes instances) whose
  instancer and source object are not hidden from render: geometry only. They occlude,
  reflect (their material) and emit, but their faces are never targets or candidate lights
  (``forbidden``) and have ``face_index`` -1 (not reported: one base mesh cannot hold
  per-instance values). They are grouped in ``object_names`` entries named
  ``"<instancer>/<object>"`` after the real objects; everything is keyed by object index
  (``job_inputs``: polygon counts per index, None for these groups), and the reports list the
  real objects only, so a real object may have any name (even ``"<instancer>/<object>"``).
- Visible objects with geometry that are not meshes (curves, text, surfaces, metaballs) are
  not exported as objects: what they evaluate to comes in as instances (geometry only, above),
  with a warning naming them (convert them to meshes to paint or light them).

Materials (per face, through ``material_index`` and the object's material slots): materials.py
- reflectance = the material's white-furnace albedo as Cycles renders it (a Principled BSDF's
  specular layer included: engine/principled.py), emitted radiance L_e (linear RGB);
  Principled BSDF, Diffuse BSDF, Emission, Mix Shader and Add Shader are read, the
  approximations (metallic, transmission, coat, sheen, subsurface, alpha) and anything not
  read (other shaders and node groups, linked colours: the viewport colour
  ``Material.diffuse_color``) are named in a warning.
- No material: reflectance 0.8 grey.
- Exitance e = pi * L_e (W/m^2). Reflectance is clamped to [0, MAX_REFLECTANCE] and
  negative emission to 0, with a warning.

Relight attributes (read from the base mesh)
- ``relight_target``: a Face Corner colour attribute, FLOAT_COLOR or BYTE_COLOR (read as linear
  RGB); a polygon is a target when the mean alpha of its corners is >= 0.5, its target
  radiosity = pi x mean RGB x target scale (scene custom property ``relight_target_scale``,
  default 1; the add-on's Target Scale reads and writes that same property). A
  ``relight_target`` of another domain or type is not used, with a warning naming it; NaN or
  infinite colours are refused; negative ones are set to 0 with a warning.
- ``relight_forbidden``: a Face attribute of any numeric type (BOOLEAN, INT, INT8, FLOAT):
  non-zero (NaN included) = forbidden. Of another domain or type it is refused (an error naming
  it: lights must never land on faces meant to be forbidden).
- ``relight_no_lights``: object custom property (or the add-on's property), a boolean or a
  number, non-zero forbids every face of the object; any other type (a string) is refused.
- Scene custom properties ``relight_target_scale`` (>= 0) and ``relight_max_patch_size``
  (metres, > 0: the scene's default patch size when the job does not set one) must be finite
  numbers; anything else is refused with a message naming the property.

"""
from __future__ import annotations

import math
import os
import warnings as _warnings
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..engine.scene import FaceSet, SceneError
from ..engine.units import MAX_REFLECTANCE, exitance_from_radiance
from ..engine.world import sees_sky
from .lamps import export_lamps
from .world import world_light

DEFAULT_REFLECTANCE = 0.8
RADIOSITY_ATTRIBUTE = "relight_radiosity"
TARGET_ATTRIBUTE = "relight_target"
FORBIDDEN_ATTRIBUTE = "relight_forbidden"
NO_LIGHTS_PROP = "relight_no_lights"
TARGET_SCALE_PROP = "relight_target_scale"
MAX_PATCH_SIZE_PROP = "relight_max_patch_size"
_FACE_INDEX_ATTRIBUTE = "_relight_face_index"
RELIGHT_OWNER_PROP = "relight_owner"  # on everything Relight creates (results.py)
#: the attribute types Relight reads and writes its layers as
TARGET_TYPES = ("FLOAT_COLOR", "BYTE_COLOR")
TARGET_DOMAIN = "CORNER"
FORBIDDEN_TYPES = ("BOOLEAN", "INT", "INT8", "FLOAT")
FORBIDDEN_DOMAIN = "FACE"
#: Blender's UI names of attribute domains and types (for messages)
DOMAIN_NAMES = {"POINT": "Vertex", "EDGE": "Edge", "FACE": "Face", "CORNER": "Face Corner",
                "CURVE": "Spline", "INSTANCE": "Instance", "LAYER": "Layer"}
TYPE_NAMES = {"FLOAT_COLOR": "Color", "BYTE_COLOR": "Byte Color", "BOOLEAN": "Boolean", "INT": "Integer",
              "INT8": "8-Bit Integer", "FLOAT": "Float", "FLOAT_VECTOR": "Vector", "FLOAT2": "2D Vector",
              "INT32_2D": "2D Integer Vector", "QUATERNION": "Quaternion", "FLOAT4X4": "4x4 Matrix",
              "STRING": "String"}
#: object types with geometry that are not exported (only meshes are)
NON_MESH_GEOMETRY = ("CURVE", "FONT", "SURFACE", "META", "CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL")


class BlendFileError(SceneError):
    """The .blend file is missing or cannot be read."""


# ------------------------------------------------------------------ files
def open_blend(path: str):
    """Open ``path`` as the current Blender file (never writes it)."""
    if not os.path.isfile(path):
        raise BlendFileError(f"no such .blend file: {path}")
    try:
        with open(path, "rb") as fh:
            head = fh.read(7)
    except OSError as exc:
        raise BlendFileError(f"cannot read {path}: {exc.strerror}") from None
    # plain files start with BLENDER; compressed ones with the gzip or zstd magic
    if not (head.startswith(b"BLENDER") or head.startswith(b"\x1f\x8b") or head.startswith(b"\x28\xb5\x2f\xfd")):
        raise BlendFileError(f"{path} is not a .blend file")
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path), load_ui=False)
    except RuntimeError as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else "unknown error"
        raise BlendFileError(f"cannot open {path}: {msg}") from None


# ------------------------------------------------------------------ materials
def material_properties(mat):
    """(reflectance (3,), radiance (3,), note or None) of a material: its white-furnace albedo
    and emitted radiance as Cycles renders it (materials.py; see the module docstring)."""
    return material_closure(mat)[:3]


def material_closure(mat):
    """``material_properties`` and the material's BSDFs (materials.Closure.lobes, for
    view-dependent radiance): (reflectance, radiance, note, lobes)."""
    from .materials import surface_closure

    if mat is not None and mat.get("relight_generated"):
        # a Relight emissive variant shown by an earlier solve: the scene's own material is
        # its source (the variant's emission is Relight's result, not the scene's light)
        mat = bpy.data.materials.get(mat.get("relight_source", "")) or None
    if mat is None:
        grey = np.full(3, DEFAULT_REFLECTANCE)
        return grey, np.zeros(3), None, [(1.0, "diffuse", (grey, 0.0))]
    c = surface_closure(mat)
    note = f"material {mat.name!r}: " + "; ".join(c.notes) if c.notes else None
    return c.reflectance, c.radiance, note, c.lobes


# ------------------------------------------------------------------ export
@dataclass
class ExportedScene:
    faces: FaceSet
    objects: list  # the exported bpy objects: FaceSet.object_names[:len(objects)]; the names after
    # them are instance groups "<instancer>/<object>" (no bpy object, 0 polygons)
    polygon_counts: dict  # object name -> number of polygons of its base mesh (the real objects)
    settings: dict = field(default_factory=dict)  # target_scale, max_patch_size (None = engine default)
    seconds: float = 0.0
    fingerprints: dict = field(default_factory=dict)  # object name -> mesh_fingerprint (stale-result check)
    face_material: np.ndarray = None  # (F,) index into ``material_lobes`` of every FaceSet face
    material_lobes: list = field(default_factory=list)  # per material: its BSDFs (materials.Closure.lobes)
    #: what an error about the scene should also say (jobs.check_solvable): "target": target layers
    #: found but not used, the target scale 0; "candidates": objects not exported, without area
    notes: dict = field(default_factory=dict)


#: positions are compared within this fraction of the object's size (times sqrt(vertices))
FINGERPRINT_TOLERANCE = 1e-6


def _vertex_weights(n):
    """Two fixed pseudo-random weights in [-0.5, 0.5) per vertex index (a Weyl sequence)."""
    i = np.arange(n, dtype=np.float64)
    return np.stack([(i * 0.6180339887498949) % 1.0, (i * 0.7548776662466927 + 0.5) % 1.0], axis=1) - 0.5


def mesh_fingerprint(ob) -> dict:
    """What a stored result must still match: the base mesh's topology (exact: a hash of its
    polygons' vertex loops) and its world-space vertex positions (two weighted sums per axis and
    the bounding box, compared within a tolerance)."""
    import hashlib

    me = ob.data
    nv, nl, npoly = len(me.vertices), len(me.loops), len(me.polygons)
    lv = foreach_array(me.loops, "vertex_index", nl, np.int64)
    lt = foreach_array(me.polygons, "loop_total", npoly, np.int64)
    topo = hashlib.blake2b(np.concatenate([[nv, nl, npoly], lt, lv]).astype(np.int64).tobytes(), digest_size=16)
    co = foreach_array(me.vertices, "co", nv, np.float64, 3).reshape(nv, 3)
    M = np.array(ob.matrix_world, dtype=np.float64)
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
        return "it moved or its vertices moved"
    return None


def render_visible_objects(scene):
    """Names of the objects that a render would see through the collection tree: every object
    linked to at least one collection whose chain from the scene collection has no
    ``hide_render`` (the object's own ``hide_render`` is checked separately)."""
    seen = set()

    def walk(coll, hidden):
        hidden = hidden or bool(getattr(coll, "hide_render", False))
        if not hidden:
            seen.update(ob.name for ob in coll.objects)
        for child in coll.children:
            walk(child, hidden)

    walk(scene.collection, False)
    return seen


def exported_objects(context=None):
    """The scene's mesh objects that are exported: visible in the view layer, not hidden from
    render (``hide_render`` of the object or of every collection it is in), and not made by
    Relight (its emitters object shows a result: a new solve does not count it as scene light)."""
    context = context or bpy.context
    view_layer = context.view_layer
    renderable = render_visible_objects(context.scene)
    return [ob for ob in context.scene.objects
            if ob.type == "MESH" and not ob.hide_render and ob.name in renderable
            and ob.visible_get(view_layer=view_layer) and ob.get(RELIGHT_OWNER_PROP) is None]


def _number_property(holder, prop, what):
    """The custom property ``prop`` of ``holder`` as a finite float (None when missing); anything
    else (a string, a list, NaN) is a SceneError naming the property."""
    value = holder.get(prop)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        shown = repr(value) if isinstance(value, str) else type(value).__name__
        raise SceneError(f"{what} custom property {prop} is {shown}, not a number: set it to a number "
                         "(or delete it)")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{what} custom property {prop} is {value}: it must be a finite number")
    return value


def scene_settings(scene):
    """The scene's Relight settings from its custom properties (one source of truth: the add-on's
    Target Scale reads and writes ``relight_target_scale`` itself). Refuses values of the wrong
    type or range with a message naming the property."""
    what = f"scene {scene.name!r}:"
    scale = _number_property(scene, TARGET_SCALE_PROP, what)
    if scale is not None and scale < 0:
        raise SceneError(f"{what} custom property {TARGET_SCALE_PROP} is {scale:g}: it must be >= 0")
    size = _number_property(scene, MAX_PATCH_SIZE_PROP, what)
    if size is not None and not size > 0:
        raise SceneError(f"{what} custom property {MAX_PATCH_SIZE_PROP} is {size:g}: it must be a positive "
                         "length in metres")
    return {"target_scale": 1.0 if scale is None else scale, "max_patch_size": size}


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


def describe_attribute(attr) -> str:
    """"a Vertex (POINT) Color (FLOAT_COLOR) attribute": what a message says about an attribute."""
    d, t = attr.domain, attr.data_type
    return f"a {DOMAIN_NAMES.get(d, d)} ({d}) {TYPE_NAMES.get(t, t)} ({t}) attribute"


def target_layer(mesh, owner=None):
    """The mesh's usable ``relight_target`` (a Face Corner FLOAT_COLOR or BYTE_COLOR attribute),
    None when there is none; a ``relight_target`` of another domain or type raises SceneError
    naming it (``owner``: the object name for the message)."""
    return _checked_layer(mesh, TARGET_ATTRIBUTE, TARGET_DOMAIN, TARGET_TYPES, owner,
                          "reads targets from a Face Corner colour attribute (Color or Byte Color), so this one is "
                          "not used: convert it (Object Data > Color Attributes > Convert, Face Corner) or remove it")


def forbidden_layer(mesh, owner=None):
    """The mesh's ``relight_forbidden`` (a Face attribute of a numeric type: BOOLEAN, INT, INT8,
    FLOAT), None when there is none; one of another domain or type raises SceneError naming it."""
    return _checked_layer(mesh, FORBIDDEN_ATTRIBUTE, FORBIDDEN_DOMAIN, FORBIDDEN_TYPES, owner,
                          "reads a Face attribute of a numeric type (Boolean, Integer or Float; non-zero = forbidden): "
                          "convert it (Object Data > Attributes > Convert, Face) or remove it")


def _checked_layer(mesh, name, domain, types, owner, reads):
    """The mesh's attribute ``name``, None when absent; of another domain or type: SceneError
    naming it, the object (``owner``) and what Relight ``reads``."""
    attr = mesh.attributes.get(name)
    if attr is None:
        return None
    if attr.domain != domain or attr.data_type not in types:
        raise SceneError(f"{owner or mesh.name}: its {name} is {describe_attribute(attr)}; Relight {reads}")
    return attr


def read_forbidden(attr, n) -> np.ndarray:
    """(n,) bool: non-zero values (NaN included) of a numeric face attribute."""
    if attr.data_type == "BOOLEAN":
        return foreach_array(attr.data, "value", n, bool)
    if attr.data_type == "FLOAT":
        v = foreach_array(attr.data, "value", n, np.float64)
        return (v != 0) | np.isnan(v)
    return foreach_array(attr.data, "value", n, np.int64) != 0


def _base_attributes(ob, target_scale, notes=None):
    """Per base-mesh polygon: target (bool), target radiosity (W/m^2), forbidden (bool).
    ``notes``: a list that gets the messages about layers found but not used."""
    me = ob.data
    n = len(me.polygons)
    target = np.zeros(n, dtype=bool)
    target_b = np.zeros((n, 3))
    forbidden = np.zeros(n, dtype=bool)
    loop_poly, _, totals = loop_polygons(me)
    try:
        attr = target_layer(me, ob.name)
    except SceneError as exc:  # found, not used: said (and repeated in a "no target" error)
        attr = None
        if notes is not None:
            notes.append(str(exc))
    if attr is not None and len(me.loops):
        col = foreach_array(attr.data, "color", len(me.loops), np.float64, 4)
        mean = np.stack([np.bincount(loop_poly, weights=col[:, k], minlength=n) for k in range(4)], axis=1)
        mean /= np.maximum(totals, 1)[:, None]
        if not np.all(np.isfinite(mean)):
            raise SceneError(f"{ob.name}: its {TARGET_ATTRIBUTE} holds NaN or infinite colours; paint it again")
        target = mean[:, 3] >= 0.5
        rgb = mean[target, :3]
        if np.any(rgb < 0):
            if notes is not None:
                notes.append(f"{ob.name}: {int(np.sum(np.any(rgb < 0, axis=1)))} target(s) with a negative colour "
                             "set to 0 (light cannot be negative)")
            rgb = np.maximum(rgb, 0.0)
        target_b[target] = exitance_from_radiance(rgb * target_scale)
    attr = forbidden_layer(me, ob.name)  # another domain or type: refused (never ignored)
    if attr is not None:
        forbidden = read_forbidden(attr, n)
    if no_lights(ob):
        forbidden[:] = True
    return target, target_b, forbidden


def no_lights(ob) -> bool:
    """The object's "no lights on this object" switch: the add-on's property, or a custom
    property of the same name (files prepared without the add-on): a boolean or a number,
    non-zero = no lights. Any other type (a string such as "false") is a SceneError."""
    raw = ob.get(NO_LIGHTS_PROP)
    if raw is not None and not isinstance(raw, (bool, int, float)):
        shown = repr(raw) if isinstance(raw, str) else type(raw).__name__
        raise SceneError(f"object {ob.name!r}: custom property {NO_LIGHTS_PROP} is {shown}, not a boolean or a "
                         "number: set it to True/False (or 1/0)")
    if isinstance(raw, float) and math.isnan(raw):
        return True
    return bool(getattr(ob, NO_LIGHTS_PROP, False) or raw)


def _evaluated_mesh(ob, context):
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


def _mesh_geometry(ob_eval, me, name):
    """Local-space arrays of an evaluated mesh: vertices, loop triangles, their polygons,
    polygon loops (vertex indices) and material indices."""
    V = foreach_array(me.vertices, "co", len(me.vertices), np.float64, 3)
    if not np.all(np.isfinite(V)):
        raise SceneError(f"object {name!r} has NaN or infinite vertex coordinates")
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    lt = foreach_array(me.loop_triangles, "vertices", nt, np.int64, 3).reshape(nt, 3)
    lt_poly = foreach_array(me.loop_triangles, "polygon_index", nt, np.int64)
    npoly = len(me.polygons)
    loop_vert = foreach_array(me.loops, "vertex_index", len(me.loops), np.int64)
    loop_poly, starts, totals = loop_polygons(me)
    mat_index = foreach_array(me.polygons, "material_index", npoly, np.int64)
    slots = [getattr(s.material, "original", s.material) for s in ob_eval.material_slots]
    return {"V": V, "lt": lt, "lt_poly": lt_poly, "loop_vert": loop_vert, "loop_poly": loop_poly,
            "loop_start": starts, "loop_total": totals, "mat_index": mat_index, "slots": slots}


class _Builder:
    """Accumulates world-space faces of several meshes into FaceSet arrays."""

    def __init__(self):
        self.verts, self.tris, self.tri_face = [], [], []
        self.loop_vert, self.loop_start, self.loop_total = [], [], []
        self.f_obj, self.f_idx, self.rho, self.e, self.tgt, self.tgt_b, self.forb = [], [], [], [], [], [], []
        self.warnings = []
        self.mat_cache = {}
        self.mat_ids = {}  # material name (None: no material) -> index into self.lobes
        self.lobes = []
        self.f_mat = []
        self.nf = self.nv = self.nl = 0

    def materials(self, slots, mat_index):
        props, ids = [], []
        for mi in range(max(len(slots), 1)):
            mat = slots[mi] if mi < len(slots) else None
            key = mat.name if mat is not None else None
            if key not in self.mat_cache:
                self.mat_cache[key] = material_closure(mat)
                self.mat_ids[key] = len(self.lobes)
                self.lobes.append(self.mat_cache[key][3])
                if self.mat_cache[key][2]:
                    self.warnings.append(self.mat_cache[key][2])
            props.append(self.mat_cache[key])
            ids.append(self.mat_ids[key])
        mi = np.clip(mat_index, 0, len(props) - 1)
        self.f_mat.append(np.asarray(ids, dtype=np.int64)[mi])
        return np.array([p[0] for p in props])[mi], exitance_from_radiance(np.array([p[1] for p in props]))[mi]

    def add(self, geo, matrix, name, oi, face_index, target, target_b, forbidden):
        M = np.asarray(matrix, dtype=np.float64)
        W = geo["V"] @ M[:3, :3].T + M[:3, 3]
        if not np.all(np.isfinite(W)):
            raise SceneError(f"object {name!r} has NaN or infinite vertex coordinates")
        flip = np.linalg.det(M[:3, :3]) < 0
        lt = geo["lt"][:, ::-1] if flip else geo["lt"]
        nv, nf = self.nv, self.nf
        self.verts.append(W)
        self.tris.append(lt + nv)
        self.tri_face.append(geo["lt_poly"] + nf)
        lv, lpoly, ls, lt_ = geo["loop_vert"], geo["loop_poly"], geo["loop_start"], geo["loop_total"]
        if flip:  # each polygon's loop reversed
            pos = np.arange(len(lv))
            lv = lv[ls[lpoly] + lt_[lpoly] - 1 - (pos - ls[lpoly])]
        self.loop_vert.append(lv + nv)
        self.loop_start.append(ls + self.nl)
        self.loop_total.append(lt_)
        self.nl += len(lv)
        rho, e = self.materials(geo["slots"], geo["mat_index"])
        npoly = len(ls)
        self.rho.append(rho)
        self.e.append(e)
        self.f_obj.append(np.full(npoly, oi))
        self.f_idx.append(face_index)
        self.tgt.append(target)
        self.tgt_b.append(target_b)
        self.forb.append(forbidden)
        self.nf += npoly
        self.nv += len(W)


def _instances(context, renderable):
    """(name, evaluated object, world matrix) of every mesh instance of the depsgraph
    (collection instances, particle and geometry-nodes instances) whose instancer and
    source object are rendered. Only valid while the depsgraph is not re-evaluated."""
    depsgraph = context.evaluated_depsgraph_get()
    for inst in depsgraph.object_instances:
        if not inst.is_instance:
            continue
        ob, parent = inst.object, inst.parent
        if ob is None or ob.type != "MESH":
            continue
        src = ob.original
        host = parent.original if parent is not None else None
        if host is not None and (host.hide_render or host.name not in renderable):
            continue
        if src is not None and src != host and src.hide_render:
            continue
        name = f"{host.name if host is not None else '?'}/{src.name if src is not None else ob.name}"
        yield name, ob, np.array(inst.matrix_world, dtype=np.float64)


def export_scene(context=None, target_scale=None) -> ExportedScene:
    """Export the visible mesh objects of the current scene (see the module docstring).

    ``context``: a bpy context (default ``bpy.context``); a Depsgraph is accepted too (its
    scene and view layer are used). ``target_scale`` overrides the scene's target scale.
    """
    import time

    t0 = time.perf_counter()
    if context is None or isinstance(context, bpy.types.Depsgraph):
        context = bpy.context
    settings = scene_settings(context.scene)
    if target_scale is not None:
        settings["target_scale"] = float(target_scale)
    renderable = render_visible_objects(context.scene)
    objs = exported_objects(context)
    notes = {"target": [], "candidates": []}
    warnings = []
    skipped = [f"{ob.name!r} ({ob.type})" for ob in context.scene.objects
               if ob.type in NON_MESH_GEOMETRY and not ob.hide_render and ob.name in renderable
               and ob.visible_get(view_layer=context.view_layer)]
    if skipped:
        text = (f"{len(skipped)} visible object(s) are not meshes: {', '.join(skipped[:10])}"
                f"{' ...' if len(skipped) > 10 else ''}; whatever geometry they evaluate to takes part as occluders "
                "and reflectors only (never targets or lights): convert them to meshes (Object > Convert > Mesh) "
                "to paint targets or place lights on them")
        warnings.append(text)
        notes["candidates"].append(text)
    b = _Builder()
    counts = {}
    names = []
    unmapped = 0
    for oi, ob in enumerate(objs):
        counts[ob.name] = len(ob.data.polygons)
        names.append(ob.name)
        target, target_b, forbidden = _base_attributes(ob, settings["target_scale"], notes["target"])
        ob_eval, me, mapping = _evaluated_mesh(ob, context)
        try:
            geo = _mesh_geometry(ob_eval, me, ob.name)
            M = np.array(ob_eval.matrix_world, dtype=np.float64)
        finally:
            ob_eval.to_mesh_clear()
        if len(geo["lt"]) and _no_area(geo, M):
            text = (f"object {ob.name!r} has no area in world space (scaled to zero?): its faces can be neither "
                    "targets nor lights")
            warnings.append(text)
            notes["candidates"].append(text)
        npoly = len(geo["loop_start"])
        idx = np.arange(npoly) if mapping is None else mapping
        unmapped += int(np.sum(idx < 0))
        ok = idx >= 0
        safe = np.where(ok, idx, 0)
        b.add(geo, M, ob.name, oi, idx, target[safe] & ok, np.where(ok[:, None], target_b[safe], 0.0),
              np.where(ok, forbidden[safe], no_lights(ob)))
    # instances: geometry only (occluders, reflectors and emitters), never targets or lights
    geo_cache, group = {}, {}
    n_inst = 0
    for name, ob, M in _instances(context, renderable):
        key = ob.data.as_pointer()
        if key not in geo_cache:
            me = ob.to_mesh()
            try:
                geo_cache[key] = _mesh_geometry(ob, me, name)
            finally:
                ob.to_mesh_clear()
        geo = geo_cache[key]
        if name not in group:  # keyed by index everywhere: a real object may have this name too
            group[name] = len(names)
            names.append(name)
        npoly = len(geo["loop_start"])
        b.add(geo, M, name, group[name], np.full(npoly, -1), np.zeros(npoly, dtype=bool),
              np.zeros((npoly, 3)), np.ones(npoly, dtype=bool))
        n_inst += 1
    if not names:
        raise SceneError("the scene has no visible mesh objects"
                         + (f" ({notes['candidates'][0]})" if notes["candidates"] else ""))
    warnings = warnings + b.warnings + [n for n in notes["target"] if n not in warnings]
    if settings["target_scale"] == 0:
        notes["target"].append("the target scale is 0 (scene custom property relight_target_scale, the add-on's "
                               "Target Scale, or --target-scale): every target asks for no light")
    if unmapped:
        warnings.append(f"{unmapped} face(s) created by modifiers could not be mapped to base-mesh polygons "
                        "and are not reported")
    if n_inst:
        warnings.append(f"{n_inst} instanced object(s) (collection or other instances) take part as occluders "
                        "and reflectors only: their faces cannot be targets or lights and are not reported")
    rho = np.concatenate(b.rho)
    e = np.concatenate(b.e)
    if np.any(rho > MAX_REFLECTANCE) or np.any(rho < 0):
        nbad = int(np.sum(np.any((rho > MAX_REFLECTANCE) | (rho < 0), axis=1)))
        warnings.append(f"reflectance of {nbad} face(s) clamped to [0, {MAX_REFLECTANCE}] "
                        "(a reflectance >= 1 would create energy)")
        rho = np.clip(rho, 0.0, MAX_REFLECTANCE)
    if not np.all(np.isfinite(e)) or not np.all(np.isfinite(rho)):
        raise SceneError("a material has a NaN or infinite colour or emission strength")
    if np.any(e < 0):
        warnings.append(f"negative emission of {int(np.sum(np.any(e < 0, axis=1)))} face(s) set to 0")
        e = np.maximum(e, 0.0)
    lamps, lamp_warnings = export_lamps(context, renderable, RELIGHT_OWNER_PROP)
    warnings.extend(w for w in lamp_warnings if w not in warnings)
    faces = FaceSet(
        vertices=np.concatenate(b.verts),
        triangles=np.concatenate(b.tris),
        triangle_face=np.concatenate(b.tri_face),
        loop_vertices=np.concatenate(b.loop_vert),
        loop_start=np.concatenate(b.loop_start),
        loop_total=np.concatenate(b.loop_total),
        face_object=np.concatenate(b.f_obj),
        face_index=np.concatenate(b.f_idx),
        object_names=names,
        reflectance=rho,
        exitance=e,
        target=np.concatenate(b.tgt),
        target_radiosity=np.concatenate(b.tgt_b),
        forbidden=np.concatenate(b.forb),
        warnings=warnings,
        face_material=np.concatenate(b.f_mat),
        material_lobes=b.lobes,
        lamps=lamps,
    )
    try:
        faces.world_radiance, faces.world_name, world_notes = world_light(context.scene, lambda: sees_sky(faces))
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    faces.warnings.extend(w for w in world_notes if w not in faces.warnings)
    fingerprints = {ob.name: mesh_fingerprint(ob) for ob in objs}
    return ExportedScene(faces, objs, counts, settings, time.perf_counter() - t0, fingerprints,
                         np.concatenate(b.f_mat), b.lobes, notes=notes)


def _no_area(geo, M) -> bool:
    """True when the object's triangles have no area in world space (but some in its own)."""
    V = geo["V"]
    T = V[geo["lt"]]
    local = np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum()
    W = T @ np.asarray(M, dtype=np.float64)[:3, :3].T
    world = np.linalg.norm(np.cross(W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]), axis=1).sum()
    return bool(local > 0 and not world > 1e-12 * local)


def job_inputs(exp: ExportedScene) -> dict:
    """Keyword arguments of jobs.run_radiosity / jobs.run_solve that come from the scene: the
    polygon counts per object index (None for the instance groups: not reported), the scene's
    patch size and the notes an error about the scene should repeat."""
    n_real = len(exp.objects)
    counts = [exp.polygon_counts[ob.name] for ob in exp.objects] + [None] * (len(exp.faces.object_names) - n_real)
    return {"polygon_counts": counts, "default_max_patch_size": exp.settings.get("max_patch_size"),
            "notes": exp.notes}


def export_faceset(context=None, target_scale=None) -> FaceSet:
    """The FaceSet of :func:`export_scene`."""
    return export_scene(context, target_scale=target_scale).faces


def face_flags(ob, kind):
    """Per base-mesh polygon of ``ob``: kind "target", "forbidden" or "candidate" (bool array)."""
    target, _, forbidden = _base_attributes(ob, 1.0, [])
    if kind == "target":
        return target
    if kind == "forbidden":
        return forbidden
    if kind == "candidate":
        return ~forbidden
    raise ValueError(f"unknown face flag {kind!r}; use target, forbidden or candidate")


def check_writable_mesh(ob):
    """SceneError when Relight cannot write on ``ob``'s mesh (linked from a library: read-only)."""
    me = ob.data
    if getattr(me, "library", None) is not None:
        raise SceneError(f"{ob.name}: its mesh is linked from {me.library.filepath} (read-only); make it local "
                         "first (Object > Relations > Make Local > Object and Data)")


def ensure_attribute(mesh, name, data_type, domain):
    """The mesh's attribute ``name`` of that type and domain, created (zeroed: unpainted,
    allowed) when missing; one of the same name but another type is replaced."""
    attr = mesh.attributes.get(name)
    if attr is not None and (attr.domain != domain or attr.data_type != data_type):
        mesh.attributes.remove(attr)
        attr = None
    if attr is None:
        if data_type in ("FLOAT_COLOR", "BYTE_COLOR"):
            attr = mesh.color_attributes.new(name, data_type, domain)
            attr.data.foreach_set("color", np.zeros(4 * len(attr.data), dtype=np.float32))
        else:
            attr = mesh.attributes.new(name, data_type, domain)
    return attr


def ensure_target_layer(mesh):
    """The mesh's ``relight_target``: the existing Face Corner colour attribute of either type
    (FLOAT_COLOR or BYTE_COLOR: never a duplicate, never replaced), else a new FLOAT_COLOR one
    (transparent black: unpainted). One of another domain or type: SceneError, nothing changed."""
    attr = target_layer(mesh)
    if attr is not None:
        return attr
    return ensure_attribute(mesh, TARGET_ATTRIBUTE, "FLOAT_COLOR", TARGET_DOMAIN)


def ensure_forbidden_layer(mesh):
    """The mesh's ``relight_forbidden``: the existing numeric Face attribute of any type
    (BOOLEAN, INT, INT8, FLOAT), else a new BOOLEAN one (all allowed). One of another domain or
    type: SceneError, nothing changed."""
    attr = forbidden_layer(mesh)
    if attr is not None:
        return attr
    return ensure_attribute(mesh, FORBIDDEN_ATTRIBUTE, "BOOLEAN", FORBIDDEN_DOMAIN)


def write_forbidden(attr, values):
    """Write (n,) bool ``values`` into a numeric face attribute of any of FORBIDDEN_TYPES (1/0)."""
    values = np.asarray(values, dtype=bool)
    if attr.data_type == "BOOLEAN":
        attr.data.foreach_set("value", values)
    elif attr.data_type == "FLOAT":
        attr.data.foreach_set("value", values.astype(np.float32))
    else:
        attr.data.foreach_set("value", values.astype(np.int32))
