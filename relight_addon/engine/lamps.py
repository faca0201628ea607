"""The scene's lamps (Blender Light objects) as Cycles renders them: their direct irradiance
on the patches, with shadow rays (no bpy).

A lamp lights the patches directly; what it puts into the radiosity system before the first
reflection is rho x H, H its direct irradiance (W/m^2 per channel): B = A^-1 (e + rho H)
(engine.inverse, ``background_irradiance``). Units and conventions, read from Cycles
(``intern/cycles/blender/light.cpp``: strength = colour x power; ``kernel/light/``) and measured
against Cycles bakes (tests/test_cycles_lamps.py):

- **Point** of power P (W) and colour c: radiant intensity I = c P / (4 pi) W/sr. Radius 0:
  E = I cos(theta) / d^2. Radius r > 0 (Blender's *soft falloff*, the default): a disk of
  radius r facing the shading point, of radiance I / (pi r^2), so E = I / (d^2 + r^2) at normal
  incidence; sampled over the disk here.
- **Spot**: a point lamp times Cycles' cone attenuation smoothstep((cos a - cos(size/2)) /
  ((1 - cos(size/2)) blend)), a the angle from the lamp's -Z axis (1 inside the cone when the
  blend is 0, 0 outside).
- **Area** of power P, shape square / rectangle / disk / ellipse of sizes (u, v): a one-sided
  Lambertian emitter along the lamp's -Z of radiance c P / (pi A) (exitance P / A); sampled
  over its surface. Spread below 180 degrees is not modelled (a warning at export).
- **Sun** of strength S (W/m^2) and angle alpha: irradiance c S cos(theta) at normal incidence,
  its directions sampled in the cone of half-angle alpha / 2.

Shadows: every mesh occludes (both sides), as in Cycles; ``cast_shadow`` off: no shadow rays.
Receiver points: stratified on each patch (kernel_transfer._sample_patches), each with its own
lamp samples, so a patch's mean is a stratified estimate; the patches a spot's cone edge crosses
(its blend ring) are sampled again with EDGE_POINTS times the points. Deterministic for a seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import unit
from .kernel_transfer import _Geometry, _sample_patches
from .sampling import SceneSampler

__all__ = ["Lamp", "KINDS", "lamp_irradiance"]

KINDS = ("POINT", "SPOT", "AREA", "SUN")
#: receiver points per patch and lamp samples per receiver point (soft lamps; a point lamp of
#: radius 0 takes one ray per receiver point, a sun of angle 0 one direction)
POINTS_PER_PATCH = 64
LAMP_SAMPLES = 4
#: patches per chunk of receiver points
CHUNK_PATCHES = 4096
#: a spot's patches that its cone's edge crosses get this many times the points (the edge is sampled)
EDGE_POINTS = 16


@dataclass
class Lamp:
    """One lamp in world space. ``power``: (3,) colour x power (W) per channel, or for a sun
    colour x strength (W/m^2). ``direction``: the unit -Z axis of the lamp (where a spot, an
    area lamp or the sun points); ``axis_u`` / ``axis_v``: its unit X and Y axes."""

    name: str
    kind: str
    position: np.ndarray
    direction: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    power: np.ndarray
    radius: float = 0.0
    spot_size: float = math.pi
    spot_blend: float = 0.0
    size_u: float = 0.0
    size_v: float = 0.0
    ellipse: bool = False
    angle: float = 0.0
    cast_shadow: bool = True
    notes: list = field(default_factory=list)
    #: Blender's Power (W; a sun's Strength, W/m^2) and colour, power = colour x energy (default:
    #: the largest channel of ``power``, and power / energy)
    energy: float = None
    color: np.ndarray = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"lamp {self.name!r}: unknown kind {self.kind!r}; one of {', '.join(KINDS)}")
        for k in ("position", "direction", "axis_u", "axis_v", "power"):
            setattr(self, k, np.asarray(getattr(self, k), dtype=np.float64).reshape(3))
        if self.energy is None:
            self.energy = float(self.power.max())
        if self.color is None:
            self.color = self.power / self.energy if self.energy > 0 else np.ones(3)
        self.color = np.asarray(self.color, dtype=np.float64).reshape(3)

    @property
    def area(self) -> float:
        """An area lamp's emitting area (m^2)."""
        a = self.size_u * self.size_v
        return a * math.pi / 4 if self.ellipse else a


