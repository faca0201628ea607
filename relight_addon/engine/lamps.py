"""The scene's lamps (Blender Light objects) as Cycles renders them: their direct irradiance
on the patches, with shadow rays (no bpy).

A lamp lights the patches directly; what it puts into the radiosity system before the first
reflection is rho x H, H its direct irradiance (W/m^2 per channel): B = A^-1 (e + rho H)
(engine.inverse, ``background_irradiance``). Units and conventions, read from Cycles
(``intern/cycles/blender/light.cpp``: strength = colour x power x 2^exposure, the temperature's
colour, and the area when Normalize is off: blender/lamps.py; ``kernel/light/``) and measured
against Cycles bakes (tests/test_cycles_lamps.py). P below is the lamp's ``power``, what Cycles
emits:

- **Point** of power P (W) and colour c: radiant intensity I = c P / (4 pi) W/sr. Radius 0:
  E = I cos(theta) / d^2. Radius r > 0 (Blender's *soft falloff*, the default): a disk of
  radius r facing the shading point, of radiance I / (pi r^2), so E = I / (d^2 + r^2) at normal
  incidence; sampled over the disk here.
- **Spot**: a point lamp times Cycles' cone attenuation smoothstep((cos a - cos(size/2)) /
  ((1 - cos(size/2)) blend)), a the angle from the lamp's -Z axis (1 inside the cone when the
  blend is 0, 0 outside).
- **Area** of power P, shape square / rectangle / disk / ellipse of sizes (u, v), Blender's
  Spread s (the full angle, rad): a one-sided emitter along the lamp's -Z of radiance
  c P / (pi A) x f(a), a the angle between the emitted direction and the -Z axis. Spread 180
  degrees: f = 1 (Lambertian). Below, Cycles' soft-box grid (``area_light_spread_attenuation``,
  intern/cycles/kernel/light/area.h, and ``LightManager::device_update_lights``,
  intern/cycles/scene/light.cpp; the same from Blender 4.0 to 5.1), with h = s / 2:
  f(a) = max(tan h - tan a, 0) N(h), N(h) = 1 / (tan h - h) (3 / h^3 for h <= 0.05, Cycles'
  Taylor branch). N makes the power independent of the spread, since
  2 pi int_0^h (tan h - tan a) cos a sin a da = pi (tan h - h): the exitance stays P / A and
  the radiance along the axis is tan h N(h) times the Lambertian one (10.7 x at 60 degrees,
  2.53 x at 120). Spread 0 (h = 0): a collimated beam along -Z, E = (c P / A) cos(theta) where
  the receiver's projection on the lamp's plane falls inside the lamp (Cycles' delta branch:
  f = pi within tan a <= 1e-5). Sampled over the part of the surface that can reach each
  receiver point, the disk of radius t tan h about its projection (t its distance to the
  plane), as Cycles' ``area_light_spread_clamp_light`` does: the smallest of the lamp, the
  rectangle bounding that disk within the lamp, and the disk itself (with a density that cancels
  f); a beam (spread below 180 degrees) takes SPREAD_POINTS x the receiver points, and the
  patches it lights partly (its edge, or a shadow's, crosses them) EDGE_POINTS x.
- **Sun** of strength S (W/m^2) and angle alpha: irradiance c S cos(theta) at normal incidence,
  its directions sampled in the cone of half-angle alpha / 2.

Shadows: every mesh occludes (both sides), as in Cycles; ``cast_shadow`` off: no shadow rays.
Receiver points: stratified on each patch (kernel_transfer._sample_patches), each with its own
lamp samples, stratified too: a point's samples in distinct cells of the lamp, and the patch's
points in distinct sub-cells of each (``_lamp_uniforms``), so a patch's mean is a stratified
estimate. The patches a spot's cone edge crosses (its blend ring) are sampled again with
EDGE_POINTS times the points; those for which the cone is narrow (``_narrow_cone``: its solid
angle under 1 / NARROW_CONE of the patch's, seen from the lamp) are integrated over the directions
from the lamp instead (``_spot_footprint``): directions drawn in the cone, each traced to the
patch (and a shadow ray back), so a spot narrower than the patches lights its whole footprint
(points sampled on the patches missed it: a 1 degree spot lit nothing, issue 35).
Deterministic for a seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import unit
from .kernel_transfer import _sample_patches, kernel_geometry
from .sampling import SceneSampler

__all__ = ["Lamp", "KINDS", "lamp_irradiance", "spread_normalization", "spread_attenuation"]

KINDS = ("POINT", "SPOT", "AREA", "SUN")
#: receiver points per patch and lamp samples per receiver point (soft lamps; a point lamp of
#: radius 0 takes one ray per receiver point, a sun of angle 0 one direction)
POINTS_PER_PATCH = 64
LAMP_SAMPLES = 4
#: patches per chunk of receiver points
CHUNK_PATCHES = 4096
#: the patches a spot's cone edge or an area beam's edge crosses get this many times the points (the edge
#: is sampled); those for which a spot's cone is narrow at least this many times as many directions
EDGE_POINTS = 16
#: the directions a spot's edge patches share (_spot_footprint): each gets this many / their number,
#: at least EDGE_POINTS x and at most 16 EDGE_POINTS x the receiver points (a narrow spot's few patches:
#: its footprint's edges across them to about 0.5 %)
FOOTPRINT_DIRECTIONS = 1 << 18
#: a spot's cone is narrow for a patch (its footprint integrated) when the patch's cap, seen from the
#: lamp, holds this many times the cone's solid angle (_narrow_cone)
NARROW_CONE = 4
#: an area lamp of spread below pi (a beam: its light changes faster across a patch) gets this many
#: times the points, and the patches partly lit by it (its edge crosses them) EDGE_POINTS times
SPREAD_POINTS = 4
#: an area lamp's spread this close to pi (rad) is pi, Lambertian (Blender's 180 degrees is a float32,
#: 8.7e-8 above pi; Cycles compares it with M_PI_F; 1e-6 below pi its attenuation differs from 1 by
#: tan a / 4e6)
SPREAD_TOLERANCE = 1e-6


@dataclass
class Lamp:
    """One lamp in world space. ``power``: (3,) what Cycles emits per channel (W; a sun's
    W/m^2): Blender's colour x Power (a sun's Strength) x ``gain``. ``direction``: the unit -Z axis of the lamp (where a spot, an
    area lamp or the sun points); ``axis_u`` / ``axis_v``: its unit X and Y axes. ``spread``: an
    area lamp's Spread (rad, Blender's: the full angle, in [0, pi]; pi = Lambertian)."""

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
    spread: float = math.pi
    angle: float = 0.0
    cast_shadow: bool = True
    notes: list = field(default_factory=list)
    #: Blender's Power (W; a sun's Strength, W/m^2) and colour, and what Cycles multiplies their
    #: product by (3,): power = colour x energy x gain (blender/lamps.py, ``cycles_gain``: the
    #: Light's Exposure, Temperature and Normalize; default 1). Defaults: gain 1, energy the
    #: largest channel of power / gain, colour power / (gain x energy)
    energy: float = None
    color: np.ndarray = None
    gain: np.ndarray = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"lamp {self.name!r}: unknown kind {self.kind!r}; one of {', '.join(KINDS)}")
        for k in ("position", "direction", "axis_u", "axis_v", "power"):
            setattr(self, k, np.asarray(getattr(self, k), dtype=np.float64).reshape(3))
        spread = float(self.spread)
        if not 0.0 <= spread <= math.pi + SPREAD_TOLERANCE:  # (Blender keeps pi as a float32, a little above)
            raise ValueError(f"lamp {self.name!r}: its spread (Blender's Spread, the full angle) must be in [0, pi] "
                             f"radians, got {self.spread!r}")
        self.spread = math.pi if spread >= math.pi - SPREAD_TOLERANCE else spread
        if self.kind == "AREA" and not self.area > 0:  # (its radiance P / A: Cycles gives it no light)
            raise ValueError(f"lamp {self.name!r}: an area lamp of size {self.size_u!r} x {self.size_v!r} m has no area "
                             "(Cycles renders no light from it): leave it out, or give it a size")
        self.gain = np.ones(3) if self.gain is None else np.asarray(self.gain, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(self.gain) & (self.gain >= 0)):
            raise ValueError(f"lamp {self.name!r}: its gain (what Cycles multiplies colour x Power by) must be finite "
                             f"and non-negative, got {self.gain.tolist()}")
        base = np.divide(self.power, self.gain, out=np.zeros(3), where=self.gain > 0)
        if self.energy is None:
            self.energy = float(base.max())
        if self.color is None:
            self.color = base / self.energy if self.energy > 0 else np.ones(3)
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


def spread_normalization(spread) -> tuple:
    """(tan h, N(h)) of an area lamp's ``spread`` (rad, the full angle; h = spread / 2): Cycles'
    ``tan_half_spread`` and ``normalize_spread`` (intern/cycles/scene/light.cpp,
    ``LightManager::device_update_lights``): N = 1 / (tan h - h), 3 / h^3 for h <= 0.05 (its
    third-order Taylor branch). (inf, 1) at spread pi (Lambertian), (0, inf) at spread 0."""
    h = 0.5 * float(spread)
    if h >= 0.5 * math.pi - 0.5 * SPREAD_TOLERANCE:
        return math.inf, 1.0
    if h <= 0.0:
        return 0.0, math.inf
    t = math.tan(h)
    return t, (1.0 / (t - h) if h > 0.05 else 3.0 / h ** 3)


def spread_attenuation(cos_a, spread) -> np.ndarray:
    """Cycles' ``area_light_spread_attenuation`` (intern/cycles/kernel/light/area.h): the factor
    max(tan h - tan a, 0) N(h) of an area lamp's radiance at the angles a from its axis, given
    their cosines ``cos_a`` (> 0: in front of it); 1 at spread pi. Spread 0 is a delta (not a
    factor): lamp_irradiance lights it directly."""
    tan_h, norm = spread_normalization(spread)
    cos_a = np.asarray(cos_a, dtype=np.float64)
    if math.isinf(tan_h):
        return np.ones_like(cos_a)
    if tan_h == 0.0:
        raise ValueError("spread 0 is a collimated beam: its radiance is a delta, not a factor")
    c = np.maximum(cos_a, 1e-300)
    tan_a = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    return (tan_h - np.minimum(tan_a, tan_h)) * norm


def _area_samples(lamp: Lamp, y, u):
    """Points q (n, 3) on an area lamp for receiver points y (n, 3) from uniforms u (n, 2), and
    their weights (n,): 1 / (the sampling density x the lamp's area A), 0 for a point off the
    lamp. Only the disk of radius r = t tan h about y's projection on the lamp's plane (t: y's
    distance to it) reaches y (the attenuation is 0 beyond: tan a = rho / t), so of the regions
    holding that part of the lamp the smallest is sampled, as Cycles' own
    ``area_light_spread_clamp_light`` does: the lamp whole (an ellipse), the rectangle bounding
    the disk clipped to the lamp's bounds (uniformly), or the disk itself with the density
    3 (r - rho) / (pi r^3), proportional to the attenuation (N / t) (r - rho), which it cancels.
    At spread pi: the whole lamp, uniformly."""
    a, b = 0.5 * lamp.size_u, 0.5 * lamp.size_v
    tan_h, _ = spread_normalization(lamp.spread)
    rel = y - lamp.position
    t = rel @ lamp.direction
    r = np.full(len(y), np.inf) if math.isinf(tan_h) else np.where(t > 0, t * tan_h, 0.0)
    su, sv = rel @ lamp.axis_u, rel @ lamp.axis_v
    u0, v0 = np.maximum(su - r, -a), np.maximum(sv - r, -b)
    du, dv = np.maximum(np.minimum(su + r, a) - u0, 0.0), np.maximum(np.minimum(sv + r, b) - v0, 0.0)
    qu, qv, region = u0 + u[:, 0] * du, v0 + u[:, 1] * dv, du * dv
    if lamp.ellipse:
        whole = math.pi * a * b <= region  # the ellipse is smaller: sampled whole (concentric map, stratified)
        e = _disk_offsets(u, 1.0, np.broadcast_to(lamp.direction, y.shape).copy())
        qu, qv = np.where(whole, a * (e @ lamp.axis_u), qu), np.where(whole, b * (e @ lamp.axis_v), qv)
        region = np.where(whole, math.pi * a * b, region)
    cone = math.pi * r * r < region  # (never at spread pi: r is infinite)
    if cone.any():
        x = 0.5 + np.cos((np.arccos(1.0 - 2.0 * u[:, 0]) - 2.0 * math.pi) / 3.0)  # inverts 3 x^2 - 2 x^3 = u
        rho, phi = x * r, 2.0 * math.pi * u[:, 1]
        qu, qv = np.where(cone, su + rho * np.cos(phi), qu), np.where(cone, sv + rho * np.sin(phi), qv)
        region = np.where(cone, math.pi * r ** 3 / (3.0 * np.maximum(r - rho, 1e-12 * r + 1e-300)), region)
    inside = ((qu / a) ** 2 + (qv / b) ** 2 <= 1.0 + 1e-9) if lamp.ellipse else \
        (np.abs(qu) <= a * (1 + 1e-9)) & (np.abs(qv) <= b * (1 + 1e-9))
    weight = np.where(inside, region / lamp.area, 0.0)
    return lamp.position + qu[:, None] * lamp.axis_u + qv[:, None] * lamp.axis_v, weight


def _collimated(lamp: Lamp, y, n):
    """Spread 0 (Cycles' delta branch): per W, E = cos(theta) / A where y's projection on the
    lamp's plane lies inside it (in front of it), else 0. Returns (E (n,), the direction to the
    lamp (n, 3), the distance to it (n,)) for the shadow rays."""
    rel = y - lamp.position
    t = rel @ lamp.direction
    su, sv = rel @ lamp.axis_u / (0.5 * lamp.size_u), rel @ lamp.axis_v / (0.5 * lamp.size_v)
    inside = (su * su + sv * sv <= 1.0) if lamp.ellipse else (np.abs(su) <= 1.0) & (np.abs(sv) <= 1.0)
    w = np.broadcast_to(-lamp.direction, y.shape)
    e = np.where(inside & (t > 0), np.maximum(n @ -lamp.direction, 0.0), 0.0) / lamp.area
    return e, w, np.maximum(t, 0.0)


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
    soft = (lamp.kind in ("POINT", "SPOT") and lamp.radius > 0) or (lamp.kind == "AREA" and lamp.spread > 0) or \
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
    elif lamp.kind == "AREA" and lamp.spread == 0.0:
        e, w, t = _collimated(lamp, y, n)
    else:
        if lamp.kind == "AREA":
            q, weight = _area_samples(lamp, y, u)
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
            # radiance f / (pi A) per W, one sample standing for the sampled region (weight x A)
            e = weight * np.maximum(cos_r, 0.0) * np.maximum(cos_l, 0.0) / np.maximum(math.pi * t * t, 1e-300)
            if lamp.spread < math.pi:
                e = e * spread_attenuation(cos_l, lamp.spread)
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


def _cell(idx, n):
    """(origin (len(idx), 2), size (2,)) of cells ``idx`` of an n-grid of [0, 1)^2: square when n
    is a square, else strips along the first coordinate."""
    idx = np.asarray(idx)
    g = int(math.isqrt(n))
    if g * g == n:
        return np.column_stack([idx // g, idx % g]) / g, np.array([1.0 / g, 1.0 / g])
    return np.column_stack([idx / n, np.zeros(len(idx))]), np.array([1.0 / n, 1.0])


def _lamp_uniforms(rng, m, k, j, ns):
    """The lamp samples' uniforms (m k, 2) of pass j of ns, for m patches of k receiver points:
    every point's ns samples in distinct cells of an ns-grid (cell j in pass j), and within that
    cell the patch's k points in distinct sub-cells of a k-grid (a random permutation per patch),
    jittered: each patch's k ns samples stratify the lamp as a grid of k ns cells."""
    sub = rng.permuted(np.tile(np.arange(k), (m, 1)), axis=1).reshape(-1)
    o_sub, c_sub = _cell(sub, k)
    o, c = _cell([j], ns)
    return o + (o_sub + rng.random((m * k, 2)) * c_sub) * c


def _patch_means(lamp, g, s, k, ns, rng, far, exact):
    """(len(s),) mean irradiance per unit power of ``lamp`` on patches s, from k stratified points
    each and ns lamp samples per point; for a point or a spot, ``exact`` (P,) the bare point
    lamp's exact patch means, times the sampled ratio (shadows, cone, disk). And (len(s),) whether
    the patch is partly lit: some of its points got light, some none (an edge crosses it)."""
    sm = g.sampler
    y, ny = _sample_patches(g, s, k, rng)
    y = np.asarray(y, dtype=np.float64).reshape(-1, 3)
    ny = np.asarray(ny, dtype=np.float64).reshape(-1, 3)
    acc = np.zeros(len(y))
    ref = np.zeros(len(y))
    for j in range(ns):
        e, r = _irradiance_at(lamp, y, ny, _lamp_uniforms(rng, len(s), k, j, ns), sm, far)
        acc += e
        if r is not None:
            ref += r
    lit = (acc > 0).reshape(len(s), k)
    per_patch = (acc / ns).reshape(len(s), k).mean(axis=1)
    if exact is not None:
        rs = ref.reshape(len(s), k).sum(axis=1) / ns
        ok = rs > 0
        per_patch = np.where(ok, exact[s] * per_patch * k / np.where(ok, rs, 1.0), per_patch)
    return per_patch, lit.any(axis=1) & ~lit.all(axis=1)


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


def _narrow_cone(lamp: Lamp, g, s) -> np.ndarray:
    """(len(s),) bool: the spot's cone is narrow for patch ``s``: its solid angle is below
    1 / NARROW_CONE of the cap about the patch's centre that holds its bounding sphere (seen
    from the lamp), so the EDGE_POINTS x points sampled on the patch would put few points in its
    footprint (a 1 degree spot on 0.5 m patches: none). Those patches are integrated over the
    cone's directions (``_spot_footprint``); the others keep the points, which sample the lamp's
    disk too (its soft shadows)."""
    v = g.center[s] - lamp.position
    d = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
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


def _spot_footprint(lamp: Lamp, g, s, grid):
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
    c = np.where(inside[:, None], lamp.direction, v / np.maximum(d, 1e-300)[:, None])
    cos_patch = np.where(inside, -1.0, np.sqrt(np.maximum(1.0 - (g.radius[s] / np.maximum(d, 1e-300)) ** 2, 0.0)))
    cone = math.cos(half) > cos_patch  # the cone is the smaller cap
    axis = np.where(cone[:, None], lamp.direction, c)
    cos_max = np.where(cone, math.cos(half), cos_patch)
    m = len(grid)  # the same directions for every patch: the patches sampling the cone share them
    grid = np.broadcast_to(grid[None], (n, m, 2))
    w = _cone_sample(np.repeat(axis, m, axis=0), np.repeat(cos_max, m), grid.reshape(-1, 2))
    pid = np.repeat(s, m)
    # the first front hit of each direction on its patch's triangles (Moller-Trumbore)
    t_hit = np.full(n * m, np.inf)
    n_hit = np.zeros((n * m, 3))
    start, count = sm.tstart[pid], sm.tcount[pid]
    for j in range(int(count.max())):
        on = np.flatnonzero(j < count)
        tri = start[on] + j
        v0, e1, e2, ww = sm.tv[tri, 0], sm.e1[tri], sm.e2[tri], w[on]
        pv = np.cross(ww, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        ok = np.abs(det) > 1e-300
        inv = 1.0 / np.where(ok, det, 1.0)
        tv = lamp.position - v0
        uu = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        vv = np.einsum("ij,ij->i", ww, qv) * inv
        tt = np.einsum("ij,ij->i", e2, qv) * inv
        front = np.einsum("ij,ij->i", sm.tn[tri], ww) < 0
        hit = ok & front & (uu >= 0) & (vv >= 0) & (uu + vv <= 1) & (tt > 0) & (tt < t_hit[on])
        t_hit[on[hit]] = tt[hit]
        n_hit[on[hit]] = sm.tn[tri[hit]]
    e = np.zeros(n * m)
    got = np.flatnonzero(np.isfinite(t_hit))
    if len(got):
        a = _spot_attenuation(lamp, w[got])
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
    g = kernel_geometry(patches, points_per_patch, sampler)
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

        def run(patches_of_pass, kp):  # their means from kp points each; returns those partly lit
            partly = [np.zeros(0, dtype=np.int64)]
            step = max(1, CHUNK_PATCHES * k // kp)
            for c0 in range(0, len(patches_of_pass), step):
                s = patches_of_pass[c0:c0 + step]
                mean, part = _patch_means(lamp, g, s, kp, ns, rng, far, exact)
                out[s, li] = mean[:, None] * lamp.power[None, :]
                partly.append(s[part])
            return np.concatenate(partly)

        if lamp.kind == "SPOT":  # the patches the cone's edge (its blend ring) crosses: EDGE_POINTS x the
            edge = _cone_edge(lamp, g, todo)  # points, or the footprint integrated where the cone is narrow
            run(np.setdiff1d(todo, edge), k)
            narrow = _narrow_cone(lamp, g, edge)
            run(edge[~narrow], k * EDGE_POINTS)
            edge = edge[narrow]
            # the directions per patch from the whole cone's count, whichever patches are asked for
            every = len(edge) if sel is None else \
                int(np.count_nonzero(_narrow_cone(lamp, g, _cone_edge(lamp, g, np.arange(P)))))
            m = int(np.clip(FOOTPRINT_DIRECTIONS // max(every, 1), k * EDGE_POINTS, 16 * k * EDGE_POINTS))
            grid = _footprint_grid(m, np.random.default_rng([int(seed), 8, li]))
            step = max(1, CHUNK_PATCHES * k // len(grid))
            for c0 in range(0, len(edge), step):
                s = edge[c0:c0 + step]
                out[s, li] = _spot_footprint(lamp, g, s, grid)[:, None] * lamp.power[None, :]
        elif lamp.kind == "AREA" and lamp.spread < math.pi:  # a beam: SPREAD_POINTS x the points, and
            run(run(todo, k * SPREAD_POINTS), k * EDGE_POINTS)  # EDGE_POINTS x on the patches its edge crosses
        else:
            run(todo, k)
    return out
