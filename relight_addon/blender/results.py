"""Engine -> Blender: Relight's results in the scene, all of them clearable exactly (bpy).

The way in is export.py. A solve's result is shown, never by cutting or re-materialising the
artist's faces, as:

- **the emitters object** ("Relight Emitters"): a new mesh object holding, for every light
  cell that emits in the configuration shown, a copy of the cell's triangles set off by
  ``OVERLAY_OFFSET`` in front of the surface it lies on. One material ("Relight Emitter"): a
  Lambertian surface of the cell's reflectance (face attribute ``relight_reflectance``, so it
  reflects as the engine modelled it) plus a one-sided emission of radiance exitance/pi (face
  attribute ``relight_emission``). So the result lights exactly the cells the report lists,
  whatever their size against the artist's polygons.
- **the radiosity layer** ``relight_radiosity`` on the artist's meshes (radiance B/pi per
  corner; the previous active and render colours are remembered and given back);
- in direct-lighting mode ("reduce"), the scene's own emitter faces switched to an emission-free
  copy of their material (``suppress_emission``; restored exactly by ``clear_suppression``), and
  its lamps set: a kept lamp's Power (a Sun's Strength) and colour, the others disabled for
  render and in the viewports (``plan_lamps``; restored exactly by lamp_state.restore);
- the lamps a solve placed (Spot, Area and Point lamps chosen among the candidates) as new Light
  objects with the solved Power, colour, cone, blend, size and orientation, in the collection
  "Relight Lamps" (``plan_placed``, ``write_placed``): Relight's own, removed by Clear and
  replaced when another configuration is shown (Make Area Lights copies them for keeps, then
  removes them and the emitters object: ``make_area_lights``); the export does not count them as
  the scene's light;
- the stored curve (scene property ``relight_result``) and the chart image.

Everything Relight creates carries ``relight_owner`` = the result's id (scene property
``relight_result_id``): Clear Results removes exactly that, by identity, never by name. Area
lights made by Make Area Lights are the artist's to keep (Clear leaves them).

Before writing anything, ``apply_stored_point`` checks the whole configuration: the stored
result decodes, every object it names exists and is unchanged since the solve (its mesh
fingerprint: topology and world-space positions within tolerance); on any failure nothing is
written and the message names the object.
"""
from __future__ import annotations

import math
import os
import uuid
import warnings as _warnings

import bpy
import numpy as np

from ..engine.geometry import group_mean
from ..engine.light_colour import blackbody_rec709, temperature_of
from ..engine.scene import SceneError
from ..engine import lights  # noqa: F401  (registers the light kinds)
from ..engine.registry import LIGHT_KINDS
from ..engine.units import TINY, radiance_from_exitance
from ..pipeline.files import atomic_output
from ..pipeline.stored import StoredResult
from . import lamp_state
from .ies_nodes import write_ies
from .lamps import cycles_gain, lamp_kind, make_plain
from .layers import DISPLAY_ATTRIBUTE, RADIOSITY_ATTRIBUTE
from .meshes import fingerprint_change, foreach_array, loop_polygons
from .visibility import RELIGHT_NAME_PROP, RELIGHT_OWNER_PROP, owner_of, tag_owned

EMISSION_ATTRIBUTE = "relight_emission"
REFLECTANCE_ATTRIBUTE = "relight_reflectance"
ORIGINAL_INDEX_ATTRIBUTE = "relight_original_material"
ORIGINAL_SLOTS_PROP = "relight_original_slots"
HAD_INDEX_PROP = "relight_had_material_index"
GENERATED_PROP = "relight_generated"
AREA_LIGHTS_PROP = "relight_area_lights"
RESULT_PROP = "relight_result"
RESULT_ID_PROP = "relight_result_id"
EMITTERS_NAME = "Relight Emitters"
EMITTER_MATERIAL = "Relight Emitter"
#: the emitters object is set off the surface by this fraction of the scene's size (``overlay_offset``):
#: far enough for the viewport's depth buffer, negligible for the light transport, at any scale
OVERLAY_OFFSET = 2e-4
CHART_IMAGE = ".relight_error_curve"
#: the pictures --render writes, by the extension of its path (Blender's image formats)
RENDER_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".exr": "OPEN_EXR", ".tif": "TIFF",
                  ".tiff": "TIFF", ".bmp": "BMP"}


class StaleResult(SceneError):
    """The stored result no longer matches the scene; nothing was written."""


def _use_nodes(mat):
    """Node materials are the only kind from Blender 5.0; older versions need the switch."""
    if bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        mat.use_nodes = True


def _owned(idblock, rid) -> bool:
    return rid is not None and owner_of(idblock) == rid


# --- the stored curve ----------------------------------------------------------------------

_cache = {}


def result_id(scene):
    return scene.get(RESULT_ID_PROP)


def load_result(scene) -> StoredResult:

    text = scene.get(RESULT_PROP)
    if not text:
        raise KeyError("no Relight result in this scene: run Solve & Reduce first")
    key = (scene.name, hash(text))
    if key not in _cache:
        _cache.clear()
        try:
            _cache[key] = StoredResult.unpack(text)
        except Exception as exc:  # zlib, base64, npz or format errors: one clear line
            raise SceneError(f"the stored Relight result of scene {scene.name!r} cannot be read "
                             f"({type(exc).__name__}); run Solve & Reduce again") from None
    return _cache[key]


def _stored_data(outcome, fingerprints=None) -> StoredResult:
    """The outcome's stored curve, with the meshes' fingerprints and what the Results panel shows
    of the solve (its summary, warnings and the scene light kept: a file solved by the CLI shows
    them too)."""
    from ..pipeline.report import fixed_light_rows, light_rows, photometric_rows, summary_line

    data = outcome.stored.with_fingerprints(fingerprints)
    data.meta.update(summary=summary_line(outcome.report, len(outcome.curve)),
                     warnings=list(outcome.report.get("warnings") or []),
                     fixed_light=fixed_light_rows(outcome.report), photometric=photometric_rows(outcome.report),
                     lights=light_rows(outcome.report))
    return data


def packed_result(outcome, fingerprints=None) -> tuple:
    """(StoredResult, its text, what load_result reads of it): the outcome's curve packed (no bpy:
    any thread; Live's worker packs a stroke's answer, the main thread then only writes it).
    ValueError on non-finite values."""
    data = _stored_data(outcome, fingerprints)
    return (data, *data.pack_and_view())


def store_result(scene, text, view=None) -> str:
    """Keep the whole curve in the scene (stored.StoredResult's packed ``text``) so any point can be
    re-applied; returns the result's new id. ``view``: what load_result reads of it (as_stored),
    when the caller has it."""
    rid = uuid.uuid4().hex
    scene[RESULT_PROP] = text
    scene[RESULT_ID_PROP] = rid
    _cache.clear()
    if view is not None:
        _cache[(scene.name, hash(text))] = view
    return rid


def show_outcome(scene, outcome, fingerprints=None, trusted=False, packed=None) -> dict:
    """Replace any previous result by this solve's: store its curve, show its final configuration.
    All-or-nothing: the new result is packed (finite values) and checked against the scene (every
    object present and unchanged since the export) before the previous one is touched; should
    showing still fail, the new result is cleared and the error raised. ``trusted``: the caller
    has checked that the meshes are the exported ones (Live mode, on its own digest of them):
    their fingerprints are not evaluated again. ``packed``: packed_result's, made by the caller."""
    data, text, view = packed_result(outcome, fingerprints) if packed is None else packed
    check_stored(scene, data, trusted)  # StaleResult when the scene changed during the solve: nothing changed yet
    clear_results(scene)
    store_result(scene, text, view)
    try:  # (the meshes checked above, the fingerprints not evaluated twice: 0.4 s at a million triangles)
        return apply_stored_point(scene, outcome.final_index, trusted=True)
    except BaseException:
        clear_results(scene)
        raise


# --- checking before writing -----------------------------------------------------------------

