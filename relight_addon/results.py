"""Engine -> Blender: Relight's results in the scene, all of them clearable exactly (bpy).

The way in is export.py. Here: the emissive light faces, the stored curve, the
``relight_radiosity`` colour layer, area lights, the chart, saving a copy and rendering.

How a configuration is shown (bpy layer; the engine never sees this):

- Each mesh with light faces gets a FACE-domain FLOAT_COLOR attribute ``relight_emission``
  holding the face's emitted *radiance* exitance/pi (W/m^2/sr), zero elsewhere.
- For every original material used by a light face, an emissive variant is created:
  a copy of that material whose surface is ``original surface + Emission``, the Emission
  colour read from ``relight_emission`` with strength 1 on the front side and 0 on the
  back (one-sided emitters, as in the radiosity model). The original surface shader is
  untouched, so the face keeps its base colour and hence its reflectance.
  Emission strength x colour = exitance / pi.
- Light faces point to the variant through new material slots appended after the
  original slots; the original material index of every face is saved in the INT face
  attribute ``relight_original_material`` and the original slot count in the mesh's
  ``relight_original_slots`` custom property.

``clear_configuration`` undoes all of it: material indices, slots, attributes, and the
generated materials, so the mesh ends exactly as it was before ``apply_configuration``.
"""
from __future__ import annotations

import math
import os
import warnings as _warnings

import bpy
import numpy as np

from .engine.scene import SceneError
from .export import RADIOSITY_ATTRIBUTE, foreach_array, loop_polygons

EMISSION_ATTRIBUTE = "relight_emission"
ORIGINAL_INDEX_ATTRIBUTE = "relight_original_material"
ORIGINAL_SLOTS_PROP = "relight_original_slots"
HAD_INDEX_PROP = "relight_had_material_index"
GENERATED_PROP = "relight_generated"
DEFAULT_REFLECTANCE = 0.8


def _use_nodes(mat):
    """Node materials are the only kind from Blender 5.0; older versions need the switch."""
    if bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        mat.use_nodes = True


