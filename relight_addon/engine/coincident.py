"""Coincident faces back to back (no bpy): a thin wall drawn as both its sides.

Artists' models hold faces that lie in one plane and face opposite ways: a partition or a thin
wall drawn as two faces back to back (a duplicated, flipped copy; the two sides of a door), a
double-sided plane. A ray that reaches them hits both at the same distance, and Embree returns
either: for some rays the side facing away from the ray. The radiosity model's faces are
one-sided, so such a hit was absorbed, counted for no patch, while the face that does face the
ray counts the light it sends back. weigh_reciprocity then scales each row to its own rays' row
sum, which lacked those hits: the floor beside a partition drawn as two coincident faces lost 7 %
of its light on average, 20 % next to it (CIE 171's obstruction case, tests/test_cie171.py), on
the side the first listed face turns its back to. The buried-points test (formfactors.
visible_fraction) read the same back hits as "inside a solid".

``Twins`` finds, for a hit on the back side of a triangle, the triangle of the same plane that
faces the ray there, and SceneSampler.first_hit answers with it: of coincident back-to-back
triangles, the ray hits the one facing it, as it would the nearer side of a wall of any
thickness. Two triangles are twins at a point when their normals are opposite within NORMAL_TOL
and the other lies within PLANE_TOL ray offsets of the point along the normal (closer than the
rays' origin offset resolves: faces 1 cm apart are two surfaces, and Embree orders them). They
need not be alike: a quad and its copy triangulated along the other diagonal, tiles laid back to
back on a plane, a copy covering part of the face (where it does not, the back stays a back).

Not every such pair is a thin wall: two solids touching (a sofa on a floor, a flight of stairs
against a wall, two boxes of one model side by side) put coincident faces face to face, the same
pair locally. What differs is the side the ray comes from: there, the inside of a solid. So a
twin answers only a ray whose side of the plane is open: INSIDE_PROBES short rays from the hit
point into that side (Embree's own answers, unresolved) of which INSIDE_SHARE reach back sides
(where no pair lies back to back: there a hit tells nothing) mean a solid's inside, and
the hit stays on the back (absorbed; formfactors.visible_fraction's points in there stay buried),
as a ray from inside a solid reaching any of its faces.

At export (engine.two_sided), ``covered_share`` tells which faces have their back against such a
twin: the scene sees that side as the twin's front, so the face is neither turned nor given a
back of its own (which, set BACK_OFFSET in front of the twin, hid it: its patches' rays started
behind the copy, the light landed on the unreported copy and the twin read black).

Cost: only triangles with an opposite, coplanar partner somewhere (``flagged``: a k-d tree of
their planes, loosely) take part; a scene without any pays nothing and its rays are as before.
A back hit on a flagged triangle casts one short probe ray along the normal, in an Embree scene of
the flagged triangles of the other orientation (the two twins never share one: the orientation is
the sign of the normal's component along SPLIT, a direction no modelled plane is parallel to in
practice, so the probe cannot return the back-facing twin again).
"""
from __future__ import annotations

import numpy as np

from .by_content import kept_by_content
from .geometry import triangle_cross, unit
from .rays import RAY_OFFSET, embree_scene

__all__ = ["NORMAL_TOL", "PLANE_TOL", "Twins", "covered_share"]

#: two triangles' normals are opposite when they differ by at most this (radians, about)
NORMAL_TOL = 1e-3
#: ... and they are coincident at a point when the other lies within this many ray offsets of it
PLANE_TOL = 4.0
#: the direction whose sign along a normal splits the triangles into two orientations
SPLIT = np.array([0.5773, 0.6151, 0.5372]) / np.linalg.norm([0.5773, 0.6151, 0.5372])
#: the directions (about the side's normal: tangent 1, tangent 2, normal) of the rays that tell
#: whether the side a ray comes from is a solid's inside: along the normal and four at 60 degrees
INSIDE_PROBES = np.array([(0, 0, 1.0), (0.866, 0, 0.5), (-0.866, 0, 0.5), (0, 0.866, 0.5), (0, -0.866, 0.5)])
#: ... a side is a solid's inside when at least this share of those rays (and one) reach back sides:
#: a closed solid's all do; a slab closed by the walls it spans (a landing between two walls) 2 of
#: 5; open space none, or one where a single face turns its back to it
INSIDE_SHARE = 0.4


