"""Rays for the engine's own small queries (no bpy): cosine-weighted directions, an Embree scene
of indexed triangles, and rays leaving one side of chosen faces.

The lowest layer of ray casting: it imports only engine.geometry, so that the modules that look at
the scene before it is a model (engine.extent's decisive region, engine.backs' view of back sides)
and the form factors (engine.formfactors) share it without importing one another.
"""
from __future__ import annotations

import numpy as np

from .geometry import group_sum, triangle_cross, unit

__all__ = ["RAY_OFFSET", "cosine_directions", "embree_scene", "side_rays"]

#: origin offset along the normal, relative to the scene's bounding-box diagonal.
RAY_OFFSET = 1e-5


def cosine_directions(u2, u3) -> np.ndarray:
    """(n, 3) float32 cosine-weighted directions about +z from two uniform samples:
    Shirley's concentric map of the unit square to the disk, lifted to the hemisphere."""
    a = 2.0 * u2 - 1.0
    b = 2.0 * u3 - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, np.float32(np.pi / 4) * (b / a), np.float32(np.pi / 2) - np.float32(np.pi / 4) * (a / b))
    phi[~np.isfinite(phi)] = 0.0  # a = b = 0: r = 0, any angle
    out = np.empty((len(a), 3), dtype=np.float32)
    out[:, 0] = r * np.cos(phi)
    out[:, 1] = r * np.sin(phi)
    out[:, 2] = np.sqrt(np.maximum(np.float32(0.0), 1.0 - out[:, 0] ** 2 - out[:, 1] ** 2))
    return out


def embree_scene(vertices, triangles):
    """An Embree scene of the triangles (indexed: half the time of one built from their corners)."""
    from embreex import rtcore as rtc
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene(rtc.EmbreeDevice(), robust=True)
    TriangleMesh(scene, np.ascontiguousarray(vertices, dtype=np.float32), np.ascontiguousarray(triangles, dtype=np.int32))
    return scene


def side_rays(vertices, triangles, triangle_face, idx, n_faces, rays_per_face, rng, side):
    """Cosine-weighted rays leaving one side (``side`` +1: the front, -1: the back) of each face
    ``idx`` from points uniform by area on it: (origins float32, directions float32, the rank in
    ``idx`` of each ray's face, the ray offset (m), each face's unit normal)."""
    n = len(idx)
    rank = np.full(n_faces, -1, dtype=np.int64)
    rank[idx] = np.arange(n)
    tri = np.flatnonzero(rank[triangle_face] >= 0)
    tri = tri[np.argsort(rank[triangle_face[tri]], kind="stable")]
    tv = vertices[triangles[tri]]
    cross = triangle_cross(tv)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    trank = rank[triangle_face[tri]]
    face_area = group_sum(trank, area, n)
    normal = unit(group_sum(trank, cross, n))
    # a triangle of each ray's face, chosen by area: the global key rank + within-face CDF
    cdf = np.cumsum(area) - np.repeat(np.cumsum(face_area) - face_area, np.bincount(trank, minlength=n))
    key = trank + cdf / np.where(face_area > 0, face_area, 1.0)[trank]
    ray_face = np.repeat(np.arange(n), rays_per_face)
    u = rng.random((len(ray_face), 4))
    pick = np.minimum(np.searchsorted(key, ray_face + u[:, 0], side="right"), len(tri) - 1)
    a, b = u[:, 1], u[:, 2]
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    p = tv[pick, 0] + a[:, None] * (tv[pick, 1] - tv[pick, 0]) + b[:, None] * (tv[pick, 2] - tv[pick, 0])
    out = side * normal[ray_face]
    t1 = unit(np.cross(out, np.where(np.abs(out[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])))
    t2 = np.cross(out, t1)
    local = cosine_directions(u[:, 3].astype(np.float32), rng.random(len(ray_face)).astype(np.float32))
    d = local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:] * out
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    offset = RAY_OFFSET * float(np.linalg.norm(hi - lo)) + 4 * np.finfo(np.float32).eps * float(np.abs(vertices).max())
    return (p + offset * out).astype(np.float32), d.astype(np.float32), ray_face, offset, normal
