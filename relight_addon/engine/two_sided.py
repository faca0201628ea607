"""Which side of each face the scene sees, and the backs of emitters (no bpy).

Cycles shades and emits both sides of a mesh face alike; the radiosity model's faces are
one-sided (a ray that reaches a back side is absorbed). Rays from the faces of the exported
chunks (engine.face_chunks.FaceChunks; engine.backs casts them) decide, before the chunks become
a FaceSet (blender/export.py), which faces are turned or doubled (``faces_seen_from_behind``)
and what becomes of the back side of emitters (``emitting_backs``). Both name what they did in
warnings.

Faces seen from behind (``faces_seen_from_behind``)
---------------------------------------------------
Rays from both sides of the faces that may be seen
from behind (engine.backs.sides_view: a front sees the scene where its rays reach any surface,
a back where they reach front sides, farther than BACK_GAP x its island's size: closer, it lies
against a surface; only backs in a shell's inside, it looks at its own inside) decide which
side the scene sees:

- an island (faces joined by their edges) whose fronts see nothing (at most SIDE_BLIND of
  their rays reach a surface) while other objects lie behind it (at least ENCLOSES of its
  backs' rays reach their fronts): the inside-out room, a cube whose normals point out of it
  as added; every face turned to face the scene (FaceChunks.flip_faces: its targets, forbidden
  state and report row stay its own);
- a face of an open island (a plane, a room without a floor, a wall with a window cut), not
  painted, whose front sees nothing and whose back sees the scene (at least SIDE_SEES of its
  rays): turned the same way (a painted one is left as painted, and named: which side the paint
  is meant for, only the artist knows);
- the faces of an open island whose backs see the scene (at least ISLAND_BOTH of their rays,
  over the island) and whose fronts see it too (a shelf that is a single plane, lit from
  above, seen from below): their backs become faces of their own (FaceChunks.add_backs:
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
(emitting_backs models their backs).

The backs of emitters (``emitting_backs``)
------------------------------------------
Cycles' mesh emission is two-sided: the back side of an emitting face emits too (what the
front does, or the back's bake when the material reads Backfacing). For the emitting faces of
open islands (open_faces; the backs of closed islands face their own inside, where Cycles'
light stays too), engine.backs.back_view tells what the back sees:

- nothing (no front side: its light leaves the scene): nothing to do;
- the scene, from a median distance of at least BACK_GAP x the size of its island (a plane lamp
  hanging in a room): the back becomes a face of its own (FaceChunks.add_backs), modelled;
- a surface closer than that (a lamp quad just under a ceiling): the light caught between
  them, which Cycles lets leak out at the edges, cannot be resolved by patches of constant
  radiosity (the surface's patches would spread the caught light over their whole area, and
  send it into the scene): not modelled, named in a warning with the light that leaks out
  into the scene (what Cycles renders more): at least the light that leaves the gap directly
  (the fraction f of the back's rays that reach the scene elsewhere than over the emitter),
  at most f (1 + rho_n) / (1 - rho_n rho_b) of the back's power after the reflections inside
  the gap (rho_n the surface's reflectance, rho_b the back's; the light reflected inside is
  more central than the emitted light, so it leaves less easily: the truth lies between).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .backs import back_view, sides_view
from .coincident import covered_share
from .rays import embree_scene
from .rays import RAY_OFFSET
from .units import MAX_REFLECTANCE

__all__ = ["BACK_GAP", "BACK_OFFSET", "ISLAND_FACES", "emitting_backs", "faces_seen_from_behind", "mixed_orientation",
           "open_faces"]

#: how far behind its front the back side of an open emitter is set (``FaceChunks.add_backs``),
#: relative to the scene's bounding-box diagonal: 10 x the rays' origin offset
#: (engine.rays.RAY_OFFSET), so that a ray reaching the front hits the front first
BACK_OFFSET = 10 * RAY_OFFSET
#: rays per emitting face of an open island that tell what its back sees (engine.backs), and
#: in all (fewer per face when there are many: at least 16)
BACK_RAYS = 256
BACK_RAY_BUDGET = 1 << 20
#: a back whose rays reach front sides at a median distance below this fraction of its island's
#: size (the square root of its emitting area) lies against a surface (emitting_backs)
BACK_GAP = 0.1
#: rays (in all) that measure the light leaving the gaps of the backs against a surface
LEAK_RAYS = 1 << 16
#: the faces that may be seen from behind (faces_seen_from_behind): rays per side of a face, and
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
#: a face of an open island whose back lies against a coincident face of an open island facing the
#: other way on at least this share of its area (engine.coincident.covered_share: a thin wall drawn
#: as both its sides) is no candidate: the scene sees that side as the other face's front
BACKED = 0.5
#: a back sees the scene where its rays reach fronts outside its island's box, grown by this
#: fraction of the box's largest side (a block standing on a floor looks at the floor inside it)
ISLAND_BOX_PAD = 0.01


def open_faces(geo) -> tuple:
    """((polygons,) bool, (polygons,) island label): the faces of a mesh (its local geometry:
    engine.face_chunks) on an island (faces joined by shared edges) that is not closed, i.e. that
    has an edge with one face or more than two: the back side of such a face may see the scene (a
    plane does), that of a closed island faces its inside."""
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


# ------------------------------------------------------------------ faces seen from behind
@dataclass
class _Candidates:
    """The faces that may be seen from behind (``_candidates``), in the order of ``where``."""

    chosen: list = field(default_factory=list)  # per chunk: its faces' FaceSet indices
    gaps: list = field(default_factory=list)  # per chunk: BACK_GAP x each face's island size
    where: list = field(default_factory=list)  # per chunk: (chunk, its faces, their islands, open?)
    areas: list = field(default_factory=list)  # per chunk: each face's area
    boxes: list = field(default_factory=list)  # per chunk: each face's island box, padded
    enclosing: list = field(default_factory=list)  # per chunk: a closed island judged inside its box
    muddled: set = field(default_factory=set)  # the objects with a closed island partly turned
    inv: np.ndarray = None  # per face: its island (among all the chunks' islands)
    n_isl: int = 0
    sample: np.ndarray = None  # the faces that the islands are first seen from


def faces_seen_from_behind(b) -> list:
    """Turn the faces of the chunks ``b`` (engine.face_chunks.FaceChunks) that the scene sees from
    behind, and give the backs that it sees from both sides faces of their own (see the module
    docstring). Returns the warnings that name what was turned or doubled, per object."""
    geometry = (np.concatenate(b.verts), np.concatenate(b.tris), np.concatenate(b.tri_face), np.concatenate(b.f_obj))
    scene = _SharedScene(geometry)  # the coincident faces' rays and the sides' rays: one Embree scene
    cand = _candidates(b, geometry, scene)
    if cand is None:
        return []
    # 1. each island from ISLAND_FACES of its faces (by area): the inside-out ones, and those
    # whose backs see the scene at all (their faces are cast one by one)
    _sample_islands(cand)
    inv = cand.inv
    inner = np.zeros(cand.n_isl, dtype=bool)  # the islands judged by their own inside (the rooms)
    inner[inv] = cand.enclosing
    mean = _island_means(cand, geometry, scene)
    inside_out = (np.where(inner, mean[3], mean[0]) <= SIDE_BLIND) & ((mean[2] >= ENCLOSES) | inner)
    turned, doubled, painted_away = {}, {}, {}
    k = 0
    for ci, sel, isl, _ in cand.where:  # the inside-out islands turned first: what the faces see next
        _apply(b, inside_out[inv[k:k + len(sel)]], turned, ci, sel, b.flip_faces)
        k += len(sel)
    # 2. the faces of the open islands whose backs see the scene (as it is now), one by one
    opened_all = np.concatenate([op for *_, op in cand.where])
    if inside_out.any():
        geometry = (np.concatenate(b.verts), np.concatenate(b.tris), geometry[2], geometry[3])
        scene = _SharedScene(geometry)  # faces turned: their triangles' corners in another order
        if (opened_all & ~inside_out[inv]).any():
            mean = _island_means(cand, geometry, scene)
    # (and the faces of a room partly turned by hand, some facing in, some out: what each sees in its box)
    partly = ~inside_out[inv] & cand.enclosing & (mean[4][inv] >= ISLAND_SEES)
    fine = np.flatnonzero(~inside_out[inv] & opened_all & (mean[1][inv] >= ISLAND_SEES) | partly)
    if len(fine):
        _judge_faces(b, cand, geometry, scene, mean, fine, partly, (turned, doubled, painted_away))
    return _turned_warnings(turned, doubled, cand.muddled, painted_away)


def _object_boxes(b) -> tuple:
    """(the centre of every object's box by object index, the objects' indices, the lower and
    upper corners of their boxes, whether each has targets)."""
    boxes = {}
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
    return centres, obj_ids, obj_lo, obj_hi, obj_painted


class _SharedScene:
    """An Embree scene (engine.rays.embree_scene) of a geometry's triangles, built when first
    asked for and then shared (``scene()``): the export's checks cast their rays into one scene."""

    def __init__(self, geometry):
        self.geometry, self.built = geometry, None

    def __call__(self):
        if self.built is None:
            self.built = embree_scene(self.geometry[0], self.geometry[1])
        return self.built


