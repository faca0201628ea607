"""The World's light: the radiance Cycles sees in every direction, and its direct irradiance on
the patches through the directions that escape the scene (no bpy).

The World is an equirectangular map of radiance (W/(m^2 sr) per channel), made by Cycles itself
from whatever the World's node tree is (blender/world.py renders it with a panoramic camera); a
uniform World is a map of one texel. Conventions (measured on Cycles, tests/test_cycles_world.py):
row 0 is the nadir (-Z), the last row the zenith (+Z), rows linear in elevation; the column of
azimuth phi = atan2(y, x) is at u = 0.75 - phi / (2 pi) (mod 1), so the image's centre looks
along +Y, a quarter to its left along -X.

Direct irradiance E = integral over the escaping hemisphere of L(w) cos(theta) dw, estimated with
cosine-weighted rays (E = pi x mean of L over the rays that hit nothing). A sun in the map (a
sky texture's sun disc, the sun of an HDRI) would make that estimate noisy: its texels, those
far brighter than the map's mean (BRIGHT) in a small patch of sky (SUN_MAX_ANGLE), are taken
out of the map and lit as Sun lamps of the same power (engine.lamps, with shadow rays), so each
patch gets them exactly as a sun. Deterministic for a seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .rays import cosine_directions
from .kernel_transfer import _sample_patches, kernel_geometry
from .lamps import CHUNK_PATCHES, Lamp, _tangents, lamp_irradiance
from .lights.sun import SUN
from .sampling import SceneSampler
from .units import TINY, exitance_from_radiance, luminance_weighted, radiance_from_exitance

__all__ = ["EnvironmentMap", "Detail", "world_irradiance", "sees_sky", "WORLD_RAYS", "SKY_MIN"]

#: hemisphere rays per patch for the World's light (one cosine-weighted direction per receiver point)
WORLD_RAYS = 1024
#: patches whose share of escaping hemisphere (1 - form-factor row sum) is at most this cast no
#: sky rays: a closed room costs nothing
SKY_MIN = 1e-3
#: a texel whose luminance exceeds this many times the map's mean (over the sphere) belongs to a sun
BRIGHT = 50.0
#: a group of bright texels is a sun when it spans at most this cone (full angle, radians); a
#: larger bright region (a window in an interior HDRI) stays in the map, sampled by the sky rays
SUN_MAX_ANGLE = math.radians(12.0)
#: the test whether the World lights the scene at all (``sees_sky``): rays in all, at least so
#: many per face, and the share of the scene's hemisphere that must escape
SKY_TEST_RAYS = 200_000
SKY_TEST_MIN_RAYS = 8
SKY_TEST_SHARE = 1e-4


def _directions(H: int, W: int, rows, cols) -> np.ndarray:
    """(len(rows), len(cols), 3) unit directions of the centres of texels (rows, cols) of an H x W map."""
    elev = ((np.asarray(rows) + 0.5) / H - 0.5) * math.pi
    phi = (0.75 - (np.asarray(cols) + 0.5) / W) * 2.0 * math.pi
    ce = np.cos(elev)[:, None]
    return np.stack([ce * np.cos(phi)[None, :], ce * np.sin(phi)[None, :],
                     np.broadcast_to(np.sin(elev)[:, None], (len(elev), len(phi)))], axis=-1)


def _solid_angles(H: int, W: int, rows, cols) -> np.ndarray:
    """(len(rows), len(cols)) solid angles (sr) of texels (rows, cols) of an H x W map."""
    rows = np.asarray(rows)
    lo, hi = (rows / H - 0.5) * math.pi, ((rows + 1) / H - 0.5) * math.pi
    band = (np.sin(hi) - np.sin(lo)) * (2.0 * math.pi / W)
    return np.broadcast_to(band[:, None], (len(rows), len(cols)))


def _sun(radiance, om, dirs, texel_angle) -> tuple:
    """(power (3,) W/m^2 at normal incidence, unit direction towards it, the full angle of the
    cone about it through the texels' centres plus one texel) of texels (n, 3) / (n,) / (n, 3)."""
    power = np.einsum("i,ic->c", om, radiance)
    d = np.einsum("i,ic->c", om * luminance_weighted(radiance), dirs)
    d /= max(np.linalg.norm(d), TINY)
    spread = float(np.max(np.arccos(np.clip(dirs @ d, -1.0, 1.0))))
    return power, d, 2.0 * spread + texel_angle


@dataclass
class Detail:
    """A block of the map rendered ``scale`` times finer: it covers texels [row, row + h) x
    [col, col + w) of the map, ``radiance`` (h scale, w scale, 3). Where a sun is, its direction
    and size come from here (a sun disc is smaller than a texel)."""

    row: int
    col: int
    scale: int
    radiance: np.ndarray

    def block(self) -> tuple:
        h, w = (n // self.scale for n in self.radiance.shape[:2])
        return slice(self.row, self.row + h), slice(self.col, self.col + w)


@dataclass
class EnvironmentMap:
    """The World's radiance (H, W, 3) W/(m^2 sr), equirectangular (the module's conventions), and
    finer blocks of it where its suns are (``details``: Detail)."""

    radiance: np.ndarray
    details: list = field(default_factory=list)

    def __post_init__(self):
        r = np.asarray(self.radiance, dtype=np.float64)
        if r.ndim == 1:
            r = r.reshape(1, 1, 3)
        if r.ndim != 3 or r.shape[2] != 3:
            raise ValueError(f"an environment map is (H, W, 3) radiance, got shape {r.shape}")
        if not all(np.all(np.isfinite(a)) for a in [r] + [d.radiance for d in self.details]):
            raise ValueError("the World's radiance has NaN or infinite values")
        self.radiance = np.maximum(r, 0.0)

    @classmethod
    def uniform(cls, radiance) -> "EnvironmentMap":
        return cls(np.asarray(radiance, dtype=np.float64).reshape(1, 1, 3))

    @property
    def shape(self):
        return self.radiance.shape[:2]

    @property
    def is_uniform(self) -> bool:
        return self.radiance.shape[:2] == (1, 1)

    def texel(self, w) -> tuple:
        """(row, column) of the texels seen along unit directions w (n, 3)."""
        H, W = self.shape
        elev = np.arcsin(np.clip(w[:, 2], -1.0, 1.0))
        row = np.clip(((elev / math.pi + 0.5) * H).astype(np.int64), 0, H - 1)
        u = np.mod(0.75 - np.arctan2(w[:, 1], w[:, 0]) / (2.0 * math.pi), 1.0)
        col = np.clip((u * W).astype(np.int64), 0, W - 1)
        return row, col

    def lookup(self, w) -> np.ndarray:
        """(n, 3) radiance along unit directions w (n, 3) (the texel's value)."""
        row, col = self.texel(w)
        return self.radiance[row, col]

    def directions(self) -> np.ndarray:
        """(H, W, 3) unit directions of the texel centres."""
        H, W = self.shape
        return _directions(H, W, np.arange(H), np.arange(W))

    def solid_angles(self) -> np.ndarray:
        """(H, W) solid angle (sr) of each texel; they sum to 4 pi."""
        H, W = self.shape
        return _solid_angles(H, W, np.arange(H), np.arange(W))

    def irradiance_up(self) -> np.ndarray:
        """(3,) irradiance (W/m^2) on an unshadowed surface facing +Z (a closed form to test
        with): its suns (split_suns) at their directions, the rest of the map texel by texel."""
        suns, rest = self.split_suns()
        cos = np.maximum(rest.directions()[..., 2], 0.0)
        return np.einsum("hw,hwc->c", rest.solid_angles() * cos, rest.radiance) + \
            sum((s.power * max(-float(s.direction[2]), 0.0) for s in suns), np.zeros(3))

    def mean_luminance(self) -> float:
        """The luminance (Rec.709) averaged over the sphere."""
        return float(np.sum(luminance_weighted(self.radiance) * self.solid_angles()) / (4.0 * math.pi))

    def sun_regions(self) -> list:
        """The map's suns, each (mask (H, W) bool, unit direction (3,) towards it, cone angle): a
        connected group of texels brighter than BRIGHT times the map's mean luminance, its
        direction their power-weighted mean, within a cone of at most SUN_MAX_ANGLE."""
        mean = self.mean_luminance()
        if self.is_uniform or mean <= 0:
            return []
        from scipy import ndimage

        labels, n = ndimage.label(luminance_weighted(self.radiance) > BRIGHT * mean)
        om, dirs = self.solid_angles(), self.directions()
        out = []
        for k in range(1, n + 1):
            sel = labels == k
            _, d, angle = _sun(self.radiance[sel], om[sel], dirs[sel], math.pi / self.shape[0])
            if angle <= SUN_MAX_ANGLE:
                out.append((sel, d, angle))
        return out

    def _detail(self, sel):
        rows, cols = np.nonzero(sel)
        for det in self.details:
            rs, cs = det.block()
            if rs.start <= rows.min() and rows.max() < rs.stop and cs.start <= cols.min() and cols.max() < cs.stop:
                return det
        return None

    def split_suns(self, name: str = "World") -> tuple:
        """(suns, rest): the map's suns as engine.lamps.Lamp (kind SUN: strength = the texels'
        radiance x solid angle, W/m^2; direction their power-weighted mean; angle the cone
        holding them), and the map without them (an EnvironmentMap). Where a Detail covers a
        sun, the sun is its bright fine texels, and the block of the map the rest of it."""
        if self.is_uniform:
            return [], self
        H, W = self.shape
        mean = self.mean_luminance()
        om, dirs = self.solid_angles(), self.directions()
        rest = self.radiance.copy()
        suns = []
        for sel, d, angle in self.sun_regions():
            det = self._detail(sel)
            if det is None:
                power = np.einsum("i,ic->c", om[sel], self.radiance[sel])
                rest[sel] = 0.0
            else:
                k = det.scale
                rs, cs = det.block()
                rows, cols = np.arange(rs.start * k, rs.stop * k), np.arange(cs.start * k, cs.stop * k)
                fine = det.radiance
                om_f = _solid_angles(H * k, W * k, rows, cols)
                bright = luminance_weighted(fine) > BRIGHT * mean
                power, d, angle = _sun(fine[bright], om_f[bright], _directions(H * k, W * k, rows, cols)[bright],
                                       math.pi / (H * k))
                left = np.where(bright[..., None], 0.0, fine) * om_f[..., None]
                h, w = len(rows) // k, len(cols) // k
                num = left.reshape(h, k, w, k, 3).sum(axis=(1, 3))
                rest[rs, cs] = num / om_f.reshape(h, k, w, k).sum(axis=(1, 3))[..., None]
            t1, t2 = (t[0] for t in _tangents(d[None, :]))
            suns.append(Lamp(name=f"{name} (sun in the texture)", kind=SUN, position=np.zeros(3), direction=-d,
                             axis_u=t1, axis_v=t2, power=power, angle=angle))
        return suns, EnvironmentMap(rest)


def _as_map(world) -> EnvironmentMap:
    return world if isinstance(world, EnvironmentMap) else EnvironmentMap.uniform(world)


def world_irradiance(patches, world, sampler: SceneSampler | None = None, seed: int = 0,
                     rays_per_patch: int = WORLD_RAYS, sky_share=None) -> np.ndarray:
    """(P, 3) direct irradiance (W/m^2) of the World on each patch. ``world``: an EnvironmentMap,
    or a uniform radiance (3,) W/(m^2 sr). The map's suns (EnvironmentMap.split_suns) are lit as
    Sun lamps (engine.lamps.lamp_irradiance); the rest with rays from stratified points, one
    cosine-weighted direction each, the directions stratified over the hemisphere too: a ray
    that hits any triangle, front or back, sees no sky; one that escapes sees the map's texel.
    ``sky_share`` (P,): an upper bound of each patch's escaping share, 1 - its form-factor row sum
    (rays that leave the scene or hit a back side): patches below SKY_MIN cast no rays."""
    P = patches.n_patches
    env = _as_map(world)
    suns, rest = env.split_suns()
    g = kernel_geometry(patches, rays_per_patch, sampler)
    sm = g.sampler
    rng = np.random.default_rng([int(seed), 11])
    out = np.zeros((P, 3))
    open_ = np.arange(P) if sky_share is None else np.flatnonzero(np.asarray(sky_share) > SKY_MIN)
    if suns and len(open_):
        out += lamp_irradiance(patches, suns, sampler=sm, seed=seed, only=open_).sum(axis=1)
    uniform = rest.radiance[0, 0] if rest.is_uniform else None
    for c0 in range(0, len(open_), CHUNK_PATCHES):
        s = open_[c0:c0 + CHUNK_PATCHES]
        y, ny = _sample_patches(g, s, rays_per_patch, rng)
        y = np.asarray(y, dtype=np.float64).reshape(-1, 3)
        ny = np.asarray(ny, dtype=np.float64).reshape(-1, 3)
        # directions stratified too: a jittered gk x gk grid of the unit square per patch, paired
        # with the points by a random permutation (the form factors' "stratified" sampling)
        m, k = len(s), rays_per_patch
        gk = int(math.isqrt(k))
        cell = np.arange(k) if gk * gk == k else None
        u = rng.random((m, k, 2), dtype=np.float32)
        if cell is not None:
            cells = rng.permuted(np.broadcast_to(cell, (m, k)), axis=1)
            u[..., 0] = (u[..., 0] + cells // gk) / gk
            u[..., 1] = (u[..., 1] + cells % gk) / gk
        local = cosine_directions(u[..., 0].ravel(), u[..., 1].ravel())
        t1, t2 = _tangents(ny)
        d = local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:3] * ny
        o = (y + ny * sm.offset).astype(np.float32)
        escaped = np.asarray(sm.first_hit(o, d.astype(np.float32))) == -1
        if uniform is not None:
            out[s] += exitance_from_radiance(escaped.reshape(m, k).mean(axis=1)[:, None]) * uniform[None, :]
        else:
            L = np.zeros((m * k, 3))
            L[escaped] = rest.lookup(d[escaped])
            out[s] += exitance_from_radiance(L.reshape(m, k, 3).mean(axis=1))
    return out


def sees_sky(faces, rays: int = SKY_TEST_RAYS, seed: int = 0) -> bool:
    """Whether the World can light the scene: cosine-weighted rays from points spread over the
    faces' fronts (each face one patch, at least SKY_TEST_MIN_RAYS each, ``rays`` in all) escape
    it, as a share of the scene's area-weighted hemisphere above SKY_TEST_SHARE. Faces whose every
    ray escapes count only when they are targets: a face lying on another (a rug's or a leg's
    bottom on the floor) sees out through the floor, but the light it gets there reaches no other
    face. An opening of a (share of the scene's area) is found when a > SKY_TEST_SHARE: a 10 x
    10 cm hole in a 4 x 3 x 2.5 m room. The World's map is not rendered for a scene that fails
    this (a closed room)."""
    from .scene import mesh_patches, scene_scale

    patches = mesh_patches(faces, 2.0 * scene_scale(faces) + 1.0)
    per_patch = max(SKY_TEST_MIN_RAYS, int(rays) // max(patches.n_patches, 1))
    share = radiance_from_exitance(world_irradiance(patches, np.ones(3), seed=seed, rays_per_patch=per_patch)[:, 0])
    counted = share < 1.0
    if faces.target is not None:
        counted |= np.asarray(faces.target, dtype=bool)[patches.face]
    area = patches.area
    return bool(np.sum(area * share * counted) > SKY_TEST_SHARE * np.sum(area))
