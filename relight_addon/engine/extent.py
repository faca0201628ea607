"""The region that decides the answer, and the automatic lengths that follow from it (no bpy).

An artist's file holds a room of a few metres inside a ground plane or a sky dome kilometres
wide, lamps far away, helpers anywhere. Every automatic length of a solve (the patch size, and
through it the light size, the lamp drop, the cost estimate) comes from the region that decides
the answer, never from the bounding box of everything:

- the *seeds*: the painted targets (else the scene's emitters, else every face);
- what they see: cosine-weighted rays from the seeds' front sides; the points they reach, up to
  the REACH_QUANTILE of their lengths (a distant ground seen at grazing angles from a patio does
  not count; the walls of the room do).

The region is the box of the seeds and of those points. Geometry outside it is modelled
coarsely, not ignored: a face's size grows with its distance from the region beyond half its
diagonal (``far_factor``: as the square of 1 + that distance over half the diagonal), and a quad that reaches far
beyond it (a ground plane under the room) is cut into a quadtree of cells, fine over the region
and coarser away from it (``quad_cells``).

Everything here is relative: the same scene in centimetres or kilometres gives the same region
and sizes, scaled.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .units import TINY

__all__ = ["Region", "decisive_region", "TriangleMeasures", "triangle_measures", "forget_measures", "far_factor", "face_sizes", "quad_cells", "is_beyond", "DIVISIONS"]

#: the automatic patch size is the region's diagonal / DIVISIONS
DIVISIONS = 20.0
#: rays cast from the seeds (in all) to find what they see
REGION_RAYS = 4096
#: the points the seeds' rays reach count up to this quantile of the rays' lengths
REACH_QUANTILE = 0.9


@dataclass(frozen=True)
class Region:
    """An axis-aligned box (m) and what it was grown from (``seeds``: "targets", "emitters" or
    "faces"); ``scene_diagonal``: the diagonal of every face's box, for the report."""

    lo: np.ndarray
    hi: np.ndarray
    seeds: str
    scene_diagonal: float

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.hi - self.lo))

    @property
    def patch_size(self) -> float:
        """The automatic patch size (m)."""
        return self.diagonal / DIVISIONS

    def distance(self, lo, hi) -> np.ndarray:
        """(n,) the distance (m) between each box [lo, hi] (n, 3) and the region (0 where they overlap)."""
        gap = np.maximum(np.maximum(self.lo - np.asarray(hi), np.asarray(lo) - self.hi), 0.0)
        return np.linalg.norm(gap, axis=1)

    def to_dict(self) -> dict:
        return {"lo": self.lo.tolist(), "hi": self.hi.tolist(), "diagonal": self.diagonal, "seeds": self.seeds,
                "scene_diagonal": self.scene_diagonal}


def _seeds(faces, area):
    for name, mask in (("targets", faces.target), ("emitters", np.any(faces.exitance > 0, axis=1))):
        if mask is not None and np.any(mask & (area > 0)):
            return name, np.flatnonzero(mask & (area > 0))
    return "faces", np.flatnonzero(area > 0)


@dataclass(frozen=True)
class TriangleMeasures:
    """A FaceSet's triangles measured once (``triangle_measures``): per triangle its cross product
    (b - a) x (c - a) (T, 3), area (T,) m^2 and longest edge (T,) m; per face its area (F,) m^2,
    longest triangle edge (F,) m (0 for a face without triangles) and box (F, 3), (F, 3) m."""

    cross: np.ndarray
    area: np.ndarray
    edge: np.ndarray
    face_area: np.ndarray
    face_edge: np.ndarray
    face_lo: np.ndarray
    face_hi: np.ndarray


def _per_face(op, values, tf, n, fill):
    """Per face, ``op`` (np.minimum / np.maximum) of ``fill`` and its triangles' ``values``: by
    segments when the triangles are in face order (an export's are), else ``op.at``; the same
    numbers either way (a min / max is exact)."""
    out = np.full((n,) + values.shape[1:], fill)
    if len(tf) and np.all(tf[1:] >= tf[:-1]) and tf[0] >= 0:
        starts = np.flatnonzero(np.concatenate([[True], tf[1:] != tf[:-1]]))
        out[tf[starts]] = op(fill, op.reduceat(values, starts, axis=0))
    else:
        op.at(out, tf, values)
    return out


