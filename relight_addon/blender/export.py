"""Blender -> engine: export the scene as an engine FaceSet (bpy). The way back is results.py.

What is exported
- Every object of type MESH that a render of the view layer shows: not hidden from render (its
  ``hide_render``, or ``hide_render`` on every collection chain it is linked through) and in a
  collection the view layer does not exclude. Hidden in the viewport (H, the eye, the monitor
  icon) it is still modelled, as Cycles still renders it, and named in a warning
  (docs/reliability.md); one disabled in the viewports is enabled while it is evaluated. Evaluated with its modifiers (depsgraph ``evaluated_get`` /
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
- Linked emission (a texture, a procedural, an attribute... on an Emission Color / Strength, or
  a Mix Shader's linked factor over an emitting branch: materials.Closure.linked_emission): each
  face's mean emitted radiance over its area, from a Cycles EMIT bake of temporary copies
  (emission_bake.py; nothing of the user's data changes), then e = pi * L_e as above. Nothing
  is baked in a scene without linked emission. Instanced objects are not baked, and a bake that
  fails keeps the unlinked part: both named in a warning with the material and its linked input.

The back side of emitters (_emitting_backs): Cycles' mesh emission leaves both sides of a face,
the radiosity model's faces are one-sided. An emitting face on a closed island (every edge shared
by two faces) faces its inside with its back: left out, as its light stays inside in Cycles too.
For an emitting face of an open island (a plane), rays from its back (engine/backs.py) decide:
- it sees nothing: nothing to do;
- it sees the scene from afar (a median distance >= BACK_GAP x its island's size: a plane lamp
  hanging in a room): its back is exported as a face of its own (the polygon reversed, set
  BACK_OFFSET x the scene's diagonal behind it, emitting the back's exitance, reflecting the
  front's reflectance, never a target or a light in `solve`, not reported; in `reduce`, an
  emitter of the scene, it is a light of its own);
- it lies against a surface (a lamp quad just under a ceiling): not modelled (the light caught in
  the gap would be spread by the surface's patches), named in a warning with its power and the
  estimated range of the light that leaks out of the gap, what Cycles renders more
  (``ExportedScene.backs``).

What Cycles renders and Relight does not model is named in a warning (_not_modelled): materials
whose Volume output is linked, volume objects (the light is taken as passing through; a World
volume: world.py), objects with Shadow Catcher or Holdout on (lit and reported as ordinary
surfaces).

Relight attributes (read from the base mesh)
- ``relight_target``: a Face Corner colour attribute, FLOAT_COLOR or BYTE_COLOR (read as linear
  RGB); a polygon is a target when the mean alpha of its corners (clipped to [0, 1]) is >= 0.5,
  its target radiosity = pi x the alpha-weighted mean RGB of its corners (a corner left unpainted,
  alpha 0, at the edge of a stroke does not darken it) x target scale (scene custom property ``relight_target_scale``,
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
from dataclasses import dataclass, field, replace

import bpy
import numpy as np

from ..engine.rays import RAY_OFFSET
from ..engine.scene import FaceSet, SceneError
from ..engine.paint import neutral_as_brightness
from ..engine.units import (MAX_REFLECTANCE, MIN_REFLECTANCE_LUX, exitance_from_radiance, illuminance_lux,
                            irradiance_from_lux)
from ..engine.world import sees_sky
from .lamps import export_lamps, hidden_warning
from .world import world_light

DEFAULT_REFLECTANCE = 0.8
RADIOSITY_ATTRIBUTE = "relight_radiosity"
#: the Results panel's view of the configuration shown (ui/display.py); removed with the radiosity layer
DISPLAY_ATTRIBUTE = "relight_display"
TARGET_ATTRIBUTE = "relight_target"
#: illuminance targets: a Face float attribute, lx (0: none)
LUX_ATTRIBUTE = "relight_target_lux"
FORBIDDEN_ATTRIBUTE = "relight_forbidden"
NO_LIGHTS_PROP = "relight_no_lights"
#: an object that is a work plane: light passes through it and it reflects none into the scene
WORK_PLANE_PROP = "relight_work_plane"
TARGET_SCALE_PROP = "relight_target_scale"
MAX_PATCH_SIZE_PROP = "relight_max_patch_size"
_FACE_INDEX_ATTRIBUTE = "_relight_face_index"
RELIGHT_OWNER_PROP = "relight_owner"  # on everything Relight creates (results.py): its result id
#: and the name it was made with: a copy (Shift-D, another data-block of a new name) is the user's
RELIGHT_NAME_PROP = "relight_owner_name"
#: metres: a vertex farther from the origin is refused (an infinite coordinate, stored as 3.4e38)
MAX_COORDINATE = 1e12
#: W/m^2/sr: a material emitting more is refused (the Sun's surface is about 2e7)
MAX_RADIANCE = 1e12
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
#: object types with geometry that are not exported (only meshes are); VOLUME objects are named
#: apart (_not_modelled: a volume is not a surface)
NON_MESH_GEOMETRY = ("CURVE", "FONT", "SURFACE", "META", "CURVES", "POINTCLOUD", "GREASEPENCIL")


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


#: Blender's names of the data-blocks that read files (for messages)
_READERS = {"Image": "image", "VectorFont": "font", "Sound": "sound", "MovieClip": "movie clip", "Volume": "volume",
            "CacheFile": "cache file", "Text": "text", "Library": "library"}


def files_read() -> list:
    """[(what reads it, absolute path)] of every file the open .blend reads from disk: its libraries
    (direct and indirect) and every external file of its data-blocks (images, a World's HDRI among
    them, fonts, sounds, clips, volumes, caches; a linked data-block's paths resolved from its
    library). An output must never replace one."""
    out = []
    for lib in bpy.data.libraries:
        # (an indirect library's path too is relative to the open file: Blender remaps it when it reads it)
        out.append((f"the library {lib.name!r} it links from", os.path.normpath(bpy.path.abspath(lib.filepath))))
    for idb, paths in _file_paths():
        if isinstance(idb, bpy.types.Library):
            continue
        what = _READERS.get(type(idb).__name__, type(idb).__name__.lower())
        for p in paths:
            if p:
                out.append((f"the {what} {idb.name!r}", os.path.normpath(bpy.path.abspath(p, library=idb.library))))
    return out


def _file_paths():
    """[(data-block, its file paths)]: bpy.data.file_path_map (Blender 4.4+); before (4.2, and
    Debian's 4.3), the data-blocks that keep a ``filepath``."""
    fpm = getattr(bpy.data, "file_path_map", None)
    if fpm is not None:
        return list(fpm(include_libraries=False).items())
    return [(idb, {idb.filepath}) for kind in ("images", "fonts", "sounds", "movieclips", "volumes", "cache_files",
                                               "texts")
            for idb in getattr(bpy.data, kind, ()) if getattr(idb, "filepath", "") not in ("", "<builtin>")
            and getattr(idb, "source", "FILE") not in ("GENERATED", "VIEWER")]


# ------------------------------------------------------------------ materials
def material_properties(mat):
    """(reflectance (3,), radiance (3,), note or None) of a material: its white-furnace albedo
    and emitted radiance as Cycles renders it (materials.py; see the module docstring). A linked
    emission is not in ``radiance``: export_scene bakes it per face."""
    reflectance, radiance, notes = material_closure(mat)[:3]
    return reflectance, radiance, (f"material {scene_material(mat).name!r}: " + "; ".join(notes) if notes else None)


def scene_material(mat):
    """The scene's own material behind ``mat``: a Relight variant shown by an earlier solve has
    its source as the scene's material (the variant's emission is Relight's result, not the
    scene's light); None stays None."""
    if mat is not None and mat.get("relight_generated"):
        return bpy.data.materials.get(mat.get("relight_source", "")) or None
    return mat


def material_closure(mat):
    """``material_properties`` and the material's BSDFs (materials.Closure.lobes, for
    view-dependent radiance) and linked emission (materials.Closure.linked_emission, baked by
    export_scene): (reflectance, radiance, notes (list), lobes, linked_emission)."""
    from .materials import surface_closure

    mat = scene_material(mat)
    if mat is None:
        grey = np.full(3, DEFAULT_REFLECTANCE)
        return grey, np.zeros(3), [], [(1.0, "diffuse", (grey, 0.0))], []
    c = surface_closure(mat)
    for part, v in (("colour (its reflectance)", c.reflectance), ("emission (colour x strength)", c.radiance)):
        if not np.all(np.isfinite(v)):
            raise SceneError(f"material {mat.name!r} has a NaN or infinite {part}: give it finite values")
    if float(np.max(c.radiance, initial=0.0)) > MAX_RADIANCE:
        raise SceneError(f"material {mat.name!r} emits a radiance of {float(np.max(c.radiance)):.3g} W/m^2/sr: an "
                         "infinite Emission Strength? (Blender stores infinity as its largest number, 3.4e+38); "
                         "give it a finite strength")
    return c.reflectance, c.radiance, list(c.notes), c.lobes, c.linked_emission


#: a note shared by many materials names this many of them
NAMED_MATERIALS = 3


def material_warnings(noted: dict) -> list:
    """One warning per note (what a material's model leaves out), naming the materials that
    have it: ``noted`` maps material name -> its notes."""
    by_note = {}
    for name, notes in noted.items():
        for note in notes:
            by_note.setdefault(note, []).append(name)
    out = []
    for note, names in by_note.items():
        shown = ", ".join(repr(n) for n in names[:NAMED_MATERIALS])
        if len(names) == 1:
            out.append(f"material {shown}: {note}")
        else:
            more = f" and {len(names) - NAMED_MATERIALS} more" if len(names) > NAMED_MATERIALS else ""
            out.append(f"{len(names)} materials ({shown}{more}): {note}")
    return out


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
    #: found but not used, the target scale 0; "candidates": objects not exported, without area;
    #: "emitters": the lamps that render but emit nothing ("'Key' (0 W)": blender/lamps.export_lamps)
    notes: dict = field(default_factory=dict)
    #: the emitters whose back side lies against a surface (not modelled: export._emitting_backs),
    #: one dict each: object, power (W), leak (low, high) W, emitted (W), distance (m), near (objects)
    backs: list = field(default_factory=list)


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
    import hashlib

    def loops(me):
        nv, nl, npoly = len(me.vertices), len(me.loops), len(me.polygons)
        return [[nv, nl, npoly], foreach_array(me.polygons, "loop_total", npoly, np.int64),
                foreach_array(me.loops, "vertex_index", nl, np.int64)]

    ob_eval = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ob_eval.to_mesh()
    try:
        parts = loops(ob.data) + loops(me)
        nv = len(me.vertices)
        co = foreach_array(me.vertices, "co", nv, np.float64, 3).reshape(nv, 3)
    finally:
        ob_eval.to_mesh_clear()
    topo = hashlib.blake2b(np.concatenate(parts).astype(np.int64).tobytes(), digest_size=16)
    M = np.array(ob_eval.matrix_world, dtype=np.float64)
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


def newer_file_warning() -> str | None:
    """The warning for a file saved by a newer Blender than this one (what this one does not know
    was dropped when it read the file, and a copy it saves will not have it), or None."""
    saved, this = tuple(bpy.data.version[:2]), tuple(bpy.app.version[:2])
    if not bpy.data.filepath or saved <= this:
        return None
    return (f"the file was saved by Blender {saved[0]}.{saved[1]}, newer than this one ({this[0]}.{this[1]}): what "
            f"{this[0]}.{this[1]} does not know was lost when it read the file, Relight solved what was left, and "
            f"a copy written by --out or a save here will not have it either")


def tag_owned(idb, rid) -> None:
    """Mark ``idb`` (an object, mesh, material, light or collection) as made by result ``rid``."""
    idb[RELIGHT_OWNER_PROP] = rid
    idb[RELIGHT_NAME_PROP] = idb.name


def owner_of(idb):
    """The result id that made ``idb``, or None when the user made it: never tagged, or a copy of
    something Relight made (its custom properties came along, its name did not: Blender names are
    unique, so a copy has another). Only what Relight made is ever removed or left out as ours."""
    rid = idb.get(RELIGHT_OWNER_PROP)
    made = idb.get(RELIGHT_NAME_PROP)
    return None if rid is None or (made is not None and made != idb.name) else rid


def render_visible_objects(context):
    """Names of the objects that a render of the view layer would see through the collection
    tree: every object linked to at least one collection of the layer that is not excluded from it
    and whose chain from the scene collection has no ``hide_render`` (the object's own
    ``hide_render`` is checked separately). Hiding in the viewport (H, the eye, the monitor icon)
    does not keep an object out of a render, so it does not keep it out of the model."""
    seen = set()

    def walk(lc, hidden):
        if lc.exclude:
            return
        hidden = hidden or bool(getattr(lc.collection, "hide_render", False))
        if not hidden:
            seen.update(ob.name for ob in lc.collection.objects)
        for child in lc.children:
            walk(child, hidden)

    walk(context.view_layer.layer_collection, False)
    return seen


def rendered(ob, renderable) -> bool:
    """Whether a render shows ``ob`` (``renderable``: render_visible_objects)."""
    return not ob.hide_render and ob.name in renderable


def exported_objects(context=None):
    """The scene's mesh objects that are exported: those a render shows (``rendered``), whether or
    not they are hidden in the viewport, and not made by Relight (its emitters object shows a
    result: a new solve does not count it as scene light)."""
    context = context or bpy.context
    renderable = render_visible_objects(context)
    return [ob for ob in context.scene.objects
            if ob.type == "MESH" and rendered(ob, renderable) and owner_of(ob) is None]


def hidden_in_viewport(context, objs) -> list:
    """The names of ``objs`` hidden in the viewport (H, the eye or the monitor icon) that renders
    show, and so Relight models."""
    return [ob.name for ob in objs if not ob.visible_get(view_layer=context.view_layer)]


class _Evaluable:
    """While open, the objects ``objs`` and their collections are enabled in the viewports, so that
    the depsgraph evaluates their modifiers as a render would (an object disabled in the viewports,
    the monitor icon, is not evaluated); everything is set back as it was on close."""

    def __init__(self, context, objs):
        self.context, self.changed = context, []
        colls = {c for ob in objs for c in ob.users_collection}
        for idb in list(objs) + sorted(colls, key=lambda c: c.name):
            if getattr(idb, "hide_viewport", False) and getattr(idb, "library", None) is None:
                self.changed.append(idb)

    def __enter__(self):
        for idb in self.changed:
            idb.hide_viewport = False
        if self.changed:
            self.context.view_layer.update()
        return self

    def __exit__(self, *exc):
        for idb in self.changed:
            idb.hide_viewport = True
        if self.changed:
            self.context.view_layer.update()
        return False


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


def linear_to_srgb(c):
    """Scene-linear -> sRGB-encoded values (what BMesh byte colour layers hold)."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def srgb_to_linear(c):
    """sRGB-encoded values (a BMesh byte colour layer's) -> scene-linear."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, np.power((c + 0.055) / 1.055, 2.4))


def _edit_target_colours(ob):
    """(loops, 4) linear RGBA of the target layer of ``ob`` in Edit Mode, read from its edit mesh
    (the mesh's own attribute data is not current there), in the mesh's loop order; None
    without the layer."""
    import bmesh

    bm = bmesh.from_edit_mesh(ob.data)
    layers = bm.loops.layers
    layer, byte = layers.float_color.get(TARGET_ATTRIBUTE), False
    if layer is None:
        layer, byte = layers.color.get(TARGET_ATTRIBUTE), True
    if layer is None:
        return None
    bm.faces.ensure_lookup_table()
    col = np.array([tuple(loop[layer]) for f in bm.faces for loop in f.loops], dtype=np.float64).reshape(-1, 4)
    if byte:
        col[:, :3] = srgb_to_linear(col[:, :3])
    return col


def lux_layer(mesh, owner=None):
    """The mesh's ``relight_target_lux`` (a Face FLOAT attribute: illuminance targets, lx), None
    when there is none; of another domain or type: SceneError naming it."""
    return _checked_layer(mesh, LUX_ATTRIBUTE, "FACE", ("FLOAT",), owner,
                          "reads it as a Face float attribute (illuminance targets, lx)")


def _lux_values(ob, n) -> np.ndarray:
    """(n,) the illuminance targets (lx, 0: none) of ``ob``'s base-mesh polygons (in Edit Mode,
    from its edit mesh); NaN, infinite or negative values refused, naming the object."""
    me = ob.data
    attr = lux_layer(me, ob.name)
    if attr is None:
        return np.zeros(n)
    if ob.mode == "EDIT" and me.is_editmode:
        import bmesh

        bm = bmesh.from_edit_mesh(me)
        layer = bm.faces.layers.float.get(LUX_ATTRIBUTE)
        v = np.array([f[layer] for f in bm.faces], dtype=np.float64) if layer is not None else np.zeros(n)
    else:
        v = foreach_array(attr.data, "value", n, np.float64)
    if len(v) != n:
        v = np.zeros(n)
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        bad = int(np.sum(~np.isfinite(v) | (v < 0)))
        raise SceneError(f"{ob.name}: {bad} face(s) of its {LUX_ATTRIBUTE} hold a negative, NaN or infinite "
                         "illuminance; fill them again (lx >= 0)")
    return v


def illuminance_targets(target, target_b, lux, reflectance, face_object, names):
    """The faces' targets (neutral paint read as a brightness: engine.paint) with their
    illuminance targets (``lux`` (F,), lx, 0: none) among them:
    a face of illuminance E_v lx is a target of radiosity reflectance x E (engine.units.
    irradiance_from_lux: white light of that illuminance), the illuminance arriving there whatever
    its reflectance. A face that reflects too little for its radiosity to tell its illuminance
    (a channel below MIN_REFLECTANCE_LUX) is refused, naming its object."""
    target_b = neutral_as_brightness(target, target_b, reflectance)  # (grey paint: a brightness, engine.paint)
    on = lux > 0
    if not on.any():
        return target, target_b
    dark = on & np.any(reflectance < MIN_REFLECTANCE_LUX, axis=1)
    if dark.any():
        objs = sorted({names[o] for o in face_object[dark]})
        raise SceneError(f"{int(dark.sum())} face(s) with an illuminance target reflect less than "
                         f"{MIN_REFLECTANCE_LUX:g} in a channel (objects: {', '.join(objs[:5])}): Relight reads "
                         "illuminance from the light a face reflects; give them a grey material, or make the object a "
                         "Work Plane (light passes through it; its material is not used)")
    target, target_b = target.copy(), target_b.copy()
    target[on] = True
    target_b[on] = reflectance[on] * irradiance_from_lux(lux[on])[:, None]
    return target, target_b


def _base_attributes(ob, target_scale, notes=None, forbidden_too=True):
    """Per base-mesh polygon: target (bool), target radiosity (W/m^2), forbidden (bool) and
    illuminance target (lx, 0: none; a face painted and given an illuminance both is refused).
    ``notes``: a list that gets the messages about layers found but not used. An object in
    Edit Mode: its edit mesh's paint. ``forbidden_too``: False leaves the forbidden faces unread
    (all False: export.repaint reads the paint alone)."""
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
        editing = ob.mode == "EDIT" and me.is_editmode
        col = _edit_target_colours(ob) if editing else None
        if col is None or len(col) != len(me.loops):
            col = foreach_array(attr.data, "color", len(me.loops), np.float64, 4)
        if not np.all(np.isfinite(col)):
            raise SceneError(f"{ob.name}: its {TARGET_ATTRIBUTE} holds NaN or infinite colours; paint it again")
        # a face is a target when its corners' mean alpha is >= 1/2; its colour is the mean over its
        # painted corners, weighted by their alpha (the edge of a stroke: the unpainted corners' colour,
        # black, is not averaged in)
        alpha = np.clip(col[:, 3], 0.0, 1.0)
        weight = np.bincount(loop_poly, weights=alpha, minlength=n)
        target = weight >= 0.5 * np.maximum(totals, 1)
        rgb = np.stack([np.bincount(loop_poly, weights=alpha * col[:, k], minlength=n) for k in range(3)],
                       axis=1)[target] / weight[target][:, None]
        if np.any(rgb < 0):
            if notes is not None:
                notes.append(f"{ob.name}: {int(np.sum(np.any(rgb < 0, axis=1)))} target(s) with a negative colour "
                             "set to 0 (light cannot be negative)")
            rgb = np.maximum(rgb, 0.0)
        target_b[target] = exitance_from_radiance(rgb * target_scale)
    attr = forbidden_layer(me, ob.name) if forbidden_too else None  # another domain or type: refused
    if attr is not None:
        forbidden = read_forbidden(attr, n)
    if no_lights(ob):
        forbidden[:] = True
    lux = _lux_values(ob, n)
    both = target & (lux > 0)
    if both.any():
        raise SceneError(f"{ob.name}: {int(both.sum())} face(s) carry both a painted target ({TARGET_ATTRIBUTE}) and "
                         f"an illuminance target ({LUX_ATTRIBUTE}): keep one kind per face (Unpaint them, or Fill "
                         "Selected with the kind you want)")
    return target, target_b, forbidden, lux


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


WORK_PLANE_NOTE = ("work plane(s) {}: light passes through them and they reflect none into the scene (their "
                   "material is not used; no light on them); Cycles renders them as surfaces unless their Ray "
                   "Visibility is off: Match Cycles Light Paths (--out) turns it off in the copy")


def painted_work_plane_warning(painted, target_b, face_object, names) -> str:
    """The warning for faces of work planes painted with a radiosity (relight_target), not given
    an illuminance: a work plane reflects no light into the scene, so its paint is read as what a
    white surface (MAX_REFLECTANCE) would reflect there, the illuminance paint / MAX_REFLECTANCE."""
    objs = sorted({names[o] for o in face_object[painted]})
    lx = illuminance_lux(target_b[painted] / MAX_REFLECTANCE)
    return (f"work plane(s) {', '.join(map(repr, objs[:5]))}{' ...' if len(objs) > 5 else ''}: "
            f"{int(painted.sum())} face(s) painted with a radiosity target (relight_target) are read as the light "
            f"that a white surface ({MAX_REFLECTANCE:g}) would reflect there, an illuminance of "
            f"{lx.min():.3g}-{lx.max():.3g} lx; a work plane takes illuminance targets: give them in lx (Fill "
            "Selected, lx), or turn Work Plane off to paint the radiosity of the surface itself")


def work_plane(ob) -> bool:
    """The object's "work plane" switch (the add-on's property, or a custom property of that name;
    a boolean or a number): light passes through its faces and they reflect none into the scene
    (a plane where the light is measured, as lighting software has them)."""
    raw = ob.get(WORK_PLANE_PROP)
    if raw is not None and not isinstance(raw, (bool, int, float)):
        raise SceneError(f"object {ob.name!r}: custom property {WORK_PLANE_PROP} is {raw!r}, not a boolean or a "
                         "number: set it to True/False (or 1/0)")
    return bool(getattr(ob, WORK_PLANE_PROP, False) or raw)


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


def _check_near(V, name, origin):
    """SceneError when a vertex of ``V`` (n, 3) lies beyond MAX_COORDINATE from ``origin``."""
    far = float(np.abs(V).max()) if np.size(V) else 0.0
    if far > MAX_COORDINATE:
        raise SceneError(f"object {name!r} has a vertex {far:.3g} m from {origin}: an infinite coordinate? (Blender "
                         f"stores infinity as its largest number, 3.4e+38); Relight models scenes within "
                         f"{MAX_COORDINATE:.0e} m")


def _mesh_geometry(ob_eval, me, name):
    """Local-space arrays of an evaluated mesh: vertices, loop triangles, their polygons,
    polygon loops (vertex indices) and material indices."""
    V = foreach_array(me.vertices, "co", len(me.vertices), np.float64, 3)
    if not np.all(np.isfinite(V)):
        raise SceneError(f"object {name!r} has NaN or infinite vertex coordinates")
    _check_near(V, name, "its origin")
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


class _Builder:
    """Accumulates world-space faces of several meshes into FaceSet arrays."""

    def __init__(self):
        self.verts, self.tris, self.tri_face = [], [], []
        self.loop_vert, self.loop_start, self.loop_total = [], [], []
        self.f_obj, self.f_idx, self.rho, self.e, self.tgt, self.tgt_b, self.forb = [], [], [], [], [], [], []
        self.lux = []  # per face: its illuminance target, lx (0: none)
        self.warnings = []
        self.mat_cache = {}
        self.mat_ids = {}  # material name (None: no material) -> index into self.lobes
        self.materials_used = {}  # material name -> the material (the exported ones)
        self.material_notes = {}  # material name -> what its model leaves out (material_warnings)
        self.lobes = []
        self.f_mat = []
        #: per chunk (one add()): its faces whose material has a linked emission (bool), its geometry
        #: (local arrays) and world matrix, and the back side's exitance (None: the front's)
        self.linked, self.geos, self.e_back = [], [], []
        self.base = []  # per chunk: its first vertex, face and loop
        self.nf = self.nv = self.nl = 0

    def materials(self, slots, mat_index):
        """(reflectance, exitance, linked emission) per face of one mesh, from its slots."""
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
        self.f_mat.append(np.asarray(ids, dtype=np.int64)[mi])
        linked = np.array([bool(p[4]) for p in props])[mi]
        return (np.array([p[0] for p in props])[mi], exitance_from_radiance(np.array([p[1] for p in props]))[mi],
                linked)

    def add(self, geo, matrix, name, oi, face_index, target, target_b, forbidden, lux=None):
        M = np.asarray(matrix, dtype=np.float64)
        if not np.all(np.isfinite(M)):
            raise SceneError(f"object {name!r} has a NaN or infinite transform (its location, rotation or scale, "
                             "or a parent's or a constraint's)")
        W = geo["V"] @ M[:3, :3].T + M[:3, 3]
        if not np.all(np.isfinite(W)):
            raise SceneError(f"object {name!r} has NaN or infinite vertex coordinates")
        _check_near(W, name, "the origin")
        flip = np.linalg.det(M[:3, :3]) < 0
        lt = geo["lt"][:, ::-1] if flip else geo["lt"]
        nv, nf = self.nv, self.nf
        self.base.append((nv, nf, self.nl))
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
        rho, e, linked = self.materials(geo["slots"], geo["mat_index"])
        self.linked.append(linked)
        self.geos.append((geo, M, name))
        self.e_back.append(None)
        npoly = len(ls)
        self.rho.append(rho)
        self.e.append(e)
        self.f_obj.append(np.full(npoly, oi))
        self.f_idx.append(face_index)
        self.tgt.append(target)
        self.tgt_b.append(target_b)
        self.forb.append(forbidden)
        self.lux.append(np.zeros(npoly) if lux is None else lux)
        self.nf += npoly
        self.nv += len(W)

    def add_backs(self, chunk, faces, offset):
        """The back side of faces ``faces`` (bool, of chunk ``chunk``) as faces of their own: the
        same polygons with their winding reversed, set ``offset`` (m) behind the front along the
        vertex normals, emitting the chunk's back exitance and reflecting its reflectance; never
        targets or lights (forbidden), not reported (face_index -1)."""
        sel = np.flatnonzero(faces)
        if not len(sel):
            return 0
        nv0, nf0, nl0 = self.base[chunk]
        W = self.verts[chunk]
        ls, lt = self.loop_start[chunk][sel] - nl0, self.loop_total[chunk][sel]
        lpos = np.repeat(ls - np.cumsum(np.concatenate([[0], lt[:-1]])), lt) + np.arange(int(lt.sum()))
        lface = np.repeat(np.arange(len(sel)), lt)
        corners = self.loop_vert[chunk][lpos] - nv0  # chunk-local vertex of each loop of the chosen faces
        used, local = np.unique(corners, return_inverse=True)
        face_of = np.full(len(self.loop_start[chunk]), -1, dtype=np.int64)
        face_of[sel] = np.arange(len(sel))
        tri_sel = face_of[self.tri_face[chunk] - nf0] >= 0
        tri = self.tris[chunk][tri_sel] - nv0
        tv = W[tri]
        tn = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])  # area vectors of the front
        vn = np.zeros((len(W), 3))
        for k in range(3):
            np.add.at(vn, tri[:, k], tn)
        vn = vn[used]
        ln = np.linalg.norm(vn, axis=1)
        vn = vn / np.where(ln > 0, ln, 1.0)[:, None]
        remap = np.full(len(W), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        # each polygon's loop reversed: its normal points the other way
        start = np.concatenate([[0], np.cumsum(lt)[:-1]])
        pos = np.arange(len(lpos))
        rev = start[lface] + lt[lface] - 1 - (pos - start[lface])
        nv, nf = self.nv, self.nf
        self.verts.append(W[used] - offset * vn)
        self.tris.append(remap[tri][:, ::-1] + nv)
        self.tri_face.append(face_of[self.tri_face[chunk][tri_sel] - nf0] + nf)
        self.loop_vert.append(local[rev] + nv)
        self.loop_start.append(start + self.nl)
        self.loop_total.append(lt.copy())
        self.base.append((nv, nf, self.nl))
        self.nl += len(lpos)
        e_back = self.e[chunk] if self.e_back[chunk] is None else self.e_back[chunk]
        self.rho.append(self.rho[chunk][sel])
        self.e.append(e_back[sel])
        self.f_mat.append(self.f_mat[chunk][sel])
        self.f_obj.append(self.f_obj[chunk][sel])
        self.f_idx.append(np.full(len(sel), -1, dtype=np.int64))
        self.tgt.append(np.zeros(len(sel), dtype=bool))
        self.tgt_b.append(np.zeros((len(sel), 3)))
        self.lux.append(np.zeros(len(sel)))
        self.forb.append(np.ones(len(sel), dtype=bool))
        self.linked.append(np.zeros(len(sel), dtype=bool))
        self.geos.append(None)
        self.e_back.append(None)
        self.nf += len(sel)
        self.nv += len(used)
        return len(sel)


    def flip_faces(self, chunk, faces):
        """Turn faces ``faces`` (bool, of chunk ``chunk``) to face the other way: their triangles'
        winding and their polygons' loops reversed (the vertices stay; nothing else changes)."""
        nv0, nf0, nl0 = self.base[chunk]
        tsel = faces[self.tri_face[chunk] - nf0]
        self.tris[chunk][tsel] = self.tris[chunk][tsel][:, ::-1]
        sel = np.flatnonzero(faces)
        ls, lt = self.loop_start[chunk][sel] - nl0, self.loop_total[chunk][sel]
        first = np.repeat(ls, lt)
        pos = first + np.arange(int(lt.sum())) - np.repeat(np.cumsum(lt) - lt, lt)
        lv = self.loop_vert[chunk]
        lv[pos] = lv[2 * first + np.repeat(lt, lt) - 1 - pos]


def open_faces(geo) -> tuple:
    """((polygons,) bool, (polygons,) island label): the faces of a mesh (``_mesh_geometry``) on an
    island (faces joined by shared edges) that is not closed, i.e. that has an edge with one face or
    more than two: the back side of such a face may see the scene (a plane does), that of a closed
    island faces its inside."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    npoly, ne = len(geo["loop_start"]), int(geo["n_edges"])
    le, lp = geo["loop_edge"], geo["loop_poly"]
    if npoly == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64)
    count = np.bincount(le, minlength=ne)
    graph = sp.coo_matrix((np.ones(len(le)), (lp, npoly + le)), shape=(npoly + ne, npoly + ne))
    _, label = connected_components(graph, directed=False)
    is_open = np.zeros(label.max() + 1, dtype=bool)
    is_open[label[npoly:][(count != 2) & (count > 0)]] = True
    return is_open[label[:npoly]], label[:npoly]


def mixed_orientation(geo, island) -> np.ndarray:
    """(islands,) bool: the islands (``island``: open_faces' labels) some of whose faces are turned
    against their neighbours (an edge that two faces run along the same way: normals flipped on
    some faces by hand, a room partly turned in)."""
    le, lp, lv = geo["loop_edge"], geo["loop_poly"], geo["loop_vert"]
    k = int(island.max()) + 1 if len(island) else 0
    if not len(le):
        return np.zeros(k, dtype=bool)
    order = np.lexsort((lv, le))  # the loops of each edge together, by their first vertex
    same = (le[order][1:] == le[order][:-1]) & (lv[order][1:] == lv[order][:-1])
    out = np.zeros(k, dtype=bool)
    out[island[lp[order][1:][same]]] = True
    return out


#: how far behind its front the back side of an open emitter is set (``Builder.add_backs``),
#: relative to the scene's bounding-box diagonal: 10 x the rays' origin offset
#: (engine.sampling.RAY_OFFSET), so that a ray reaching the front hits the front first
BACK_OFFSET = 10 * RAY_OFFSET
#: rays per emitting face of an open island that tell what its back sees (engine.backs), and
#: in all (fewer per face when there are many: at least 16)
BACK_RAYS = 256
BACK_RAY_BUDGET = 1 << 20
#: a back whose rays reach front sides at a median distance below this fraction of its island's
#: size (the square root of its emitting area) lies against a surface (_emitting_backs)
BACK_GAP = 0.1
#: rays (in all) that measure the light leaving the gaps of the backs against a surface
LEAK_RAYS = 1 << 16
#: the faces that may be seen from behind (_faces_seen_from_behind): rays per side of a face, and
#: in all (fewer per face when there are many: at least 4)
SIDE_RAYS = 32
SIDE_RAY_BUDGET = 1 << 21
#: a side whose rays reach a surface at most this often sees nothing; a back whose rays reach the
#: scene at least SIDE_SEES often sees it; a closed island holds the scene when its backs' rays
#: reach other objects' fronts at least ENCLOSES often
SIDE_BLIND = 0.02
SIDE_SEES = 0.1
ENCLOSES = 0.01
#: an island is first seen from this many of its faces (by area); its faces are cast one by one
#: when at least ISLAND_SEES of those backs' rays see the scene
ISLAND_FACES = 64
ISLAND_SEES = 0.02
#: an island's faces are modelled from both sides when its backs' rays see the scene at least
#: this often (all of them: one plane is lit and seen alike on its whole)
ISLAND_BOTH = 0.25
#: a back sees the scene where its rays reach fronts outside its island's box, grown by this
#: fraction of the box's largest side (a block standing on a floor looks at the floor inside it)
ISLAND_BOX_PAD = 0.01


def _painted_not_rendered(context, renderable) -> str | None:
    """What explains a missing target: painted meshes a render does not show (hidden from render,
    in a collection hidden from render or excluded from the view layer), or that exist only as the
    source of instances (their instances are geometry only)."""
    def painted(ob):
        return ob.type == "MESH" and ob.data is not None and TARGET_ATTRIBUTE in ob.data.attributes

    off = [ob.name for ob in context.scene.objects if painted(ob) and not rendered(ob, renderable)]
    in_scene = set(context.scene.objects)
    instanced = sorted({ob.name for ob in context.scene.objects if ob.instance_type == "COLLECTION"
                        and ob.instance_collection is not None
                        for ob in ob.instance_collection.all_objects if painted(ob) and ob not in in_scene})
    parts = []
    if off:
        parts.append(f"painted object(s) {', '.join(map(repr, off[:10]))} are not rendered (hidden from render, "
                     "the camera icon, or in a collection hidden from render or excluded from the view layer)")
    if instanced:
        parts.append(f"painted object(s) {', '.join(map(repr, instanced[:10]))} are only in an instanced collection: "
                     "instances are geometry only (paint a real object, or make the instance real: "
                     "Object > Apply > Make Instances Real)")
    return "; ".join(parts) or None


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
    renderable = render_visible_objects(context)
    objs = exported_objects(context)
    notes = {"target": [], "candidates": [], "emitters": []}
    warnings = []
    newer = newer_file_warning()
    if newer:
        warnings.append(newer)
    hidden = hidden_in_viewport(context, objs)
    if hidden:
        warnings.append(hidden_warning(hidden))
    unpainted = _painted_not_rendered(context, renderable)
    if unpainted:
        notes["target"].append(unpainted)
    skipped = [f"{ob.name!r} ({ob.type})" for ob in context.scene.objects
               if ob.type in NON_MESH_GEOMETRY and rendered(ob, renderable)]
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
    with _Evaluable(context, objs):  # (disabled in the viewports: evaluated as a render would)
        for oi, ob in enumerate(objs):
            counts[ob.name] = len(ob.data.polygons)
            names.append(ob.name)
            target, target_b, forbidden, lux = _base_attributes(ob, settings["target_scale"], notes["target"])
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
                  np.where(ok, forbidden[safe], no_lights(ob)), np.where(ok, lux[safe], 0.0))
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
    b.warnings.extend(material_warnings(b.material_notes))
    b.warnings.extend(_bake_linked_emission(b, objs, context))
    b.names = names
    b.warnings.extend(_faces_seen_from_behind(b))
    back_warnings, backs = _emitting_backs(b)
    b.warnings.extend(back_warnings)
    b.warnings.extend(_not_modelled(context, objs, b, renderable))
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
    lamps, lamp_warnings = export_lamps(context, renderable, owner_of, notes["emitters"])
    warnings.extend(w for w in lamp_warnings if w not in warnings)
    lux = np.concatenate(b.lux)
    planes = [oi for oi, ob in enumerate(objs) if work_plane(ob)]
    passes = np.isin(np.concatenate(b.f_obj), planes) if planes else None
    if passes is not None:  # reflect none into the scene (nothing sees them): read as white, no light on them
        rho, e = rho.copy(), e.copy()
        rho[passes], e[passes] = MAX_REFLECTANCE, 0.0
        warnings.append(WORK_PLANE_NOTE.format(", ".join(repr(objs[oi].name) for oi in planes)))
        painted = passes & np.concatenate(b.tgt) & ~(lux > 0)
        if painted.any():
            warnings.append(painted_work_plane_warning(painted, np.concatenate(b.tgt_b), np.concatenate(b.f_obj), names))
    target, target_b = illuminance_targets(np.concatenate(b.tgt), np.concatenate(b.tgt_b), lux, rho,
                                           np.concatenate(b.f_obj), names)
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
        target=target,
        target_radiosity=target_b,
        target_lux=lux,
        passes=passes,
        forbidden=np.concatenate(b.forb) | (passes if passes is not None else False),
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
                         np.concatenate(b.f_mat), b.lobes, notes=notes, backs=backs)


def repaint(exp: ExportedScene, objects=None, base: FaceSet | None = None) -> FaceSet:
    """The exported faces with the paint their objects hold now (Live mode, after a stroke): the
    targets and their radiosity read again from each object's base mesh (an object in Edit Mode:
    from its edit mesh), mapped onto the exported faces as export_scene maps them; everything else
    as exported. ``objects``: the names of the objects to read again (None: all), the others'
    paint as in ``base`` (an earlier repaint of ``exp``; default: the export). The caller checks
    that nothing else changed (pipeline.prepared's stale check)."""
    faces = exp.faces
    was = faces if base is None else base
    target, radiosity = was.target.copy(), was.target_radiosity.copy()
    lux = np.zeros(faces.n_faces) if was.target_lux is None else was.target_lux.copy()
    scale = exp.settings["target_scale"]
    rows_of = _object_rows(exp)
    for oi, ob in enumerate(exp.objects):
        if objects is not None and ob.name not in objects:
            continue
        t, b, _, lx = _base_attributes(ob, scale, forbidden_too=False)  # (in Edit Mode: its edit mesh's paint)
        rows = rows_of[oi]
        idx = faces.face_index[rows]
        ok = (idx >= 0) & (idx < len(t))
        target[rows] = np.where(ok, t[np.where(ok, idx, 0)], False)
        radiosity[rows] = np.where(ok[:, None], b[np.where(ok, idx, 0)], 0.0)
        lux[rows] = np.where(ok, lx[np.where(ok, idx, 0)], 0.0)
    target, radiosity = illuminance_targets(target, radiosity, lux, faces.reflectance, faces.face_object,
                                            faces.object_names)
    return replace(faces, target=target, target_radiosity=radiosity, target_lux=lux)


def _object_rows(exp: ExportedScene) -> list:
    """[the exported faces of object i] for every object of ``exp`` (made once, kept on it)."""
    rows = exp.__dict__.get("_object_rows")
    if rows is None:
        order = np.argsort(exp.faces.face_object, kind="stable")
        edges = np.searchsorted(exp.faces.face_object[order], np.arange(len(exp.objects) + 1))
        rows = exp.__dict__["_object_rows"] = [order[edges[i]:edges[i + 1]] for i in range(len(exp.objects))]
    return rows


def _linked_text(b, names) -> str:
    """"'Mat' (Emission Color of Principled BSDF, ...)": the materials and their linked emission."""
    return ", ".join(f"{n!r} ({', '.join(b.mat_cache[n][4])})" for n in names)


def _bake_linked_emission(b, objs, context) -> list:
    """Each face whose material has a linked emission gets its mean emitted radiance from a
    Cycles bake (emission_bake.py): its exitance pi x that, front and back. Nothing happens when
    no face has one. Returns the warnings (what could not be baked is named with its material)."""
    from .emission_bake import BakeRequest, bake_emission

    requests, chunk_of, inst = [], {}, {}
    for ci, linked in enumerate(b.linked):
        if b.geos[ci] is None or not linked.any():
            continue
        geo, _, name = b.geos[ci]
        mats = _linked_materials(b, geo, linked)
        if ci < len(objs):  # the real objects are the first chunks, one each, in order
            requests.append(BakeRequest(name, objs[ci], linked, [scene_material(m) for m in geo["slots"]]))
            chunk_of[name] = ci
        else:
            inst.setdefault(name, set()).update(mats)
    out = []
    for name, mats in inst.items():
        out.append(f"instances {name!r}: the linked emission of material(s) {_linked_text(b, sorted(mats))} is not "
                   "baked for instanced objects: their faces emit only its unlinked part (make the instances real: "
                   "Object > Apply > Make Instances Real)")
    if not requests:
        return out
    try:
        baked, notes = bake_emission(requests, context.scene, context.evaluated_depsgraph_get())
    except RuntimeError as exc:
        mats = sorted(set().union(*(_linked_materials(b, b.geos[chunk_of[r.name]][0], r.faces) for r in requests)))
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        return out + [f"the linked emission of material(s) {_linked_text(b, mats)} could not be evaluated by a Cycles "
                      f"bake ({reason}): their faces emit only its unlinked part"]
    for name, (front, back) in baked.items():
        ci = chunk_of[name]
        mask = b.linked[ci]
        b.e[ci] = b.e[ci].copy()
        b.e[ci][mask] = exitance_from_radiance(front[mask])
        b.e_back[ci] = b.e[ci].copy()
        b.e_back[ci][mask] = exitance_from_radiance(back[mask])
    return out + notes


def _linked_materials(b, geo, faces) -> set:
    """Names of the materials with a linked emission on ``faces`` of a mesh."""
    slots = geo["slots"]
    mi = np.clip(geo["mat_index"][faces], 0, max(len(slots), 1) - 1)
    return {slots[i].name for i in np.unique(mi) if i < len(slots) and slots[i] is not None}


def _faces_seen_from_behind(b) -> list:
    """Cycles shades both sides of a mesh face alike; the radiosity model's faces are one-sided
    (a ray reaching a back side is absorbed). Rays from both sides of the faces that may be seen
    from behind (engine.backs.sides_view: a front sees the scene where its rays reach any surface,
    a back where they reach front sides, farther than BACK_GAP x its island's size: closer, it lies
    against a surface; only backs in a shell's inside, it looks at its own inside) decide which
    side the scene sees:

    - an island (faces joined by their edges) whose fronts see nothing (at most SIDE_BLIND of
      their rays reach a surface) while other objects lie behind it (at least ENCLOSES of its
      backs' rays reach their fronts): the inside-out room, a cube whose normals point out of it
      as added; every face turned to face the scene (Builder.flip_faces: its targets, forbidden
      state and report row stay its own);
    - a face of an open island (a plane, a room without a floor, a wall with a window cut), not
      painted, whose front sees nothing and whose back sees the scene (at least SIDE_SEES of its
      rays): turned the same way (a painted one is left as painted, and named: which side the paint
      is meant for, only the artist knows);
    - the faces of an open island whose backs see the scene (at least ISLAND_BOTH of their rays,
      over the island) and whose fronts see it too (a shelf that is a single plane, lit from
      above, seen from below): their backs become faces of their own (Builder.add_backs:
      reflecting their reflectance, never targets or lights, not reported). An island only some of
      whose backs see the scene is left one-sided (the shipped staircase's landings: modelling a
      few of their faces' tops moved the prediction 3 % off Cycles).

    What a back sees counts outside its island's box: the inside of a block open at the bottom
    and standing on a floor looks at the floor under it, a cavity no light enters (modelled, the
    floor's patches straddling the block's edge would carry light into it).

    A closed island whose box holds another object whole, with targets (that object's or its
    own): a room and its furniture. It is judged by what its sides see inside its own box
    (sides_view's ``front_in``, ``back_in``): a ground plane or a garden around a room whose
    normals point out is not what its fronts are meant to see (issue 35, case 12). Such a room
    turned in part by hand (its floor and a wall in, the rest out): the faces whose fronts see
    nothing of its inside while their backs see some are turned (painted or not). A closed island
    with faces turned against their neighbours (``mixed_orientation``) that is no such room (an
    empty room, a crate with a face flipped) is named in a warning, modelled as it is.

    Closed islands (solids) face their inside with their backs: rays are cast only for those
    whose box holds another object's centre. Emitting faces keep their orientation
    (_emitting_backs models their backs). Returns the warnings that name what was turned or
    doubled, per object."""
    from ..engine.backs import sides_view

    chosen, gaps, where, areas, boxes_of, enclosing = [], [], [], [], [], []
    muddled = set()  # the objects with a closed island partly turned
    islands, boxes = {}, {}
    for ci in range(len(b.e)):
        if len(b.verts[ci]):
            o, W = int(b.f_obj[ci][0]) if len(b.f_obj[ci]) else -1, b.verts[ci]
            lo, hi = boxes.get(o, (W.min(axis=0), W.max(axis=0)))
            boxes[o] = (np.minimum(lo, W.min(axis=0)), np.maximum(hi, W.max(axis=0)))
    centres = {o: 0.5 * (lo + hi) for o, (lo, hi) in boxes.items()}
    painted = {int(o) for ci in range(len(b.e)) if len(b.tgt[ci]) for o in np.unique(b.f_obj[ci][b.tgt[ci]])}
    obj_ids = np.array(list(boxes), dtype=np.int64)
    obj_lo, obj_hi = (np.array([boxes[o][j] for o in obj_ids]).reshape(-1, 3) for j in (0, 1))
    obj_painted = np.isin(obj_ids, list(painted))
    for ci in range(len(b.e)):
        if b.geos[ci] is None or not len(b.e[ci]):
            continue
        geo = b.geos[ci][0]
        if id(geo) not in islands:  # instances share their mesh's arrays
            islands[id(geo)] = open_faces(geo)
            islands[id(geo)] += (mixed_orientation(geo, islands[id(geo)][1]),)
        is_open, island, mixed = islands[id(geo)]
        back = b.e[ci] if b.e_back[ci] is None else b.e_back[ci]
        still = ~(np.any(b.e[ci] > 0, axis=1) | np.any(back > 0, axis=1) | b.linked[ci])
        k = int(island.max()) + 1
        area = _chunk_face_areas(b, ci)
        size = np.sqrt(np.bincount(island, weights=area, minlength=k))
        # a closed island is cast when its box holds another object's centre
        nv0, nf0, _ = b.base[ci]
        lab = np.repeat(island, b.loop_total[ci])
        order = np.argsort(lab, kind="stable")
        P = b.verts[ci][b.loop_vert[ci][order] - nv0]
        first = np.searchsorted(lab[order], np.arange(k))
        lo, hi = np.minimum.reduceat(P, first, axis=0), np.maximum.reduceat(P, first, axis=0)
        others = np.array([c for o, c in centres.items() if o != int(b.f_obj[ci][0])]).reshape(-1, 3)
        holds = np.any(np.all((others[None] > lo[:, None]) & (others[None] < hi[:, None]), axis=2), axis=1)
        sel = np.flatnonzero(still & (is_open | holds[island] | mixed[island]))
        if len(sel):
            chosen.append(nf0 + sel)
            gaps.append(BACK_GAP * size[island[sel]])
            where.append((ci, sel, island[sel], is_open[sel]))
            areas.append(area[sel])
            pad = ISLAND_BOX_PAD * (hi - lo).max(axis=1, keepdims=True)
            boxes_of.append(np.stack([lo - pad, hi + pad], axis=1)[island[sel]])
            # a closed island whose box holds another object whole (a room and its furniture), and
            # targets (its own or that object's), is judged by what its sides see inside that box: a
            # ground plane or a garden around it is outside (a pierced slab, a sunk pillow: held in
            # part; a casing round a hidden part: no target; judged as before)
            own = int(b.f_obj[ci][0])
            held = obj_ids != own
            whole = np.all((obj_lo[held][None] >= (lo - pad)[:, None]) & (obj_hi[held][None] <= (hi + pad)[:, None]),
                           axis=2)
            whole &= obj_painted[held][None] | (np.bincount(island, weights=b.tgt[ci], minlength=k) > 0)[:, None]
            enclosing.append(whole.any(axis=1)[island[sel]] & ~is_open[sel])
            # a closed island partly turned (some faces in, the others out): turned when it is a
            # room (above), named otherwise (a solid with a face flipped: which side is meant?)
            if (mixed[island[sel]] & ~is_open[sel]).any():
                muddled.add(b.names[own])
    if not chosen:
        return []
    geometry = (np.concatenate(b.verts), np.concatenate(b.tris), np.concatenate(b.tri_face), np.concatenate(b.f_obj))
    areas = np.concatenate(areas)
    # 1. each island from ISLAND_FACES of its faces (by area): the inside-out ones, and those
    # whose backs see the scene at all (their faces are cast one by one)
    label = np.concatenate([isl.astype(np.int64) + ci * (1 << 32) for ci, _, isl, _ in where])
    keys, inv, count = np.unique(label, return_inverse=True, return_counts=True)
    order = np.argsort(inv, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(count)])
    rng = np.random.default_rng(0)
    sample = [order[np.isin(inv[order], np.flatnonzero(count <= ISLAND_FACES))]]  # small islands: every face
    for j in np.flatnonzero(count > ISLAND_FACES):
        rows = order[bounds[j]:bounds[j + 1]]
        drawn = rows[areas[rows] > 0]  # zero-area faces are never drawn (an artist's file has hundreds)
        if len(drawn) <= ISLAND_FACES:
            sample.append(drawn if len(drawn) else rows[:ISLAND_FACES])
            continue
        sample.append(rng.choice(drawn, ISLAND_FACES, replace=False, p=areas[drawn] / areas[drawn].sum()))
    sample = np.sort(np.concatenate(sample))
    faces_all, gaps, boxes_of = np.concatenate(chosen), np.concatenate(gaps), np.concatenate(boxes_of)
    enclosing = np.concatenate(enclosing)
    n_isl = len(keys)
    inner = np.zeros(n_isl, dtype=bool)  # the islands judged by their own inside (the rooms)
    inner[inv] = enclosing

    def island_means(geometry):
        coarse = sides_view(*geometry, faces_all[sample], gaps[sample], SIDE_RAYS, box=boxes_of[sample])
        return [np.bincount(inv[sample], weights=x, minlength=n_isl) / np.bincount(inv[sample], minlength=n_isl)
                for x in (coarse.front, coarse.back, coarse.back_other, coarse.front_in, coarse.back_in)]

    mean = island_means(geometry)
    inside_out = (np.where(inner, mean[3], mean[0]) <= SIDE_BLIND) & ((mean[2] >= ENCLOSES) | inner)
    turned, doubled, painted_away = {}, {}, {}

    def apply(mask, count, ci, sel, act):
        if mask.any():
            faces = np.zeros(len(b.e[ci]), dtype=bool)
            faces[sel[mask]] = True
            act(ci, faces)
            name = b.names[int(b.f_obj[ci][0])]
            count[name] = count.get(name, 0) + int(mask.sum())

    k = 0
    for ci, sel, isl, _ in where:  # the inside-out islands turned first: what the faces see next
        apply(inside_out[inv[k:k + len(sel)]], turned, ci, sel, b.flip_faces)
        k += len(sel)
    # 2. the faces of the open islands whose backs see the scene (as it is now), one by one
    opened_all = np.concatenate([op for *_, op in where])
    if inside_out.any():
        geometry = (np.concatenate(b.verts), np.concatenate(b.tris), geometry[2], geometry[3])
        if (opened_all & ~inside_out[inv]).any():
            mean = island_means(geometry)
    # (and the faces of a room partly turned by hand, some facing in, some out: what each sees in its box)
    partly = ~inside_out[inv] & enclosing & (mean[4][inv] >= ISLAND_SEES)
    fine = np.flatnonzero(~inside_out[inv] & opened_all & (mean[1][inv] >= ISLAND_SEES) | partly)
    if len(fine):
        rays = int(np.clip(SIDE_RAY_BUDGET // (2 * len(fine)), 4, SIDE_RAYS))
        view = sides_view(*geometry, faces_all[fine], gaps[fine], rays, seed=1, box=boxes_of[fine])
        V = geometry[0]
        offset = BACK_OFFSET * max(float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))), 1e-9)
        front_all, back_all, cast_all = np.zeros(len(faces_all)), np.zeros(len(faces_all)), np.zeros(len(faces_all), bool)
        front_all[fine] = np.where(partly[fine], view.front_in, view.front)
        back_all[fine] = np.where(partly[fine], view.back_in, view.back)
        cast_all[fine] = True
        k = 0
        for ci, sel, _, _ in where:
            front, back, cast, room = (x[k:k + len(sel)] for x in (front_all, back_all, cast_all, partly))
            k += len(sel)
            sees = cast & (back >= SIDE_SEES)
            blind = front <= SIDE_BLIND
            # a room's faces that face out while the rest face in: their fronts see nothing of its
            # inside, their backs some of it (not all: what lies within the gap of their edges does
            # not count); turned, painted or not (a closed island's inside is what the scene in it sees)
            apply(cast & room & blind & (back >= ISLAND_SEES), turned, ci, sel, b.flip_faces)
            sees &= ~room
            # both sides: the whole island's backs see the scene (a plane seen from below), not a
            # few of its faces (a staircase's landings, whose tops see the flights' backs)
            both = cast & ~blind & ~room & (mean[1][inv[k - len(sel):k]] >= ISLAND_BOTH)
            apply(sees & blind & ~b.tgt[ci][sel], turned, ci, sel, b.flip_faces)
            apply(both, doubled, ci, sel, lambda c, f: b.add_backs(c, f, offset))
            apply(sees & blind & b.tgt[ci][sel], painted_away, ci, sel, lambda c, f: None)
    out = []
    if turned:
        out.append(f"{_counted(turned)} face away from the scene (their normals point away from where the "
                   "scene sees them: a room whose normals point out of it): modelled from their other side, as "
                   "Cycles renders both sides of a face alike (Mesh > Normals > Flip makes it the mesh's own)")
    if doubled:
        out.append(f"{_counted(doubled)} are seen from both sides (single planes lit on one side, seen from the "
                   "other): their back sides are modelled as faces of their own (never targets or lights)")
    muddled -= set(turned)
    if muddled:
        out.append(f"{', '.join(repr(n) for n in sorted(muddled))}: some faces of a closed part face one way, their "
                   "neighbours the other (normals flipped by hand?), and what they see does not tell which side the "
                   "scene is on: modelled as they are; Mesh > Normals > Recalculate Outside (or Inside) makes them agree")
    if painted_away:
        out.append(f"{_counted(painted_away)} are painted but face away from the scene (their fronts see no "
                   "surface, their backs the scene): they are solved as painted on their fronts; if the paint is "
                   "meant for the side the scene sees, flip them (Edit Mode: Mesh > Normals > Flip)")
    return out