def _candidates(b, geometry, scene):
    """The faces that may be seen from behind: the still faces (emitting none, front or back) of
    the open islands, of the closed islands whose box holds another object's centre and of those
    with faces turned against their neighbours; None when there are none."""
    objects = _object_boxes(b)
    cand, islands = _Candidates(), {}
    chunks = [ci for ci in range(len(b.e)) if b.geos[ci] is not None and len(b.e[ci])]
    opened = np.zeros(b.nf, dtype=bool)
    for ci in chunks:
        geo = b.geos[ci][0]
        if id(geo) not in islands:  # instances share their mesh's arrays
            islands[id(geo)] = open_faces(geo)
            islands[id(geo)] += (mixed_orientation(geo, islands[id(geo)][1]),)
        nf0 = b.base[ci][1]
        opened[nf0:nf0 + len(b.e[ci])] = islands[id(geo)][0]
    # faces of open islands back to back (a thin wall's two sides; not a card lying on a solid,
    # which is turned as before)
    share = covered_share(*geometry[:3], b.nf, among=opened, scene=scene)
    backed = np.zeros(b.nf, dtype=bool) if share is None else share >= BACKED
    for ci in chunks:
        _chunk_candidates(b, ci, islands[id(b.geos[ci][0])], objects, cand, backed)
    if not cand.chosen:
        return None
    cand.areas = np.concatenate(cand.areas)
    cand.chosen, cand.gaps = np.concatenate(cand.chosen), np.concatenate(cand.gaps)
    cand.boxes = np.concatenate(cand.boxes)
    cand.enclosing = np.concatenate(cand.enclosing)
    return cand


