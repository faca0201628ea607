"""A spot lamp: a point lamp (point_source.py) times Cycles' cone, Blender's Spot Size (the cone's
full angle) and Blend (no bpy).

Its irradiance: smoothstep((cos a - cos(size/2)) / ((1 - cos(size/2)) blend)), a the angle from
its -Z axis (1 inside the cone when the blend is 0, 0 outside), times the point lamp's. The
patches its cone's edge crosses (its blend ring) are sampled again with EDGE_POINTS times the
points; those for which the cone is narrow (``_narrow_cone``: its solid angle under 1 /
NARROW_CONE of the patch's, seen from the lamp) are integrated over the directions from the lamp
instead (``_spot_footprint``): directions drawn in the cone, each traced to the patch (and a
shadow ray back), so a spot narrower than the patches lights its whole footprint (points sampled
on the patches missed it: a 1 degree spot lit nothing, issue 35). It reaches the patches its cone
meets. The solve offers, from every mounting position, a spot per cluster it sees and CONES entry
(engine/candidate_lamps.py) and refines its aim, Spot Size, Blend and position; its strength is its
power per channel (W).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..lamps import EDGE_POINTS, CHUNK_PATCHES, Lamp, _tangents
from ..registry import LIGHT_KINDS
from ..units import TINY
from .kind import Capability
from .placed import UNIT_POWER, WRITER, check_length, frame
from .point_source import PointSourceKind

#: the directions a spot's edge patches share (_spot_footprint): each gets this many / their number,
#: at least EDGE_POINTS x and at most 16 EDGE_POINTS x the receiver points (a narrow spot's few patches:
#: its footprint's edges across them to about 0.5 %)
FOOTPRINT_DIRECTIONS = 1 << 18
#: a spot's cone is narrow for a patch (its footprint integrated) when the patch's cap, seen from the
#: lamp, holds this many times the cone's solid angle (_narrow_cone)
NARROW_CONE = 4
#: a spot's cone: its half-angle is the cluster's and this much more (relative)
CONE_MARGIN = 0.02
#: the spots per position and cluster: (cone, Blender's Blend); cone "cover": the smallest cone
#: holding the whole cluster, "area": the cone of the cluster's solid angle (as large as it)
CONES = (("cover", 0.3), ("area", 0.3))


def _spot_attenuation(lamp, w_from_lamp):
    """Cycles' spot cone (kernel/light/spot.h): smoothstep((cos a - cos_half) * smooth)."""
    cos_half = math.cos(0.5 * lamp.spot_size)
    ca = w_from_lamp @ lamp.direction
    if lamp.spot_blend <= 0:
        return (ca > cos_half).astype(np.float64)
    x = np.clip((ca - cos_half) / ((1.0 - cos_half) * lamp.spot_blend), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)



def _cone_edge(lamp, g, todo) -> np.ndarray:
    """The patches of ``todo`` that a spot's cone edge crosses: the directions to them (their
    bounding spheres') span part of the ring between the full-strength cone and the cone's
    limit, where the light changes across a patch."""
    v = g.center[todo] - lamp.position
    d = np.maximum(np.linalg.norm(v, axis=1), TINY)
    ang = np.arccos(np.clip((v @ lamp.direction) / d, -1.0, 1.0))
    spread = np.arcsin(np.clip(g.radius[todo] / d, 0.0, 1.0))
    cos_half = math.cos(0.5 * lamp.spot_size)
    inner = math.acos(min(1.0, cos_half + (1.0 - cos_half) * max(lamp.spot_blend, 0.0)))
    return todo[(ang - spread < 0.5 * lamp.spot_size) & (ang + spread > inner)]


