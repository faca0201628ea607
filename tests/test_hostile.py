"""The hostile-input catalogue (issue 11; docs/reliability.md): a table of cases through the CLI
(in-process ``cli.main``; a real process where a signal matters) and through the add-on's
operators (``bpy.ops`` with ``relight_addon.register()``).

Every case states the exit code (CLI) or the operator's outcome, the one-line message (matched in
part), and is checked for: the input .blend's bytes unchanged; no NaN or inf in the report (strict
JSON) or in the scene (Relight's attributes, lights, stored result); a failed operation leaves the
scene exactly as it was (a snapshot of every object, mesh attribute, material, light, collection
and custom property); a failed CLI run writes no --out (and no report unless it says so).

The scenes are tiny (a 1 m room: a painted floor under a 2 x 2 ceiling, one patch per face) and
the rays few, so the whole table runs in about a minute.
"""
from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np
import pytest

from conftest import ROOT, file_digest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")

RAYS = ["--rays-per-patch", "256"]


# ============================================================================ scenes

def _reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
from relight_addon.engine.cost import estimate_patch_count  # noqa: E402


def _grid(n, size=1.0, z=0.0, flip=False, x0=0.0, y0=0.0):
    verts = [(x0 + size * i / n, y0 + size * j / n, z) for j in range(n + 1) for i in range(n + 1)]
    faces = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            f = (a, a + 1, a + n + 2, a + n + 1)
            faces.append(f[::-1] if flip else f)
    return verts, faces


def _mesh(name, verts, faces, collection=None, material=None):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    if material is not None:
        me.materials.append(material)
    ob = bpy.data.objects.new(name, me)
    (collection or bpy.context.scene.collection).objects.link(ob)
    return ob