def _objects_of(scene, data):
    """{object index: bpy object} of the stored objects present in the scene (real objects only:
    instance groups have no polygons)."""
    out = {}
    off = data.polygon_offset
    for oi, name in enumerate(data.objects):
        if off[oi + 1] == off[oi]:
            continue
        ob = scene.objects.get(name)
        if ob is None or ob.type != "MESH":
            raise StaleResult(f"object {name!r} of the stored result is no longer in the scene: solve again")
        out[oi] = ob
    return out


def check_stored(scene, data, trusted=False):
    """Validate the stored result against the scene: every object present and unchanged (its
    polygon count; its fingerprint unless ``trusted``: show_outcome's)."""
    objs = _objects_of(scene, data)
    fps = {} if trusted else data.meta.get("fingerprints", {})
    for oi, ob in objs.items():
        fp = fps.get(ob.name)
        n = int(data.polygon_offset[oi + 1] - data.polygon_offset[oi])
        if len(ob.data.polygons) != n:
            raise StaleResult(f"{ob.name} has changed since the solve ({len(ob.data.polygons)} polygons, "
                              f"{n} when solved): nothing applied; solve again")
        if fp is not None:
            why = fingerprint_change(ob, fp)
            if why:
                raise StaleResult(f"{ob.name} has changed since the solve ({why}): nothing applied; solve again")
    return objs


# --- the emitters object -----------------------------------------------------------------------

def _emitter_material(rid):
    mat = bpy.data.materials.new(EMITTER_MATERIAL)
    tag_owned(mat, rid)
    _use_nodes(mat)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    for name, value in (("Roughness", 1.0), ("Specular IOR Level", 0.0), ("Emission Strength", 1.0)):
        if name in bsdf.inputs:
            bsdf.inputs[name].default_value = value
    refl = nt.nodes.new("ShaderNodeAttribute")
    refl.attribute_type = "GEOMETRY"
    refl.attribute_name = REFLECTANCE_ATTRIBUTE
    emit = nt.nodes.new("ShaderNodeAttribute")
    emit.attribute_type = "GEOMETRY"
    emit.attribute_name = EMISSION_ATTRIBUTE
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    front = nt.nodes.new("ShaderNodeMath")
    front.operation = "SUBTRACT"
    front.inputs[0].default_value = 1.0
    nt.links.new(geo.outputs["Backfacing"], front.inputs[1])
    nt.links.new(refl.outputs["Color"], bsdf.inputs["Base Color"])
    nt.links.new(emit.outputs["Color"], bsdf.inputs["Emission Color"])
    nt.links.new(front.outputs["Value"], bsdf.inputs["Emission Strength"])
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    for k, node in enumerate((refl, emit, geo, front)):
        node.location = (-600, 300 - 160 * k)
    out.location = (300, 0)
    mat.diffuse_color = (1.0, 0.9, 0.5, 1.0)
    cyc = getattr(mat, "cycles", None)
    if cyc is not None and hasattr(cyc, "emission_sampling"):
        # the emission is front-only and read from an attribute: tell Cycles to sample it as a
        # light from the front (Auto cannot estimate attribute-driven emission well)
        cyc.emission_sampling = "FRONT"
    return mat


def overlay_offset(scale, points) -> float:
    """How far (m) in front of its surface an emitter is set: OVERLAY_OFFSET of the scene's size
    ``scale`` (m), and never below what float32 coordinates of ``points`` can resolve."""
    far = float(np.abs(np.asarray(points, dtype=np.float64)).max()) if np.size(points) else 0.0
    return max(OVERLAY_OFFSET * float(scale), 64 * float(np.finfo(np.float32).eps) * far, 1e-12)


def _emitter_mesh_data(data, exitance, scale):
    """Triangles (n, 3, 3), per-triangle radiance, reflectance and cell of the cells that emit
    in configuration ``exitance`` (n_lights, 3); cells with a negative net exitance are not shown."""
    cell_e = data.light_basis() @ exitance
    lit = np.any(cell_e > 0, axis=1) & ~np.any(cell_e < 0, axis=1)
    tc = data.cell_triangle_cell
    sel = lit[tc]
    tri = data.cell_triangles[sel].astype(np.float64)
    cell = tc[sel]
    offset = overlay_offset(scale, data.cell_triangles)
    tri = tri + offset * data.cell_normal[cell][:, None, :]
    return tri, radiance_from_exitance(cell_e[cell]), data.cell_reflectance[cell], cell, int(np.sum(np.any(cell_e < 0, axis=1)))


def _build_emitters(scene, rid, tri, radiance, reflectance, radiosity, cell):
    """The emitters object: one triangle per row of ``tri`` (face attribute ``relight_cell``: the
    light cell it belongs to); returns the object (None if empty)."""
    if not len(tri):
        return None
    n = len(tri)
    me = bpy.data.meshes.new(EMITTERS_NAME)
    tag_owned(me, rid)
    me.vertices.add(3 * n)
    me.vertices.foreach_set("co", tri.reshape(-1).astype(np.float32))
    me.loops.add(3 * n)
    me.loops.foreach_set("vertex_index", np.arange(3 * n, dtype=np.int32))
    me.polygons.add(n)
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * n, 3, dtype=np.int32))
    if hasattr(me.polygons[0], "loop_total") and bpy.app.version < (4, 0, 0):
        me.polygons.foreach_set("loop_total", np.full(n, 3, dtype=np.int32))
    me.update(calc_edges=True)
    for name, values in ((EMISSION_ATTRIBUTE, radiance), (REFLECTANCE_ATTRIBUTE, reflectance)):
        a = me.attributes.new(name, "FLOAT_COLOR", "FACE")
        rgba = np.ones((n, 4), dtype=np.float32)
        rgba[:, :3] = values
        a.data.foreach_set("color", rgba.ravel())
    me.attributes.new("relight_cell", "INT", "FACE").data.foreach_set("value", np.asarray(cell, dtype=np.int32))
    rad = me.color_attributes.new(RADIOSITY_ATTRIBUTE, "FLOAT_COLOR", "CORNER")
    rgba = np.ones((3 * n, 4), dtype=np.float32)
    rgba[:, :3] = np.repeat(radiance_from_exitance(radiosity), 3, axis=0)
    rad.data.foreach_set("color", rgba.ravel())
    me.color_attributes.active_color = rad
    me.materials.append(_emitter_material(rid))
    me.update()
    ob = bpy.data.objects.new(EMITTERS_NAME, me)
    tag_owned(ob, rid)
    ob.hide_select = False
    scene.collection.objects.link(ob)
    return ob


def _remove_emitters(rid):
    for ob in [o for o in bpy.data.objects if o.type == "MESH" and _owned(o, rid)]:
        me = ob.data
        mats = [m for m in me.materials if m is not None and _owned(m, rid)]
        bpy.data.objects.remove(ob)
        if me.users == 0:
            bpy.data.meshes.remove(me)
        for m in mats:
            if m.users == 0:
                bpy.data.materials.remove(m)
    for m in [m for m in bpy.data.materials if _owned(m, rid) and m.users == 0]:
        bpy.data.materials.remove(m)


def emitters_object(scene):
    rid = result_id(scene)
    if rid is None:
        return None
    return next((o for o in scene.objects if o.type == "MESH" and _owned(o, rid)), None)


# --- direct-lighting mode: the scene's own emitters switched off --------------------------------

def _dark_variant(source, rid):
    """A copy of material ``source`` with its own emission set to 0 (direct-lighting mode: the
    scene's emitter faces stop emitting; the emitters object shows what the reduction kept)."""
    mat = source.copy()
    mat.name = f"{source.name} (Relight, off)"
    mat[GENERATED_PROP] = True
    tag_owned(mat, rid)
    mat["relight_source"] = source.name
    _use_nodes(mat)
    nt = mat.node_tree
    for node in nt.nodes:
        if node.type == "BSDF_PRINCIPLED" and "Emission Strength" in node.inputs:
            sock = node.inputs["Emission Strength"]
            for link in list(sock.links):
                nt.links.remove(link)
            sock.default_value = 0.0
        elif node.type == "EMISSION":
            for link in list(node.inputs["Strength"].links):
                nt.links.remove(link)
            node.inputs["Strength"].default_value = 0.0
    return mat


