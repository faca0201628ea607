"""Relight's attribute layers and properties (bpy): the targets, illuminance targets and
forbidden faces painted on meshes, the objects' switches (no lights, work plane) and the scene's
settings; read for the export, created and written for the tools that paint them.

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
- ``relight_target_lux``: a Face FLOAT attribute, the illuminance targets (lx, 0: none);
  negative, NaN or infinite values are refused. A face painted and given an illuminance both is
  refused.
- ``relight_work_plane``: object custom property (or the add-on's property): light passes through
  the object and it reflects none into the scene (a plane where the light is measured).
"""
from __future__ import annotations

import math

import numpy as np

from ..engine.paint import neutral_as_brightness
from ..engine.scene import SceneError
from ..engine.units import MIN_REFLECTANCE_LUX, exitance_from_radiance, irradiance_from_lux
from .meshes import foreach_array, loop_polygons

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


def _edit_face_values(me, name, data_type, n):
    """(n,) float64: the Face attribute ``name`` of ``data_type`` (BOOLEAN, INT, FLOAT) of mesh
    ``me`` in Edit Mode, read from its edit mesh (the mesh's own attribute data is empty there);
    None when BMesh cannot read it (a Boolean layer before Blender 4.3, an 8-bit integer one)."""
    import bmesh

    bm = bmesh.from_edit_mesh(me)
    kind = {"BOOLEAN": "bool", "INT": "int", "FLOAT": "float"}.get(data_type)
    group = getattr(bm.faces.layers, kind, None) if kind else None
    layer = group.get(name) if group is not None else None
    if layer is None or len(bm.faces) != n:
        return None
    return np.array([f[layer] for f in bm.faces], dtype=np.float64)


def _edit_forbidden(ob, attr, n, strict=True):
    """(n,) bool: the forbidden faces of ``ob`` in Edit Mode (_edit_face_values); a layer BMesh
    cannot read: SceneError naming the object (not ``strict``: None)."""
    v = _edit_face_values(ob.data, FORBIDDEN_ATTRIBUTE, attr.data_type, n)
    if v is None:
        if not strict:
            return None
        raise SceneError(f"{ob.name}: its {FORBIDDEN_ATTRIBUTE} ({attr.data_type}) cannot be read in Edit Mode in "
                         f"this Blender: leave Edit Mode (Tab), then solve")
    return (v != 0) | np.isnan(v)


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
        v = _edit_face_values(me, LUX_ATTRIBUTE, "FLOAT", n)
        v = np.zeros(n) if v is None else v
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


def base_attributes(ob, target_scale, notes=None, strict=True):
    """Per base-mesh polygon: target (bool), target radiosity (W/m^2), forbidden (bool) and
    illuminance target (lx, 0: none; a face painted and given an illuminance both is refused).
    ``notes``: a list that gets the messages about layers found but not used. An object in
    Edit Mode: its edit mesh's paint and forbidden faces; a forbidden layer BMesh cannot read
    there: SceneError, or (not ``strict``: Live's read of the paint) forbidden None."""
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
    attr = forbidden_layer(me, ob.name)  # another domain or type: refused
    if attr is not None:
        forbidden = _edit_forbidden(ob, attr, n, strict) if ob.mode == "EDIT" and me.is_editmode \
            else read_forbidden(attr, n)
    if no_lights(ob) and forbidden is not None:
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


def work_plane(ob) -> bool:
    """The object's "work plane" switch (the add-on's property, or a custom property of that name;
    a boolean or a number): light passes through its faces and they reflect none into the scene
    (a plane where the light is measured, as lighting software has them)."""
    raw = ob.get(WORK_PLANE_PROP)
    if raw is not None and not isinstance(raw, (bool, int, float)):
        raise SceneError(f"object {ob.name!r}: custom property {WORK_PLANE_PROP} is {raw!r}, not a boolean or a "
                         "number: set it to True/False (or 1/0)")
    return bool(getattr(ob, WORK_PLANE_PROP, False) or raw)


def face_flags(ob, kind):
    """Per base-mesh polygon of ``ob``: kind "target", "forbidden" or "candidate" (bool array)."""
    target, _, forbidden, lux = base_attributes(ob, 1.0, [])
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