def _narrow_cone(lamp, g, s) -> np.ndarray:
    """(len(s),) bool: the spot's cone is narrow for patch ``s``: its solid angle is below
    1 / NARROW_CONE of the cap about the patch's centre that holds its bounding sphere (seen
    from the lamp), so the EDGE_POINTS x points sampled on the patch would put few points in its
    footprint (a 1 degree spot on 0.5 m patches: none). Those patches are integrated over the
    cone's directions (``_spot_footprint``); the others keep the points, which sample the lamp's
    disk too (its soft shadows)."""
    v = g.center[s] - lamp.position
    d = np.maximum(np.linalg.norm(v, axis=1), TINY)
    sin_patch = np.clip(g.radius[s] / d, 0.0, 1.0)
    cap = np.where(d <= g.radius[s], 2.0, 1.0 - np.sqrt(1.0 - sin_patch ** 2))  # 1 - cos of the patch's cap
    return (1.0 - math.cos(0.5 * lamp.spot_size)) * NARROW_CONE < cap


def _cone_sample(axis, cos_max, u):
    """Unit directions (n, 3) uniform in solid angle within the caps of half-angle acos(cos_max)
    (n,) about the unit ``axis`` (n, 3), from uniforms u (n, 2)."""
    cz = 1.0 - u[:, 0] * (1.0 - cos_max)
    sz = np.sqrt(np.maximum(1.0 - cz * cz, 0.0))
    phi = 2.0 * math.pi * u[:, 1]
    t1, t2 = _tangents(axis)
    return cz[:, None] * axis + (sz * np.cos(phi))[:, None] * t1 + (sz * np.sin(phi))[:, None] * t2


def _footprint_grid(m, rng) -> np.ndarray:
    """(m', 2) a jittered grid of m' = floor(sqrt(m))^2 uniforms, drawn once per lamp: every patch of
    a spot's edge gets the same directions whichever patches are asked for (a stroke's few rows are
    those of a whole solve)."""
    side = int(math.isqrt(m))
    return (np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), axis=-1).reshape(-1, 2)
            + rng.random((side * side, 2))) / side


def _front_hits(sm, pid, origin, w) -> tuple:
    """(distances (n,), normals (n, 3)): the first front hit of each direction ``w`` (n, 3) from
    ``origin`` on the triangles of its patch ``pid`` (n,) (Moller-Trumbore); inf where none."""
    n = len(w)
    t_hit = np.full(n, np.inf)
    n_hit = np.zeros((n, 3))
    start, count = sm.tstart[pid], sm.tcount[pid]
    for j in range(int(count.max())):
        on = np.flatnonzero(j < count)
        tri = start[on] + j
        v0, e1, e2, ww = sm.tv[tri, 0], sm.e1[tri], sm.e2[tri], w[on]
        pv = np.cross(ww, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        ok = np.abs(det) > TINY
        inv = 1.0 / np.where(ok, det, 1.0)
        tv = origin - v0
        uu = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        vv = np.einsum("ij,ij->i", ww, qv) * inv
        tt = np.einsum("ij,ij->i", e2, qv) * inv
        front = np.einsum("ij,ij->i", sm.tn[tri], ww) < 0
        hit = ok & front & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt > 0) & (tt < t_hit[on])
        t_hit[on[hit]] = tt[hit]
        n_hit[on[hit]] = sm.tn[tri[hit]]
    return t_hit, n_hit


