"""What the back side of a face sees (no bpy): Cycles' mesh emission leaves both sides of a face.

The radiosity model's faces are one-sided (a ray that reaches a back side is absorbed), while
Cycles shades and emits both sides of a mesh face alike. engine/two_sided.py decides with
``back_view`` what to do with the back of each emitting face of an open mesh: cosine-weighted
rays from points uniform by area on the face, leaving its back side, tell

- ``front``: the fraction of the back's light that reaches the front side of some face (the
  rest leaves the scene, or lands on back sides, which Relight takes as black);
- ``distance``: the median length of those rays (m), and ``object``: the object they reach
  most often (-1: none);
- per ray, whether the point it reaches lies ``over`` the emitter (a second ray from there
  towards the emitter's plane hits the chosen faces of the same object): a ray that reaches the
  scene elsewhere has left the gap between a back and the surface it lies against.

A back that sees the scene from afar (a plane lamp hanging in a room) is modelled as a face of
its own; one that lies against a surface (``distance`` small against the emitter's size: a lamp
quad just under a ceiling) would trap its light in the gap, which patch-constant radiosity
cannot resolve, and is named in a warning instead (engine/two_sided.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .by_content import kept_by_content
from .geometry import triangle_cross, unit
from .rays import embree_scene, side_rays

__all__ = ["BackView", "SidesView", "back_view", "sides_view"]


@dataclass
class BackView:
    """Per face asked for (in the order of ``faces``): see the module docstring."""

    faces: np.ndarray  # (n,) FaceSet face indices
    front: np.ndarray  # (n,) fraction of the back's (cosine-weighted) rays that reach a front side
    distance: np.ndarray  # (n,) median length of those rays (m), inf when none
    object: np.ndarray  # (n,) the object index those rays reach most often, -1 when none
    ray_face: np.ndarray  # (n x rays,) the face (position in ``faces``) each ray leaves
    ray_length: np.ndarray  # (n x rays,) how far each ray goes to a front side, inf when it reaches none
    over: np.ndarray  # (n x rays,) the front side it reaches lies over the chosen faces of its object
    ray_hit: np.ndarray  # (n x rays,) the face whose front side it reaches, -1 when none


def _hit_normals(vertices, triangles, prim):
    """(len(prim), 3) unit normals of the triangles ``prim`` (the ones rays reached)."""
    return unit(triangle_cross(vertices[triangles[prim]]))


def back_view(vertices, triangles, triangle_face, face_object, chosen, rays_per_face: int = 64,
              seed: int = 0) -> BackView:
    """Cast ``rays_per_face`` cosine-weighted rays from the back side of every face of ``chosen``
    ((F,) bool or face indices) against all the triangles: world-space ``vertices`` (V, 3),
    ``triangles`` (T, 3), the face of each triangle ``triangle_face`` (T,) and the object of each
    face ``face_object`` (F,) (a FaceSet's arrays; embreex)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangle_face = np.asarray(triangle_face, dtype=np.int64)
    face_object = np.asarray(face_object, dtype=np.int64)
    n_faces = len(face_object)
    chosen = np.asarray(chosen)
    idx = np.flatnonzero(chosen) if chosen.dtype == bool else chosen.astype(np.int64)
    n = len(idx)
    if n == 0:
        z, zi = np.zeros(0), np.zeros(0, dtype=np.int64)
        return BackView(idx, z, z, zi, zi, z, np.zeros(0, dtype=bool), zi)
    triangles = np.asarray(triangles, dtype=np.int64)
    rank = np.full(n_faces, -1, dtype=np.int64)
    rank[idx] = np.arange(n)
    org, d, ray_face, offset, normal = side_rays(vertices, triangles, triangle_face, idx, n_faces, rays_per_face,
                                                  np.random.default_rng(seed), -1)
    back = -normal[ray_face]
    scene = embree_scene(vertices, triangles)
    hit = scene.run(org, d, output=1)
    prim = np.asarray(hit["primID"], dtype=np.int64)
    tfar = np.asarray(hit["tfar"], dtype=np.float64)
    ok = prim >= 0
    front = np.zeros(len(prim), dtype=bool)
    front[ok] = np.einsum("ij,ij->i", _hit_normals(vertices, triangles, prim[ok]), d[ok]) < 0
    hit_face = np.where(front, triangle_face[np.maximum(prim, 0)], -1)
    # is the point a ray reaches over its emitter? a second ray from it, back towards the
    # emitter's plane along the face's normal, hits one of the chosen faces of the same object
    over = np.zeros(len(prim), dtype=bool)
    if front.any():
        q = (org[front] + d[front] * (tfar[front, None] - offset)).astype(np.float32)
        d2 = np.ascontiguousarray(-back[ray_face[front]], dtype=np.float32)
        prim2 = np.asarray(scene.run(q, d2), dtype=np.int64)
        f2 = np.where(prim2 >= 0, triangle_face[np.maximum(prim2, 0)], -1)
        src_obj = face_object[idx[ray_face[front]]]
        over[front] = (f2 >= 0) & (rank[np.maximum(f2, 0)] >= 0) & (face_object[np.maximum(f2, 0)] == src_obj)
    frac = np.bincount(ray_face[front], minlength=n) / rays_per_face
    # per face: the median length of its front-reaching rays, and the object they reach most
    rf, tf, of = ray_face[front], tfar[front], face_object[hit_face[front]]
    dist = np.full(n, np.inf)
    obj = np.full(n, -1, dtype=np.int64)
    if len(rf):
        order = np.lexsort((tf, rf))
        rf_s, tf_s = rf[order], tf[order]
        start = np.searchsorted(rf_s, np.arange(n), side="left")
        count = np.bincount(rf_s, minlength=n)
        has = count > 0
        lo_i = start + (count - 1) // 2
        hi_i = start + count // 2
        dist[has] = 0.5 * (tf_s[lo_i[has]] + tf_s[hi_i[has]])
        pair, pc = np.unique(np.stack([rf, of], axis=1), axis=0, return_counts=True)
        best = np.lexsort((-pc, pair[:, 0]))  # per face, its most frequent object first
        first = np.searchsorted(pair[best, 0], np.arange(n), side="left")
        obj[has] = pair[best, 1][first[has]]
    return BackView(idx, frac, dist, obj, ray_face, np.where(front, tfar, np.inf), over, hit_face)


@dataclass
class SidesView:
    """Per face asked for (in the order of ``faces``): what each of its sides sees (sides_view)."""

    faces: np.ndarray  # (n,) FaceSet face indices
    front: np.ndarray  # (n,) fraction of the front's rays that reach a face (either of its sides) farther than its gap
    back: np.ndarray  # (n,) fraction of the back's rays that reach the front side of a face farther than its gap
    #: (and outside its box, when given)
    back_other: np.ndarray  # (n,) fraction of the back's rays that reach the front of another object's face
    #: with ``box``: the fractions of the front's rays reaching a face, and of the back's reaching a
    #: front side, farther than its gap and inside its box (what a closed island's sides see of its
    #: own inside: a room's, whatever lies around it); without, zeros
    front_in: np.ndarray = None
    back_in: np.ndarray = None


@kept_by_content()
def sides_view(vertices, triangles, triangle_face, face_object, chosen, gap, rays_per_face: int = 16,
               seed: int = 0, box=None, scene=None) -> SidesView:
    """Cast ``rays_per_face`` cosine-weighted rays from each side of every face of ``chosen``
    ((F,) bool or face indices) against all the triangles (a FaceSet's arrays, as back_view):
    whether the scene lies in front of a face, behind it, or both. What a back sees counts where
    its rays reach front sides (a back that sees only other backs looks into the inside of a
    shell); ``gap`` (scalar or per chosen face, m): a side whose rays reach a surface closer than
    this lies against it (a floor on a ground plane), those rays do not count. ``box`` ((n, 2, 3):
    per chosen face the corners of a box, its island's): a back counts only the fronts it reaches
    outside it (the inside of a block standing on a floor, closed by the floor, is not the scene's),
    and ``front_in``, ``back_in`` count what each side reaches inside it. ``scene``: a function
    returning an Embree scene of exactly these triangles (engine.rays.embree_scene), one is built
    here otherwise. The answers are kept by content (the same scene exported again: no ray cast)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangle_face = np.asarray(triangle_face, dtype=np.int64)
    face_object = np.asarray(face_object, dtype=np.int64)
    chosen = np.asarray(chosen)
    idx = np.flatnonzero(chosen) if chosen.dtype == bool else chosen.astype(np.int64)
    n = len(idx)
    if n == 0:
        z = np.zeros(0)
        return SidesView(idx, z, z, z, z, z)
    triangles = np.asarray(triangles, dtype=np.int64)
    scene = embree_scene(vertices, triangles) if scene is None else scene()
    rng = np.random.default_rng(seed)
    out = []
    for side in (1, -1):
        org, d, ray_face, _, _ = side_rays(vertices, triangles, triangle_face, idx, len(face_object),
                                            rays_per_face, rng, side)
        hit = scene.run(org, d, output=1)
        prim = np.asarray(hit["primID"], dtype=np.int64)
        out.append((ray_face, prim, np.asarray(hit["tfar"], dtype=np.float64), d, org))
    gap = np.broadcast_to(np.asarray(gap, dtype=np.float64), (n,))
    box = None if box is None else np.asarray(box, dtype=np.float64)

    def inside(ray_face, prim, tfar, d, org):  # (rays,) whether the point a ray reaches lies in its face's box
        if box is None:
            return np.zeros(len(prim), dtype=bool)
        q = org.astype(np.float64) + d.astype(np.float64) * np.where(prim >= 0, tfar, 0.0)[:, None]
        return (prim >= 0) & np.all((q >= box[ray_face, 0]) & (q <= box[ray_face, 1]), axis=1)

    def frac(mask):
        return np.bincount(ray_face[mask], minlength=n) / rays_per_face

    ray_face, prim, tfar, d, org = out[0]
    reach = (prim >= 0) & (tfar >= gap[ray_face])
    front, front_in = frac(reach), frac(reach & inside(ray_face, prim, tfar, d, org))
    ray_face, prim, tfar, d, org = out[1]
    ok = prim >= 0
    p = prim[ok]
    fronts = np.zeros(len(prim), dtype=bool)
    fronts[ok] = np.einsum("ij,ij->i", _hit_normals(vertices, triangles, p), d[ok]) < 0
    far = fronts & (tfar >= gap[ray_face])
    within = inside(ray_face, prim, tfar, d, org)
    other = fronts.copy()
    other[ok] &= face_object[triangle_face[p]] != face_object[idx[ray_face[ok]]]
    return SidesView(idx, front, frac(far & ~within) if box is not None else frac(far), frac(other),
                     front_in, frac(far & within))