def _spot_attenuation(lamp: Lamp, w_from_lamp):
    """Cycles' spot cone (kernel/light/spot.h): smoothstep((cos a - cos_half) * smooth)."""
    cos_half = math.cos(0.5 * lamp.spot_size)
    ca = w_from_lamp @ lamp.direction
    if lamp.spot_blend <= 0:
        return (ca > cos_half).astype(np.float64)
    x = np.clip((ca - cos_half) / ((1.0 - cos_half) * lamp.spot_blend), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _tangents(normal):
    """Two unit tangents (t1, t2), each (n, 3), completing the unit normals (n, 3) to a frame."""
    t1 = unit(np.cross(normal, np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])))
    return t1, np.cross(normal, t1)


def _disk_offsets(u, radius, normal):
    """Points on disks of ``radius`` about the origin, perpendicular to ``normal`` (n, 3), from
    uniforms u (n, 2) (concentric map: stratification is kept)."""
    a, b = 2.0 * u[:, 0] - 1.0, 2.0 * u[:, 1] - 1.0
    big = np.abs(a) > np.abs(b)
    rr = np.where(big, a, b)
    phi = np.where(big, (math.pi / 4) * b / np.where(a == 0, 1, a), math.pi / 2 - (math.pi / 4) * a / np.where(b == 0, 1, b))
    rr = rr * radius
    t1, t2 = _tangents(normal)
    return (rr * np.cos(phi))[:, None] * t1 + (rr * np.sin(phi))[:, None] * t2


def _samples_per_point(lamp: Lamp) -> int:
    soft = (lamp.kind in ("POINT", "SPOT") and lamp.radius > 0) or lamp.kind == "AREA" or \
        (lamp.kind == "SUN" and lamp.angle > 0)
    return LAMP_SAMPLES if soft else 1