def suppress_emission(obj, polygons, rid, variants) -> int:
    """Switch polygons ``polygons`` of ``obj`` to emission-free copies of their materials, keeping
    everything needed to restore them (``clear_suppression``)."""
    polygons = np.unique(np.asarray(polygons, dtype=np.int64))
    mesh = obj.data
    if not len(polygons) or mesh.library is not None:
        return 0
    n_poly = len(mesh.polygons)
    orig = foreach_array(mesh.polygons, "material_index", n_poly, np.int32)
    n_slots = len(mesh.materials)
    if n_slots == 0:
        return 0  # no material: nothing emits
    mesh[ORIGINAL_SLOTS_PROP] = n_slots
    mesh[HAD_INDEX_PROP] = "material_index" in mesh.attributes
    keep = mesh.attributes.new(ORIGINAL_INDEX_ATTRIBUTE, "INT", "FACE")
    keep.data.foreach_set("value", orig)
    new_index = orig.copy()
    slot_of = {}
    for p in polygons:
        s = int(orig[p])
        src = mesh.materials[s] if 0 <= s < n_slots else None
        if src is None:
            continue
        if s not in slot_of:
            if src.name not in variants:
                variants[src.name] = _dark_variant(src, rid)
            mesh.materials.append(variants[src.name])
            slot_of[s] = len(mesh.materials) - 1
        new_index[p] = slot_of[s]
    mesh.polygons.foreach_set("material_index", new_index)
    mesh.update()
    return len(polygons)


def clear_suppression(obj) -> bool:
    """Restore ``obj``'s mesh exactly as it was before ``suppress_emission``."""
    mesh = obj.data
    if ORIGINAL_SLOTS_PROP not in mesh.keys():
        return False
    n_orig = int(mesh[ORIGINAL_SLOTS_PROP])
    attr = mesh.attributes.get(ORIGINAL_INDEX_ATTRIBUTE)
    if attr is not None:
        idx = np.empty(len(mesh.polygons), dtype=np.int32)
        attr.data.foreach_get("value", idx)
        mesh.polygons.foreach_set("material_index", idx)
        mesh.attributes.remove(mesh.attributes[ORIGINAL_INDEX_ATTRIBUTE])
        if not mesh.get(HAD_INDEX_PROP, True) and "material_index" in mesh.attributes:
            mesh.attributes.remove(mesh.attributes["material_index"])
    generated = []
    while len(mesh.materials) > n_orig:
        mat = mesh.materials.pop(index=len(mesh.materials) - 1)
        if mat is not None and mat.get(GENERATED_PROP):
            generated.append(mat)
    del mesh[ORIGINAL_SLOTS_PROP]
    if HAD_INDEX_PROP in mesh.keys():
        del mesh[HAD_INDEX_PROP]
    for mat in generated:
        if mat.users == 0:
            bpy.data.materials.remove(mat)
    mesh.update()
    return True


# --- apply, clear ------------------------------------------------------------------------------

def polygon_rows(data, values):
    """Per-patch ``values`` (P, 3) -> per global polygon (n_polygons, 3), the stored area weights."""
    return np.asarray(data.polygon_weight_matrix() @ values)


#: the light kinds' writers (engine.lights.LightKind.writer) this layer has: "surface" lights are
#: shown as their emitting cells in the emitters object, and made into one area light per cell by
#: make_area_lights; "lamp" lights (direct mode: the scene's own lamps) by the lamps themselves, their
#: Power and colour set or the lamp disabled, restorably (``plan_lamps``, lamp_state.py); "placed"
#: lights (the Spot, Area and Point lamps a solve placed) as new Light objects in a collection
#: Relight owns (``plan_placed``, ``write_placed``), converted for keeps by make_area_lights. A new
#: writer is a function here and its name in this tuple.
WRITERS = ("surface", "lamp", "placed")
#: the collection of the lamps a solve placed (owned: Clear removes it, by identity)
PLACED_COLLECTION = "Relight Lamps"


def _lights_of_writer(data, writer) -> np.ndarray:
    """Indices of the stored lights whose kind is written by ``writer``."""
    names = LIGHT_KINDS.names()
    kinds = np.asarray(data.light_kind, dtype=np.int64)
    return np.array([j for j, code in enumerate(kinds) if 0 <= code < len(names)
                     and LIGHT_KINDS[names[code]].impl.writer == writer], dtype=np.int64)


#: whether this Blender's Lights have a Temperature (4.5 on; 4.2 has not: a blackbody lamp's colour
#: is then its colour alone)
HAS_TEMPERATURE = "use_temperature" in bpy.types.Light.bl_rna.properties


def plan_placed(data, strength) -> list:
    """The placed writer's plan for configuration ``strength`` (n_lights, 3), computed and checked
    before anything is written: per placed lamp that is on, (its stored record, Blender's Power
    (W) and colour: Power x colour = its power per channel; engine.lights.lamp.blender_values)."""
    from ..engine.lights.lamp import blender_values

    plan = []
    colour = data.meta.get("light_colour") or {}
    for j in _lights_of_writer(data, "placed"):
        s = np.asarray(strength[j], dtype=np.float64)
        if not np.any(s > 0):
            continue
        rec = dict(data.lamps[int(data.light_lamp[j])], kind=LIGHT_KINDS.names()[int(data.light_kind[j])])
        gain = np.asarray(rec.get("gain", np.ones(3)), dtype=np.float64)  # (a fixture's: its IES node's flux)
        if colour.get("mode") == "blackbody" and HAS_TEMPERATURE:  # the Light's Temperature carries its colour
            t = float(temperature_of(s[None, :], *colour["range_K"])[0])
            rec, gain = dict(rec, temperature_K=t), blackbody_rec709(t) * gain
        energy, color = blender_values(s, rec["energy"], rec["color"], gain)
        values = np.concatenate([[energy], color, rec["position"], rec["direction"], rec["axis_u"], rec["axis_v"]])
        if not np.all(np.isfinite(values)):
            raise SceneError(f"lamp {rec['name']!r} of the stored result has non-finite values: solve again")
        plan.append((rec, float(energy), color))
    return plan


def new_lamp(rec, energy, color, owner=None):
    """A new Light object (not linked) of a lamp record (a lamp kind's ``record``, engine/lights/kind.py;
    pipeline.kept's): its type, Power and colour, its kind's own settings (``LampKind.blender_light``:
    a spot's Spot Size and Blend, a radius, an area lamp's shape, sizes and Spread; its ``kind``, the
    lamp kind's name, where the record gives one, else the kind of its Blender type), its
    Temperature (a blackbody light's ``temperature_K``, where this Blender has Use Temperature), and
    its frame (X = axis_u, Y = axis_v, -Z = direction) at its position; ``owner``: Relight's owner id."""
    from mathutils import Matrix

    ld = bpy.data.lights.new(rec["name"], rec["type"])
    make_plain(ld)  # Cycles emits colour x Power
    if rec.get("temperature_K") is not None and HAS_TEMPERATURE:  # ... x its blackbody colour (a blackbody light)
        ld.use_temperature = True
        ld.temperature = float(rec["temperature_K"])
    ld.energy = float(energy)
    ld.color = tuple(float(x) for x in color)
    kind = LIGHT_KINDS[rec["kind"]].impl if "kind" in rec else lamp_kind(ld)
    for attribute, value in kind.blender_light(rec).items():  # its kind's own settings
        setattr(ld, attribute, value)
    ies = kind.blender_ies(rec)
    if ies is not None:  # an IES Texture node holding its LM-63 as an internal text (saved in the .blend)
        write_ies(ld, *ies, owner=owner)
    ob = bpy.data.objects.new(rec["name"], ld)
    M = np.eye(4)
    M[:3, 0], M[:3, 1] = rec["axis_u"], rec["axis_v"]
    M[:3, 2], M[:3, 3] = -np.asarray(rec["direction"]), rec["position"]
    ob.matrix_world = Matrix(M.tolist())
    if owner is not None:
        tag_owned(ld, owner)
        tag_owned(ob, owner)
    return ob


def add_kept_lamps(scene, records) -> list:
    """Kept lamps (pipeline.kept's records) made the scene's own lamps, in its collection: the
    solve counts their light as the scene's, and no result removes them. Returns their names."""
    names = []
    for rec in records:
        ob = new_lamp(rec, rec["energy"], rec["color"])
        scene.collection.objects.link(ob)
        names.append(ob.name)
    return names


