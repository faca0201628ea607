"""An area lamp: a rectangle (or a disk, an ellipse) of a size, one-sided along its -Z, of Blender's
Spread (no bpy).

Cycles' area light (engine.lamps' docstring): of power P, shape square / rectangle / disk /
ellipse of sizes (u, v) and Spread s (the full angle), a one-sided emitter of radiance c P / (pi A)
x f(a), a the angle from its -Z axis: f = 1 at 180 degrees (Lambertian); below, Cycles' soft-box
grid f(a) = max(tan h - tan a, 0) N(h), h = s / 2 (``spread_attenuation``); spread 0 a collimated
beam (``_collimated``). Sampled over the part of the surface that can reach each receiver point
(``_area_samples``); a beam takes SPREAD_POINTS x the receiver points, and the patches it lights
partly EDGE_POINTS x. It reaches the patches in front of its plane (of a beam, those its beam
meets). The solve offers, from every mounting position, AREA_BEAMS squares of the light size for
each of the first AREA_CLUSTERS clusters it sees (engine/candidate_lamps.py), and refines its aim,
sizes and position; its strength is its power per channel (W).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..geometry import unit
from ..lamps import EDGE_POINTS, LAMP_SAMPLES, SPREAD_TOLERANCE, Lamp, _disk_offsets
from ..registry import LIGHT_KINDS
from ..units import TINY
from .kind import Capability, LampKind
from .placed import UNIT_POWER, WRITER, check_length, frame

__all__ = ["AREA", "AreaKind", "area_lamp", "blender_shape", "spread_normalization", "spread_attenuation"]

#: an area lamp of spread below pi (a beam: its light changes faster across a patch) gets this many
#: times the points, and the patches partly lit by it (its edge crosses them) EDGE_POINTS times
SPREAD_POINTS = 4
#: the first clusters a mounting position sees that area lamps are aimed at
AREA_CLUSTERS = 2
#: the area lamps per position and cluster: "wide" (Spread 180 degrees) and "cover" (the beam whose
#: footprint just holds the cluster; where the lamp's square alone is wider, a projector whose
#: penumbra at the cluster is MIN_PENUMBRA x the lamp's size)
AREA_BEAMS = ("wide", "cover")
MIN_PENUMBRA = 0.1


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
    c = np.maximum(cos_a, TINY)
    tan_a = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    return (tan_h - np.minimum(tan_a, tan_h)) * norm


def _area_samples(lamp, y, u):
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
        region = np.where(cone, math.pi * r ** 3 / (3.0 * np.maximum(r - rho, 1e-12 * r + TINY)), region)
    inside = ((qu / a) ** 2 + (qv / b) ** 2 <= 1.0 + 1e-9) if lamp.ellipse else \
        (np.abs(qu) <= a * (1 + 1e-9)) & (np.abs(qv) <= b * (1 + 1e-9))
    weight = np.where(inside, region / lamp.area, 0.0)
    return lamp.position + qu[:, None] * lamp.axis_u + qv[:, None] * lamp.axis_v, weight


def _collimated(lamp, y, n):
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



def _cover_tan(v, t, size) -> float:
    """tan(spread / 2) of the "cover" area lamp (a square of side ``size``) whose footprint just
    holds the points at ``v`` (n, 3) from its centre, of depths ``t`` (n,) along its axis: a point
    whose projection on the lamp's plane is rho from the centre is lit when the square (holding
    the disk of radius size / 2) comes within t tan(spread / 2) of the projection, so the largest
    (rho - size / 2) / t; at least MIN_PENUMBRA size / (2 t) (a projector)."""
    rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", v, v) - t * t, 0.0))
    return float(max(np.max((rho - 0.5 * size) / t), 0.5 * MIN_PENUMBRA * size / float(t.max())))


def _blender_size(light, matrix) -> tuple:
    """A Blender area Light's (size u, size v, ellipse) in world space: its sizes x its object's X
    and Y scale, from its world matrix ``matrix`` (4, 4)."""
    su = float(light.size)
    sv = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else su
    return (su * float(np.linalg.norm(matrix[:3, 0])), sv * float(np.linalg.norm(matrix[:3, 1])),
            light.shape in ("DISK", "ELLIPSE"))


def _shape(size_u, size_v, ellipse) -> tuple:
    """(Blender's area shape: SQUARE, RECTANGLE, DISK or ELLIPSE, whether both sizes are the same)."""
    same = abs(size_u - size_v) <= 1e-9 * max(size_u, size_v)
    return ("DISK" if same else "ELLIPSE") if ellipse else ("SQUARE" if same else "RECTANGLE"), same


@dataclass(frozen=True)
class AreaKind(LampKind):
    """Blender's Area light (see the module docstring)."""

    blender_type = "AREA"
    flags = Capability.AIMED | Capability.EMITTING_AREA | Capability.PLACEABLE
    option = "area_lamps"
    parameters = ("aim_u", "aim_v", "log_size_u", "log_size_v", "slide_u", "slide_v")

    def check(self, lamp) -> None:
        if not lamp.area > 0:  # (its radiance P / A: Cycles gives it no light)
            raise ValueError(f"lamp {lamp.name!r}: an area lamp of size {lamp.size_u!r} x {lamp.size_v!r} m has no "
                             "area (Cycles renders no light from it): leave it out, or give it a size")

    def samples_per_point(self, lamp) -> int:
        return LAMP_SAMPLES if lamp.spread > 0 else 1

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        if lamp.spread == 0.0:
            e, w, t = _collimated(lamp, y, n)
            return e, w, t, None
        q, weight = _area_samples(lamp, y, u)
        d = q - y
        t = np.linalg.norm(d, axis=1)
        w = d / np.maximum(t, TINY)[:, None]
        cos_r = np.einsum("ij,ij->i", n, w)
        cos_l = -(w @ lamp.direction)
        # radiance f / (pi A) per W, one sample standing for the sampled region (weight x A)
        e = weight * np.maximum(cos_r, 0.0) * np.maximum(cos_l, 0.0) / np.maximum(math.pi * t * t, TINY)
        if lamp.spread < math.pi:
            e = e * spread_attenuation(cos_l, lamp.spread)
        return e, w, t, None

    def light_patches(self, lamp, job) -> None:
        """A beam: SPREAD_POINTS x the points, and EDGE_POINTS x on the patches its edge crosses."""
        if lamp.spread < math.pi:
            job.run(job.run(job.todo, job.k * SPREAD_POINTS), job.k * EDGE_POINTS)
        else:
            job.run(job.todo, job.k)

    def reach(self, lamp, patches, radius) -> np.ndarray:
        """The patches in front of its plane, and of a beam those whose bounding sphere's projection
        on its plane comes within (t + radius) tan(spread / 2) of its rectangle, t the depth of
        their centre."""
        v = patches.center - lamp.position[None, :]
        t = v @ lamp.direction
        ok = t > -(radius + 0.5 * math.hypot(lamp.size_u, lamp.size_v))
        if lamp.spread < math.pi:
            gap = np.hypot(np.maximum(np.abs(v @ lamp.axis_u) - 0.5 * lamp.size_u, 0.0),
                           np.maximum(np.abs(v @ lamp.axis_v) - 0.5 * lamp.size_v, 0.0))
            ok &= gap <= (t + radius) * math.tan(0.5 * lamp.spread) + radius
        return np.flatnonzero(ok)

    def per_position(self, n_clusters, work=False) -> int:
        """AREA_BEAMS per cluster, at most AREA_CLUSTERS; ``work``: an area lamp takes LAMP_SAMPLES
        lamp samples a point, and a beam narrower than 180 degrees SPREAD_POINTS times the points."""
        area = sum(LAMP_SAMPLES * (1 if beam == "wide" else SPREAD_POINTS) for beam in AREA_BEAMS) if work \
            else len(AREA_BEAMS)
        return area * min(n_clusters, AREA_CLUSTERS)

    def offer_for(self, mount, rank, cluster, axis, half) -> None:
        """For the first AREA_CLUSTERS clusters, per AREA_BEAMS entry a square of the light size:
        "wide" facing the cluster's centre, "cover" along ``axis`` at the spread whose footprint
        just holds the cluster (none for a cluster reaching behind the lamp's plane)."""
        if rank >= AREA_CLUSTERS:
            return
        p, size = mount.position, mount.size
        v = cluster.points - p[None, :]
        t = v @ axis  # the vertices' depths along the axis
        for beam in AREA_BEAMS:
            if beam == "wide":
                mount.add(self, area_lamp(f"Relight Area {mount.count + 1}", p, unit((cluster.center - p)[None, :])[0],
                                          size))
            elif np.all(t > 0):
                mount.add(self, area_lamp(f"Relight Area {mount.count + 1}", p, axis, size,
                                          spread=2.0 * math.atan(_cover_tan(v, t, size))))

    def refined(self, lamp, values, steps):
        fu, fv = (math.exp(steps.step_log * values[k]) for k in ("log_size_u", "log_size_v"))
        if not all(steps.size_range[0] <= f <= steps.size_range[1] for f in (fu, fv)):
            return None
        return replace(lamp, size_u=lamp.size_u * fu, size_v=lamp.size_v * fv)

    def report_fields(self, lamp) -> dict:
        return {"shape": blender_shape(lamp), "size": [float(lamp.size_u), float(lamp.size_v)],
                "spread": float(lamp.spread), "spread_deg": float(np.degrees(lamp.spread))}

    def blender_light(self, record) -> dict:
        shape, same = _shape(record["size_u"], record["size_v"], record["ellipse"])
        out = {"shape": shape, "size": float(record["size_u"])}
        if not same:
            out["size_y"] = float(record["size_v"])
        out["spread"] = float(record.get("spread", math.pi))  # (a record stored before the spread was kept: 180 degrees)
        return out

    def blender_settings(self, light, matrix) -> tuple:
        su, sv, ellipse = _blender_size(light, matrix)
        return {"size_u": su, "size_v": sv, "ellipse": ellipse, "spread": float(light.spread)}, []

    def blender_dark(self, light, matrix):
        """An area lamp of size 0: Cycles renders no light from it (``Light::has_contribution``)."""
        if min(_blender_size(light, matrix)[:2]) > 0:
            return None
        sv = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
        return (f"is an area lamp of size 0 ({light.size:g} x {sv:g} m): Cycles renders no light from it (an area "
                "light of size zero does not contribute): left out; give it a size, or make it a Point lamp",
                "an area lamp of size 0")

    def cycles_area(self, light, matrix) -> float:
        """Its area (world space)."""
        su, sv, ellipse = _blender_size(light, matrix)
        return su * sv * (np.pi / 4 if ellipse else 1.0)


AREA = AreaKind("area", "Area Lamp", "An area lamp placed and aimed by the solve: its power per channel (W)",
                source="irradiance", strength_unit="W", shape="area", writer=WRITER)
LIGHT_KINDS.register(AREA.name, AREA.label, AREA.description)(AREA)


def area_lamp(name, position, direction, size_u, size_v=None, ellipse=False, spread=math.pi) -> Lamp:
    """The engine.lamps.Lamp of a placed area lamp (1 W per channel), of sides ``size_u`` along its
    X and ``size_v`` (default ``size_u``) along its Y (m, > 0), a disk / ellipse with ``ellipse``,
    emitting along ``direction``, of ``spread`` (rad, Blender's Spread: the full angle, in (0, pi];
    pi = Lambertian). ValueError for a size that is not a positive length or a spread out of range."""
    su = check_length(size_u, "an area lamp's size")
    sv = su if size_v is None else check_length(size_v, "an area lamp's size")
    if not (0.0 < float(spread) <= math.pi):
        raise ValueError(f"an area lamp's spread (Blender's Spread, the full angle) must be in (0, pi] radians, "
                         f"got {spread!r}")
    d, u, v = frame(direction)
    return Lamp(name, AREA, position, d, u, v, UNIT_POWER, size_u=su, size_v=sv, ellipse=bool(ellipse),
                spread=float(spread))


def blender_shape(lamp) -> str:
    """Blender's area-light shape of a Lamp: SQUARE, RECTANGLE, DISK or ELLIPSE."""
    return _shape(lamp.size_u, lamp.size_v, lamp.ellipse)[0]
