"""Linked emission -> each face's mean emitted radiance, as Cycles gives it: an EMIT bake (bpy).

A material whose emission is linked (materials.Closure.linked_emission: an Emission Color or
Strength fed by an image texture, a procedural, an attribute..., or a Mix Shader's linked factor
over an emitting branch) emits what its node tree evaluates to at each point of the surface.
``bake_emission`` asks Cycles for it: an EMIT bake (the emitted radiance L_e, W/(m^2 sr), of the
whole surface shader at each texel, exactly as Cycles shades it) of temporary copies, and returns
per face the mean over its area.

Nothing of the user's data is changed, even on error:
- a temporary scene (Cycles, CPU, BAKE_SAMPLES samples, the user's scene's thread settings)
  holds one temporary object per baked object: a new mesh ``bpy.data.meshes.new_from_object`` of
  its evaluated mesh (modifiers applied, every UV map and attribute kept, the render UV map
  unchanged; a mesh without UV map gets an all-zero one, as Cycles reads a missing UV map), the
  original's texture space and world matrix, and copies of its materials;
- each material copy gets an Image Texture node, made active, that is the bake target: one
  float image for all objects, in which every baked face has its own square cell of a
  temporary UV map (the face mapped onto the cell by an affine map of its plane, so that the
  texel centres sample the face uniformly by area; faces not baked get no area). The image is
  pre-filled with a sentinel and baked with margin 0 without clearing: exactly the texels whose
  centre lies inside a face are written, and the face's mean is their mean;
- everything (scene, objects, meshes, material copies, image) is removed in a ``finally``.

The back side: Cycles shades both sides of a face alike, so a face's back emits what its front
does, unless the material reads Geometry > Backfacing: then the back is baked again from copies
in which that output is replaced by 1 (``back``; engine/two_sided.py models the back of an open emitter,
see its docstring). Named in a warning and baked as they are: a Light Path node (the bake sees
the surface as a camera ray does, other surfaces see it through diffuse and shadow rays), a
Backfacing inside a node group (the back then gets the front's emission), an Object Info
Random (the temporary object's own). A face too small for a texel of its cell gets the mean of
its material on the object, counted in a warning. Cost: nothing happens without linked
emission; with it, one bake of the faces that need it, at most TEXEL_BUDGET texels (cells of 32
x 32 texels for up to 1024 faces, smaller above, at least 6 x 6; an image of at most 4096 x 4096):
benchmarks/bench_emission_bake.py on 2 cores shared with other jobs: an open grid of 10^4
textured faces exports in 2.1-3.5 s instead of 0.4-0.6 s untextured, one of 10^5 in 4.6-11 s
instead of 1.6-2.2 s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import bpy
import numpy as np

from ..engine.units import exitance_from_radiance
from .exported_materials import scene_material

__all__ = ["BakeRequest", "bake_emission", "bake_linked_emission", "BAKE_SAMPLES"]

#: Cycles samples per texel of the EMIT bake (the face mean averages all its texels, a grid over
#: the face: anti-aliasing each texel adds little)
BAKE_SAMPLES = 2
#: texels per side of a face's cell (the most and the fewest, and the image's largest side), and
#: the texels baked in all (smaller cells when there are many faces: the bake's time)
CELL_MAX, CELL_MIN, IMAGE_MAX = 32, 6, 4096
TEXEL_BUDGET = 1 << 20
SENTINEL = -1.0
_PAD = 1
_UV = "relight_emission_bake"
_ZERO_UV = "UVMap"


@dataclass
class BakeRequest:
    """One object to bake: ``faces`` (n_polygons,) bool, the polygons of its evaluated mesh whose
    material has a linked emission; ``slots`` its materials (the evaluated object's slots)."""

    name: str
    obj: object  # the original bpy object
    faces: np.ndarray
    slots: list


def _affine_cells(me, faces, first_cell, ncol, cell, res):
    """(loops, 2) UVs: face k of ``faces`` (in order) mapped onto cell first_cell + k by an affine map
    of its plane (its principal axes, each stretched to the cell: area-uniform), the other faces
    collapsed to a point (no texel)."""
    nl, npoly = len(me.loops), len(me.polygons)
    co = np.zeros(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    lv = np.zeros(nl, dtype=np.int64)
    me.loops.foreach_get("vertex_index", lv)
    ls = np.zeros(npoly, dtype=np.int64)
    lt = np.zeros(npoly, dtype=np.int64)
    me.polygons.foreach_get("loop_start", ls)
    me.polygons.foreach_get("loop_total", lt)
    uv = np.zeros((nl, 2))
    inner = cell - 2 * _PAD
    chosen = np.flatnonzero(faces)
    cells = first_cell + np.arange(len(chosen))
    for n in np.unique(lt[chosen]):  # faces of n corners at once
        sel = lt[chosen] == n
        f, cidx = chosen[sel], cells[sel]
        idx = ls[f][:, None] + np.arange(n)  # (m, n) loops
        p = co[lv[idx]]
        q = p - p.mean(axis=1, keepdims=True)
        nrm = np.sum(np.cross(q, np.roll(q, -1, axis=1)), axis=1)  # Newell
        nn = np.linalg.norm(nrm, axis=1)
        ok = nn > 0
        nrm = nrm / np.where(ok, nn, 1.0)[:, None]
        q = q - np.einsum("mnk,mk->mn", q, nrm)[..., None] * nrm[:, None, :]  # onto the plane
        _, _, vt = np.linalg.svd(q, full_matrices=False)
        q2 = np.einsum("mnk,mjk->mnj", q, vt[:, :2])
        lo, hi = q2.min(axis=1, keepdims=True), q2.max(axis=1, keepdims=True)
        span = np.where(hi - lo > 0, hi - lo, 1.0)
        t = (q2 - lo) / span * inner + _PAD
        corner = np.stack([cidx % ncol, cidx // ncol], axis=1)[:, None, :] * cell
        u = (t + corner) / res
        uv[idx[ok].ravel()] = u[ok].reshape(-1, 2)  # faces without area: no texel
    return uv


def _tree_uses(tree, idname, output, seen=None):
    """(at the top level, inside a node group): whether a node ``idname``'s ``output`` (None: any)
    is linked."""
    seen = seen if seen is not None else set()
    top = any(l.from_node.bl_idname == idname and output in (None, l.from_socket.name) and not l.is_muted
              for l in tree.links)
    inner = False
    for n in tree.nodes:
        sub = getattr(n, "node_tree", None)
        if n.bl_idname == "ShaderNodeGroup" and sub is not None and sub.name not in seen:
            seen.add(sub.name)
            a, b = _tree_uses(sub, idname, output, seen)
            inner = inner or a or b
    return top, inner


def _backfacing_to_one(tree):
    """Replace every top-level link from Geometry > Backfacing by a Value node of 1 (the back side)."""
    for link in [l for l in tree.links
                 if l.from_node.bl_idname == "ShaderNodeNewGeometry" and l.from_socket.name == "Backfacing"]:
        to = link.to_socket
        tree.links.remove(link)
        one = tree.nodes.new("ShaderNodeValue")
        one.outputs[0].default_value = 1.0
        tree.links.new(one.outputs[0], to)


def bake_emission(requests, scene, depsgraph) -> tuple:
    """Bake the faces of ``requests`` (BakeRequest) in a temporary scene (see the module docstring);
    ``scene``: the user's (its thread settings), ``depsgraph``: its evaluated depsgraph.

    Returns ({name: (front (n_polygons, 3), back (n_polygons, 3))} radiance W/(m^2 sr), zero on the
    faces not asked for, [warnings]). A bake that fails raises RuntimeError (the caller names the
    materials and keeps their unlinked emission)."""
    requests = [r for r in requests if np.any(r.faces)]
    if not requests:
        return {}, []
    warnings = []
    ncol, cell, res = _cell_layout(requests)
    bake = _BakeScene(res)
    try:
        bake.start(scene)
        temp, first, back_needed = [], 0, []
        for r in requests:
            ob, baked_slots = _bake_copy(bake, r, depsgraph, first, (ncol, cell, res), len(temp))
            for mat in baked_slots:
                if mat is not None and _ray_dependent(mat, r, warnings):
                    back_needed.append((len(temp), mat.name))
            temp.append((r, ob, first, baked_slots))
            first += int(np.sum(r.faces))
        front_px = _bake(bake.tmp, [t[1] for t in temp], bake.image("front"), res)
        back_px = None
        back_objs = sorted({k for k, _ in back_needed})
        if back_objs:
            for k in back_objs:
                ob, baked_slots = temp[k][1], temp[k][3]
                for i, mat in enumerate(baked_slots):
                    ob.data.materials[i] = bake.copy_of(mat, "back")
            back_px = _bake(bake.tmp, [temp[k][1] for k in back_objs], bake.image("back"), res)
        out, thin = _sides(temp, front_px, back_px, back_objs, back_needed, ncol, cell)
        if thin:
            warnings.append(f"{thin} face(s) with a linked emission are too small to bake: each is given the mean "
                            "emission of its material on its object")
        return out, list(dict.fromkeys(warnings))
    finally:
        bake.remove()


def _cell_layout(requests) -> tuple:
    """(cells per row, texels per side of a cell, the image's side) for the faces of ``requests``;
    RuntimeError when they are too many to bake."""
    n_cells = int(sum(int(np.sum(r.faces)) for r in requests))
    ncol = max(1, math.ceil(math.sqrt(n_cells)))
    cell = min(IMAGE_MAX // ncol, CELL_MAX, max(CELL_MIN, int(math.sqrt(TEXEL_BUDGET / n_cells))))
    if cell < CELL_MIN:
        raise RuntimeError(f"{n_cells} faces with a linked emission are too many to bake "
                           f"(at most {(IMAGE_MAX // CELL_MIN) ** 2})")
    return ncol, cell, ncol * cell


class _BakeScene:
    """The temporary scene of a bake, its target images and material copies; ``remove`` deletes
    everything it made."""

    def __init__(self, res):
        self.res, self.tmp = res, None
        self.made = {"scenes": [], "objects": [], "meshes": [], "materials": [], "images": []}
        self.images = {}
        self.copies = {"front": {}, "back": {}}  # original material (None: a placeholder) -> its copy per side

    def start(self, scene):
        """Make the bake scene: Cycles on the CPU, ``scene``'s threads."""
        tmp = self.tmp = bpy.data.scenes.new("relight_emission_bake")
        self.made["scenes"].append(tmp)
        tmp.render.engine = "CYCLES"
        c = tmp.cycles
        c.device, c.samples, c.use_denoising = "CPU", BAKE_SAMPLES, False
        c.use_adaptive_sampling = False
        tmp.render.threads_mode = scene.render.threads_mode
        tmp.render.threads = scene.render.threads

    def image(self, side):
        """The bake target of one side (made when first needed), pre-filled with the sentinel."""
        res = self.res
        if side not in self.images:
            img = bpy.data.images.new(f"relight_emission_bake_{side}", res, res, alpha=True, float_buffer=True)
            self.made["images"].append(img)
            img.colorspace_settings.name = "Non-Color"
            img.pixels.foreach_set(np.full(res * res * 4, SENTINEL, dtype=np.float32))
            self.images[side] = img
        return self.images[side]

    def copy_of(self, mat, side):
        """The bake copy of ``mat``; None: a placeholder that emits nothing (the slots of the
        faces not baked, which get no texel)."""
        key = mat.name if mat is not None else None
        if key not in self.copies[side]:
            m = mat.copy() if mat is not None else bpy.data.materials.new("relight_emission_bake_none")
            self.made["materials"].append(m)
            if mat is None and bpy.app.version < (5, 0, 0):
                m.use_nodes = True
            if mat is None:
                m.node_tree.nodes.clear()
            nt = m.node_tree
            if side == "back":
                _backfacing_to_one(nt)
            node = nt.nodes.new("ShaderNodeTexImage")
            node.image = self.image(side)
            nt.nodes.active = node
            self.copies[side][key] = m
        return self.copies[side][key]

    def remove(self):
        """Delete everything the bake made."""
        for kind in ("objects", "scenes", "meshes", "materials", "images"):
            coll = getattr(bpy.data, kind)
            for idb in self.made[kind]:
                try:
                    coll.remove(idb)
                except (ReferenceError, RuntimeError):
                    pass


def _bake_copy(bake, r, depsgraph, first, layout, k) -> tuple:
    """(the temporary object ``k`` that bakes request ``r``, its slots' materials (None: not
    baked)): a copy of its evaluated mesh, its faces' cells from ``first`` on in a UV map of its
    own (``layout``: _cell_layout), the bake copies of its materials, linked to the bake scene."""
    ncol, cell, res = layout
    ob_eval = r.obj.evaluated_get(depsgraph)
    me = bpy.data.meshes.new_from_object(ob_eval, preserve_all_data_layers=True, depsgraph=depsgraph)
    bake.made["meshes"].append(me)
    if len(me.polygons) != len(r.faces):
        raise RuntimeError(f"object {r.name!r}: its evaluated mesh changed while it was baked")
    if len(me.uv_layers) == 0:  # as Cycles reads a missing UV map: zero
        me.uv_layers.new(name=_ZERO_UV)
    render_uv = next((u.name for u in me.uv_layers if u.active_render), None)
    bake_uv = me.uv_layers.new(name=_UV)
    if render_uv is not None:
        me.uv_layers[render_uv].active_render = True
    bake_uv.data.foreach_set("uv", _affine_cells(me, r.faces, first, ncol, cell, res).ravel())
    me.uv_layers.active = bake_uv
    orig = r.obj.data
    if hasattr(orig, "texspace_location"):
        me.use_auto_texspace = False
        me.texspace_location = orig.texspace_location
        me.texspace_size = orig.texspace_size
    slots = list(r.slots) or [None]
    used = {min(int(i), len(slots) - 1) for i in np.unique(_material_index(me)[r.faces])}
    baked_slots = [mat if i in used and getattr(mat, "node_tree", None) is not None else None
                   for i, mat in enumerate(slots)]
    me.materials.clear()
    for mat in baked_slots:
        me.materials.append(bake.copy_of(mat, "front"))
    ob = bpy.data.objects.new(f"relight_emission_bake_{k}", me)
    bake.made["objects"].append(ob)
    ob.matrix_world = r.obj.matrix_world
    bake.tmp.collection.objects.link(ob)
    return ob, baked_slots


def _ray_dependent(mat, r, warnings) -> bool:
    """Whether the emission of ``mat`` reads Backfacing itself (its back side is baked apart);
    ``warnings`` gets what a bake from the camera cannot tell (a Light Path node, Backfacing read
    in a node group, Object Info > Random)."""
    lp_top, lp_in = _tree_uses(mat.node_tree, "ShaderNodeLightPath", None)
    if lp_top or lp_in:
        warnings.append(f"material {mat.name!r}: its emission may depend on the ray type (a Light Path "
                        "node): baked as the camera sees it")
    bf_top, bf_in = _tree_uses(mat.node_tree, "ShaderNodeNewGeometry", "Backfacing")
    if bf_in and not bf_top:
        warnings.append(f"material {mat.name!r}: a node group reads Backfacing: the back side of its "
                        "faces is given the front's emission")
    if _tree_uses(mat.node_tree, "ShaderNodeObjectInfo", "Random")[0]:
        warnings.append(f"material {mat.name!r}: Object Info > Random is the baked copy's, not "
                        f"{r.name!r}'s")
    return bool(bf_top)


def _sides(temp, front_px, back_px, back_objs, back_needed, ncol, cell) -> tuple:
    """({name: (front, back)} per-face radiance of the baked objects ``temp``, the number of faces
    too small to bake)."""
    out, thin = {}, 0
    for k, (r, ob, start, baked_slots) in enumerate(temp):
        front, n_thin = _face_means(front_px, r, ob.data, start, ncol, cell)
        thin += n_thin
        back = front.copy()
        if k in back_objs:
            back_mats = {m for kk, m in back_needed if kk == k}
            names = np.array([getattr(m, "name", None) in back_mats for m in baked_slots])
            dep = names[np.minimum(_material_index(ob.data), len(baked_slots) - 1)] & r.faces
            b, _ = _face_means(back_px, r, ob.data, start, ncol, cell)
            back[dep] = b[dep]
        out[r.name] = (front, back)
    return out, thin


def _material_index(me):
    mi = np.zeros(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("material_index", mi)
    return mi


def _bake(tmp, objects, img, res):
    """EMIT bake of ``objects`` (in the temporary scene ``tmp``) into ``img``: (res, res, 4) pixels."""
    view_layer = tmp.view_layers[0]
    with bpy.context.temp_override(scene=tmp, view_layer=view_layer, active_object=objects[0], object=objects[0],
                                   selected_objects=objects, selected_editable_objects=objects):
        bpy.ops.object.bake(type="EMIT", margin=0, use_clear=False, target="IMAGE_TEXTURES", uv_layer=_UV)
    px = np.empty(res * res * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    if not np.all(np.isfinite(px)):
        raise RuntimeError("the emission bake produced NaN or infinite values")
    return px.reshape(res, res, 4)


def _face_means(px, r, me, start, ncol, cell):
    """(n_polygons, 3) mean of the written texels of each requested face (0 elsewhere), and how
    many requested faces had none (given their material's area-weighted mean on the object)."""
    n = len(r.faces)
    chosen = np.flatnonzero(r.faces)
    nrow = px.shape[0] // cell
    blocks = px.reshape(nrow, cell, ncol, cell, 4).transpose(0, 2, 1, 3, 4).reshape(nrow * ncol, cell * cell, 4)
    b = blocks[start:start + len(chosen)].astype(np.float64)
    written = b[..., 3] > SENTINEL / 2
    count = written.sum(axis=1)
    sums = np.einsum("ct,ctk->ck", written, b[..., :3])
    out = np.zeros((n, 3))
    got = np.zeros(n, dtype=bool)
    out[chosen] = sums / np.maximum(count, 1)[:, None]
    got[chosen] = count > 0
    missing = r.faces & ~got
    if missing.any():
        area = np.zeros(n)
        me.polygons.foreach_get("area", area)
        mi = _material_index(me)
        for i in np.unique(mi[missing]):
            ok = got & (mi == i)
            w = area[ok]
            mean = (out[ok] * w[:, None]).sum(axis=0) / w.sum() if w.sum() > 0 else np.zeros(3)
            out[missing & (mi == i)] = mean
    return out, int(missing.sum())


def bake_linked_emission(b, objs, context) -> list:
    """Each face whose material has a linked emission gets its mean emitted radiance from a
    Cycles bake (emission_bake.py): its exitance pi x that, front and back. Nothing happens when
    no face has one. Returns the warnings (what could not be baked is named with its material)."""
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


def _linked_text(b, names) -> str:
    """"'Mat' (Emission Color of Principled BSDF, ...)": the materials and their linked emission."""
    return ", ".join(f"{n!r} ({', '.join(b.mat_cache[n][4])})" for n in names)