#: on a placed lamp: the name of the stored lamp record it shows (its object may be named otherwise)
PLACED_LAMP_PROP = "relight_lamp"
#: on a kept lamp: {"result": the result's id, "lamp": its record's name, "name": the kept object's name}
KEPT_PROP = "relight_kept"


def write_placed(scene, rid, plan) -> None:
    """Write ``plan_placed``'s plan: the lamps, owned by the result ``rid``, in a collection of their own."""
    if not plan:
        return
    coll = bpy.data.collections.new(PLACED_COLLECTION)
    tag_owned(coll, rid)
    scene.collection.children.link(coll)
    for rec, energy, color in plan:
        ob = new_lamp(rec, energy, color, owner=rid)
        ob[PLACED_LAMP_PROP] = rec["name"]
        coll.objects.link(ob)


def _disown(*idbs) -> None:
    """The artist's from now on: Relight's owner marks removed (no result removes it)."""
    for idb in idbs:
        for prop in (RELIGHT_OWNER_PROP, RELIGHT_NAME_PROP, PLACED_LAMP_PROP):
            if prop in idb:
                del idb[prop]


def kept_twins(scene, rid) -> dict:
    """{record name: kept object} of the lamps of result ``rid`` kept by Keep Lamps (``keep_placed``)
    still in the scene under the name they were kept with (a copy or a renamed one is the artist's
    like any other lamp)."""
    out = {}
    for ob in scene.objects:
        mark = ob.get(KEPT_PROP) if ob.type == "LIGHT" else None
        if mark is not None and rid is not None and mark.get("result") == rid and mark.get("name") == ob.name:
            out[str(mark.get("lamp"))] = ob
    return out


def without_kept(scene, rid, plan) -> tuple:
    """(plan, notes): ``plan_placed``'s plan without the lamps a kept twin stands for (issue 35,
    case 5: Keep Lamps then the same row clicked again recreated every lamp beside its kept twin,
    twice the light). A kept lamp is the scene's from then on: it is never placed again; where it
    differs from the row (another Power, colour, place, or off in this row) a note names it, since
    the row's prediction then does not hold for the scene as it is."""
    kept = kept_twins(scene, rid)
    if not kept:
        return plan, []
    out, notes, seen = [], [], set()
    for rec, energy, color in plan:
        ob = kept.get(rec["name"])
        if ob is None:
            out.append((rec, energy, color))
            continue
        seen.add(rec["name"])
        ld, M = ob.data, lamp_state.world_matrix(ob)
        same = (ld.type == rec["type"] and np.isclose(ld.energy, energy, rtol=1e-5, atol=1e-9)
                and np.allclose(np.array(ld.color)[:3], color, rtol=1e-5, atol=1e-6)
                and np.allclose(M[:3, 3], rec["position"], atol=1e-6)
                and np.allclose(-M[:3, 2] / max(float(np.linalg.norm(M[:3, 2])), TINY), rec["direction"], atol=1e-6))
        if not same:
            notes.append(f"lamp {rec['name']!r} is kept as {ob.name!r}, which differs from this configuration's "
                         f"(Power {ld.energy:.4g} W, {energy:.4g} W here, or moved): it is not placed again, and "
                         "the prediction holds only after Solve & Reduce")
    for name, ob in kept.items():
        if name not in seen:
            notes.append(f"lamp {name!r} is kept as {ob.name!r} and lights the scene, though this configuration has "
                         "it off: the prediction holds only after Solve & Reduce")
    return out, notes


def keep_placed(scene) -> list:
    """The lamps the shown result placed made the scene's own (issue 20, item 3): untagged (no
    result removes them), named "<name> (kept)", in the scene's collection. The next solve counts
    their light as the scene's and finds Max Lights more around them (pipeline/kept.py). Returns
    their names; nothing placed: SceneError."""
    from ..pipeline.kept import KEPT_SUFFIX

    rid = result_id(scene)
    obs = [o for o in scene.objects if o.type == "LIGHT" and _owned(o, rid)]
    if not obs:
        raise SceneError("the shown configuration has no placed lamp to keep (its lights are emissive cells, "
                         "Make Area Lights made them yours, or nothing is solved yet)")
    names = []
    for ob in obs:
        lamp = ob.get(PLACED_LAMP_PROP, ob.name)
        _disown(ob, ob.data)
        ob.name = ob.name + KEPT_SUFFIX
        ob[KEPT_PROP] = {"result": rid, "lamp": lamp, "name": ob.name}  # its row shows it, never a twin
        if ob.name not in scene.collection.objects:
            scene.collection.objects.link(ob)
        for coll in list(ob.users_collection):
            if coll is not scene.collection and owner_of(coll) is not None:
                coll.objects.unlink(ob)
        names.append(ob.name)
    return names


def _remove_objects(obs, data_ours=lambda d: True) -> int:
    """Remove objects ``obs`` (Relight's) and their data that ``data_ours`` says is Relight's too, when
    no user is left (a Shift-D copy has its own data; an Alt-D copy shares it, and then the data stays
    with it)."""
    for ob in obs:
        d = ob.data
        bpy.data.objects.remove(ob)
        if d is not None and d.users == 0 and not d.use_fake_user and data_ours(d):
            getattr(bpy.data, {"LIGHT": "lights", "MESH": "meshes"}[d.id_type]).remove(d)
    return len(obs)


def empty_collection(coll, ours) -> bool:
    """Ownership of a collection's *contents*, checked before any removal (issue 35): remove the
    objects of ``coll`` that ``ours(object)`` says Relight made, then the collection itself only if
    nothing else is left in it. What the artist put there (a lamp of their own, a Shift-D copy of
    Relight's, a Relight lamp they renamed: visibility.owner_of) stays, and so does the collection, then
    theirs (its owner marks removed). Returns True when the collection was removed."""
    _remove_objects([o for o in coll.objects if ours(o)])
    if len(coll.objects) or len(coll.children):
        for prop in (RELIGHT_OWNER_PROP, RELIGHT_NAME_PROP):
            if prop in coll:
                del coll[prop]
        return False
    bpy.data.collections.remove(coll)
    return True


def _remove_placed(rid) -> int:
    """Remove the lamps (objects, their Light data) that result ``rid`` placed, and its collection
    unless the artist's objects are in it (``empty_collection``)."""
    n = _remove_objects([o for o in bpy.data.objects if o.type == "LIGHT" and _owned(o, rid)], lambda d: _owned(d, rid))
    for text in [t for t in bpy.data.texts if _owned(t, rid) and t.users == 0]:  # a placed fixture's LM-63
        bpy.data.texts.remove(text)
    for coll in [c for c in bpy.data.collections if _owned(c, rid)]:
        empty_collection(coll, lambda o: False)
    return n