def triangle_measures(faces) -> TriangleMeasures:
    """The triangles of ``faces`` measured (TriangleMeasures): shared by the region, the memory
    check before meshing (engine.cost.estimate_patch_count) and the patch models' meshing; computed
    once per FaceSet and geometry (cached on the FaceSet, as the region; ``forget_measures`` drops it)."""
    from .geometry import triangle_cross

    V, tri, tf = faces.vertices, faces.triangles, faces.triangle_face
    with np.errstate(over="ignore", invalid="ignore"):
        key = (id(V), id(tri), id(tf), V.shape, tri.shape, float(V.sum()))
    cached = faces.__dict__.get("_triangle_measures")
    if cached is not None and cached[0] == key:
        return cached[1]
    T = V[tri]
    with np.errstate(over="ignore", invalid="ignore"):
        cr = triangle_cross(T)
        area = 0.5 * np.linalg.norm(cr, axis=1)
        edge = np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(axis=1)
        F = faces.n_faces
        m = TriangleMeasures(cr, area, edge, np.bincount(tf, weights=area, minlength=F),
                             _per_face(np.maximum, edge, tf, F, 0.0),
                             _per_face(np.minimum, T.min(axis=1), tf, F, np.inf),
                             _per_face(np.maximum, T.max(axis=1), tf, F, -np.inf))
    faces.__dict__["_triangle_measures"] = (key, m)
    return m


def forget_measures(faces):
    """Drop the FaceSet's cached ``triangle_measures`` (their memory: 40 bytes a triangle, 64 a face)."""
    faces.__dict__.pop("_triangle_measures", None)


def _face_areas(faces):
    return triangle_measures(faces).face_area


def decisive_region(faces, rays: int = REGION_RAYS, seed: int = 0) -> Region:
    """The region of ``faces`` (a FaceSet) that decides the answer (module docstring), computed
    once per FaceSet and geometry, targets and emitters (it is cached on the FaceSet)."""
    V = faces.vertices
    key = (V.shape, float(V.sum()), hash(faces.target.tobytes()) if faces.target is not None else 0,
           hash(np.any(faces.exitance > 0, axis=1).tobytes()))
    cached = faces.__dict__.get("_decisive_region")
    if cached is not None and cached[0] == key:
        return cached[1]
    region = _region(faces, rays, seed)
    faces.__dict__["_decisive_region"] = (key, region)
    return region


