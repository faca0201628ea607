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

Each kind's computations are its own (engine/lights/point.py, spot.py, area.py, sun.py: the
LampKind ``Lamp.kind`` is); this module holds the Lamp, what every kind shares (receiver points,
lamp samples, shadow rays) and ``lamp_irradiance``, which asks each lamp's kind.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import unit
from .kernel_transfer import _sample_patches, kernel_geometry
from .sampling import SceneSampler

__all__ = ["Lamp", "LampJob", "PatchDraws", "PatchStreams", "lamp_irradiance"]

#: receiver points per patch and lamp samples per receiver point (soft lamps; a point lamp of
#: radius 0 takes one ray per receiver point, a sun of angle 0 one direction)
POINTS_PER_PATCH = 64
LAMP_SAMPLES = 4
#: patches per chunk of receiver points
CHUNK_PATCHES = 4096
#: the patches a spot's cone edge or an area beam's edge crosses get this many times the points (the edge
#: is sampled); those for which a spot's cone is narrow at least this many times as many directions
EDGE_POINTS = 16
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
    kind: object  # its LampKind (engine/lights/: point, spot, area, sun): the whole behaviour of its kind
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
    #: a photometric lamp's distribution (engine.photometry.CyclesProfile: engine/lights/photometric.py)
    profile: object = None
    #: Blender's Power (W; a sun's Strength, W/m^2) and colour, and what Cycles multiplies their
    #: product by (3,): power = colour x energy x gain (blender/lamps.py, ``cycles_gain``: the
    #: Light's Exposure, Temperature and Normalize; default 1). Defaults: gain 1, energy the
    #: largest channel of power / gain, colour power / (gain x energy)
    energy: float = None
    color: np.ndarray = None
    gain: np.ndarray = None

    def __post_init__(self):
        if not callable(getattr(self.kind, "irradiance_at", None)):
            raise ValueError(f"lamp {self.name!r}: its kind must be a lamp kind (engine.lights: a LampKind), "
                             f"got {self.kind!r}")
        for k in ("position", "direction", "axis_u", "axis_v", "power"):
            setattr(self, k, np.asarray(getattr(self, k), dtype=np.float64).reshape(3))
        spread = float(self.spread)
        if not 0.0 <= spread <= math.pi + SPREAD_TOLERANCE:  # (Blender keeps pi as a float32, a little above)
            raise ValueError(f"lamp {self.name!r}: its spread (Blender's Spread, the full angle) must be in [0, pi] "
                             f"radians, got {self.spread!r}")
        self.spread = math.pi if spread >= math.pi - SPREAD_TOLERANCE else spread
        self.kind.check(self)
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


def _mix64(x):
    """splitmix64's finaliser on uint64 arrays (wrapping arithmetic): a well-mixed hash of each."""
    with np.errstate(over="ignore"):
        z = np.asarray(x, dtype=np.uint64) + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