def plan_lamps(scene, data, strength) -> tuple:
    """The lamp writer's plan for configuration ``strength`` (n_lights, 3), computed and checked
    before anything is written: [(object, (Power, colour) or None = disable)] and messages about
    lamps that cannot be written (linked from a library). StaleResult when a stored lamp is no
    longer in the scene or changed since the solve (its type, position, direction, or what it
    emits: its Power, colour, Exposure, Temperature, Normalize as the user set them). A kept lamp's
    Power and colour make Cycles emit the solved power through its own Exposure, Temperature and
    Normalize (blender/lamps.cycles_gain); SceneError when they cannot (a channel its Temperature's
    colour lacks)."""
    from ..engine.lights.lamp import blender_values

    plan, skipped = [], []
    light_lamp = np.asarray(data.light_lamp if data.light_lamp is not None else [], dtype=np.int64)
    own = _lights_of_writer(data, "lamp") if len(light_lamp) else np.zeros(0, dtype=np.int64)
    own = own[light_lamp[own] >= 0]
    if len(own):
        bpy.context.evaluated_depsgraph_get()  # the enabled lamps' matrix_world up to date (one just re-enabled)
    for j in own:
        rec = data.lamps[int(light_lamp[j])]
        name = rec["name"]
        ob = scene.objects.get(name)
        if ob is None or ob.type != "LIGHT":
            raise StaleResult(f"lamp {name!r} of the stored result is no longer in the scene: solve again")
        was = lamp_state.before(ob)
        ld = ob.data if was is None else was["data"]
        energy = float(ld.energy if was is None else was["energy"])
        color = np.array(ld.color if was is None else was["color"], dtype=np.float64)[:3]
        M = lamp_state.world_matrix(ob)
        direction = -M[:3, 2] / max(float(np.linalg.norm(M[:3, 2])), TINY)
        gain = cycles_gain(ld, M)  # (Relight changes only a lamp's Power and colour: its Exposure etc. are the user's)
        why = None
        if ld.type != rec["type"]:
            why = f"a {ld.type} lamp, {rec['type']} when solved"
        elif ob.hide_render if was is None else was["hide_render"]:
            why = "it is disabled in renders"
        elif not np.allclose(color * energy * gain, rec["power"], rtol=1e-5, atol=1e-9):
            why = f"it emits {np.round(color * energy * gain, 4).tolist()} (Power {energy:g}, colour " \
                  f"{np.round(color, 4).tolist()}, its Exposure, Temperature and Normalize), " \
                  f"{np.round(rec['power'], 4).tolist()} when solved"
        elif not (np.allclose(M[:3, 3], rec["position"], rtol=1e-6, atol=1e-6)
                  and np.allclose(direction, rec["direction"], atol=1e-6)):
            why = "it moved or turned"
        if why:
            raise StaleResult(f"lamp {name!r} has changed since the solve ({why}): nothing applied; solve again")
        if ob.library is not None or ld.library is not None:
            skipped.append(f"lamp {name!r} is linked from a library (read-only): it renders as it is, not as this "
                           "configuration sets it; make it local to see the reduction")
            continue
        s = np.asarray(strength[j], dtype=np.float64)
        lamp_state.check_not_animated(ob, power=bool(np.any(s > 0)))  # a driver or keyframes would override it
        try:
            plan.append((ob, blender_values(s, rec["energy"], rec["color"], gain) if np.any(s > 0) else None))
        except ValueError as e:
            raise SceneError(f"lamp {name!r}: {e}; Relight sets only its Power and colour: turn its Temperature "
                             "off (or raise it) and solve again") from None
    return plan, skipped


def write_lamps(plan, rid) -> None:
    """Write ``plan_lamps``' plan: a kept lamp's Power and colour, the others disabled."""
    for ob, values in plan:
        if values is None:
            lamp_state.disable(ob, rid)
        else:
            lamp_state.set_power(ob, rid, *values)


def check_writers(data) -> None:
    """SceneError, before anything is written, when the stored lights include a kind this version
    cannot show (a code it does not know, or a kind whose writer it lacks)."""
    names = LIGHT_KINDS.names()
    for code in np.unique(np.asarray(data.light_kind, dtype=np.int64)):
        kind = names[code] if 0 <= code < len(names) else None
        if kind is None or LIGHT_KINDS[kind].impl.writer not in WRITERS:
            raise SceneError(f"the stored Relight result holds lights of a kind this version cannot show "
                             f"({kind if kind is not None else f'code {code}'}); run Solve & Reduce again")


def apply_stored_point(scene, index, trusted=False) -> dict:
    """Show configuration ``index`` of the stored curve: the emitters object (cells with a positive
    exitance: a material cannot emit negative light), the radiosity layer, and in direct-lighting
    mode the scene's emitters switched off and its lamps set (the kept ones' Power and colour,
    the others disabled). Everything is checked before anything is written.
    Returns {"lights": lights shown, "negative": lights with a negative exitance, not shown,
    "skipped": [messages about objects that could not take the radiosity layer]}."""
    data = load_result(scene)
    rid = result_id(scene) or uuid.uuid4().hex
    n_points = len(data.n_lights)
    if not 0 <= int(index) < n_points:
        raise ValueError(f"configuration {index} does not exist (0..{n_points - 1})")
    index = int(index)
    objs = check_stored(scene, data, trusted)
    check_writers(data)
    exitance = data.exitance[index].astype(np.float64)
    if not (np.all(np.isfinite(exitance)) and np.all(np.isfinite(data.radiosity[index]))):
        raise SceneError("the stored result holds non-finite values: solve again")
    # everything computed before anything is written
    scale = float(np.ptp(data.cell_triangles.reshape(-1, 3), axis=0).max()) if len(data.cell_triangles) else 1.0
    tri, radiance, reflectance, cell, n_neg_cells = _emitter_mesh_data(data, exitance, scale)
    patch_b = data.radiosity[index].astype(np.float64)
    cell_b = patch_b[data.cell_patch][cell]
    poly_b = polygon_rows(data, patch_b)
    off = data.polygon_offset
    layers, skipped = _radiosity_layers(objs, poly_b, off)
    suppress = _emission_to_suppress(data, objs, off, skipped) if data.meta.get("command") == "reduce" else []
    lamp_plan, lamp_skipped = plan_lamps(scene, data, exitance)
    skipped.extend(lamp_skipped)
    placed, kept_notes = without_kept(scene, rid, plan_placed(data, exitance))
    skipped.extend(kept_notes)
    # write
    clear_shown(scene)
    if rid != result_id(scene):
        scene[RESULT_ID_PROP] = rid
    _build_emitters(scene, rid, tri, radiance, reflectance, cell_b, cell)
    for ob, values in layers:
        write_radiosity_layer(ob, values)
    variants = {}
    for ob, polys in suppress:
        suppress_emission(ob, polys, rid, variants)
    write_lamps(lamp_plan, rid)
    write_placed(scene, rid, placed)
    scene["relight_shown"] = index
    neg = np.any(exitance < 0, axis=1)
    lit = np.any(exitance > 0, axis=1) & ~neg
    rows = data.meta.get("rows") or []  # what the Results panel lists for this row (results written before: none)
    return {"lights": int(lit.sum()), "negative": int(neg.sum()), "negative_cells": n_neg_cells, "skipped": skipped,
            "panel": rows[index] if index < len(rows) else None}


def _radiosity_layers(objs, poly_b, off) -> tuple:
    """([(object, its polygons' radiosity)] to write, [messages]): one layer per mesh (objects sharing
    a mesh named, one line per mesh), linked objects skipped."""
    layers, skipped, seen_mesh, sharing = [], [], {}, {}
    for oi, ob in objs.items():
        why = linked_message(ob)
        if why:
            skipped.append(why)
            continue
        if ob.data.name in seen_mesh:
            sharing.setdefault(seen_mesh[ob.data.name], []).append(ob.name)
            continue
        seen_mesh[ob.data.name] = ob.name
        layers.append((ob, poly_b[off[oi]:off[oi + 1]]))
    for first, others in sharing.items():  # one line per shared mesh, not one per duplicate (a chess set's pieces)
        skipped.append(f"{len(others)} object(s) share their mesh with {first} ({', '.join(others[:3])}"
                       f"{', ...' if len(others) > 3 else ''}): the radiosity layer shows {first}'s values")
    return layers, skipped


def _emission_to_suppress(data, objs, off, skipped) -> list:
    """A reduction's [(object, its emitting polygons)] whose emission is switched off (``skipped``
    gets the linked ones, which cannot be)."""
    suppress = []
    lp_ptr, lp = data.light_polygons_indptr, data.light_polygons
    for oi, ob in objs.items():
        sel = np.flatnonzero(data.light_object == oi)
        polys = np.concatenate([lp[lp_ptr[j]:lp_ptr[j + 1]] for j in sel]) if len(sel) else np.zeros(0, int)
        if len(polys) and linked_message(ob):
            skipped.append(f"{ob.name}: its mesh is linked (read-only), so its own emission cannot be switched "
                           "off: it still emits on top of the reduced lights; make it local to see the reduction "
                           "alone")
        elif len(polys):
            suppress.append((ob, polys - off[oi]))
    return suppress


def _remove_shown_lights(scene, rid) -> int:
    """Remove Relight's lights of the row shown: the emitters object and the lamps the solve placed
    (clear_shown; make_area_lights, once it made them the artist's). Returns the objects removed."""
    n = int(emitters_object(scene) is not None)
    _remove_emitters(rid)
    return n + _remove_placed(rid)