def _chunk_candidates(b, ci, topology, objects, cand, backed) -> None:
    """Add the candidate faces of chunk ``ci`` (``topology``: open_faces' and mixed_orientation's
    answers for its mesh; ``objects``: _object_boxes; ``backed``: per face, its back against a
    coincident face facing the other way) to ``cand``."""
    centres, obj_ids, obj_lo, obj_hi, obj_painted = objects
    is_open, island, mixed = topology
    back = b.e[ci] if b.e_back[ci] is None else b.e_back[ci]
    still = ~(np.any(b.e[ci] > 0, axis=1) | np.any(back > 0, axis=1) | b.linked[ci])
    k = int(island.max()) + 1
    area = b.face_areas(ci)
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
    sel = np.flatnonzero(still & ~backed[nf0:nf0 + len(still)] & (is_open | holds[island] | mixed[island]))
    if not len(sel):
        return
    cand.chosen.append(nf0 + sel)
    cand.gaps.append(BACK_GAP * size[island[sel]])
    cand.where.append((ci, sel, island[sel], is_open[sel]))
    cand.areas.append(area[sel])
    pad = ISLAND_BOX_PAD * (hi - lo).max(axis=1, keepdims=True)
    cand.boxes.append(np.stack([lo - pad, hi + pad], axis=1)[island[sel]])
    # a closed island whose box holds another object whole (a room and its furniture), and
    # targets (its own or that object's), is judged by what its sides see inside that box: a
    # ground plane or a garden around it is outside (a pierced slab, a sunk pillow: held in
    # part; a casing round a hidden part: no target; judged as before)
    own = int(b.f_obj[ci][0])
    held = obj_ids != own
    whole = np.all((obj_lo[held][None] >= (lo - pad)[:, None]) & (obj_hi[held][None] <= (hi + pad)[:, None]),
                   axis=2)
    whole &= obj_painted[held][None] | (np.bincount(island, weights=b.tgt[ci], minlength=k) > 0)[:, None]
    cand.enclosing.append(whole.any(axis=1)[island[sel]] & ~is_open[sel])
    # a closed island partly turned (some faces in, the others out): turned when it is a
    # room (above), named otherwise (a solid with a face flipped: which side is meant?)
    if (mixed[island[sel]] & ~is_open[sel]).any():
        cand.muddled.add(b.names[own])