def _region(faces, rays, seed):
    from .rays import embree_scene, side_rays

    V = np.asarray(faces.vertices, dtype=np.float64)
    scene_lo, scene_hi = V.min(axis=0), V.max(axis=0)
    scene_diag = float(np.linalg.norm(scene_hi - scene_lo))
    area = _face_areas(faces)
    kind, idx = _seeds(faces, area)
    if len(idx) == 0:
        return Region(scene_lo, scene_hi, "faces", scene_diag)
    corners = V[faces.loop_vertices[np.concatenate([np.arange(s, s + t) for s, t in
                                                    zip(faces.loop_start[idx], faces.loop_total[idx])])]] \
        if len(idx) < 200_000 else V[faces.triangles[np.isin(faces.triangle_face, idx)].reshape(-1)]
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    rng = np.random.default_rng(seed)
    if len(idx) > rays:  # the rays' faces drawn by area
        idx = np.sort(rng.choice(idx, rays, replace=False, p=area[idx] / area[idx].sum()))
    per_face = max(1, rays // len(idx))
    org, d, _, _, _ = side_rays(V, faces.triangles, faces.triangle_face, idx, faces.n_faces, per_face, rng, 1)
    keep = None if faces.passes is None else ~faces.passes[faces.triangle_face]  # work planes let light through
    tris = faces.triangles if keep is None else faces.triangles[keep]
    if len(tris):
        hit = embree_scene(V, tris).run(org, d, output=1)
        t = np.asarray(hit["tfar"], dtype=np.float64)[np.asarray(hit["primID"]) >= 0]
        if len(t):
            reach = np.quantile(t, REACH_QUANTILE)
            ok = (np.asarray(hit["primID"]) >= 0) & (np.asarray(hit["tfar"]) <= reach)
            p = org[ok] + d[ok] * np.asarray(hit["tfar"])[ok, None]
            if len(p):
                lo, hi = np.minimum(lo, p.min(axis=0)), np.maximum(hi, p.max(axis=0))
    if not np.linalg.norm(hi - lo) > 1e-6 * max(scene_diag, TINY):  # a point: the whole scene
        return Region(scene_lo, scene_hi, "faces", scene_diag)
    return Region(np.maximum(lo, scene_lo), np.minimum(hi, scene_hi), kind, scene_diag)


def far_factor(region: Region, lo, hi) -> np.ndarray:
    """(n,) >= 1: how much larger than inside the region a patch may be in each box [lo, hi]
    (n, 3): 1 within half the region's diagonal of it (the rest of a building its targets do not
    see: coarser there, the staircase's top floor moved Cycles' agreement on its painted steps by
    1.5 %), then (1 + the distance beyond that over half the diagonal)^2 (a ground plane
    9 km wide around a room then adds about 3,000 patches, not 10^8)."""
    half = 0.5 * region.diagonal
    return (1.0 + np.maximum(region.distance(lo, hi) - half, 0.0) / half) ** 2


def face_boxes(faces):
    """(F, 3), (F, 3): each face's bounding box (m), from its triangles."""
    m = triangle_measures(faces)
    return m.face_lo, m.face_hi


def face_sizes(faces, size) -> np.ndarray:
    """(F,) m: the patch sizes ``size`` ((F,) or a scalar: what each face would get inside the
    region) grown with each face's distance from the region (``far_factor``); a face other than a
    quad that reaches beyond the region (a ground of two triangles kilometres wide) is cut into at
    most 2 x DIVISIONS pieces an edge (a quad larger than the region is cut by ``quad_cells`` instead)."""
    region = decisive_region(faces)
    lo, hi = face_boxes(faces)
    s = np.broadcast_to(np.asarray(size, dtype=np.float64), (faces.n_faces,)) * far_factor(region, lo, hi)
    beyond = np.any(lo < region.lo, axis=1) | np.any(hi > region.hi, axis=1)
    edge = np.linalg.norm(hi - lo, axis=1)
    return np.where(beyond & (faces.loop_total != 4), np.maximum(s, edge / (2 * DIVISIONS)), s)


def _bilinear(p, u, v):
    """Points of the bilinear quad p (4, 3) (polygon order) at parameters u, v (n,)."""
    u, v = u[:, None], v[:, None]
    return (1 - u) * (1 - v) * p[0] + u * (1 - v) * p[1] + u * v * p[2] + (1 - u) * v * p[3]


def quad_cells(region: Region, p, size: float) -> np.ndarray:
    """A quad ``p`` (4, 3) (polygon order) larger than the region (a ground plane under the
    room) cut into cells no larger than ``size`` (m) times their ``far_factor``: a quadtree of
    its parameter square, fine over the region and coarser away from it (the cells need not
    share edges: each is a patch of its own). Returns (n, 2, 3, 3): two triangles a cell."""
    cells = np.array([[0.0, 1.0, 0.0, 1.0]])  # u0, u1, v0, v1
    done = []
    for _ in range(64):
        if not len(cells):
            break
        u0, u1, v0, v1 = cells.T
        c = np.stack([_bilinear(p, u0, v0), _bilinear(p, u1, v0), _bilinear(p, u1, v1), _bilinear(p, u0, v1)], axis=1)
        edge = np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2).max(axis=1)
        split = edge > size * far_factor(region, c.min(axis=1), c.max(axis=1))
        done.append(c[~split])
        um, vm = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
        s = split
        cells = np.concatenate([np.stack([u0[s], um[s], v0[s], vm[s]], 1), np.stack([um[s], u1[s], v0[s], vm[s]], 1),
                                np.stack([um[s], u1[s], vm[s], v1[s]], 1), np.stack([u0[s], um[s], vm[s], v1[s]], 1)])
    c = np.concatenate(done)
    return np.stack([c[:, [0, 1, 2]], c[:, [0, 2, 3]]], axis=1)


def is_beyond(region: Region, p) -> bool:
    """Whether a quad ``p`` (4, 3) is larger than the region (then cut by ``quad_cells``)."""
    return float(np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).max()) > region.diagonal