def clear_shown(scene) -> int:
    """Remove what shows a configuration (emitters object, radiosity layers, suppressed
    emitters; the lamps it set are given back as they were), keeping the stored curve. Returns
    the number of objects cleaned."""
    rid = result_id(scene)
    n = _remove_shown_lights(scene, rid) if rid is not None else 0
    for obj in scene.objects:
        if obj.type == "LIGHT" and obj.library is None:
            n += int(lamp_state.restore(obj))
    for obj in scene.objects:
        if obj.type != "MESH" or obj.data is None or obj.data.library is not None:
            continue
        a = clear_suppression(obj)
        b = remove_radiosity_layer(obj)
        n += int(a or b)
    for key in ("relight_shown", CONVERTED_PROP):
        if key in scene.keys():
            del scene[key]
    return n


def clear_results(scene) -> int:
    """Remove every trace of Relight's results (by identity): what shows a configuration, the
    stored curve and the chart. Area lights made by Make Area Lights stay (they are the artist's)."""
    n = clear_shown(scene)
    rid = result_id(scene)
    for img in [i for i in bpy.data.images if _owned(i, rid)]:  # the predicted camera image (view target)
        bpy.data.images.remove(img)
    for key in (RESULT_PROP, RESULT_ID_PROP):
        if key in scene.keys():
            del scene[key]
    img = bpy.data.images.get(CHART_IMAGE)
    if img is not None:
        bpy.data.images.remove(img)
    _cache.clear()
    return n


def shown_light_polygons(scene, obj) -> np.ndarray:
    """(n_polygons,) bool: the polygons of ``obj`` under a light of the configuration shown."""
    n = len(obj.data.polygons)
    out = np.zeros(n, dtype=bool)
    if RESULT_PROP not in scene.keys() or "relight_shown" not in scene.keys():
        return out
    data = load_result(scene)
    if obj.name not in data.objects:
        return out
    oi = data.objects.index(obj.name)
    e = data.exitance[int(scene["relight_shown"])]
    lit = np.flatnonzero(np.any(e > 0, axis=1) & (data.light_object == oi))
    ptr, lp = data.light_polygons_indptr, data.light_polygons
    off = data.polygon_offset[oi]
    for j in lit:
        p = lp[ptr[j]:ptr[j + 1]] - off
        out[p[(p >= 0) & (p < n)]] = True
    return out


#: on the scene: the row Make Area Lights converted (Relight's emitters of it removed); deleted,
#: with ``relight_shown``, when a row is shown again or the result cleared (clear_shown)
CONVERTED_PROP = "relight_converted"
#: the collection Make Area Lights puts its lights in (one per result; the artist's to keep)
AREA_COLLECTION = "Relight Lights"


def _cell_objects(data) -> np.ndarray:
    """(|C|,) the index in ``data.objects`` of the object each light cell lies on (-1: none)."""
    B = data.light_basis().tocoo()
    out = np.full(B.shape[0], -1, dtype=np.int64)
    out[B.row] = np.asarray(data.light_object, dtype=np.int64)[B.col]
    return out


def _nearest_object(obs, position) -> str:
    """The name of the mesh object of ``obs`` whose surface is nearest ``position`` (world, m): the
    one a lamp hangs from (the solve hangs its lamps in front of a surface that may hold lights); ""
    when none has a surface."""
    from mathutils import Vector

    p, best = Vector(position), (math.inf, "")
    for ob in obs:
        M = ob.matrix_world
        try:
            hit, co, _n, _i = ob.closest_point_on_mesh(M.inverted_safe() @ p)
        except RuntimeError:  # no evaluated mesh (e.g. its collection excluded from the view layer)
            continue
        if hit:
            best = min(best, ((M @ co - p).length, ob.name))
    return best[1]


def _numbered(base, taken) -> str:
    """``base`` + the first number from 1 that makes a name not in ``taken`` (then taken)."""
    n = 1
    while f"{base} {n}" in taken:
        n += 1
    taken.add(f"{base} {n}")
    return f"{base} {n}"


def make_area_lights(scene, index) -> dict:
    """Convert configuration ``index``, the one shown, into the artist's own lights (issue 36,
    item 6): one area light per light cell that emits, a one-sided area light of the cell's area at
    its centre (set off like the emitters object), facing along its normal, power = exitance x area
    (W) -- a rectangle of its sides for a rectangular cell (grid cells of quads), else a square of
    its area -- and a copy of each lamp the solve placed as it is in the scene (as the artist
    edited it: issue 35, case 3; a kept or renamed one is already the artist's, a deleted one is not
    brought back), in the collection "Relight Lights".

    Then Relight's own lights of the row stop rendering, so that a render shows the row's light
    once, not twice: the emitters object and the lamps the solve placed are *removed*, as
    clear_shown removes them. Removing, not hiding from render, because a hidden copy would stay
    one click (the eye, the camera icon) from doubling the light again, would be copied or kept
    by Keep Lamps beside its converted twin, and is one more thing to explain; the stored result
    is all a row needs to be shown again. What else shows the row stays, since it still describes
    what renders: the radiosity layer, the scene's emitters switched off and its lamps set (direct
    lighting), and the stored curve: a click on a row shows that row again with Relight's lights
    (beside these, which no result removes), Clear Results gives the rest back.

    Names: "Relight <Kind> <object> <n>" (Area for a cell; Spot, Area, Point for a lamp, as its
    Light's type), the object the cell lies on or the lamp hangs from (the nearest of the objects
    holding light cells, else of the solved objects), the first number from 1 no object has yet: an
    artist's object of that name keeps it. Converting the same row again after showing it again
    replaces the lights this made (those it still marks: visibility.owner_of's rule) and so gives the
    same names.

    All or nothing: everything is computed and checked (the row is the one shown and not converted
    already, it has a light of Relight's, finite values, positive areas; cells without area are
    left out) before anything is
    written. Returns {"names": the new lights' names, "collection": its name, "removed": Relight's
    objects removed, "reduce": whether the scene's own emitters and lamps are set by the result (a
    reduction: Clear Results gives them back as they were, beside these lights)}."""
    data, index, objs = _row_to_convert(scene, index)
    rid = result_id(scene)
    exitance = data.exitance[index].astype(np.float64)
    if not np.all(np.isfinite(exitance)):
        raise SceneError("the stored result holds non-finite values: solve again")
    cell_object = _cell_objects(data)
    plan = _cell_lights_plan(data, exitance, cell_object)
    holders = [objs[oi] for oi in sorted(set(cell_object.tolist()) & set(objs))] or list(objs.values())
    placed = _placed_to_copy(scene, data, rid, holders)
    if not plan and not placed:
        raise SceneError(f"configuration {index} has no light of Relight's to make yours (its lights are the "
                         "scene's own lamps and emitters, as it sets them, or none): nothing to convert")
    # write: replace this result's own earlier lights (by identity), add the new ones, then remove
    # Relight's lights of the row
    coll, taken = _area_lights_collection(scene, rid), set(bpy.data.objects.keys())  # (taken: after the old ones went)
    names = [_new_cell_light(coll, rid, taken, *cell) for cell in plan]
    for p, base in placed:
        obj = p.copy()
        obj.data = p.data.copy()
        _disown(obj, obj.data)
        obj.name = obj.data.name = _numbered(base, taken)
        coll.objects.link(obj)
        _mark_area_light(obj, rid)
        names.append(obj.name)
    removed = _remove_shown_lights(scene, rid)
    scene[CONVERTED_PROP] = index
    return {"names": names, "collection": coll.name, "removed": removed,
            "reduce": data.meta.get("command") == "reduce"}


def _row_to_convert(scene, index) -> tuple:
    """(stored result, index, its objects) of the row make_area_lights converts, checked: it exists,
    it is the one shown and not converted already, its objects and writers are there."""
    data = load_result(scene)
    n_points = len(data.n_lights)
    if not 0 <= int(index) < n_points:
        raise ValueError(f"configuration {index} does not exist (0..{n_points - 1})")
    index = int(index)
    shown = scene.get("relight_shown")
    if shown is None or int(shown) != index:
        raise SceneError(f"configuration {index} is not the one shown: click its row first (Make Area Lights "
                         "converts what the scene shows)")
    if scene.get(CONVERTED_PROP) == index:
        raise SceneError(f"configuration {index} is already your lights (Make Area Lights made them and removed "
                         "Relight's): nothing to convert; a click on a row shows it again with Relight's lights")
    objs = check_stored(scene, data)
    check_writers(data)
    return data, index, objs