class PatchStreams:
    """Uniforms (a generator's ``random`` and ``permuted``, for _sample_patches and _lamp_uniforms)
    that depend only on (``key``, the draw, the patch, the index within the patch's share): each
    of the patches ``patches``' receiver points and lamp samples is its own, the same whichever
    patches are asked with it. (A generator's stream gives a patch the values after those of the
    patches before it: when a moved lamp reaches other patches, every later patch's points
    change.) Counter-based: splitmix64 of the counters."""

    def __init__(self, key, patches):
        h = np.uint64(0)
        for part in key:
            h = _mix64(h ^ np.uint64(int(part) & 0xFFFFFFFFFFFFFFFF))
        self.key, self.patches, self.draws = h, np.asarray(patches, dtype=np.uint64), 0

    def _bits(self, shape) -> np.ndarray:
        m = len(self.patches)
        n = int(np.prod(shape))
        if m == 0 or n % m:
            raise ValueError(f"{shape} values are not a share per patch of {m} patches")
        self.draws += 1
        row = _mix64(_mix64(self.key ^ np.uint64(self.draws)) ^ self.patches)  # (m,)
        return _mix64(row[:, None] ^ np.arange(n // m, dtype=np.uint64)[None, :]).reshape(shape)

    def random(self, shape, dtype=np.float64) -> np.ndarray:
        """Uniforms in [0, 1) of ``shape``, its first axis (or its rows, patch-major) the patches'."""
        bits = self._bits(shape)
        if np.dtype(dtype) == np.float32:
            return ((bits >> np.uint64(40)).astype(np.float32) * np.float32(2.0 ** -24))
        return (bits >> np.uint64(11)).astype(np.float64) * (2.0 ** -53)

    def permuted(self, a, axis=1) -> np.ndarray:
        """Each row of ``a`` (m, n) in an order of its patch's own."""
        if axis != 1 or np.ndim(a) != 2:
            raise ValueError("PatchStreams.permuted permutes the rows of an (m, n) array")
        return np.take_along_axis(a, np.argsort(self._bits(np.shape(a)), axis=1), axis=1)


class _StreamDraws:
    """A chunk's receiver points and lamp uniforms drawn in turn from one generator ``rng``."""

    def __init__(self, rng):
        self.rng = rng

    def points(self, g, s, k):
        return _sample_patches(g, s, k, self.rng)

    def uniforms(self, s, k, j, ns):
        return _lamp_uniforms(self.rng, len(s), k, j, ns)


class PatchDraws:
    """Each patch's own receiver points and lamp uniforms (PatchStreams of ``seed``), kept once
    drawn: ``lamp_irradiance(per_patch=)`` of a lamp evaluated again and again (the lamp
    refinement's search: a patch's points are the same at every evaluation, and drawn once)."""

    def __init__(self, seed):
        self.seed, self._kept = int(seed), {}

    def of_run(self, index, run, k, ns) -> "_KeptDraws":
        """The draws of a lamp job's run ``run`` (LampJob.run) of lamp ``index``, k points, ns samples."""
        key = (index, run, k, ns)
        if key not in self._kept:
            self._kept[key] = _KeptDraws((self.seed, 7) + key, k, ns)
        return self._kept[key]


class _KeptDraws:
    """One run's draws of a PatchDraws: every patch's k points and ns x k lamp uniforms, filled as
    patches are asked (each patch's from PatchStreams of ``key``: the order they come in changes
    nothing)."""

    def __init__(self, key, k, ns):
        self.key, self.k, self.ns, self.have = key, k, ns, None

    def points(self, g, s, k):
        if self.have is None:  # (np.empty: the memory of the patches never asked stays untouched)
            P = g.P
            self.have = np.zeros(P, dtype=bool)
            self.y, self.ny = np.empty((P, self.k, 3), np.float32), np.empty((P, self.k, 3), np.float32)
            self.u = np.empty((self.ns, P, self.k, 2))
        new = np.unique(s[~self.have[s]])
        if len(new):
            streams = PatchStreams(self.key, new)
            self.y[new], self.ny[new] = _sample_patches(g, new, k, streams)
            for j in range(self.ns):
                self.u[j, new] = _lamp_uniforms(streams, len(new), k, j, self.ns).reshape(len(new), k, 2)
            self.have[new] = True
        return self.y[s], self.ny[s]

    def uniforms(self, s, k, j, ns):
        return self.u[j, s].reshape(-1, 2)


def _patch_means(lamp, g, s, k, ns, draws, far, exact):
    """(len(s),) mean irradiance per unit power of ``lamp`` on patches s, from k stratified points
    each and ns lamp samples per point (drawn by ``draws``: a _StreamDraws, or a PatchDraws' run);
    for a point or a spot, the bare point lamp's exact patch means (``exact(patches)``:
    LampJob.exact) times the sampled ratio (shadows, cone, disk), asked
    only for the patches some point of which got light (elsewhere the mean is 0 whatever the exact
    one: a spot's cone or a shadow leaves most of a dense prop's triangles out of the sum). And
    (len(s),) whether the patch is partly lit: some of its points got light, some none (an edge
    crosses it)."""
    sm = g.sampler
    y, ny = draws.points(g, s, k)
    y = np.asarray(y, dtype=np.float64).reshape(-1, 3)
    ny = np.asarray(ny, dtype=np.float64).reshape(-1, 3)
    acc = np.zeros(len(y))
    ref = None
    for j in range(ns):
        e, r = _irradiance_at(lamp, y, ny, draws.uniforms(s, k, j, ns), sm, far)
        acc += e
        if r is not None:
            ref = r if ref is None else ref + r
    lit = (acc > 0).reshape(len(s), k)
    per_patch = (acc / ns).reshape(len(s), k).mean(axis=1)
    if ref is not None:
        rs = ref.reshape(len(s), k).sum(axis=1) / ns
        ok = rs > 0
        need = np.flatnonzero(ok & (per_patch > 0))
        mean = exact(s[need])
        if mean is not None:
            full = np.zeros(len(s))
            full[need] = mean
            per_patch = np.where(ok, full * per_patch * k / np.where(ok, rs, 1.0), per_patch)
    return per_patch, lit.any(axis=1) & ~lit.all(axis=1)


def _irradiance_at(lamp: Lamp, y, n, u, sampler, far):
    """Direct irradiance (n,) per unit power (one channel) at points y (n, 3) with normals n
    (n, 3), one lamp sample each from uniforms u (n, 2) (its kind's ``irradiance_at``), shadow
    rays on ``sampler``; and its kind's control variate at the same points (a point or a spot:
    the bare point-lamp irradiance cos / (4 pi d^2)), else None."""
    e, w, t, ref = lamp.kind.irradiance_at(lamp, y, n, u, far)
    if lamp.cast_shadow:
        lit = e > 0
        if lit.any():
            o = (y[lit] + n[lit] * sampler.offset).astype(np.float32)
            ok = sampler.visible(o, w[lit].astype(np.float32),
                                 np.maximum(t[lit] - 2 * sampler.offset, 0.0).astype(np.float32))
            e[np.flatnonzero(lit)[~ok]] = 0.0
    return e, ref


class LampJob:
    """One lamp's patch means in ``lamp_irradiance``, which its kind's ``light_patches`` computes:
    ``todo`` the patches asked for (``restricted``: fewer than all ``n_patches``), ``k`` receiver
    points per patch, ``g`` the kernel geometry (its sampler, centres, radii, areas); ``run``
    samples patches with some points each, ``put`` sets means computed otherwise, ``rng(stream)``
    a generator of this lamp's own for one more stream. ``per_patch``: a PatchDraws (each patch's
    points and lamp samples its own, kept), or None: drawn in turn from one stream."""

    def __init__(self, lamp, index, g, out, todo, restricted, k, seed, far, per_patch=None):
        self.lamp, self.index, self.g, self.out, self.todo, self.restricted, self.k = \
            lamp, index, g, out, todo, restricted, k
        self.n_patches, self.seed, self.far = out.shape[0], int(seed), far
        self.ns = lamp.kind.samples_per_point(lamp)
        self._draws = _StreamDraws(self.rng(7))
        self.per_patch, self.runs = per_patch, 0

    def rng(self, stream):
        return np.random.default_rng([self.seed, stream, self.index])

    def exact(self, s):
        """(len(s),) the exact patch means of the lamp's control variate on patches ``s`` (its
        kind's ``point_means``), or None for a kind without one."""
        means = self.lamp.kind.point_means(self.lamp, self.g.sampler, s, True, self.n_patches)
        return None if means is None else means[s]

    def put(self, s, mean) -> None:
        """The means ``mean`` (len(s),) per unit power on patches ``s``."""
        self.out[s, self.index] = mean[:, None] * self.lamp.power[None, :]

    def run(self, patches_of_pass, kp) -> np.ndarray:
        """The means of ``patches_of_pass`` from kp points each; returns those partly lit."""
        partly = [np.zeros(0, dtype=np.int64)]
        step = max(1, CHUNK_PATCHES * self.k // kp)
        self.runs += 1
        for c0 in range(0, len(patches_of_pass), step):
            s = patches_of_pass[c0:c0 + step]
            draws = self._draws if self.per_patch is None else self.per_patch.of_run(self.index, self.runs, kp, self.ns)
            mean, part = _patch_means(self.lamp, self.g, s, kp, self.ns, draws, self.far, self.exact)
            self.put(s, mean)
            partly.append(s[part])
        return np.concatenate(partly)


def _far(sampler) -> float:
    """A distance beyond the scene (m): 4 x its bounding box's diagonal + 1, computed once per
    sampler (0.1-0.3 s on a million triangles, at each of the lamp refinement's evaluations)."""
    if "_far" not in sampler.__dict__:
        sampler._far = 4.0 * float(np.linalg.norm(np.ptp(sampler.tv.reshape(-1, 3), axis=0))) + 1.0
    return sampler._far


def lamp_irradiance(patches, lamps, sampler: SceneSampler | None = None, seed: int = 0,
                    points_per_patch: int = POINTS_PER_PATCH, only=None, per_patch=None) -> np.ndarray:
    """(P, n_lamps, 3) direct irradiance (W/m^2) of each lamp on each patch (area mean), with
    shadow rays on ``sampler`` (built here when not given: pass the form factors' one).
    ``only``: the indices of the patches to light (the others get 0), default all; or a list of
    such index arrays, one per lamp (e.g. the patches a spot's cone can reach). Each lamp's kind
    computes its means (``light_patches``, on a LampJob). ``per_patch``: a PatchDraws, each
    patch's receiver points and lamp samples drawn for it alone (the same whichever patches are
    lit, so a moved lamp's means change only as the lamp does: the lamp refinement's search), kept
    across calls; None: drawn in turn from a stream of the seed, per call."""
    P = patches.n_patches
    out = np.zeros((P, len(lamps), 3))
    if not lamps:
        return out
    g = kernel_geometry(patches, points_per_patch, sampler)
    far = _far(g.sampler)
    per_lamp = only is not None and not isinstance(only, np.ndarray) and len(only) == len(lamps) and \
        all(np.ndim(o) == 1 for o in only)
    for li, lamp in enumerate(lamps):
        sel = only[li] if per_lamp else only
        todo = np.arange(P) if sel is None else np.asarray(sel, dtype=np.int64).reshape(-1)
        lamp.kind.light_patches(lamp, LampJob(lamp, li, g, out, todo, sel is not None, points_per_patch, seed, far,
                                                    per_patch))
    return out