def _irradiance_at(lamp: Lamp, y, n, u, sampler, far):
    """Direct irradiance (n,) per unit power (one channel) at points y (n, 3) with normals n
    (n, 3), one lamp sample each from uniforms u (n, 2); shadow rays on ``sampler``. For a point
    or a spot also the bare point-lamp irradiance cos / (4 pi d^2) at the same points (the
    control variate of ``lamp_irradiance``), else None."""
    ref = None
    if lamp.kind == "SUN":
        w0 = -lamp.direction
        if lamp.angle > 0:  # a direction in the cone of half-angle angle / 2, uniform in solid angle
            cz = 1.0 - u[:, 0] * (1.0 - math.cos(0.5 * lamp.angle))
            sz = np.sqrt(np.maximum(1.0 - cz * cz, 0.0))
            phi = 2.0 * math.pi * u[:, 1]
            t1, t2 = (t[0] for t in _tangents(w0[None, :]))
            w = cz[:, None] * w0 + (sz * np.cos(phi))[:, None] * t1 + (sz * np.sin(phi))[:, None] * t2
        else:
            w = np.broadcast_to(w0, y.shape)
        cos_r = np.einsum("ij,ij->i", n, w)
        e = np.maximum(cos_r, 0.0)
        t = np.full(len(y), far)
    else:
        if lamp.kind == "AREA":
            if lamp.ellipse:
                q = _disk_offsets(u, 1.0, np.broadcast_to(lamp.direction, y.shape).copy())
                qa, qb = q @ lamp.axis_u, q @ lamp.axis_v  # in the unit disk
                q = (0.5 * lamp.size_u * qa)[:, None] * lamp.axis_u + (0.5 * lamp.size_v * qb)[:, None] * lamp.axis_v
            else:
                q = ((u[:, 0] - 0.5) * lamp.size_u)[:, None] * lamp.axis_u + \
                    ((u[:, 1] - 0.5) * lamp.size_v)[:, None] * lamp.axis_v
            q = q + lamp.position
        else:
            toy = y - lamp.position  # from the lamp to the points, and its unit direction
            nd = unit(toy)
            q = np.broadcast_to(lamp.position, y.shape)
            if lamp.radius > 0:  # the disk facing the shading point (soft falloff)
                q = q + _disk_offsets(u, lamp.radius, nd)
        d = q - y
        t = np.linalg.norm(d, axis=1)
        w = d / np.maximum(t, 1e-300)[:, None]
        cos_r = np.einsum("ij,ij->i", n, w)
        if lamp.kind == "AREA":
            cos_l = -(w @ lamp.direction)
            # radiance 1 / (pi A) per W, one sample standing for the whole area A
            e = np.maximum(cos_r, 0.0) * np.maximum(cos_l, 0.0) / np.maximum(math.pi * t * t, 1e-300)
        else:
            if lamp.radius > 0:  # radiance I / (pi r^2) over the disk of area pi r^2, facing y
                cos_l = -np.einsum("ij,ij->i", w, nd)
                e = np.maximum(cos_r, 0.0) * np.maximum(cos_l, 0.0) / np.maximum(t * t, 1e-300)
            else:
                e = np.maximum(cos_r, 0.0) / np.maximum(t * t, 1e-300)
            e = e / (4.0 * math.pi)  # intensity P / (4 pi) per W
            d0 = np.maximum(np.einsum("ij,ij->i", toy, toy), 1e-300)
            ref = np.maximum(-np.einsum("ij,ij->i", n, toy), 0.0) / (4.0 * math.pi * d0 ** 1.5)
            if lamp.kind == "SPOT":
                e = e * _spot_attenuation(lamp, nd)
    if lamp.cast_shadow:
        lit = e > 0
        if lit.any():
            o = (y[lit] + n[lit] * sampler.offset).astype(np.float32)
            ok = sampler.visible(o, w[lit].astype(np.float32),
                                 np.maximum(t[lit] - 2 * sampler.offset, 0.0).astype(np.float32))
            e[np.flatnonzero(lit)[~ok]] = 0.0
    return e, ref


def _solid_angles(tv, x):
    """(T,) solid angle (sr) of each triangle tv (T, 3, 3) seen from point x (3,), 0 when x lies
    behind the triangle's plane (Van Oosterom and Strackee)."""
    a, b, c = tv[:, 0] - x, tv[:, 1] - x, tv[:, 2] - x
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb + \
        np.einsum("ij,ij->i", b, c) * la
    omega = 2.0 * np.arctan2(np.abs(num), den)
    # the lamp must be in front: on the side of the triangle's normal (e1 x e2)
    return np.where(num < 0, omega, 0.0)  # num = a . (b x c) < 0 <=> x on the normal's side


