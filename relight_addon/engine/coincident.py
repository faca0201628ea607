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

Cost: only triangles with an opposite, coplanar partner somewhere (``flagged``: a k-d tree of
their planes, loosely) take part; a scene without any pays nothing and its rays are as before.
A back hit on a flagged triangle casts one short probe ray along the normal, in an Embree scene of
the flagged triangles of the other orientation (the two twins never share one: the orientation is
the sign of the normal's component along SPLIT, a direction no modelled plane is parallel to in
practice, so the probe cannot return the back-facing twin again).
"""
from __future__ import annotations

import numpy as np

from .rays import embree_scene

__all__ = ["NORMAL_TOL", "PLANE_TOL", "Twins"]

#: two triangles' normals are opposite when they differ by at most this (radians, about)
NORMAL_TOL = 1e-3
#: ... and they are coincident at a point when the other lies within this many ray offsets of it
PLANE_TOL = 4.0
#: the direction whose sign along a normal splits the triangles into two orientations
SPLIT = np.array([0.5773, 0.6151, 0.5372]) / np.linalg.norm([0.5773, 0.6151, 0.5372])


class Twins:
    """The flagged triangles of a scene (see the module docstring) and their probe scenes; build
    with ``Twins.of``, which returns None when no triangle has an opposite coplanar partner."""

    def __init__(self, tv, tn, flagged, offset):
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
    def of(cls, tv, tn, ta, offset, among=None):
        """Twins of the triangles ``tv`` (T, 3, 3) with unit normals ``tn`` and areas ``ta`` (those
        ``among``, indices, when given: the others are not in the ray scene), ``offset`` the rays'
        origin offset (m); None when no triangle has a partner facing the other way in its plane.
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
        dist, _ = cKDTree(X).query(-X, k=1, distance_upper_bound=3 * NORMAL_TOL)
        flagged = idx[np.isfinite(dist)]
        return cls(tv, tn, flagged, offset) if len(flagged) else None

    def facing(self, org, d, prim) -> np.ndarray:
        """``prim`` (the triangle each ray (origins, directions (n, 3)) hits first, -1 for a miss)
        with every hit on the back side of a flagged triangle replaced by its twin there, the
        triangle of the other orientation that faces the ray at the hit point (see the module
        docstring); unchanged where there is none."""
        prim = np.asarray(prim)
        sel = np.flatnonzero((prim >= 0) & self.flag[np.maximum(prim, 0)])
        if not len(sel):
            return prim
        t = prim[sel].astype(np.int64)
        n = self.tn[t]
        dd = np.asarray(d, dtype=np.float64)[sel]
        cos = np.einsum("ij,ij->i", n, dd)
        back = cos > 0
        sel, t, n, dd, cos = sel[back], t[back], n[back], dd[back], cos[back]
        if not len(sel):
            return prim
        o = np.asarray(org, dtype=np.float64)[sel]
        q = o + (np.einsum("ij,ij->i", n, self.tv0[t] - o) / cos)[:, None] * dd  # the hit point on t's plane
        out = prim.copy()
        for side in (False, True):
            m = np.flatnonzero(self.side[t] == side)
            scene = self.scenes[int(not side)]
            if not len(m) or scene is None:
                continue
            # the probe: from the ray's side of the plane across it, along t's normal (the twin faces it)
            p0 = (q[m] - self.reach * n[m]).astype(np.float32)
            hit = np.asarray(scene.run(p0, n[m].astype(np.float32), dists=np.full(len(m), 2 * self.reach,
                                                                                 dtype=np.float32)))
            ok = hit >= 0
            twin = self.members[int(not side)][np.maximum(hit, 0)]
            ok &= np.einsum("ij,ij->i", self.tn[twin], n[m]) <= -self.cos
            out[sel[m[ok]]] = twin[ok]
        return out