def _sample_islands(cand) -> None:
    """Each candidate's island (``cand.inv``, ``cand.n_isl``) and the faces each island is first
    seen from (``cand.sample``): all of a small island's, ISLAND_FACES of a larger one's, drawn
    by area."""
    label = np.concatenate([isl.astype(np.int64) + ci * (1 << 32) for ci, _, isl, _ in cand.where])
    keys, inv, count = np.unique(label, return_inverse=True, return_counts=True)
    order = np.argsort(inv, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(count)])
    rng = np.random.default_rng(0)
    areas = cand.areas
    sample = [order[np.isin(inv[order], np.flatnonzero(count <= ISLAND_FACES))]]  # small islands: every face
    for j in np.flatnonzero(count > ISLAND_FACES):
        rows = order[bounds[j]:bounds[j + 1]]
        drawn = rows[areas[rows] > 0]  # zero-area faces are never drawn (an artist's file has hundreds)
        if len(drawn) <= ISLAND_FACES:
            sample.append(drawn if len(drawn) else rows[:ISLAND_FACES])
            continue
        sample.append(rng.choice(drawn, ISLAND_FACES, replace=False, p=areas[drawn] / areas[drawn].sum()))
    cand.inv, cand.n_isl, cand.sample = inv, len(keys), np.sort(np.concatenate(sample))


def _island_means(cand, geometry, scene) -> list:
    """Per island, the mean over its sampled faces of sides_view's front, back, back_other,
    front_in and back_in."""
    sample, inv, n_isl = cand.sample, cand.inv, cand.n_isl
    coarse = sides_view(*geometry, cand.chosen[sample], cand.gaps[sample], SIDE_RAYS, box=cand.boxes[sample],
                        scene=scene)
    return [np.bincount(inv[sample], weights=x, minlength=n_isl) / np.bincount(inv[sample], minlength=n_isl)
            for x in (coarse.front, coarse.back, coarse.back_other, coarse.front_in, coarse.back_in)]


def _apply(b, mask, count, ci, sel, act) -> None:
    """``act(ci, faces)`` on the faces ``sel[mask]`` of chunk ``ci``, counted per object in ``count``."""
    if mask.any():
        faces = np.zeros(len(b.e[ci]), dtype=bool)
        faces[sel[mask]] = True
        act(ci, faces)
        name = b.names[int(b.f_obj[ci][0])]
        count[name] = count.get(name, 0) + int(mask.sum())


def _judge_faces(b, cand, geometry, scene, mean, fine, partly, counts) -> None:
    """Cast rays from the faces ``fine`` (positions among the candidates) one by one and turn,
    double or name them (``counts``: turned, doubled, painted away, per object)."""
    turned, doubled, painted_away = counts
    inv, faces_all = cand.inv, cand.chosen
    rays = int(np.clip(SIDE_RAY_BUDGET // (2 * len(fine)), 4, SIDE_RAYS))
    view = sides_view(*geometry, faces_all[fine], cand.gaps[fine], rays, seed=1, box=cand.boxes[fine], scene=scene)
    V = geometry[0]
    offset = BACK_OFFSET * max(float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))), 1e-9)
    front_all, back_all, cast_all = np.zeros(len(faces_all)), np.zeros(len(faces_all)), np.zeros(len(faces_all), bool)
    front_all[fine] = np.where(partly[fine], view.front_in, view.front)
    back_all[fine] = np.where(partly[fine], view.back_in, view.back)
    cast_all[fine] = True
    k = 0
    for ci, sel, _, _ in cand.where:
        front, back, cast, room = (x[k:k + len(sel)] for x in (front_all, back_all, cast_all, partly))
        k += len(sel)
        sees = cast & (back >= SIDE_SEES)
        blind = front <= SIDE_BLIND
        # a room's faces that face out while the rest face in: their fronts see nothing of its
        # inside, their backs some of it (not all: what lies within the gap of their edges does
        # not count); turned, painted or not (a closed island's inside is what the scene in it sees)
        _apply(b, cast & room & blind & (back >= ISLAND_SEES), turned, ci, sel, b.flip_faces)
        sees &= ~room
        # both sides: the whole island's backs see the scene (a plane seen from below), not a
        # few of its faces (a staircase's landings, whose tops see the flights' backs)
        both = cast & ~blind & ~room & (mean[1][inv[k - len(sel):k]] >= ISLAND_BOTH)
        _apply(b, sees & blind & ~b.tgt[ci][sel], turned, ci, sel, b.flip_faces)
        _apply(b, both, doubled, ci, sel, lambda c, f: b.add_backs(c, f, offset))
        _apply(b, sees & blind & b.tgt[ci][sel], painted_away, ci, sel, lambda c, f: None)


