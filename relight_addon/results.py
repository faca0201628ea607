"""Relight results in the Blender scene: emissive light faces that can be cleared exactly.

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

import numpy as np

import bpy

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


def apply_configuration(obj, polygon_index, radiance) -> int:
    """Make polygons ``polygon_index`` of ``obj`` emit ``radiance`` (k, 3) = exitance/pi.

    Any configuration already applied to ``obj`` is cleared first. Returns the number
    of emitting faces. Radiance must be finite and >= 0 (negative exitances cannot be
    shown by a material; the caller decides what to do with them).
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
            mesh.materials.append(_emissive_variant(src))
            slot_of_source[src_slot] = len(mesh.materials) - 1
        new_index[p] = slot_of_source[src_slot]
    mesh.polygons.foreach_set("material_index", new_index)
    mesh.update()
    return len(polygon_index)