def _emissive_variant(source):
    """A copy of material ``source`` (or a grey default for None) that adds a one-sided
    emission read from the ``relight_emission`` face attribute."""
    if source is None:
        mat = bpy.data.materials.new("Relight emitter")
        _use_nodes(mat)
        bsdf = next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = (DEFAULT_REFLECTANCE,) * 3 + (1.0,)
        mat.diffuse_color = (DEFAULT_REFLECTANCE,) * 3 + (1.0,)
    else:
        mat = source.copy()
        mat.name = f"{source.name} (Relight)"
    mat[GENERATED_PROP] = True
    mat["relight_source"] = source.name if source is not None else ""
    _use_nodes(mat)
    nt = mat.node_tree
    for node in nt.nodes:  # the copy's own emission is replaced by Relight's
        if node.type == "BSDF_PRINCIPLED" and "Emission Strength" in node.inputs:
            sock = node.inputs["Emission Strength"]
            for link in list(sock.links):
                nt.links.remove(link)
            sock.default_value = 0.0
        elif node.type == "EMISSION":
            for link in list(node.inputs["Strength"].links):
                nt.links.remove(link)
            node.inputs["Strength"].default_value = 0.0
    out = next((n for n in nt.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None)
    if out is None:
        out = next((n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"), None)
    if out is None:
        out = nt.nodes.new("ShaderNodeOutputMaterial")
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = EMISSION_ATTRIBUTE
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    front = nt.nodes.new("ShaderNodeMath")
    front.operation = "SUBTRACT"
    front.inputs[0].default_value = 1.0
    nt.links.new(geo.outputs["Backfacing"], front.inputs[1])
    emit = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(attr.outputs["Color"], emit.inputs["Color"])
    nt.links.new(front.outputs["Value"], emit.inputs["Strength"])
    add = nt.nodes.new("ShaderNodeAddShader")
    surface = out.inputs["Surface"]
    if surface.is_linked:
        nt.links.new(surface.links[0].from_socket, add.inputs[0])
    nt.links.new(emit.outputs["Emission"], add.inputs[1])
    nt.links.new(add.outputs["Shader"], surface)
    for k, node in enumerate((attr, geo, front, emit, add)):
        node.location = (out.location.x - 600 + 120 * k, out.location.y - 300)
    return mat


def light_faces(obj) -> np.ndarray:
    """Per polygon of ``obj``: does it emit in the configuration shown (bool array)."""
    mesh = obj.data
    n = len(mesh.polygons)
    attr = mesh.attributes.get(EMISSION_ATTRIBUTE)
    if attr is None:
        return np.zeros(n, dtype=bool)
    em = np.zeros(4 * n, dtype=np.float32)
    attr.data.foreach_get("color", em)
    return em.reshape(n, 4)[:, :3].max(axis=1) > 0


def clear_configuration(obj) -> bool:
    """Restore ``obj``'s mesh exactly as it was before ``apply_configuration``.

    Returns True if there was something to clear.
    """
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
    emission = mesh.attributes.get(EMISSION_ATTRIBUTE)
    if emission is not None:
        mesh.attributes.remove(emission)
    del mesh[ORIGINAL_SLOTS_PROP]
    if HAD_INDEX_PROP in mesh.keys():
        del mesh[HAD_INDEX_PROP]
    for mat in generated:
        if mat.users == 0:
            bpy.data.materials.remove(mat)
    mesh.update()
    return True


def apply_configuration(obj, polygon_index, radiance, variants=None) -> int:
    """Make polygons ``polygon_index`` of ``obj`` emit ``radiance`` (k, 3) = exitance/pi.

    Any configuration already applied to ``obj`` is cleared first. Returns the number
    of emitting faces. Radiance must be finite and >= 0 (negative exitances cannot be
    shown by a material; the caller decides what to do with them). ``variants``: a dict
    shared between calls so that objects with the same material share one emissive variant.
    """
    clear_configuration(obj)
    polygon_index = np.asarray(polygon_index, dtype=np.int64).reshape(-1)
    radiance = np.asarray(radiance, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(radiance)):
        raise ValueError("refusing to apply non-finite emission")
    mesh = obj.data
    n_poly = len(mesh.polygons)
    if len(polygon_index) == 0:
        return 0
    if polygon_index.min() < 0 or polygon_index.max() >= n_poly:
        raise ValueError(f"{obj.name}: light face index out of range")

    orig = np.empty(n_poly, dtype=np.int32)
    mesh.polygons.foreach_get("material_index", orig)
    n_slots = len(mesh.materials)
    mesh[ORIGINAL_SLOTS_PROP] = n_slots
    mesh[HAD_INDEX_PROP] = "material_index" in mesh.attributes
    keep = mesh.attributes.new(ORIGINAL_INDEX_ATTRIBUTE, "INT", "FACE")
    keep.data.foreach_set("value", orig)
    if n_slots == 0:
        # faces without a material render with the default; keep it that way with an
        # empty slot 0 so that the appended emissive slots are used only by light faces
        mesh.materials.append(None)

    emission = np.zeros((n_poly, 4), dtype=np.float32)
    emission[:, 3] = 1.0
    emission[polygon_index, :3] = np.clip(radiance, 0.0, None)
    attr = mesh.attributes.new(EMISSION_ATTRIBUTE, "FLOAT_COLOR", "FACE")
    attr.data.foreach_set("color", emission.ravel())

    new_index = orig.copy()
    slot_of_source = {}
    for p in polygon_index:
        src_slot = int(orig[p]) if n_slots else -1
        if src_slot not in slot_of_source:
            src = mesh.materials[src_slot] if 0 <= src_slot < n_slots else None
            key = src.name if src is not None else None
            variant = (variants or {}).get(key)
            if variant is None or variant.name not in bpy.data.materials:
                variant = _emissive_variant(src)
                if variants is not None:
                    variants[key] = variant
            mesh.materials.append(variant)
            slot_of_source[src_slot] = len(mesh.materials) - 1
        new_index[p] = slot_of_source[src_slot]
    mesh.polygons.foreach_set("material_index", new_index)
    mesh.update()
    return len(polygon_index)


# --- the stored curve: store, apply a point, clear ------------------------------------------

RESULT_PROP = "relight_result"
_cache = {}


def store_result(scene, outcome) -> None:
    """Keep the whole curve in the scene (see curve_store) so any point can be re-applied."""
    from .curve_store import pack_curve

    text = pack_curve(outcome.stored)
    scene[RESULT_PROP] = text
    _cache.clear()


def show_outcome(scene, outcome) -> None:
    """Replace any previous result by this solve's: store its curve, show its final configuration."""
    clear_results(scene)
    store_result(scene, outcome)
    apply_stored_point(scene, outcome.final_index)


def load_result(scene) -> dict:
    from .curve_store import unpack_curve

    text = scene.get(RESULT_PROP)
    if not text:
        raise KeyError("no Relight result in this scene: run Solve & Reduce first")
    key = (scene.name, hash(text))
    if key not in _cache:
        _cache.clear()
        _cache[key] = unpack_curve(text)
    return _cache[key]


def apply_stored_point(scene, index) -> dict:
    """Show configuration ``index`` of the stored curve: emissive light faces (positive
    exitances only: a material cannot emit negative light) and the radiosity layer.
    Returns {"lights": n shown, "negative": n not shown}."""
    data = load_result(scene)
    n_points = len(data["n_lights"])
    if not 0 <= index < n_points:
        raise ValueError(f"configuration {index} does not exist (0..{n_points - 1})")
    names = data["objects"]
    exitance = data["exitance"][index]
    negative = np.any(exitance < 0, axis=1)
    # inverse mode: only the lit faces change; direct-lighting mode ("reduce"): every original
    # emitter is managed, so that suppressed ones stop emitting
    lit = np.any(exitance != 0, axis=1) | (data["meta"].get("command") == "reduce")
    shown = 0
    variants = {}
    for oi, name in enumerate(names):
        obj = scene.objects.get(name)
        if obj is None or obj.type != "MESH":
            continue
        sel = (data["light_object"] == oi) & lit & ~negative
        faces = data["light_face"][sel]
        if len(faces) and faces.max() >= len(obj.data.polygons):
            raise ValueError(f"{name} has changed since the solve: solve again")
        rad = exitance[sel] / np.pi
        apply_configuration(obj, faces, rad, variants)
        shown += int(np.sum(np.any(rad > 0, axis=1)))
        rsel = data["radiosity_object"] == oi
        if np.any(rsel):
            face_b = np.zeros((len(obj.data.polygons), 3))
            idx = data["radiosity_face"][rsel]
            if idx.max() >= len(face_b):
                raise ValueError(f"{name} has changed since the solve: solve again")
            face_b[idx] = data["radiosity"][index][rsel]
            write_radiosity_layer(obj, face_b)
    return {"lights": shown, "negative": int(negative.sum())}


def clear_results(scene) -> int:
    """Remove every trace of Relight's results from the scene's meshes and the stored curve."""
    n = 0
    for obj in scene.objects:
        if obj.type != "MESH":
            continue
        a = clear_configuration(obj)
        b = remove_radiosity_layer(obj)
        n += int(a or b)
    if RESULT_PROP in scene.keys():
        del scene[RESULT_PROP]
    coll = bpy.data.collections.get("Relight Lights")
    if coll is not None:
        for o in list(coll.objects):
            data = o.data
            bpy.data.objects.remove(o)
            if data is not None and data.users == 0:
                bpy.data.lights.remove(data)
        bpy.data.collections.remove(coll)
    img = bpy.data.images.get(CHART_IMAGE)
    if img is not None:
        bpy.data.images.remove(img)
    _cache.clear()
    return n


def make_area_lights(scene, index) -> int:
    """Real Blender area lights for configuration ``index``: a square light of the face's
    area at its centre, facing along its normal, with power = exitance x area (W)."""
    from mathutils import Vector

    data = load_result(scene)
    exitance = data["exitance"][index]
    power = exitance * data["light_area"][:, None]
    sel = np.flatnonzero(np.any(exitance > 0, axis=1) & ~np.any(exitance < 0, axis=1))
    coll = bpy.data.collections.get("Relight Lights")
    if coll is None:
        coll = bpy.data.collections.new("Relight Lights")
        scene.collection.children.link(coll)
    for o in list(coll.objects):
        bpy.data.objects.remove(o)
    for k in sel:
        total = float(power[k].sum())
        light = bpy.data.lights.new(f"Relight light {k}", "AREA")
        light.shape = "SQUARE"
        light.size = float(np.sqrt(data["light_area"][k]))
        light.energy = total  # Blender's area-light power is in W (radiant flux)
        light.color = tuple(float(c) for c in power[k] / max(power[k].max(), 1e-30))
        obj = bpy.data.objects.new(light.name, light)
        obj.location = Vector(data["light_center"][k])
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = Vector((0, 0, -1)).rotation_difference(Vector(data["light_normal"][k]))
        coll.objects.link(obj)
    return len(sel)


CHART_IMAGE = ".relight_error_curve"


def update_chart(scene) -> None:
    """Redraw the error-curve chart image, marking the shown configuration. Call it after a
    solve or a change of configuration, never from a panel's draw (no ID writes there)."""
    from .curve_store import error_chart

    settings = scene.relight
    if len(settings.curve) == 0 or RESULT_PROP not in scene.keys():
        return
    data = load_result(scene)
    current = int(data["point_index"][settings.curve_index]) if settings.curve_index < len(data["point_index"]) else None
    pixels = error_chart(data["curve_n_lights"], data["curve_relative_error"], data["curve_n_negative"],
                         current=current)
    h, w = pixels.shape[:2]
    img = bpy.data.images.get(CHART_IMAGE)
    if img is None or tuple(img.size) != (w, h):
        if img is not None:
            bpy.data.images.remove(img)
        img = bpy.data.images.new(CHART_IMAGE, w, h, alpha=True, float_buffer=True)
    img.pixels.foreach_set(pixels.ravel())
    img.update()
    img.preview_ensure()
    img.preview.reload()


def chart_icon(scene) -> int:
    """icon_value of the error-curve chart, 0 when there is none (safe in draw())."""
    img = bpy.data.images.get(CHART_IMAGE)
    if img is None or img.preview is None:
        return 0
    return img.preview.icon_id


# --- the radiosity colour layer, saving and rendering ----------------------------------

def save_copy(path: str):
    """Save the current state to ``path`` as a copy (the open file keeps its own path)."""
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path), copy=True, compress=True)



def _vertex_smoothed_corners(me, poly_values, poly_area):
    """Corner values: per vertex, the area-weighted mean of its polygons' values."""
    loop_poly, _, _ = loop_polygons(me)
    loop_vert = foreach_array(me.loops, "vertex_index", len(me.loops), np.int64)
    nv = len(me.vertices)
    w = poly_area[loop_poly]
    num = np.stack([np.bincount(loop_vert, weights=w * poly_values[loop_poly, k], minlength=nv)
                    for k in range(3)], axis=1)
    den = np.bincount(loop_vert, weights=w, minlength=nv)
    cnt = np.bincount(loop_vert, minlength=nv)
    plain = np.stack([np.bincount(loop_vert, weights=poly_values[loop_poly, k], minlength=nv)
                      for k in range(3)], axis=1) / np.maximum(cnt, 1)[:, None]
    vert = np.where(den[:, None] > 0, num / np.where(den > 0, den, 1.0)[:, None], plain)
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
    vals = np.asarray(poly_radiosity, dtype=np.float64).reshape(-1, 3) / math.pi
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


def write_radiosity(objects, radiosity, areas):
    """Write radiance B/pi into ``relight_radiosity`` on each object's mesh (see
    ``write_radiosity_layer``). ``radiosity[name]``: (n_polygons, 3) W/m^2 per base polygon;
    ``areas[name]``: (n_polygons,) weights (m^2). A mesh shared by several exported objects
    is made single-user first (each object gets its own values)."""
    written = set()
    for ob in objects:
        if ob.name not in radiosity:
            continue
        if ob.data.name in written or ob.data.library is not None:
            ob.data = ob.data.copy()
        written.add(ob.data.name)
        write_radiosity_layer(ob, radiosity[ob.name], areas[ob.name])


def render_radiosity(path, context=None, samples=16, resolution=None, attribute=RADIOSITY_ATTRIBUTE):
    """Render the ``relight_radiosity`` colours with Cycles (CPU) to a PNG at ``path``.

    Every surface is shown as an emitter of its baked radiance B/pi (a view-layer material
    override: Attribute ``relight_radiosity`` -> Emission, strength 1), on a black world,
    from the scene camera, with the Standard view transform: a face of radiance 1 is white.
    The scene's materials and world are restored afterwards.
    """
    context = context or bpy.context
    scene = context.scene
    if scene.camera is None:
        raise SceneError("the scene has no camera to render from")
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
    world = bpy.data.worlds.new("relight_black")
    world.color = (0.0, 0.0, 0.0)
    r = scene.render
    saved = (context.view_layer.material_override, scene.world, r.engine, r.filepath, r.image_settings.file_format,
             scene.view_settings.view_transform, scene.view_settings.look, scene.view_settings.exposure)
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
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.view_settings.exposure = 0.0
        r.image_settings.file_format = "PNG"
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        r.filepath = os.path.abspath(path)
        bpy.ops.render.render(write_still=True)
    finally:
        (context.view_layer.material_override, scene.world, r.engine, r.filepath, r.image_settings.file_format,
         scene.view_settings.view_transform, scene.view_settings.look, scene.view_settings.exposure) = saved
        bpy.data.materials.remove(mat)
        bpy.data.worlds.remove(world)