def _placed_to_copy(scene, data, rid, holders) -> list:
    """[(object, base name)] of the lamps result ``rid`` placed, as they are in the scene, in the
    stored order (stable names), each named after the nearest of ``holders``."""
    order = {rec["name"]: k for k, rec in enumerate(data.lamps)}
    placed = sorted((o for o in scene.objects if o.type == "LIGHT" and _owned(o, rid)),
                    key=lambda o: (order.get(o.get(PLACED_LAMP_PROP), len(order)), o.name))
    return [(o, f"Relight {o.data.type.title()} {_nearest_object(holders, o.matrix_world.translation)}".strip())
            for o in placed]


def _cell_lights_plan(data, exitance, cell_object) -> list:
    """make_area_lights' area light per light cell that emits at ``exitance`` (n_lights, 3): (base
    name, shape, size, Power, colour, location, rotation); cells without area are left out."""
    cell_e = data.light_basis() @ exitance
    cells = np.flatnonzero(np.any(cell_e > 0, axis=1) & ~np.any(cell_e < 0, axis=1))
    tc = data.cell_triangle_cell
    tri_all = data.cell_triangles.astype(np.float64)
    scale = float(np.ptp(tri_all.reshape(-1, 3), axis=0).max()) if len(tri_all) else 1.0
    offset = overlay_offset(scale, tri_all)
    plan = []
    for c in cells:  # everything computed first
        tri = tri_all[tc == c]
        a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        area = float(a.sum())
        if not (area > 0 and np.isfinite(area)):
            continue
        center = (tri.mean(axis=1) * a[:, None]).sum(axis=0) / area
        n = data.cell_normal[c]
        power = cell_e[c] * area
        shape, size, rot = _cell_frame(tri, n, area)
        values = np.concatenate([center, n, power, size, rot.ravel()])
        if not np.all(np.isfinite(values)):
            raise SceneError(f"light cell {int(c)} of the stored result has non-finite geometry: solve again")
        where = data.objects[cell_object[c]] if 0 <= cell_object[c] < len(data.objects) else ""
        # Cycles: a light emits colour x Power in each channel (intern/cycles/blender/light.cpp)
        plan.append((f"Relight Area {where}".strip(), shape, size, float(power.max()),
                     power / max(power.max(), 1e-30), center + offset * n, rot))
    return plan


def _cell_frame(tri, n, area) -> tuple:
    """(shape, size, rotation) of a cell's area light: the cell's own frame (its longest edge and the
    side across it), a rectangle of its sides for a rectangular cell, else a square of its area."""
    pts = tri.reshape(-1, 3)
    e1 = tri[0, 1] - tri[0, 0]
    u = e1 - n * (e1 @ n)
    u /= max(np.linalg.norm(u), 1e-30)
    v = np.cross(n, u)
    su, sv = np.ptp(pts @ u), np.ptp(pts @ v)
    if len(tri) == 2 and abs(su * sv - area) <= 1e-3 * area:  # a rectangle
        shape, size = "RECTANGLE", (float(sv), float(su))
    else:
        shape, size = "SQUARE", (float(np.sqrt(area)), float(np.sqrt(area)))
    return shape, size, np.column_stack([v, u, -n])  # a rotation; the light shines along its local -Z


def _area_lights_collection(scene, rid):
    """The collection of make_area_lights' lights of result ``rid``: its earlier one emptied of the
    lights it made (what the user put there stays), else a new one."""
    old = [c for c in bpy.data.collections if rid is not None and c.get(AREA_LIGHTS_PROP) == rid]
    coll = None
    for c in old:  # Make Area Lights again replaces its own lights of this result, and only those
        if not empty_collection(c, lambda o: _made_area_light(o, rid)):  # what the user put there stays
            coll = coll or c
    if coll is None:
        coll = bpy.data.collections.new(AREA_COLLECTION)
        coll[AREA_LIGHTS_PROP] = rid or ""
        scene.collection.children.link(coll)
    return coll


def _new_cell_light(coll, rid, taken, base, shape, size, energy, color, location, rot) -> str:
    """A cell's area light (``_cell_lights_plan``'s entry) made in ``coll``; returns its name."""
    from mathutils import Matrix, Vector

    name = _numbered(base, taken)
    light = bpy.data.lights.new(name, "AREA")
    make_plain(light)  # Cycles emits colour x Power
    light.shape = shape
    light.size = size[0]
    if shape == "RECTANGLE":
        light.size_y = size[1]
    light.energy = energy  # Blender's area-light power is radiant flux (W)
    light.color = tuple(float(x) for x in color)
    obj = bpy.data.objects.new(name, light)
    obj.matrix_world = Matrix.Translation(Vector(location)) @ Matrix(rot.tolist()).to_4x4()
    coll.objects.link(obj)
    _mark_area_light(obj, rid)
    return obj.name


def _mark_area_light(ob, rid) -> None:
    """Make Area Lights' lights are the user's lights (a solve counts them), marked only so that the
    next Make Area Lights of the same result replaces them and nothing else (visibility.owner_of's
    rule: a copy, of another name, is not replaced)."""
    ob[AREA_LIGHTS_PROP] = rid or ""
    ob[RELIGHT_NAME_PROP] = ob.name


def _made_area_light(ob, rid) -> bool:
    return ob.get(AREA_LIGHTS_PROP) == (rid or "") and ob.get(RELIGHT_NAME_PROP) == ob.name


# --- the chart ---------------------------------------------------------------------------------
def update_chart(scene) -> None:
    """Ask the Results panel to redraw its chart. The chart is drawn on demand by the panel
    (blender/ui/panels.py, from ``chart_data``) at the sidebar's width; nothing is written here."""
    redraw_sidebars()


def redraw_sidebars() -> None:
    """Redraw the 3D Views' sidebars (the chart, the progress bar), not the viewports themselves."""
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm is not None else ():
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                for region in area.regions:
                    if region.type == "UI":
                        region.tag_redraw()


def chart_data(scene) -> dict | None:
    """What the error chart shows, or None without a result: the whole curve (``n_lights``,
    ``relative_error``, ``n_negative``), ``current`` (index on it of the configuration shown)
    and ``bound``: per curve point, the lower bound of the relative error any non-negative
    lights as many as that point's can reach (the stored certificate: exact where the search
    was exhaustive, else NNLS; NaN where there is none), or None when the result has none."""
    settings = scene.relight
    if len(settings.curve) == 0 or RESULT_PROP not in scene.keys():
        return None
    data = load_result(scene)
    k = settings.curve_index
    current = int(data.point_index[k]) if 0 <= k < len(data.point_index) else None
    bound = data.curve_bound_relative_error
    if bound is not None:
        bound = np.asarray(bound, dtype=np.float64)
        bound = np.where(bound >= 0, bound, np.nan)  # -1: no certificate for that point
        if len(bound) != len(data.curve_n_lights) or not np.isfinite(bound).any():
            bound = None
    return {"n_lights": data.curve_n_lights, "relative_error": data.curve_relative_error,
            "n_negative": data.curve_n_negative, "current": current, "bound": bound}


# --- the radiosity colour layer, saving and rendering ----------------------------------

def _save_mainfile(**kw):
    return bpy.ops.wm.save_as_mainfile(**kw)


def save_copy(path: str):
    """Save the current state to ``path`` as a copy (the open file keeps its own path), whole or
    not at all (``pipeline.files.atomic_output``)."""
    atomic_output(path, lambda tmp: _save_mainfile(filepath=tmp, copy=True, compress=True))



