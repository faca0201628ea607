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

Materials: exported_materials.py. The faces that the scene sees from behind are turned or
doubled, and the back side of open emitters modelled or named in a warning, by
engine/two_sided.py (``ExportedScene.backs``). Relight's attribute layers (targets, illuminance
targets, forbidden faces, the objects' switches, the scene's settings): layers.py. Which objects
a render shows: visibility.py; the meshes as arrays: meshes.py.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import bpy
import numpy as np

from ..engine.scene import FaceSet, SceneError
from ..engine.two_sided import emitting_backs, faces_seen_from_behind
from ..engine.units import MAX_REFLECTANCE, illuminance_lux
from ..engine.world import sees_sky
from .blend_files import newer_file_warning
from .emission_bake import bake_linked_emission
from .exported_materials import material_warnings, not_modelled
from .lamps import export_lamps, hidden_warning
from .layers import (TARGET_ATTRIBUTE, base_attributes, illuminance_targets, no_lights, scene_settings,
                     work_plane)
from .meshes import Builder, evaluated_mesh, geometry_fingerprint, mesh_fingerprint, mesh_geometry, no_area
from .visibility import (Evaluable, exported_objects, hidden_in_viewport, mesh_instances, owner_of,
                         render_visible_objects, rendered)
from .world import world_light

#: object types with geometry that are not exported (only meshes are); VOLUME objects are named
#: apart (exported_materials.not_modelled: a volume is not a surface)
NON_MESH_GEOMETRY = ("CURVE", "FONT", "SURFACE", "META", "CURVES", "POINTCLOUD", "GREASEPENCIL")


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
    #: the emitters whose back side lies against a surface (not modelled: engine.two_sided.emitting_backs),
    #: one dict each: object, power (W), leak (low, high) W, emitted (W), distance (m), near (objects)
    backs: list = field(default_factory=list)


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
    warnings = _scene_warnings(context, objs, renderable, notes)
    b = Builder()
    with Evaluable(context, objs) as shown:  # (disabled in the viewports: evaluated as a render would)
        counts, unmapped, fingerprints = _add_objects(b, context, objs, settings["target_scale"], notes, warnings)
        n_inst = _add_instances(b, context, renderable)
    for ob in objs:  # those shown only for the export: fingerprinted as the viewport evaluates them
        if ob in shown.changed or any(c in shown.changed for c in ob.users_collection):
            fingerprints[ob.name] = mesh_fingerprint(ob)
    names = b.names
    if not names:
        raise SceneError("the scene has no visible mesh objects"
                         + (f" ({notes['candidates'][0]})" if notes["candidates"] else ""))
    b.warnings.extend(material_warnings(b.material_notes))
    b.warnings.extend(bake_linked_emission(b, objs, context))
    b.warnings.extend(faces_seen_from_behind(b))
    back_warnings, backs = emitting_backs(b)
    b.warnings.extend(back_warnings)
    b.warnings.extend(not_modelled(context, objs, b, renderable))
    warnings = warnings + b.warnings + [n for n in notes["target"] if n not in warnings]
    _count_notes(settings, unmapped, n_inst, notes, warnings)
    rho, e = _checked_materials(b, warnings)
    lamps, lamp_warnings = export_lamps(context, renderable, owner_of, notes["emitters"])
    warnings.extend(w for w in lamp_warnings if w not in warnings)
    faces = _face_set(b, objs, rho, e, warnings, lamps)
    try:
        faces.world_radiance, faces.world_name, world_notes = world_light(context.scene, lambda: sees_sky(faces))
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    faces.warnings.extend(w for w in world_notes if w not in faces.warnings)
    return ExportedScene(faces, objs, counts, settings, time.perf_counter() - t0, fingerprints,
                         np.concatenate(b.f_mat), b.lobes, notes=notes, backs=backs)


def _scene_warnings(context, objs, renderable, notes) -> list:
    """The warnings about the scene as a whole, before its meshes are read: a file saved by a newer
    Blender, objects hidden in the viewport, painted objects that do not render (a target note),
    visible objects that are not meshes (a candidates note too)."""
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
    return warnings


def _add_objects(b, context, objs, target_scale, notes, warnings) -> tuple:
    """Add the evaluated mesh of every object of ``objs`` to ``b`` with its base mesh's paint:
    (polygon counts of the base meshes by name, the number of faces a modifier made that map to
    no base-mesh polygon, each object's mesh fingerprint: meshes.geometry_fingerprint)."""
    counts, unmapped, fingerprints = {}, 0, {}
    for oi, ob in enumerate(objs):
        counts[ob.name] = len(ob.data.polygons)
        b.names.append(ob.name)
        target, target_b, forbidden, lux = base_attributes(ob, target_scale, notes["target"])
        ob_eval, me, mapping = evaluated_mesh(ob, context)
        try:
            geo = mesh_geometry(ob_eval, me, ob.name)
            M = np.array(ob_eval.matrix_world, dtype=np.float64)
            fingerprints[ob.name] = geometry_fingerprint(ob, geo, M)
        finally:
            ob_eval.to_mesh_clear()
        if len(geo["lt"]) and no_area(geo, M):
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
    return counts, unmapped, fingerprints