def _emissive(name, strength, color=(1, 1, 1)):
    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    p = next(n for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    p.inputs["Emission Color"].default_value = (*color, 1)
    p.inputs["Emission Strength"].default_value = strength
    return m


def _paint(ob, color=(0.2, 0.2, 0.2), alpha=1.0, dtype="FLOAT_COLOR", domain="CORNER", polys=None):
    me = ob.data
    if dtype in ("FLOAT_COLOR", "BYTE_COLOR"):
        a = me.color_attributes.new("relight_target", dtype, domain)
        n = len(a.data)
        col = np.zeros((n, 4))
        if domain == "CORNER" and polys is not None:
            for p in polys:
                poly = me.polygons[p]
                col[poly.loop_start:poly.loop_start + poly.loop_total] = (*color, alpha)
        else:
            col[:] = (*color, alpha)
        a.data.foreach_set("color", col.ravel().astype(np.float32))
    else:  # a non-colour attribute of that name
        a = me.attributes.new("relight_target", dtype, domain)
        a.data.foreach_set("value", np.ones(len(a.data), dtype=np.float32))
    return a


def _forbid(ob, values, dtype="INT", domain="FACE"):
    a = ob.data.attributes.new("relight_forbidden", dtype, domain)
    vals = np.zeros(len(a.data))
    vals[:len(values)] = values
    cast = {"BOOLEAN": bool, "FLOAT": np.float32}.get(dtype, np.int32)
    a.data.foreach_set("value", vals.astype(cast))
    return a


def _room(paint=True, color=(0.2, 0.2, 0.2), **paint_kw):
    """A 1 m floor (2 x 2 faces, targets, no lights) under a 1 m ceiling (2 x 2 candidates)."""
    fv, ff = _grid(2)
    floor = _mesh("floor", fv, ff)
    floor["relight_no_lights"] = True
    if paint:
        _paint(floor, color, **paint_kw)
    cv, cf = _grid(2, z=1.0, flip=True)
    ceiling = _mesh("ceiling", cv, cf)
    return floor, ceiling


def _save(path, patch_size=10.0):
    if patch_size is not None and "relight_max_patch_size" not in bpy.context.scene.keys():
        bpy.context.scene["relight_max_patch_size"] = patch_size
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return str(path)


def _library(dirpath, painted=False):
    """A library .blend holding the ceiling (object and mesh 'lib_ceiling')."""
    _reset()
    cv, cf = _grid(2, z=1.0, flip=True)
    ob = _mesh("lib_ceiling", cv, cf)
    if painted:
        _paint(ob)
    path = os.path.join(dirpath, "lib.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    _reset()
    return path


def _link(lib, name):
    with bpy.data.libraries.load(lib, link=True, relative=True) as (src, dst):
        dst.objects = [name]
    ob = dst.objects[0]
    bpy.context.scene.collection.objects.link(ob)
    return ob


def build(name, d):
    """Build scene ``name`` in directory ``d``; returns its path (or a path that is not a scene)."""
    path = os.path.join(d, f"{name}.blend")
    _reset()
    if name == "room":
        _room()
    elif name == "room_unpainted":
        _room(paint=False)
    elif name == "room_black":
        _room(color=(0.0, 0.0, 0.0))
    elif name == "scale_string":
        _room()
        bpy.context.scene["relight_target_scale"] = "bright"
    elif name == "scale_zero":
        _room()
        bpy.context.scene["relight_target_scale"] = 0.0
    elif name == "scale_negative":
        _room()
        bpy.context.scene["relight_target_scale"] = -2.0
    elif name == "scale_nan":
        _room()
        bpy.context.scene["relight_target_scale"] = float("nan")
    elif name == "scale_two":
        _room()
        bpy.context.scene["relight_target_scale"] = 2.0
    elif name == "size_string":
        _room()
        bpy.context.scene["relight_max_patch_size"] = "big"
    elif name == "size_zero":
        _room()
        bpy.context.scene["relight_max_patch_size"] = 0.0
    elif name == "size_tiny":
        _room()
        bpy.context.scene["relight_max_patch_size"] = 1e-6
    elif name == "no_lights_string":
        _, ceiling = _room()
        ceiling["relight_no_lights"] = "false"
    elif name == "target_point":
        _room(domain="POINT")
    elif name == "target_float_corner":
        _room(dtype="FLOAT")
    elif name == "target_byte":
        _room(dtype="BYTE_COLOR")
    elif name == "target_nan":
        _room(color=(math.nan, 0.2, 0.2))
    elif name == "target_negative":
        floor, _ = _room(color=(-0.5, 0.2, 0.2), polys=[0])
        col = np.zeros((len(floor.data.loops), 4), dtype=np.float32)
        floor.data.attributes["relight_target"].data.foreach_get("color", col.ravel())
        col[4:] = (0.2, 0.2, 0.2, 1.0)  # polygons 1..3 ordinary targets
        floor.data.attributes["relight_target"].data.foreach_set("color", col.ravel())
    elif name == "forbidden_int_all":
        _, ceiling = _room()
        _forbid(ceiling, [1, 1, 1, 1], "INT")
    elif name == "forbidden_int_half":
        _, ceiling = _room()
        _forbid(ceiling, [1, 0, 0, 1], "INT")
    elif name == "forbidden_float_half":
        _, ceiling = _room()
        _forbid(ceiling, [0.5, 0, 0, -3.0], "FLOAT")
    elif name == "forbidden_point":
        _, ceiling = _room()
        _forbid(ceiling, [1] * 9, "BOOLEAN", "POINT")
    elif name == "text_only_light":
        fv, ff = _grid(2)
        floor = _mesh("floor", fv, ff)
        floor["relight_no_lights"] = True
        _paint(floor)
        curve = bpy.data.curves.new("Text", "FONT")
        curve.body = "Hi"
        text = bpy.data.objects.new("Text", curve)
        text.location = (0.2, 0.2, 1.0)
        text.rotation_euler = (math.pi, 0, 0)
        bpy.context.scene.collection.objects.link(text)
    elif name == "ceiling_scaled_to_zero":
        _, ceiling = _room()
        ceiling.scale = (0.0, 0.0, 0.0)
    elif name == "instance_collision":
        fv, ff = _grid(2)
        floor = _mesh("floor", fv, ff)
        floor["relight_no_lights"] = True
        _paint(floor)
        coll = bpy.data.collections.new("src")  # not linked to the scene: only instanced
        wv, wf = _grid(1, x0=5, y0=5, z=0.5)
        _mesh("ceiling", wv, wf, collection=coll)
        inst = bpy.data.objects.new("Inst", None)
        inst.instance_type = "COLLECTION"
        inst.instance_collection = coll
        bpy.context.scene.collection.objects.link(inst)
        cv, cf = _grid(2, z=1.0, flip=True)
        _mesh("Inst/ceiling", cv, cf)  # a real object with the instance group's name
    elif name == "linked_ceiling":
        lib = _library(d)
        fv, ff = _grid(2)
        floor = _mesh("floor", fv, ff)
        floor["relight_no_lights"] = True
        _paint(floor)
        _link(lib, "lib_ceiling")
    elif name == "linked_lamp":  # radiosity: the library's ceiling emits
        _reset()
        cv, cf = _grid(2, z=1.0, flip=True)
        _mesh("lib_ceiling", cv, cf, material=_emissive("lamp", 1.0))
        lib = os.path.join(d, "lib_lamp.blend")
        bpy.ops.wm.save_as_mainfile(filepath=lib)
        _reset()
        fv, ff = _grid(2)
        _mesh("floor", fv, ff)
        _link(lib, "lib_ceiling")
    elif name == "bright_lamp":
        _room()
        led = _emissive("led", 30000.0)  # radiosity 94,000 W/m^2: above float16's 65,504
        _mesh("led", [(0.49, 0.49, 0.95), (0.51, 0.49, 0.95), (0.51, 0.51, 0.95), (0.49, 0.51, 0.95)],
              [(3, 2, 1, 0)], material=led)
    elif name == "lamp_room":  # radiosity/reduce: an emissive ceiling
        fv, ff = _grid(2)
        _mesh("floor", fv, ff)
        cv, cf = _grid(2, z=1.0, flip=True)
        _mesh("ceiling", cv, cf, material=_emissive("lamp", 1.0))
    elif name == "empty":
        pass
    elif name == "nan_vertex":
        _mesh("bad", [(0, 0, 0), (1, 0, 0), (math.nan, 1, 0)], [(0, 1, 2)])
    elif name == "corrupt_result":
        _room()
        bpy.context.scene["relight_result"] = "this is not a stored result"
        bpy.context.scene["relight_result_id"] = "0123"
    elif name == "slow_room":  # ~8000 patches: seconds of ray casting, then a long factorisation
        _room()
        bpy.context.scene["relight_max_patch_size"] = 0.016
    elif name == "not_a_blend":
        path = os.path.join(d, "not_a_blend.blend")
        with open(path, "wb") as fh:
            fh.write(b"this is not a blend file at all")
        return path
    elif name == "truncated":
        path = os.path.join(d, "truncated.blend")
        with open(path, "wb") as fh:
            fh.write(b"BLENDER-v404RENDH" + b"\0" * 20)
        return path
    elif name == "missing":
        return os.path.join(d, "missing.blend")
    elif name == "directory":
        return d
    else:
        raise KeyError(name)
    _save(path)
    _reset()
    return path


def scene_cache(tmp_path_factory, prefix, builder):
    """get(name) -> path of scene ``name`` made by ``builder(name, directory)``, built once (lazily)."""
    d = str(tmp_path_factory.mktemp(prefix))
    built = {}

    def get(name):
        if name not in built:
            built[name] = builder(name, d)
        return built[name]

    return get


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """scenes(name) -> path of the scene, built once per module (lazily)."""
    return scene_cache(tmp_path_factory, "hostile", build)


# ============================================================================ checks

def strict_json(path):
    """The report, refusing NaN / Infinity (json's non-standard constants)."""
    def bad(c):
        raise AssertionError(f"non-finite {c} in {path}")

    with open(path) as fh:
        return json.load(fh, parse_constant=bad)


def _attr_values(a):
    n = len(a.data)
    if a.data_type in ("FLOAT_COLOR", "BYTE_COLOR"):
        v = np.zeros(4 * n, dtype=np.float32)
        a.data.foreach_get("color", v)
    elif a.data_type in ("FLOAT_VECTOR",):
        v = np.zeros(3 * n, dtype=np.float32)
        a.data.foreach_get("vector", v)
    elif a.data_type == "FLOAT2":
        v = np.zeros(2 * n, dtype=np.float32)
        a.data.foreach_get("vector", v)
    elif a.data_type == "FLOAT":
        v = np.zeros(n, dtype=np.float32)
        a.data.foreach_get("value", v)
    elif a.data_type in ("INT", "INT8"):
        v = np.zeros(n, dtype=np.int32)
        a.data.foreach_get("value", v)
    elif a.data_type == "BOOLEAN":
        v = np.zeros(n, dtype=bool)
        a.data.foreach_get("value", v)
    else:
        return None
    return v


def _props(idb):
    out = {}
    for k in idb.keys():
        v = idb[k]
        out[k] = repr(v.to_dict() if hasattr(v, "to_dict") else (v.to_list() if hasattr(v, "to_list") else v))
    return out


def snapshot():
    """Everything a Relight operation could change, hashed: objects (type, transform, collections,
    custom properties), meshes (polygons, materials, every non-internal attribute's values),
    collections, lights, materials, images, the scene's custom properties."""
    out = {}
    for ob in bpy.data.objects:
        d = {"type": ob.type, "matrix": np.round(np.array(ob.matrix_world), 9).tolist(),
             "collections": sorted(c.name for c in ob.users_collection), "props": _props(ob)}
        if ob.type == "MESH":
            me = ob.data
            d["mesh"] = (me.name, len(me.polygons), [m.name if m else None for m in me.materials], _props(me))
            d["attributes"] = {a.name: (a.domain, a.data_type, hashlib.sha256(v.tobytes()).hexdigest()
                                        if (v := _attr_values(a)) is not None else None)
                               for a in me.attributes if not a.name.startswith(".")}
        if ob.type == "LIGHT":
            d["light"] = (ob.data.type, ob.data.energy, tuple(ob.data.color))
        out["object " + ob.name] = d
    out["collections"] = {c.name: (sorted(o.name for o in c.objects), _props(c)) for c in bpy.data.collections}
    out["scene"] = _props(bpy.context.scene)
    for kind in ("meshes", "materials", "lights", "images", "collections", "objects"):
        out[kind] = sorted(x.name for x in getattr(bpy.data, kind))
    return out


def assert_scene_finite():
    """No NaN or inf anywhere Relight writes: mesh attributes, lights, the stored result."""
    for me in bpy.data.meshes:
        for a in me.attributes:
            v = _attr_values(a)
            if v is not None and v.dtype.kind == "f":
                assert np.all(np.isfinite(v)), f"non-finite values in {me.name}.{a.name}"
    for light in bpy.data.lights:
        assert math.isfinite(light.energy) and all(math.isfinite(c) for c in light.color), light.name
    for ob in bpy.data.objects:
        assert np.all(np.isfinite(np.array(ob.matrix_world))), ob.name
    scene = bpy.context.scene
    if "relight_result" in scene.keys():
        from relight_addon.blender import results

        try:
            data = results.load_result(scene)
        except ValueError:
            return  # an unreadable stored result (a case of its own) holds no number at all
        for k, v in vars(data).items():
            if isinstance(v, np.ndarray) and v.dtype.kind == "f":
                assert np.all(np.isfinite(v)), f"non-finite stored {k}"


# ============================================================================ the CLI table

@dataclass
class Cli:
    id: str
    scene: str
    extra: list = field(default_factory=list)
    code: int = 2
    message: str = ""  # in the one error line (code 2), or in a report warning (code 0)
    command: str = "solve"
    report: bool = True  # pass --report {tmp}/r.json
    out: bool = False  # pass --out {tmp}/out.blend
    report_left: bool = False  # a failure that still leaves the report (written first)
    check: object = None  # check(report, out_path_or_None, tmp) for passing cases


def _surface_lights(report):
    """The final configuration's surface lights (a lamp the solve placed has no polygon)."""
    return [light for light in report["final"]["lights"] if light["polygons"]]


def _lights(report):
    return [(light["object"], tuple(light["polygons"])) for light in report["final"]["lights"]]


def _check_no_light_on(*forbidden):
    """Some light answers, and no surface light lies on a forbidden polygon (a lamp the solve
    placed has no polygon: where it may hang is tests/test_engine_lamp_refinement.py's Mount)."""
    def check(report, out, tmp):
        lit = {(o, p) for o, polys in _lights(report) for p in polys}
        assert report["final"]["lights"] and not lit & set(forbidden), (lit, _lights(report))
    return check


def _check_instance_collision(report, out, tmp):
    # the real object named like the instance group keeps its rows and its lights
    assert len(report["objects"]["Inst/ceiling"]["radiosity"]) == 4
    surface = _surface_lights(report)
    assert surface and all(light["object"] == "Inst/ceiling" for light in surface)
    assert set(report["objects"]) == {"floor", "Inst/ceiling"}  # instance groups are not reported
    bpy.ops.wm.open_mainfile(filepath=out)
    assert "relight_radiosity" in bpy.data.objects["Inst/ceiling"].data.attributes


def _check_linked(report, out, tmp):
    surface = _surface_lights(report)
    assert surface and all(light["object"] == "lib_ceiling" for light in surface)
    bpy.ops.wm.open_mainfile(filepath=out)
    from relight_scene import emitted

    shown = emitted(bpy.context.scene)  # the lights are in the saved copy (Relight's own object)
    assert shown is not None and len(shown["triangles"]) >= 2 * len(surface)
    assert "relight_radiosity" in bpy.data.objects["floor"].data.attributes
    assert "relight_radiosity" not in bpy.data.objects["lib_ceiling"].data.attributes


def _check_bright(report, out, tmp):
    bpy.ops.wm.open_mainfile(filepath=out)
    from relight_addon.blender import results

    data = results.load_result(bpy.context.scene)
    assert data.radiosity.max() > 65504.0  # beyond float16, stored exactly as float32 allows
    b = np.array(report["objects"]["led"]["radiosity"])
    assert b.max() == pytest.approx(math.pi * 30000.0, rel=1e-3)  # its own exitance (+ a little reflected)


def _room_target_norm(report, scale=1.0):
    """||b_P|| of the room: pi x 0.2 x scale on every target patch (equal areas), 3 channels."""
    return math.pi * 0.2 * scale * math.sqrt(3 * report["inverse"]["n_targets"])


def _check_scale_two(report, out, tmp):
    assert report["inverse"]["target_norm"] == pytest.approx(_room_target_norm(report, 2.0), rel=1e-6)  # float32


def _check_byte_equals_float(report, out, tmp):
    # a byte layer holds 0.2 to 1/255 in sRGB: the targets agree with the FLOAT_COLOR room's to 1 %
    assert report["inverse"]["target_norm"] == pytest.approx(_room_target_norm(report), rel=0.01)


def _check_negative_target(report, out, tmp):
    assert any("1 target(s) with a negative colour set to 0" in w for w in report["warnings"])
    assert report["objects"]["floor"]["target"][0] == pytest.approx([0.0, math.pi * 0.2, math.pi * 0.2])


def _check_room_ok(report, out, tmp):
    assert report["inverse"]["target_norm"] == pytest.approx(_room_target_norm(report), rel=1e-6)


CLI_CASES = [
    # --- files
    Cli("missing-file", "missing", message="no such .blend file"),
    Cli("not-a-blend", "not_a_blend", message="is not a .blend file"),
    Cli("truncated-blend", "truncated", message="truncated.blend"),
    Cli("scene-is-a-directory", "directory", message="no such .blend file"),
    Cli("empty-scene", "empty", message="no visible mesh objects"),
    Cli("nan-vertex", "nan_vertex", command="radiosity", message="NaN or infinite vertex coordinates"),
    # --- options
    Cli("seed-negative", "room", ["--seed", "-1"], message="--seed: must be a non-negative integer"),
    Cli("seed-not-int", "room", ["--seed", "x"], message="--seed: not an integer"),
    Cli("rays-zero", "room", ["--rays-per-patch", "0"], message="must be at least 1"),
    Cli("rays-one", "room", ["--rays-per-patch", "1", "--estimator", "raycast", "--patch-model", "polygon",
                             "--no-spot-lamps"],  # the cells' rays alone
        message="no ray from a candidate light reached a target with 1 ray(s) per patch"),
    Cli("rays-absurd", "room", ["--rays-per-patch", str(10 ** 11)], message="of memory (estimate), more than the"),
    Cli("patch-size-micro", "room", ["--max-patch-size", "1e-6"], message="of memory (estimate), more than the"),
    Cli("patch-size-1e-300", "room", ["--max-patch-size", "1e-300"], message="of memory (estimate), more than the"),
    Cli("patch-size-nan", "room", ["--max-patch-size", "nan"], message="must be a positive length"),
    Cli("patch-size-negative", "room", ["--max-patch-size", "-1"], message="must be a positive length"),
    Cli("light-size-zero", "room", ["--light-size", "0"], message="must be a positive length"),
    Cli("refine-passes-negative", "room", ["--refine-passes", "-1"], message="must be 0 or more"),
    Cli("target-scale-zero", "room", ["--target-scale", "0"], message="--target-scale: must be a positive number"),
    Cli("target-scale-nan", "room", ["--target-scale", "nan"], message="--target-scale: must be a positive number"),
    Cli("error-threshold-negative", "room", ["--error-threshold", "-1"], message="--error-threshold"),
    Cli("max-lights-zero", "room", ["--max-lights", "0"], message="must be at least 1"),
    Cli("unknown-selection", "room", ["--selection", "magic"], message="invalid choice: 'magic'"),
    Cli("unknown-option", "room", ["--bogus"], message="unrecognized arguments: --bogus"),
    Cli("no-report", "room", report=False, message="--report"),
    # --- outputs: checked before any work
    Cli("report-equals-out", "room", ["--report", "{tmp}/same.out", "--out", "{tmp}/same.out"], report=False,
        message="--report and --out name the same file"),
    Cli("report-equals-render", "room", ["--report", "{tmp}/same.png", "--render", "{tmp}/same.png"], report=False,
        message="--report and --render name the same file"),
    Cli("out-equals-render", "room", ["--out", "{tmp}/x", "--render", "{tmp}/x"], message="--out and --render"),
    Cli("out-is-input", "room", ["--out", "{scene}"], message="--out must not be the input file"),
    Cli("report-is-input", "room", ["--report", "{scene}"], report=False, message="--report must not be the input"),
    Cli("out-under-a-file", "room", ["--out", "{scene}/x.blend"], message="is not a directory"),
    Cli("report-under-a-file", "room", ["--report", "{scene}/r.json", "--out", "{tmp}/o.blend"], report=False,
        message="cannot write --report"),
    Cli("report-is-a-directory", "room", ["--report", "{tmp}"], report=False, message="it is a directory"),
    Cli("out-unwritable", "room", ["--out", "/proc/relight-x.blend"], message="cannot write --out"),
    Cli("report-unwritable-before-out", "room", ["--report", "/proc/r.json", "--out", "{tmp}/o.blend"],
        report=False, message="cannot write --report"),
    # --- scene properties and attributes
    Cli("scale-string", "scale_string", message="custom property relight_target_scale is 'bright', not a number"),
    Cli("scale-zero", "scale_zero", message="every target asks for radiosity 0"),
    Cli("scale-negative", "scale_negative", message="relight_target_scale is -2: it must be >= 0"),
    Cli("scale-nan", "scale_nan", message="relight_target_scale is nan: it must be a finite number"),
    Cli("scale-two", "scale_two", code=0, check=_check_scale_two),
    Cli("patch-size-string", "size_string", message="custom property relight_max_patch_size is 'big'"),
    Cli("patch-size-prop-zero", "size_zero", message="relight_max_patch_size is 0: it must be a positive length"),
    Cli("patch-size-prop-tiny", "size_tiny", message="of memory (estimate), more than the"),
    Cli("no-lights-string", "no_lights_string",
        message="object 'ceiling': custom property relight_no_lights is 'false', not a boolean or a number"),
    Cli("no-target", "room_unpainted", message="no target: paint a radiosity"),
    Cli("black-targets", "room_black", message="every target asks for radiosity 0"),
    Cli("target-point-domain", "target_point",
        message="floor: its relight_target is a Vertex (POINT) Color (FLOAT_COLOR) attribute"),
    Cli("target-float-corner", "target_float_corner",
        message="its relight_target is a Face Corner (CORNER) Float (FLOAT) attribute"),
    Cli("target-nan", "target_nan", message="floor: its relight_target holds NaN or infinite colours"),
    Cli("target-negative", "target_negative", code=0, check=_check_negative_target),
    Cli("target-byte", "target_byte", code=0, check=_check_byte_equals_float),
    Cli("forbidden-int-all", "forbidden_int_all", message="no candidate light: every face is forbidden"),
    Cli("forbidden-int-half", "forbidden_int_half", code=0,
        check=_check_no_light_on(("ceiling", 0), ("ceiling", 3))),
    Cli("forbidden-float-half", "forbidden_float_half", code=0,
        check=_check_no_light_on(("ceiling", 0), ("ceiling", 3))),
    Cli("forbidden-point-domain", "forbidden_point",
        message="ceiling: its relight_forbidden is a Vertex (POINT) Boolean (BOOLEAN) attribute"),
    Cli("text-as-the-only-light", "text_only_light", message="are not meshes: 'Text' (FONT)"),
    Cli("scaled-to-zero", "ceiling_scaled_to_zero", message="object 'ceiling' has no area in world space"),
    Cli("reduce-no-emitter", "room", command="reduce", message="no emitter to reduce"),
    # --- results: storage, keys, linked data
    Cli("instance-name-collision", "instance_collision", code=0, out=True, check=_check_instance_collision),
    Cli("linked-mesh", "linked_ceiling", code=0, out=True, message="linked from", check=_check_linked),
    Cli("bright-lamp-float16", "bright_lamp", code=0, out=True, check=_check_bright),
    Cli("corrupt-stored-result-replaced", "corrupt_result", code=0, out=True, check=_check_room_ok),
    Cli("radiosity-out", "lamp_room", command="radiosity", code=0, out=True),
    Cli("radiosity-linked-mesh", "linked_lamp", command="radiosity", code=0, out=True, message="linked from",
        check=lambda report, out, tmp: _check_linked_radiosity(out)),
    Cli("reduce-linked-emitter", "linked_lamp", command="reduce", code=0, out=True,
        message="lib_ceiling: its mesh is linked (read-only), so its own emission cannot be switched off"),
]


def _check_linked_radiosity(out):
    bpy.ops.wm.open_mainfile(filepath=out)
    assert "relight_radiosity" in bpy.data.objects["floor"].data.attributes
    assert "relight_radiosity" not in bpy.data.objects["lib_ceiling"].data.attributes
    assert bpy.data.objects["lib_ceiling"].data.library is not None  # still the library's mesh


def _fill(a, tmp, scene):
    return str(a).replace("{tmp}", str(tmp)).replace("{scene}", scene)


@pytest.mark.parametrize("case", CLI_CASES, ids=[c.id for c in CLI_CASES])
def test_cli(case, run_cli, scenes, tmp_path):
    if any("/proc/" in str(a) for a in case.extra) and not os.path.isdir("/proc/self"):
        pytest.skip("needs /proc (Linux) for an unwritable path that root cannot write either")
    scene = scenes(case.scene)
    before = file_digest(scene) if os.path.isfile(scene) else None
    report_path = tmp_path / "r.json"
    out_path = tmp_path / "out.blend"
    argv = [case.command, scene] + (["--report", report_path] if case.report else [])
    argv += (["--out", out_path] if case.out else []) + [_fill(a, tmp_path, scene) for a in case.extra]
    if "--rays-per-patch" not in case.extra:
        argv += RAYS
    code, report, err = run_cli(argv)
    assert "Traceback" not in err, err
    assert code == case.code, err
    if before is not None:
        assert file_digest(scene) == before, "the input file changed"
    if case.code == 2:
        lines = [ln for ln in err.strip().splitlines() if ln.startswith("relight: error:")]
        assert len(lines) == 1 and err.strip().splitlines()[-1] == lines[0], err
        assert case.message in lines[0], lines[0]
        assert not out_path.exists() and not any(p.suffix == ".blend" for p in tmp_path.iterdir())
        assert report_path.exists() == case.report_left
        return
    report = strict_json(report_path)
    if case.message:
        assert any(case.message in w for w in report["warnings"]), report["warnings"]
    if case.out:
        assert out_path.exists()
    if case.check is not None:
        case.check(report, str(out_path) if case.out else None, tmp_path)
    if case.out:
        bpy.ops.wm.open_mainfile(filepath=str(out_path))
        assert_scene_finite()


def test_cli_report_survives_a_failing_save(run_cli, scenes, tmp_path, monkeypatch):
    """The report is written before --out: a save that fails (after the checks) still leaves it."""
    from relight_addon.blender import results

    def fail(path):
        raise RuntimeError("Error: Cannot open file x.blend@ for writing: No space left on device")

    monkeypatch.setattr(results, "save_copy", fail)
    scene = scenes("room")
    before = file_digest(scene)
    code, _, err = run_cli(["solve", scene, "--report", tmp_path / "r.json", "--out", tmp_path / "o.blend", *RAYS])
    assert code == 2 and err.strip().splitlines()[-1] == (
        f"relight: error: cannot write --out {tmp_path / 'o.blend'}: Cannot open file x.blend@ for writing: "
        "No space left on device")
    report = strict_json(tmp_path / "r.json")
    assert report["final"]["lights"] and report["command"] == "solve"
    assert file_digest(scene) == before


def test_cli_unexpected_error_is_one_line(run_cli, scenes, tmp_path, monkeypatch):
    """An unexpected exception anywhere (here a TypeError inside the job) is still one line, exit 2."""
    from relight_addon.pipeline import jobs

    def boom(*a, **k):
        raise TypeError("something nobody expected")

    monkeypatch.setattr(jobs, "run_solve", boom)
    code, _, err = run_cli(["solve", scenes("room"), "--report", tmp_path / "r.json", *RAYS])
    assert code == 2 and "Traceback" not in err
    assert err.strip().splitlines()[-1] == ("relight: error: unexpected TypeError: something nobody expected "
                                            "(please report it; RELIGHT_DEBUG=1 shows the traceback)")


def test_cli_memory_error_is_one_line(run_cli, scenes, tmp_path, monkeypatch):
    from relight_addon.pipeline import jobs

    def oom(*a, **k):
        raise MemoryError("Unable to allocate 32.0 GiB for an array with shape (1073741824, 4)")

    monkeypatch.setattr(jobs, "run_solve", oom)
    code, _, err = run_cli(["solve", scenes("room"), "--report", tmp_path / "r.json", *RAYS])
    assert code == 2 and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("relight: error: out of memory: Unable to allocate 32.0 GiB")
    assert not (tmp_path / "r.json").exists()


def test_cli_estimate_before_progress(run_cli, scenes, tmp_path):
    """stderr (not a terminal): the estimate first, then Blender-style progress lines; --quiet: none."""
    code, report, err = run_cli(["solve", scenes("room"), "--report", tmp_path / "r.json", *RAYS])
    assert code == 0
    lines = err.strip().splitlines()
    assert re.fullmatch(r"relight: \d+ patches: about .* of memory and .* s \(estimate\)", lines[0]), lines[0]
    progress = [ln for ln in lines[1:] if " s | " in ln]
    assert progress and len(progress) == len(lines) - 1, lines
    assert any("form factors" in ln for ln in progress) and any("reduction" in ln for ln in progress)
    assert report["estimate"]["memory_bytes"] > 0
    code, _, err = run_cli(["solve", scenes("room"), "--report", tmp_path / "r.json", "--quiet", *RAYS])
    assert code == 0 and err == ""


def test_progress_display_modes():
    from relight_addon.cli import Progress

    s = io.StringIO()
    p = Progress(s, tty=False)
    for f in (0.0, 0.01, 0.05, 0.1, 0.15, 0.5, 0.5):
        p("form_factors", f)
    p("reduction", 0.9)
    p.close()
    lines = s.getvalue().splitlines()
    assert [ln.split("| ")[1] for ln in lines] == ["form factors   0 %", "form factors  10 %", "form factors  50 %",
                                                   "reduction  90 %"]
    s = io.StringIO()
    p = Progress(s, tty=True)
    p("form_factors", 0.5)
    p("inverse", 0.8)
    p.close()
    text = s.getvalue()
    assert text.count("\r") == 2 and text.endswith("\n") and text.count("\n") == 1
    assert "[############............]  50 %" in text


def test_patch_count_estimate_is_exact_for_the_polygon_model(bpy_clean):
    """The memory guard's patch count before meshing, against the meshed count (quads split into
    grids, triangles into k x k pieces, small faces whole)."""
    from relight_addon.blender import export
    from relight_addon.pipeline import meshing
    from relight_addon.engine.options import JobOptions

    _room()
    _mesh("tri", [(0, 0, 2), (1, 0, 2), (0, 1, 2)], [(0, 1, 2)])
    _mesh("ngon", [(0, 0, 3), (1, 0, 3), (1.5, 0.5, 3), (1, 1, 3), (0, 1, 3)], [(0, 1, 2, 3, 4)])
    exp = export.export_scene()
    for size in (10.0, 0.3, 0.1, 0.07):
        opts = JobOptions(max_patch_size=size, patch_model="polygon").validate()
        est = estimate_patch_count(exp.faces, opts)
        assert est == meshing.mesh_for_job(exp.faces, opts).n_patches, size


# ---------------------------------------------------------------------------- Ctrl-C: real processes

def _start(args):
    return subprocess.Popen([sys.executable, "-m", "relight_addon", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _interrupt_when(proc, predicate, quiet=None, timeout=120):
    """Read stderr lines until ``predicate(line)`` (or, with ``quiet``, until no line came for
    that many seconds after it), then send SIGINT; returns (exit code, all stderr, seconds from
    SIGINT to exit)."""
    import queue
    import threading

    lines = queue.Queue()

    def reader():
        for ln in iter(proc.stderr.readline, ""):
            lines.put(ln)

    threading.Thread(target=reader, daemon=True).start()
    seen, armed = [], False
    t_end = time.time() + timeout
    while time.time() < t_end:
        try:
            line = lines.get(timeout=quiet if (armed and quiet) else 1.0)
        except queue.Empty:
            if armed and quiet:
                break  # quiet for ``quiet`` s: inside a long stage
            if proc.poll() is not None:
                break
            continue
        seen.append(line)
        if not armed and predicate(line):
            armed = True
            if not quiet:
                break
    if not armed or proc.poll() is not None:
        proc.kill()
        proc.communicate()
        pytest.fail("the awaited stage never came:\n" + "".join(seen))
    t0 = time.time()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=120)
    dt = time.time() - t0
    time.sleep(0.3)  # the reader drains what is left
    while not lines.empty():
        seen.append(lines.get())
    return proc.returncode, "".join(seen), dt


@pytest.mark.parametrize("stage", ["ray casting", "a long stage"])
def test_ctrl_c_cancels_with_130(stage, scenes, tmp_path):
    """SIGINT during ray casting, and inside the first stage that runs for seconds without a
    progress line (about 8000 patches): 'relight: cancelled', exit 130 within seconds, no
    traceback, no report, input unchanged."""
    scene = scenes("slow_room")
    before = file_digest(scene)
    proc = _start(["solve", scene, "--report", tmp_path / "r.json", "--rays-per-patch", "1024"])

    def percent(ln):
        m = re.search(r"\| form factors +(\d+) %", ln)
        return int(m.group(1)) if m else -1

    if stage == "ray casting":
        code, err, dt = _interrupt_when(proc, lambda ln: 10 <= percent(ln) < 30)
    else:  # no progress line for 3 s once the ray casting has started
        code, err, dt = _interrupt_when(proc, lambda ln: percent(ln) >= 0, quiet=3.0)
    assert code == 130, err
    lines = err.strip().splitlines()
    assert "Traceback" not in err and lines[-1] == "relight: cancelled", err
    assert lines[0].startswith("relight: ") and lines[0].endswith("(estimate)")
    assert not (tmp_path / "r.json").exists()
    assert file_digest(scene) == before
    assert dt < 10, dt


# ============================================================================ the operator table

@pytest.fixture(scope="module")
def addon():
    import relight_addon

    relight_addon.register()
    yield
    _reset()
    relight_addon.unregister()


def _open(path):
    bpy.ops.wm.open_mainfile(filepath=path)
    return bpy.context.scene


def _activate(*names, mode=None):
    if bpy.context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    for ob in bpy.context.scene.objects:
        ob.select_set(ob.name in names)
    bpy.context.view_layer.objects.active = bpy.data.objects[names[0]]
    if mode == "EDIT":
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")


def _colors(ob, name="relight_target"):
    a = ob.data.attributes[name]
    v = np.zeros(4 * len(a.data), dtype=np.float32)
    a.data.foreach_get("color", v)
    return v.reshape(-1, 4)


@dataclass
class Op:
    id: str
    scene: str
    setup: object  # setup() after the scene is open: selection, mode, prior solve...
    run: object  # run() -> the operator's result set
    error: str = ""  # "" -> FINISHED; else the ERROR report (bpy.ops raises RuntimeError), in part
    warning: str = ""  # a WARNING the operator must report (printed by Blender)
    check: object = None  # check() after a FINISHED run


def _solve():
    return bpy.ops.relight.solve()


def _prepare_solved():
    bpy.context.scene.relight.rays_per_patch = 256
    result = _solve()
    assert result == {"FINISHED"}
    return result


def _sort_ceiling_faces():
    import bmesh

    _prepare_solved()
    me = bpy.data.objects["ceiling"].data
    bm = bmesh.new()
    bm.from_mesh(me)
    bm.faces.ensure_lookup_table()
    bm.faces.sort(key=lambda f: -f.index)
    bm.to_mesh(me)
    bm.free()
    me.update()


def _delete_ceiling():
    _prepare_solved()
    bpy.data.objects.remove(bpy.data.objects["ceiling"])


def _user_relight_lights():
    coll = bpy.data.collections.new("Relight Lights")
    bpy.context.scene.collection.children.link(coll)
    coll.objects.link(bpy.data.objects.new("my_key_light", bpy.data.lights.new("my_key_light", "POINT")))


def _check_byte_kept():
    ob = bpy.data.objects["floor"]
    a = ob.data.attributes["relight_target"]
    assert a.data_type == "BYTE_COLOR" and (_colors(ob)[:, 3] == 1).all()
    assert [x.name for x in ob.data.color_attributes] == ["relight_target"]


def _check_byte_fill():
    bpy.ops.object.mode_set(mode="OBJECT")
    ob = bpy.data.objects["floor"]
    assert [(a.name, a.data_type) for a in ob.data.color_attributes] == [("relight_target", "BYTE_COLOR")]
    c = _colors(ob)  # linear values, as export reads them: the paint colour (0.5, 0.25, 1) to 1/255 in sRGB
    assert np.allclose(c[:, :3], (0.5, 0.25, 1.0), atol=0.01) and (c[:, 3] == 1).all()
    from relight_addon.blender import layers

    t = layers.face_flags(ob, "target")
    assert t.all()


def _check_forbid_kept_type(dtype):
    def check():
        bpy.ops.object.mode_set(mode="OBJECT")
        a = bpy.data.objects["ceiling"].data.attributes["relight_forbidden"]
        assert a.data_type == dtype and a.domain == "FACE"
        from relight_addon.blender import layers

        assert layers.face_flags(bpy.data.objects["ceiling"], "forbidden").all()
    return check


def _check_user_collection_kept():
    coll = bpy.data.collections["Relight Lights"]
    assert [o.name for o in coll.objects] == ["my_key_light"]


def _check_scale_synced():
    scene = bpy.context.scene
    assert scene.relight.target_scale == 2.0  # the panel shows the custom property
    scene.relight.target_scale = 3.0
    assert scene["relight_target_scale"] == 3.0  # and writes it


def _check_linked_solve():
    from relight_scene import emitted

    shown = emitted(bpy.context.scene)
    assert shown is not None and len(shown["triangles"]) > 0  # the lights show
    assert "relight_radiosity" not in bpy.data.objects["lib_ceiling"].data.attributes
    assert "relight_radiosity" in bpy.data.objects["floor"].data.attributes


def _check_bright_solve():
    from relight_addon.blender import results

    data = results.load_result(bpy.context.scene)
    assert data.radiosity.max() > 65504.0


def _check_int_forbidden_solve():
    from relight_addon.blender import results

    lit = results.shown_light_polygons(bpy.context.scene, bpy.data.objects["ceiling"])
    settings = bpy.context.scene.relight
    assert settings.curve[settings.curve_index].n_lights > 0  # cells, or lamps the solve placed
    assert not lit[0] and not lit[3]


def _check_area_lights_beside_users():
    _check_user_collection_kept()
    ours = [c for c in bpy.data.collections if c.get("relight_area_lights")]
    assert len(ours) == 1 and ours[0].name != "Relight Lights"
    lights = [o.data for o in ours[0].objects]
    settings = bpy.context.scene.relight
    n = settings.curve[settings.curve_index].n_lights  # one area light per lit cell: at least one per light
    # an area light per lit cell, a copy of each lamp the solve placed: at least one per light
    assert len(lights) >= n > 0 and all(light.type in ("AREA", "SPOT", "POINT") and light.energy > 0
                                        for light in lights)

OP_CASES = [
    # --- targets
    Op("paint-keeps-byte-layer", "target_byte", lambda: _activate("floor"), lambda: bpy.ops.relight.paint_targets(),
       check=_check_byte_kept),
    Op("paint-point-layer-refused", "target_point", lambda: _activate("floor"),
       lambda: bpy.ops.relight.paint_targets(), error="its relight_target is a Vertex (POINT) Color"),
    Op("paint-linked-mesh-refused", "linked_ceiling", lambda: _activate("lib_ceiling"),
       lambda: bpy.ops.relight.paint_targets(), error="its mesh is linked from"),
    Op("fill-into-byte-layer", "target_byte",
       lambda: (setattr(bpy.context.scene.relight, "paint_color", (0.5, 0.25, 1.0)), _activate("floor", mode="EDIT")),
       lambda: bpy.ops.relight.fill_targets(), check=_check_byte_fill),
    Op("fill-all-or-nothing", "target_point", lambda: _activate("ceiling", "floor", mode="EDIT"),
       lambda: bpy.ops.relight.fill_targets(), error="floor: its relight_target is a Vertex (POINT)"),
    Op("clear-targets-linked-refused", "linked_painted", lambda: _activate("lib_ceiling", "floor"),
       lambda: bpy.ops.relight.clear_targets(), error="lib_ceiling: its mesh is linked"),
    # --- candidates
    Op("forbid-into-int-layer", "forbidden_int_half", lambda: _activate("ceiling", mode="EDIT"),
       lambda: bpy.ops.relight.forbid_faces(), check=_check_forbid_kept_type("INT")),
    Op("forbid-into-float-layer", "forbidden_float_half", lambda: _activate("ceiling", mode="EDIT"),
       lambda: bpy.ops.relight.forbid_faces(), check=_check_forbid_kept_type("FLOAT")),
    Op("forbid-point-layer-refused", "forbidden_point", lambda: _activate("ceiling", mode="EDIT"),
       lambda: bpy.ops.relight.forbid_faces(), error="ceiling: its relight_forbidden is a Vertex (POINT)"),
    Op("select-point-forbidden-refused", "forbidden_point", lambda: _activate("ceiling"),
       lambda: bpy.ops.relight.select_faces(kind="FORBIDDEN"), error="its relight_forbidden is a Vertex"),
    # --- solve
    Op("solve-scale-string", "scale_string", lambda: None, _solve,
       error="custom property relight_target_scale is 'bright'"),
    Op("solve-scale-zero-from-panel", "room", lambda: setattr(bpy.context.scene.relight, "target_scale", 0.0),
       _solve, error="every target asks for radiosity 0"),
    Op("target-scale-one-source", "scale_two", lambda: None, lambda: {"FINISHED"}, check=_check_scale_synced),
    Op("solve-no-lights-string", "no_lights_string", lambda: None, _solve,
       error="custom property relight_no_lights is 'false'"),
    Op("solve-point-target", "target_point", lambda: None, _solve, error="no target: paint a radiosity"),
    Op("solve-micro-patches", "size_tiny", lambda: None, _solve, error="of memory (estimate), more than the"),
    Op("solve-linked-mesh", "linked_ceiling", lambda: None, _prepare_solved, warning="its mesh is linked from",
       check=_check_linked_solve),
    Op("solve-bright-lamp", "bright_lamp", lambda: None, _prepare_solved, check=_check_bright_solve),
    Op("solve-int-forbidden", "forbidden_int_half", lambda: None, _prepare_solved, check=_check_int_forbidden_solve),
    # --- results
    Op("apply-without-result", "room", lambda: None, lambda: bpy.ops.relight.apply_configuration(index=0),
       error="No Relight result in this scene"),
    Op("apply-stale-sorted-faces", "room", _sort_ceiling_faces, lambda: bpy.ops.relight.apply_configuration(index=0),
       error="ceiling has changed since the solve (its polygons or their vertex order changed): nothing applied"),
    Op("apply-object-deleted", "room", _delete_ceiling, lambda: bpy.ops.relight.apply_configuration(index=0),
       error="object 'ceiling' of the stored result is no longer in the scene"),
    Op("apply-index-out-of-range", "room", _prepare_solved, lambda: bpy.ops.relight.apply_configuration(index=99),
       error="Configuration 99 does not exist"),
    Op("area-lights-corrupt-result", "corrupt_result", lambda: None, lambda: bpy.ops.relight.make_area_lights(),
       error="the stored Relight result of scene 'Scene' cannot be read"),
    Op("area-lights-without-result", "room", _user_relight_lights, lambda: bpy.ops.relight.make_area_lights(),
       error="no Relight result in this scene"),
    Op("area-lights-stale", "room", _sort_ceiling_faces, lambda: bpy.ops.relight.make_area_lights(),
       error="ceiling has changed since the solve"),
    Op("clear-results-keeps-user-collection", "room", _user_relight_lights,
       lambda: bpy.ops.relight.clear_results(), check=_check_user_collection_kept),
    Op("area-lights-beside-user-collection", "room", lambda: (_user_relight_lights(), _prepare_solved()),
       lambda: bpy.ops.relight.make_area_lights(), check=_check_area_lights_beside_users),
    Op("apply-linked-mesh-warns", "linked_ceiling", _prepare_solved,
       lambda: bpy.ops.relight.apply_configuration(index=0), warning="its mesh is linked from",
       check=_check_linked_solve),
]




def _build_extra(name, d):
    if name == "linked_painted":  # the library's ceiling carries a relight_target
        lib = _library(d, painted=True)
        fv, ff = _grid(2)
        floor = _mesh("floor", fv, ff)
        _paint(floor)
        _link(lib, "lib_ceiling")
        return _save(os.path.join(d, "linked_painted.blend"))
    raise KeyError(name)


@pytest.mark.parametrize("case", OP_CASES, ids=[c.id for c in OP_CASES])
def test_operator(case, addon, scenes, tmp_path, capfd):
    try:
        path = scenes(case.scene)
    except KeyError:
        _reset()
        path = _build_extra(case.scene, str(tmp_path))
        _reset()
    before_file = file_digest(path)
    _open(path)
    case.setup()
    if bpy.context.mode != "OBJECT":  # the snapshot reads object-mode data; edit mode is re-entered
        bpy.ops.object.mode_set(mode="OBJECT")
        before = snapshot()
        bpy.ops.object.mode_set(mode="EDIT")
    else:
        before = snapshot()
    capfd.readouterr()
    if case.error:
        with pytest.raises(RuntimeError) as info:
            case.run()
        message = str(info.value)
        assert message.startswith("Error: ") and len(message.strip().splitlines()) == 1, message
        assert case.error in message, message
        if bpy.context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        assert snapshot() == before, "a refused operation changed the scene"
    else:
        assert case.run() == {"FINISHED"}
        printed = capfd.readouterr()
        if case.warning:
            assert case.warning in printed.out + printed.err
        if case.check is not None:
            case.check()
    if bpy.context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    assert_scene_finite()
    assert file_digest(path) == before_file