def _patch_means(lamp, g, s, k, ns, rng, far, exact):
    """(len(s),) mean irradiance per unit power of ``lamp`` on patches s, from k stratified points
    each and ns lamp samples per point; for a point or a spot, ``exact`` (P,) the bare point
    lamp's exact patch means, times the sampled ratio (shadows, cone, disk)."""
    sm = g.sampler
    y, ny = _sample_patches(g, s, k, rng)
    y = np.asarray(y, dtype=np.float64).reshape(-1, 3)
    ny = np.asarray(ny, dtype=np.float64).reshape(-1, 3)
    acc = np.zeros(len(y))
    ref = np.zeros(len(y))
    for j in range(ns):  # stratified lamp samples: one stratum of a ns-grid per pass
        u = rng.random((len(y), 2))
        if ns > 1:
            gk = int(math.isqrt(ns))
            if gk * gk == ns:
                u = (u + np.array([j // gk, j % gk])) / gk
            else:
                u[:, 0] = (u[:, 0] + j) / ns
        e, r = _irradiance_at(lamp, y, ny, u, sm, far)
        acc += e
        if r is not None:
            ref += r
    per_patch = (acc / ns).reshape(len(s), k).mean(axis=1)
    if exact is not None:
        rs = ref.reshape(len(s), k).sum(axis=1) / ns
        ok = rs > 0
        per_patch = np.where(ok, exact[s] * per_patch * k / np.where(ok, rs, 1.0), per_patch)
    return per_patch


def _cone_edge(lamp: Lamp, g, todo) -> np.ndarray:
    """The patches of ``todo`` that a spot's cone edge crosses: the directions to them (their
    bounding spheres') span part of the ring between the full-strength cone and the cone's
    limit, where the light changes across a patch."""
    v = g.center[todo] - lamp.position
    d = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
    ang = np.arccos(np.clip((v @ lamp.direction) / d, -1.0, 1.0))
    spread = np.arcsin(np.clip(g.radius[todo] / d, 0.0, 1.0))
    cos_half = math.cos(0.5 * lamp.spot_size)
    inner = math.acos(min(1.0, cos_half + (1.0 - cos_half) * max(lamp.spot_blend, 0.0)))
    return todo[(ang - spread < 0.5 * lamp.spot_size) & (ang + spread > inner)]


def lamp_irradiance(patches, lamps, sampler: SceneSampler | None = None, seed: int = 0,
                    points_per_patch: int = POINTS_PER_PATCH, only=None) -> np.ndarray:
    """(P, n_lamps, 3) direct irradiance (W/m^2) of each lamp on each patch (area mean), with
    shadow rays on ``sampler`` (built here when not given: pass the form factors' one).
    ``only``: the indices of the patches to light (the others get 0), default all; or a list of
    such index arrays, one per lamp (e.g. the patches a spot's cone can reach)."""
    P = patches.n_patches
    out = np.zeros((P, len(lamps), 3))
    if not lamps:
        return out
    g = _Geometry(patches, points_per_patch, sampler=sampler)
    sm = g.sampler
    far = 4.0 * float(np.linalg.norm(np.ptp(sm.tv.reshape(-1, 3), axis=0))) + 1.0
    per_lamp = only is not None and not isinstance(only, np.ndarray) and len(only) == len(lamps) and \
        all(np.ndim(o) == 1 for o in only)
    for li, lamp in enumerate(lamps):
        k = points_per_patch
        ns = _samples_per_point(lamp)
        rng = np.random.default_rng([int(seed), 7, li])
        sel = only[li] if per_lamp else only
        todo = np.arange(P) if sel is None else np.asarray(sel, dtype=np.int64).reshape(-1)
        exact = None
        if lamp.kind in ("POINT", "SPOT"):  # the bare point lamp's patch mean: I x solid angle / area
            tri = slice(None) if sel is None else np.flatnonzero(np.isin(sm.tri_patch, todo))
            om = np.bincount(sm.tri_patch[tri], weights=_solid_angles(sm.tv[tri].astype(np.float64), lamp.position),
                             minlength=P)
            exact = om / (4.0 * math.pi * np.maximum(sm.area, 1e-300))
        passes = [(todo, k)]
        if lamp.kind == "SPOT":  # the patches the cone's edge (its blend ring) crosses: EDGE_POINTS x the points
            edge = _cone_edge(lamp, g, todo)
            passes = [(np.setdiff1d(todo, edge), k), (edge, k * EDGE_POINTS)]
        for patches_of_pass, kp in passes:
            for c0 in range(0, len(patches_of_pass), max(1, CHUNK_PATCHES * k // kp)):
                s = patches_of_pass[c0:c0 + max(1, CHUNK_PATCHES * k // kp)]
                out[s, li] = _patch_means(lamp, g, s, kp, ns, rng, far, exact)[:, None] * lamp.power[None, :]
    return out