def _counted(per_object) -> str:
    """"3 face(s) of 'Room', 1 of 'Shelf' ...": counts per object, the largest first."""
    rows = sorted(per_object.items(), key=lambda kv: -kv[1])
    head = ", ".join(f"{n} of {name!r}" for name, n in rows[:5]) + (" ..." if len(rows) > 5 else "")
    return f"{sum(per_object.values())} face(s) ({head})"


def _emitting_backs(b) -> tuple:
    """Cycles' mesh emission is two-sided: the back side of an emitting face emits too (what the
    front does, or the back's bake when the material reads Backfacing). For the emitting faces of
    open islands (open_faces; the backs of closed islands face their own inside, where Cycles'
    light stays too), engine.backs.back_view tells what the back sees:

    - nothing (no front side: its light leaves the scene): nothing to do;
    - the scene, from a median distance of at least BACK_GAP x the size of its island (a plane lamp
      hanging in a room): the back becomes a face of its own (Builder.add_backs), modelled;
    - a surface closer than that (a lamp quad just under a ceiling): the light caught between
      them, which Cycles lets leak out at the edges, cannot be resolved by patches of constant
      radiosity (the surface's patches would spread the caught light over their whole area, and
      send it into the scene): not modelled, named in a warning with the light that leaks out
      into the scene (what Cycles renders more): at least the light that leaves the gap directly
      (the fraction f of the back's rays that reach the scene elsewhere than over the emitter),
      at most f (1 + rho_n) / (1 - rho_n rho_b) of the back's power after the reflections inside
      the gap (rho_n the surface's reflectance, rho_b the back's; the light reflected inside is
      more central than the emitted light, so it leaves less easily: the truth lies between).

    Returns (warnings, one dict per object whose back is against a surface: object, power (W,
    summed over the channels), leak (low, high) W, emitted (W, the scene's), distance (m), near)."""
    from ..engine.backs import back_view

    areas = [_chunk_face_areas(b, ci) for ci in range(len(b.e))]
    emitted = float(sum(float((e * a[:, None]).sum()) for e, a in zip(b.e, areas)))
    chosen, size, chunks, islands = [], [], [], {}
    for ci in range(len(b.e)):
        back = b.e[ci] if b.e_back[ci] is None else b.e_back[ci]
        if b.geos[ci] is None or not np.any(back > 0):
            continue
        geo = b.geos[ci][0]
        if id(geo) not in islands:  # instances share their mesh's arrays
            islands[id(geo)] = open_faces(geo)
        is_open, island = islands[id(geo)]
        sel = np.flatnonzero(np.any(back > 0, axis=1) & is_open)
        if not len(sel):
            continue
        island_area = np.bincount(island[sel], weights=areas[ci][sel], minlength=island.max() + 1)
        chosen.append(b.base[ci][1] + sel)
        size.append(np.sqrt(island_area[island[sel]]))
        chunks.append((ci, sel, back))
    if not chosen:
        return [], []
    chosen, size = np.concatenate(chosen), np.concatenate(size)
    geometry = (np.concatenate(b.verts), np.concatenate(b.tris), np.concatenate(b.tri_face), np.concatenate(b.f_obj))
    view = back_view(*geometry, chosen, int(np.clip(BACK_RAY_BUDGET // len(chosen), 16, BACK_RAYS)))
    modelled = (view.front > 0) & (view.distance >= BACK_GAP * size)
    against = (view.front > 0) & ~modelled
    rows = {}
    if against.any():  # the light leaving a gap is a small fraction: counted on more rays
        per = int(np.clip(LEAK_RAYS // int(against.sum()), BACK_RAYS, 16 * BACK_RAYS))
        fine = back_view(*geometry, chosen[against], per, seed=1)
        rho = np.concatenate(b.rho)
        f_obj, f_rho = geometry[3], np.clip(rho, 0.0, MAX_REFLECTANCE).mean(axis=1)
        for j, face in enumerate(chosen[against]):
            ci = int(np.searchsorted([bs[1] for bs in b.base], face, side="right") - 1)
            local = face - b.base[ci][1]
            back = b.e[ci] if b.e_back[ci] is None else b.e_back[ci]
            rays = fine.ray_face == j
            reach = rays & np.isfinite(fine.ray_length)
            f = float(np.sum(reach & ~fine.over)) / max(int(np.sum(rays)), 1)
            under = fine.ray_hit[reach & fine.over]
            rho_n = float(f_rho[under].mean()) if len(under) else 0.0
            rho_b = float(f_rho[face])
            power = float(back[local].sum() * areas[ci][local])
            row = rows.setdefault(int(f_obj[face]), {"object": b.names[int(f_obj[face])], "power": 0.0,
                                                     "leak": [0.0, 0.0], "emitted": emitted, "distance": [],
                                                     "near": set()})
            row["power"] += power
            row["leak"][0] += power * f
            row["leak"][1] += power * f * (1 + rho_n) / (1 - rho_n * rho_b)
            row["distance"].append(float(fine.distance[j]))
            row["near"].add(b.names[int(fine.object[j])] if fine.object[j] >= 0 else "?")
    V = geometry[0]
    offset = BACK_OFFSET * max(float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))), 1e-9)
    k = 0
    for ci, sel, _ in chunks:
        pick = np.zeros(len(b.e[ci]), dtype=bool)
        pick[sel[modelled[k:k + len(sel)]]] = True
        b.add_backs(ci, pick, offset)
        k += len(sel)
    out, notes = [], []
    for row in rows.values():
        row["distance"] = float(np.median(row["distance"]))
        row["near"] = sorted(row["near"])
        lo, hi = (100 * x / emitted for x in row["leak"])
        out.append(f"object {row['object']!r}: the back side of its emitting faces lies "
                   f"{1000 * row['distance']:.3g} mm from {', '.join(map(repr, row['near']))} (median): Cycles emits "
                   "from both sides of a mesh face, and "
                   f"the light caught between them is not modelled ({row['power']:.3g} W, "
                   f"{100 * row['power'] / emitted:.3g} % of the scene's emitted power); Cycles renders the scene "
                   f"brighter by what leaks out of the gap, {lo:.2g} to {hi:.2g} % of the emitted power (estimated): "
                   "give the emitter a closed shape, or move it away from the surface")
        notes.append(row)
    return out, notes


def _chunk_face_areas(b, ci) -> np.ndarray:
    """(faces,) world-space areas (m^2) of the faces of chunk ``ci`` of a Builder."""
    from ..engine.geometry import group_sum, triangle_areas

    nv0, nf0, _ = b.base[ci]
    return group_sum(b.tri_face[ci] - nf0, triangle_areas(b.verts[ci][b.tris[ci] - nv0]), len(b.e[ci]))


def _volume_output(mat) -> bool:
    """Whether the material's active output (All or Cycles) has its Volume input linked."""
    from .materials import active_output

    out = active_output(mat)
    return out is not None and "Volume" in out.inputs and any(not l.is_muted for l in out.inputs["Volume"].links)


def _not_modelled(context, objs, b, renderable) -> list:
    """Warnings naming what Cycles renders and Relight does not model: volumes (materials with a
    Volume output, volume objects; a World volume: world.py), shadow catchers and holdouts."""
    out = []
    vol = sorted(n for n, m in b.materials_used.items() if _volume_output(m))
    if vol:
        out.append(f"material(s) {', '.join(map(repr, vol))}: a volume shader is linked to the Volume output; volumes "
                   "(absorption, scattering, emission) are not modelled: Relight treats the light as passing through "
                   "and reads only the surface")
    volumes = [ob.name for ob in context.scene.objects if ob.type == "VOLUME" and rendered(ob, renderable)]
    if volumes:
        out.append(f"volume object(s) {', '.join(map(repr, volumes[:10]))}{' ...' if len(volumes) > 10 else ''}: "
                   "volumes are not modelled (Relight treats light as passing through them)")
    catchers = [ob.name for ob in objs if getattr(ob, "is_shadow_catcher", False)]
    if catchers:
        out.append(f"object(s) {', '.join(map(repr, catchers))}: Shadow Catcher (Object > Visibility) is not modelled: "
                   "Relight lights and reports them as ordinary surfaces (their material reflects and occludes)")
    holdouts = [ob.name for ob in objs if getattr(ob, "is_holdout", False)]
    if holdouts:
        out.append(f"object(s) {', '.join(map(repr, holdouts))}: Holdout (Object > Visibility) is not modelled: "
                   "Relight treats them as ordinary surfaces (their material reflects and occludes)")
    return out


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
    target, _, forbidden, lux = _base_attributes(ob, 1.0, [])
    if kind == "target":
        return target | (lux > 0)
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