def _vertex_smoothed_corners(me, poly_values, poly_area):
    """Corner values: per vertex, the area-weighted mean of its polygons' values."""
    loop_poly, _, _ = loop_polygons(me)
    loop_vert = foreach_array(me.loops, "vertex_index", len(me.loops), np.int64)
    vert = group_mean(loop_vert, poly_values[loop_poly], len(me.vertices), poly_area[loop_poly])
    return vert[loop_vert]


ORIGINAL_ACTIVE_COLOR_PROP = "relight_original_active_color"
ORIGINAL_RENDER_COLOR_PROP = "relight_original_render_color"


def write_radiosity_layer(ob, poly_radiosity, poly_area=None):
    """Write per-polygon radiosity B (W/m^2) as the corner colour layer ``relight_radiosity``
    holding radiance B/pi (comparable with a Cycles COMBINED bake; per vertex, the
    area-weighted mean of its polygons), made the active and render colour. The previous
    active/render colours are remembered on the mesh for ``remove_radiosity_layer``.
    ``poly_area``: the weights (default: the mesh's own polygon areas)."""
    me = ob.data
    vals = radiance_from_exitance(np.asarray(poly_radiosity, dtype=np.float64).reshape(-1, 3))
    if not np.all(np.isfinite(vals)):
        raise SceneError(f"{ob.name}: refusing to write non-finite radiosity")
    if poly_area is None:
        poly_area = foreach_array(me.polygons, "area", len(me.polygons), np.float64)
    corner = _vertex_smoothed_corners(me, vals, np.asarray(poly_area, dtype=np.float64))
    attr = me.color_attributes.get(RADIOSITY_ATTRIBUTE)
    if attr is not None and (attr.domain != "CORNER" or attr.data_type != "FLOAT_COLOR"):
        me.color_attributes.remove(attr)
        attr = None
    if attr is None:
        if ORIGINAL_ACTIVE_COLOR_PROP not in me.keys():
            active = me.color_attributes.active_color
            me[ORIGINAL_ACTIVE_COLOR_PROP] = active.name if active is not None else ""
            me[ORIGINAL_RENDER_COLOR_PROP] = me.color_attributes.render_color_index
        attr = me.color_attributes.new(RADIOSITY_ATTRIBUTE, "FLOAT_COLOR", "CORNER")
    rgba = np.ones((len(me.loops), 4), dtype=np.float32)
    rgba[:, :3] = corner
    attr.data.foreach_set("color", rgba.ravel())
    me.color_attributes.active_color = attr
    me.color_attributes.render_color_index = me.color_attributes.find(RADIOSITY_ATTRIBUTE)
    me.update()


def remove_radiosity_layer(ob) -> bool:
    """Remove ``relight_radiosity`` and give back the active and render colours it replaced."""
    me = ob.data
    if DISPLAY_ATTRIBUTE in me.color_attributes:  # (the view made of it: ui/display.py)
        me.color_attributes.remove(me.color_attributes[DISPLAY_ATTRIBUTE])
    attr = me.color_attributes.get(RADIOSITY_ATTRIBUTE)
    if attr is None:
        return False
    me.color_attributes.remove(attr)
    name = me.get(ORIGINAL_ACTIVE_COLOR_PROP, "")
    if name and name in me.color_attributes:
        me.color_attributes.active_color = me.color_attributes[name]
    if ORIGINAL_RENDER_COLOR_PROP in me.keys():
        idx = int(me[ORIGINAL_RENDER_COLOR_PROP])
        if 0 <= idx < len(me.color_attributes):
            me.color_attributes.render_color_index = idx
        del me[ORIGINAL_RENDER_COLOR_PROP]
    if ORIGINAL_ACTIVE_COLOR_PROP in me.keys():
        del me[ORIGINAL_ACTIVE_COLOR_PROP]
    me.update()
    return True


def linked_message(ob) -> str | None:
    """Why Relight cannot write its radiosity layer on ``ob``'s mesh (linked from a library:
    read-only, and not saved with this file), or None when it can."""
    lib = ob.data.library or ob.library
    if lib is None:
        return None
    return (f"{ob.name}: its mesh is linked from {lib.filepath} (read-only), so the radiosity layer is not written "
            "(the lights are shown); make it local (Object > Relations > Make Local > Object and Data) to see it")


def write_radiosity(objects, radiosity, areas, skipped=None):
    """Write radiance B/pi into ``relight_radiosity`` on each object's mesh (see
    ``write_radiosity_layer``). ``radiosity[name]``: (n_polygons, 3) W/m^2 per base polygon;
    ``areas[name]``: (n_polygons,) weights (m^2). A mesh shared by several exported objects
    is made single-user first (each object gets its own values). Linked (library) meshes are
    read-only: skipped, with a message appended to ``skipped`` (a list). Everything is checked
    before the first write."""
    plan, seen = [], set()
    for ob in objects:
        if ob.name not in radiosity:
            continue
        why = linked_message(ob)
        if why:
            if skipped is not None and why not in skipped:
                skipped.append(why)
            continue
        values = np.asarray(radiosity[ob.name], dtype=np.float64)
        if not np.all(np.isfinite(values)):
            raise SceneError(f"{ob.name}: refusing to write non-finite radiosity")
        plan.append((ob, values, ob.data.name in seen))
        seen.add(ob.data.name)
    for ob, values, shared in plan:
        if shared:
            ob.data = ob.data.copy()
        write_radiosity_layer(ob, values, areas[ob.name])


def _attribute_emission_material(attribute):
    """A new material emitting the colour attribute ``attribute`` (Emission of strength 1)."""
    mat = bpy.data.materials.new("relight_radiosity_view")
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore", DeprecationWarning)
        if not mat.use_nodes:
            mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    at = nt.nodes.new("ShaderNodeAttribute")
    at.attribute_name = attribute
    nt.links.new(at.outputs["Color"], em.inputs["Color"])
    em.inputs["Strength"].default_value = 1.0
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def render_radiosity(path, context=None, samples=16, resolution=None, attribute=RADIOSITY_ATTRIBUTE,
                     view_transform="Standard"):
    """Render the ``relight_radiosity`` colours with Cycles (CPU) to ``path``, in the format its
    extension names (RENDER_FORMATS), whole or not at all.

    Every surface is shown as an emitter of its baked radiance B/pi (a view-layer material
    override: Attribute ``relight_radiosity`` -> Emission, strength 1), on a black world,
    from the scene camera, with the Standard view transform (a face of radiance 1 is white) unless
    ``view_transform`` says otherwise (e.g. "AgX", which compresses the lights' highlights).
    The scene's materials and world are restored afterwards.
    """
    context = context or bpy.context
    scene = context.scene
    if scene.camera is None:
        raise SceneError("the scene has no camera to render from")
    fmt = RENDER_FORMATS.get(os.path.splitext(path)[1].lower())
    if fmt is None:
        raise SceneError(f"{path}: the picture's format is read from its extension, one of "
                         f"{', '.join(RENDER_FORMATS)}")
    mat = _attribute_emission_material(attribute)
    world = bpy.data.worlds.new("relight_black")
    world.color = (0.0, 0.0, 0.0)
    r = scene.render
    saved = (context.view_layer.material_override, scene.world, r.engine, r.filepath, r.image_settings.file_format,
             scene.view_settings.view_transform, scene.view_settings.look, scene.view_settings.exposure,
             r.use_file_extension)
    try:
        context.view_layer.material_override = mat
        scene.world = world
        r.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = int(samples)
        scene.cycles.use_denoising = False
        scene.cycles.max_bounces = 0
        if resolution is not None:
            r.resolution_x, r.resolution_y = resolution
        scene.view_settings.view_transform = view_transform
        scene.view_settings.look = "None"
        scene.view_settings.exposure = 0.0
        r.image_settings.file_format = fmt
        r.use_file_extension = False  # exactly the path asked for (Blender would rename shot.jpg to shot.png)

        def write(tmp):
            r.filepath = tmp
            bpy.ops.render.render(write_still=True)

        atomic_output(path, write)
    finally:
        (context.view_layer.material_override, scene.world, r.engine, r.filepath, r.image_settings.file_format,
         scene.view_settings.view_transform, scene.view_settings.look, scene.view_settings.exposure,
         r.use_file_extension) = saved
        bpy.data.materials.remove(mat)
        bpy.data.worlds.remove(world)