def _turned_warnings(turned, doubled, muddled, painted_away) -> list:
    """The warnings that name what was turned or doubled, per object."""
    out = []
    if turned:
        out.append(f"{_counted(turned)} face away from the scene (their normals point away from where the "
                   "scene sees them: a room whose normals point out of it): modelled from their other side, as "
                   "Cycles renders both sides of a face alike (Mesh > Normals > Flip makes it the mesh's own)")
    if doubled:
        out.append(f"{_counted(doubled)} are seen from both sides (single planes lit on one side, seen from the "
                   "other): their back sides are modelled as faces of their own (never targets or lights)")
    muddled = muddled - set(turned)
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


# ------------------------------------------------------------------ the backs of emitters
def emitting_backs(b) -> tuple:
    """Give the back side of the open emitters of the chunks ``b`` (engine.face_chunks.FaceChunks)
    that see the scene from afar faces of their own, and name those against a surface (see the
    module docstring). Returns (warnings, one dict per object whose back is against a surface:
    object, power (W, summed over the channels), leak (low, high) W, emitted (W, the scene's),
    distance (m), near)."""
    # (the emitting chunks' areas only: the others emit nothing, and a million triangles' took 0.25 s)
    areas = [b.face_areas(ci) if np.any(b.e[ci] > 0) or (b.e_back[ci] is not None and np.any(b.e_back[ci] > 0))
             else None for ci in range(len(b.e))]
    emitted = float(sum(float((e * a[:, None]).sum()) for e, a in zip(b.e, areas) if a is not None))
    found = _open_emitters(b, areas)
    if found is None:
        return [], []
    chosen, size, chunks = found
    geometry = (np.concatenate(b.verts), np.concatenate(b.tris), np.concatenate(b.tri_face), np.concatenate(b.f_obj))
    view = back_view(*geometry, chosen, int(np.clip(BACK_RAY_BUDGET // len(chosen), 16, BACK_RAYS)))
    modelled = (view.front > 0) & (view.distance >= BACK_GAP * size)
    against = (view.front > 0) & ~modelled
    rows = _gap_rows(b, geometry, chosen[against], areas, emitted) if against.any() else {}
    V = geometry[0]
    offset = BACK_OFFSET * max(float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))), 1e-9)
    k = 0
    for ci, sel, _ in chunks:
        pick = np.zeros(len(b.e[ci]), dtype=bool)
        pick[sel[modelled[k:k + len(sel)]]] = True
        b.add_backs(ci, pick, offset)
        k += len(sel)
    return _gap_warnings(rows, emitted)


def _open_emitters(b, areas):
    """(the FaceSet indices of the faces of open islands whose back emits, the size of each one's
    island (the square root of its emitting area), [(chunk, its faces, its back exitance)]), or
    None when there are none."""
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
        return None
    return np.concatenate(chosen), np.concatenate(size), chunks


def _gap_rows(b, geometry, against, areas, emitted) -> dict:
    """Per object (by index), its emitting faces ``against`` a surface: their power, the light
    leaking out of the gap (low, high), their median distance and the objects near them (the
    light leaving a gap is a small fraction: counted on more rays)."""
    rows = {}
    per = int(np.clip(LEAK_RAYS // len(against), BACK_RAYS, 16 * BACK_RAYS))
    fine = back_view(*geometry, against, per, seed=1)
    rho = np.concatenate(b.rho)
    f_obj, f_rho = geometry[3], np.clip(rho, 0.0, MAX_REFLECTANCE).mean(axis=1)
    for j, face in enumerate(against):
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
    return rows


def _gap_warnings(rows, emitted) -> tuple:
    """(the warnings naming the emitters whose back lies against a surface, their rows)."""
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