class Twins:
    """The flagged triangles of a scene (see the module docstring) and their probe scenes; build
    with ``Twins.of``, which returns None when no triangle has an opposite coplanar partner."""

    def __init__(self, tv, tn, flagged, offset, trace):
        self.trace = trace
        self.tv0 = np.asarray(tv[:, 0], dtype=np.float64)
        self.tn = np.asarray(tn, dtype=np.float64)
        self.flag = np.zeros(len(tn), dtype=bool)
        self.flag[flagged] = True
        self.side = (self.tn @ SPLIT) > 0
        self.reach = PLANE_TOL * float(offset)
        self.cos = np.cos(NORMAL_TOL)
        #: per orientation (False, True): its flagged triangles and an Embree scene of them
        self.members, self.scenes = [], []
        for side in (False, True):
            m = flagged[self.side[flagged] == side]
            self.members.append(m)
            corners = np.asarray(tv[m], dtype=np.float64).reshape(-1, 3)
            self.scenes.append(embree_scene(corners, np.arange(len(corners)).reshape(-1, 3)) if len(m) else None)

    @classmethod
    def of(cls, tv, tn, ta, offset, trace, among=None):
        """Twins of the triangles ``tv`` (T, 3, 3) with unit normals ``tn`` and areas ``ta`` (those
        ``among``, indices, when given: the others are not in the ray scene), ``offset`` the rays'
        origin offset (m), ``trace(org, d)`` the scene's own first hit (a triangle index, -1 for a
        miss; origins and directions (n, 3) float32); None when no triangle has a partner facing the other way in its plane.
        A partner is looked for loosely (planes within NORMAL_TOL x the scene's size, about its
        centre): the probes decide exactly."""
        from scipy.spatial import cKDTree

        tv = np.asarray(tv, dtype=np.float64)
        idx = np.arange(len(tv)) if among is None else np.asarray(among, dtype=np.int64)
        idx = idx[np.asarray(ta)[idx] > 0]
        if len(idx) < 2:
            return None
        centroid = tv[idx].mean(axis=1)
        lo, hi = centroid.min(axis=0), centroid.max(axis=0)
        n = np.asarray(tn, dtype=np.float64)[idx]
        c = np.einsum("ij,ij->i", n, centroid - 0.5 * (lo + hi))
        # a plane's distance measured in NORMAL_TOL units of normal: coincident planes within
        # PLANE_TOL offsets, or tilted by NORMAL_TOL over half the scene, are within 2 NORMAL_TOL
        span = PLANE_TOL * float(offset) + NORMAL_TOL * 0.5 * float(np.linalg.norm(hi - lo))
        X = np.concatenate([n, (c * (NORMAL_TOL / span))[:, None]], axis=1)
        # moved apart by 1e-9 (a fixed draw): a k-d tree of many equal points (a floor of 180,000
        # coplanar triangles) cannot split them and took 180 s to build
        X += np.random.default_rng(0).uniform(-1e-9, 1e-9, X.shape)
        # (the tree's shape and the query's threads change no distance: the same flags, faster)
        tree = cKDTree(X, balanced_tree=False, compact_nodes=False)
        dist, _ = tree.query(-X, k=1, distance_upper_bound=3 * NORMAL_TOL, workers=-1)
        flagged = idx[np.isfinite(dist)]
        return cls(tv, tn, flagged, offset, trace) if len(flagged) else None

    def facing(self, org, d, prim) -> np.ndarray:
        """``prim`` (the triangle each ray (origins, directions (n, 3)) hits first, -1 for a miss)
        with every hit on the back side of a flagged triangle replaced by its twin there, the
        triangle of the other orientation that faces the ray at the hit point, when the ray comes
        from an open side (see the module docstring); unchanged elsewhere."""
        prim = np.asarray(prim)
        sel = np.flatnonzero((prim >= 0) & self.flag[np.maximum(prim, 0)])
        if not len(sel):
            return prim
        t = prim[sel].astype(np.int64)
        dd = np.asarray(d, dtype=np.float64)[sel]
        back = np.einsum("ij,ij->i", self.tn[t], dd) > 0
        sel, t, dd = sel[back], t[back], dd[back]
        if not len(sel):
            return prim
        q = self._on_plane(np.asarray(org, dtype=np.float64)[sel], dd, t)
        twin = self.twin_at(q, t)
        has = np.flatnonzero(twin >= 0)
        out = prim.copy()
        if len(has):  # the ray's side of the plane (-n: it reached t's back) open, not a solid's inside
            open_ = has[~self.inside(q[has], -self.tn[t[has]])]
            out[sel[open_]] = twin[open_]
        return out

    def _on_plane(self, o, d, t) -> np.ndarray:
        """Where the rays (origins, directions (n, 3) float64) meet the planes of the triangles t."""
        n = self.tn[t]
        return o + (np.einsum("ij,ij->i", n, self.tv0[t] - o) / np.einsum("ij,ij->i", n, d))[:, None] * d

    def twin_at(self, q, t) -> np.ndarray:
        """(n,) the triangle of the other orientation that faces t's normal's way at the points q
        (on the planes of the flagged triangles t), -1 where there is none: a probe ray along t's
        normal across the plane, PLANE_TOL offsets either side, in the other orientation's scene."""
        out = np.full(len(t), -1, dtype=np.int64)
        n = self.tn[t]
        for side in (False, True):
            m = np.flatnonzero(self.side[t] == side)
            scene = self.scenes[int(not side)]
            if not len(m) or scene is None:
                continue
            p0 = (q[m] - self.reach * n[m]).astype(np.float32)
            hit = np.asarray(scene.run(p0, n[m].astype(np.float32), dists=np.full(len(m), 2 * self.reach,
                                                                                 dtype=np.float32)))
            twin = self.members[int(not side)][np.maximum(hit, 0)]
            ok = (hit >= 0) & (np.einsum("ij,ij->i", self.tn[twin], n[m]) <= -self.cos)
            out[m[ok]] = twin[ok]
        return out

    def inside(self, q, side) -> np.ndarray:
        """(n,) bool: the side ``side`` (unit normals (n, 3)) of the points ``q`` (on a flagged
        plane) is a solid's inside: of the INSIDE_PROBES rays from just off q into it (Embree's own
        answers), at least INSIDE_SHARE (and one) reach a back side. A hit where two triangles lie
        back to back tells nothing (it may be another pair, a solid's face against another), and
        does not count."""
        t1 = unit(np.cross(side, np.where(np.abs(side[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])))
        t2 = np.cross(side, t1)
        k = len(INSIDE_PROBES)
        d = (INSIDE_PROBES[None, :, :1] * t1[:, None] + INSIDE_PROBES[None, :, 1:2] * t2[:, None]
             + INSIDE_PROBES[None, :, 2:] * side[:, None]).reshape(-1, 3)
        org = np.repeat(q + self.reach * side, k, axis=0)
        prim = np.asarray(self.trace(org.astype(np.float32), d.astype(np.float32)))
        hit = prim >= 0
        t = np.maximum(prim, 0)
        back = hit & (np.einsum("ij,ij->i", self.tn[t], d) >= 0)
        known = np.ones(len(prim), dtype=bool)
        paired = np.flatnonzero(hit & self.flag[t])
        if len(paired):
            known[paired] = self.twin_at(self._on_plane(org[paired], d[paired], t[paired]), t[paired]) < 0
        solid = (back & known).reshape(-1, k).sum(axis=1)
        return solid >= np.maximum(1, INSIDE_SHARE * known.reshape(-1, k).sum(axis=1))


#: barycentric points (a, b) of the triangle (v0 + a e1 + b e2) at which covered_share asks
COVER_POINTS = np.array([(1 / 3, 1 / 3), (1 / 6, 1 / 6), (2 / 3, 1 / 6), (1 / 6, 2 / 3),
                         (0.1, 0.45), (0.45, 0.1), (0.45, 0.45)])


@kept_by_content()
def covered_share(vertices, triangles, triangle_face, n_faces: int, among=None, scene=None):
    """(n_faces,) the share of each face's area (a FaceSet's or FaceChunks' world-space
    ``vertices``, ``triangles``, ``triangle_face``) whose back lies against a coincident face that
    faces the other way (at COVER_POINTS of each triangle, weighted by area), among the faces
    ``among`` ((n_faces,) bool; default all), or None when no such pair exists. ``scene``: a
    function returning an Embree scene of exactly these triangles (called only when some
    triangle has a partner: the probes' rays); one is built here otherwise. The answers are kept by
    content (engine.by_content: the same scene exported again casts no ray)."""
    V = np.asarray(vertices, dtype=np.float64)
    tv = V[np.asarray(triangles, dtype=np.int64)]
    cross = triangle_cross(tv)
    ta = 0.5 * np.linalg.norm(cross, axis=1)
    tn = cross / np.where(ta > 0, 2 * ta, 1.0)[:, None]
    lo, hi = V.min(axis=0), V.max(axis=0)
    offset = RAY_OFFSET * float(np.linalg.norm(hi - lo)) + 4 * np.finfo(np.float32).eps * float(np.abs(V).max())
    if scene is None:
        def scene():
            return embree_scene(V, triangles)
    built = []

    def trace(org, d):  # the scene's first hits, the scene built on the first rays
        if not built:
            built.append(scene())
        return built[0].run(org, d)

    face = np.asarray(triangle_face, dtype=np.int64)
    twins = Twins.of(tv, tn, ta, offset, trace, among=None if among is None else np.flatnonzero(
        np.asarray(among, dtype=bool)[face]))
    if twins is None:
        return None
    t = np.flatnonzero(twins.flag)
    k = len(COVER_POINTS)
    tt = np.repeat(t, k)
    a, b = np.tile(COVER_POINTS[:, 0], len(t)), np.tile(COVER_POINTS[:, 1], len(t))
    p = tv[tt, 0] + a[:, None] * (tv[tt, 1] - tv[tt, 0]) + b[:, None] * (tv[tt, 2] - tv[tt, 0])
    n = tn[tt]
    # a ray reaching each point from behind its triangle: answered by the twin facing it, if any
    got = twins.facing(p - n, n, tt)
    covered = np.bincount(face[tt], weights=(got != tt) * np.repeat(ta[t], k) / k, minlength=n_faces)
    area = np.bincount(face, weights=ta, minlength=n_faces)
    return covered / np.where(area > 0, area, 1.0)