def _spot_footprint(lamp, g, s, grid):
    """(len(s),) mean irradiance per unit power of a spot on patches ``s`` (those its cone's edge
    crosses), as the integral over the directions from the lamp: a patch of area A gets
    E = (1 / A) int I a(w) r(w) dw over the directions w that reach its front (its solid angle,
    shadow rays from the point hit), I = 1 / (4 pi), a the cone's attenuation, r = d^2 / (d^2 +
    r_lamp^2) the soft falloff's disk (exact on its axis, where the disk is seen whole). The m
    directions per patch (a jittered grid) are drawn uniformly in the smaller of two caps that
    hold every direction that counts: the cone (a < size / 2) and the cap about the patch's
    centre that holds its bounding sphere. A spot narrower than the patches puts every direction
    into its footprint, which points sampled on the patches miss (a 1 degree spot: nothing, a 3
    degree one 9 % low, issue 35). The disk's soft shadows are taken as the point's."""
    n = len(s)
    if n == 0:
        return np.zeros(0)
    sm = g.sampler
    half = 0.5 * lamp.spot_size
    v = g.center[s] - lamp.position
    d = np.linalg.norm(v, axis=1)
    inside = d <= g.radius[s]  # the lamp within the patch's bounding sphere: any direction
    c = np.where(inside[:, None], lamp.direction, v / np.maximum(d, TINY)[:, None])
    cos_patch = np.where(inside, -1.0, np.sqrt(np.maximum(1.0 - (g.radius[s] / np.maximum(d, TINY)) ** 2, 0.0)))
    cone = math.cos(half) > cos_patch  # the cone is the smaller cap
    axis = np.where(cone[:, None], lamp.direction, c)
    cos_max = np.where(cone, math.cos(half), cos_patch)
    m = len(grid)  # the same directions for every patch: the patches sampling the cone share them
    grid = np.broadcast_to(grid[None], (n, m, 2))
    w = _cone_sample(np.repeat(axis, m, axis=0), np.repeat(cos_max, m), grid.reshape(-1, 2))
    pid = np.repeat(s, m)
    t_hit, n_hit = _front_hits(sm, pid, lamp.position, w)
    e = np.zeros(n * m)
    got = np.flatnonzero(np.isfinite(t_hit))
    if len(got):
        a = lamp.kind.attenuation(lamp, w[got])  # (its kind's: a photometric spot's cone x profile)
        t = t_hit[got]
        e[got] = a * t * t / (t * t + lamp.radius ** 2) / (4.0 * math.pi)
        if lamp.cast_shadow:
            lit = np.flatnonzero(e[got] > 0)
            if len(lit):
                k = got[lit]
                y = lamp.position + t_hit[k, None] * w[k] + n_hit[k] * sm.offset
                ok = sm.visible(y.astype(np.float32), (-w[k]).astype(np.float32),
                                np.maximum(t_hit[k] - 2 * sm.offset, 0.0).astype(np.float32))
                e[k[~ok]] = 0.0
    omega = 2.0 * math.pi * (1.0 - cos_max)
    return e.reshape(n, m).mean(axis=1) * omega / g.area[s]



def _solid_angle(patches, cluster, position) -> float:
    """The solid angle (sr) the cluster's patches subtend at ``position`` (sum of A cos / d^2)."""
    v = position[None, :] - patches.center[cluster.patches]
    d2 = np.maximum((v * v).sum(axis=1), TINY)
    cos = np.maximum((patches.normal[cluster.patches] * v).sum(axis=1), 0.0) / np.sqrt(d2)
    return float(min((patches.area[cluster.patches] * cos / d2).sum(), 4 * math.pi))