def _add_instances(b, context, renderable) -> int:
    """Add the mesh instances to ``b`` (geometry only: occluders, reflectors and emitters, never
    targets or lights), grouped by "<instancer>/<object>" name; returns how many."""
    geo_cache, group = {}, {}
    n_inst = 0
    for name, ob, M in mesh_instances(context, renderable):
        key = ob.data.as_pointer()
        if key not in geo_cache:
            me = ob.to_mesh()
            try:
                geo_cache[key] = mesh_geometry(ob, me, name)
            finally:
                ob.to_mesh_clear()
        geo = geo_cache[key]
        if name not in group:  # keyed by index everywhere: a real object may have this name too
            group[name] = len(b.names)
            b.names.append(name)
        npoly = len(geo["loop_start"])
        b.add(geo, M, name, group[name], np.full(npoly, -1), np.zeros(npoly, dtype=bool),
              np.zeros((npoly, 3)), np.ones(npoly, dtype=bool))
        n_inst += 1
    return n_inst


def _count_notes(settings, unmapped, n_inst, notes, warnings) -> None:
    """The notes and warnings on a target scale of 0, on unmapped faces and on instances."""
    if settings["target_scale"] == 0:
        notes["target"].append("the target scale is 0 (scene custom property relight_target_scale, the add-on's "
                               "Target Scale, or --target-scale): every target asks for no light")
    if unmapped:
        warnings.append(f"{unmapped} face(s) created by modifiers could not be mapped to base-mesh polygons "
                        "and are not reported")
    if n_inst:
        warnings.append(f"{n_inst} instanced object(s) (collection or other instances) take part as occluders "
                        "and reflectors only: their faces cannot be targets or lights and are not reported")


def _checked_materials(b, warnings) -> tuple:
    """(reflectance, exitance) of every face: a reflectance outside [0, MAX_REFLECTANCE] clamped
    and a negative emission set to 0 (with a warning); NaN or infinite ones refused."""
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
    return rho, e


def _face_set(b, objs, rho, e, warnings, lamps) -> FaceSet:
    """The FaceSet of the chunks ``b``: the work planes' faces pass light and reflect none (white,
    no light on them), the illuminance targets among the targets."""
    names = b.names
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
    return FaceSet(
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


def repaint(exp: ExportedScene, objects=None, base: FaceSet | None = None, target_scale=None) -> FaceSet:
    """The exported faces with the paint their objects hold now (Live mode, after a stroke): the
    targets and their radiosity read again from each object's base mesh (an object in Edit Mode:
    from its edit mesh), mapped onto the exported faces as export_scene maps them, and the forbidden
    faces read again with them (the caller compares them with the export's: the prepared state
    cannot follow a change); everything else as exported. ``objects``: the names of the objects to
    read again (None: all), the others' paint as in ``base`` (an earlier repaint of ``exp``;
    default: the export). ``target_scale``: the scene's now (default: the export's). The caller
    checks that nothing else changed (pipeline.prepared's stale check)."""
    faces = exp.faces
    was = faces if base is None else base
    target, radiosity = was.target.copy(), was.target_radiosity.copy()
    lux = np.zeros(faces.n_faces) if was.target_lux is None else was.target_lux.copy()
    forbidden = was.forbidden.copy()
    passes = np.zeros(faces.n_faces, dtype=bool) if faces.passes is None else faces.passes
    scale = exp.settings["target_scale"] if target_scale is None else float(target_scale)
    rows_of = _object_rows(exp)
    read = []
    for oi, ob in enumerate(exp.objects):
        if objects is not None and ob.name not in objects:
            continue
        t, b, forb, lx = base_attributes(ob, scale, strict=False)  # (in Edit Mode: its edit mesh's paint)
        rows = rows_of[oi]
        idx = faces.face_index[rows]
        ok = (idx >= 0) & (idx < len(t))
        target[rows] = np.where(ok, t[np.where(ok, idx, 0)], False)
        radiosity[rows] = np.where(ok[:, None], b[np.where(ok, idx, 0)], 0.0)
        lux[rows] = np.where(ok, lx[np.where(ok, idx, 0)], 0.0)
        # (a face of no base polygon, a back the export added: as exported; a layer Edit Mode cannot
        # read, a Boolean one before Blender 4.3: as read before, read again out of Edit Mode)
        if forb is not None:
            forbidden[rows] = np.where(ok, forb[np.where(ok, idx, 0)] | passes[rows], faces.forbidden[rows])
        read.append(rows)
    if objects is None:
        target, radiosity = illuminance_targets(target, radiosity, lux, faces.reflectance, faces.face_object,
                                                faces.object_names)
    elif read:  # (the other faces' paint is read as it was: ``was``'s, already through it; a million-
        # triangle room's every face took 45 ms of the main thread at each stroke)
        rows = np.concatenate(read)
        target[rows], radiosity[rows] = illuminance_targets(target[rows], radiosity[rows], lux[rows],
                                                            faces.reflectance[rows], faces.face_object[rows],
                                                            faces.object_names)
    return replace(faces, target=target, target_radiosity=radiosity, target_lux=lux, forbidden=forbidden)


def _object_rows(exp: ExportedScene) -> list:
    """[the exported faces of object i] for every object of ``exp`` (made once, kept on it)."""
    rows = exp.__dict__.get("_object_rows")
    if rows is None:
        order = np.argsort(exp.faces.face_object, kind="stable")
        edges = np.searchsorted(exp.faces.face_object[order], np.arange(len(exp.objects) + 1))
        rows = exp.__dict__["_object_rows"] = [order[edges[i]:edges[i + 1]] for i in range(len(exp.objects))]
    return rows


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