@dataclass(frozen=True)
class SpotKind(PointSourceKind):
    """Blender's Spot light (see the module docstring)."""

    blender_type = "SPOT"
    flags = Capability.AIMED | Capability.PLACEABLE
    option = "spot_lamps"
    parameters = ("aim_u", "aim_v", "log_size", "blend", "slide_u", "slide_v")

    def attenuation(self, lamp, w_from_lamp):
        return _spot_attenuation(lamp, w_from_lamp)

    def light_patches(self, lamp, job) -> None:
        """The patches the cone's edge (its blend ring) crosses: EDGE_POINTS x the points, or the
        footprint integrated where the cone is narrow; the others ``job.k`` points."""
        g, k, todo = job.g, job.k, job.todo
        edge = _cone_edge(lamp, g, todo)
        job.run(np.setdiff1d(todo, edge), k)
        narrow = _narrow_cone(lamp, g, edge)
        job.run(edge[~narrow], k * EDGE_POINTS)
        edge = edge[narrow]
        # the directions per patch from the whole cone's count, whichever patches are asked for
        every = len(edge) if not job.restricted else \
            int(np.count_nonzero(_narrow_cone(lamp, g, _cone_edge(lamp, g, np.arange(job.n_patches)))))
        m = int(np.clip(FOOTPRINT_DIRECTIONS // max(every, 1), k * EDGE_POINTS, 16 * k * EDGE_POINTS))
        grid = _footprint_grid(m, job.rng(8))
        step = max(1, CHUNK_PATCHES * k // len(grid))
        for c0 in range(0, len(edge), step):
            s = edge[c0:c0 + step]
            job.put(s, _spot_footprint(lamp, g, s, grid))

    def reach(self, lamp, patches, radius) -> np.ndarray:
        """The patches its cone meets (their bounding spheres)."""
        v = patches.center - lamp.position[None, :]
        dist = np.linalg.norm(v, axis=1)
        cos_a = (v @ lamp.direction) / np.maximum(dist, TINY)
        ang = np.arccos(np.clip(cos_a, -1.0, 1.0)) - np.arcsin(np.clip(radius / np.maximum(dist, TINY), 0, 1))
        return np.flatnonzero(ang < 0.5 * lamp.spot_size)

    def per_position(self, n_clusters, work=False) -> int:
        return len(CONES) * n_clusters

    def offer_for(self, mount, rank, cluster, axis, half) -> None:
        """Per CONES entry, a spot along ``axis``: "cover" just holds the cluster (CONE_MARGIN more),
        "area" is as large as the cluster's solid angle."""
        for cone, blend in CONES:
            if cone == "cover":
                spot = 2.0 * half * (1.0 + CONE_MARGIN)
            else:  # the cone of the cluster's solid angle: 2 pi (1 - cos(half)) = omega
                spot = 2.0 * math.acos(max(-1.0, 1.0 - _solid_angle(mount.patches, cluster, mount.position)
                                           / (2 * math.pi)))
            if 0 < spot <= math.pi:
                mount.add(self, spot_lamp(f"Relight Spot {mount.count + 1}", mount.position, axis, spot, blend))

    def aim_half_angle(self, lamp) -> float:
        return 0.5 * lamp.spot_size

    def refined(self, lamp, values, steps):
        size = lamp.spot_size * math.exp(steps.step_log * values["log_size"])
        blend = lamp.spot_blend + steps.step_blend * values["blend"]
        if not (0.0 < size <= math.pi and 0.0 <= blend <= 1.0):
            return None
        return replace(lamp, spot_size=size, spot_blend=blend)

    def report_fields(self, lamp) -> dict:
        return {"radius": float(lamp.radius), "spot_size": float(lamp.spot_size),
                "spot_blend": float(lamp.spot_blend), "cone_angle_deg": float(np.degrees(lamp.spot_size))}

    def blender_light(self, record) -> dict:
        return {"shadow_soft_size": float(record["radius"]), "spot_size": float(record["spot_size"]),
                "spot_blend": float(record["spot_blend"]), "show_cone": True}

    def blender_settings(self, light, matrix) -> tuple:
        kw, notes = super().blender_settings(light, matrix)
        kw["spot_size"], kw["spot_blend"] = float(light.spot_size), float(light.spot_blend)
        sx, sy, sz = (float(np.linalg.norm(matrix[:3, i])) for i in range(3))
        if max(sx, sy, sz) - min(sx, sy, sz) > 1e-6 * max(sx, sy, sz):
            notes.append("a non-uniform scale (an elliptic cone) is modelled as a round cone")
        return kw, notes


SPOT = SpotKind("spot", "Spot", "A spot lamp placed and aimed by the solve: its power per channel (W)",
                source="irradiance", strength_unit="W", shape="spot", writer=WRITER)
LIGHT_KINDS.register(SPOT.name, SPOT.label, SPOT.description)(SPOT)


def spot_lamp(name, position, direction, spot_size, spot_blend=0.0, radius=0.0) -> Lamp:
    """The engine.lamps.Lamp of a placed spot (1 W per channel): cone of full angle ``spot_size``
    (rad, Blender's Spot Size, in (0, pi]) and ``spot_blend`` (Blender's Blend, in [0, 1]),
    ``radius`` (m, >= 0). ValueError for a value Blender could not hold."""
    if not (0.0 < float(spot_size) <= math.pi):
        raise ValueError(f"a spot's size (its cone's full angle) must be in (0, pi] radians, got {spot_size!r}")
    if not (0.0 <= float(spot_blend) <= 1.0):
        raise ValueError(f"a spot's blend must be in [0, 1], got {spot_blend!r}")
    d, u, v = frame(direction)
    return Lamp(name, SPOT, position, d, u, v, UNIT_POWER, radius=check_length(radius, "a spot's radius", False),
                spot_size=float(spot_size), spot_blend=float(spot_blend))
