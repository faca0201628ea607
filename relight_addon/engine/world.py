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
from dataclasses import dataclass

import numpy as np

from .formfactors import _cosine_directions
from .kernel_transfer import _Geometry, _sample_patches
from .lamps import CHUNK_PATCHES, Lamp, _tangents, lamp_irradiance
from .sampling import SceneSampler

__all__ = ["EnvironmentMap", "world_irradiance", "WORLD_RAYS", "SKY_MIN"]

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
#: luminance weights of linear Rec.709
LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass
class EnvironmentMap:
    """The World's radiance (H, W, 3) W/(m^2 sr), equirectangular (the module's conventions)."""

    radiance: np.ndarray

    def __post_init__(self):
        r = np.asarray(self.radiance, dtype=np.float64)
        if r.ndim == 1:
            r = r.reshape(1, 1, 3)
        if r.ndim != 3 or r.shape[2] != 3:
            raise ValueError(f"an environment map is (H, W, 3) radiance, got shape {r.shape}")
        if not np.all(np.isfinite(r)):
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
        elev = ((np.arange(H) + 0.5) / H - 0.5) * math.pi
        phi = (0.75 - (np.arange(W) + 0.5) / W) * 2.0 * math.pi
        ce = np.cos(elev)[:, None]
        return np.stack([ce * np.cos(phi)[None, :], ce * np.sin(phi)[None, :],
                         np.broadcast_to(np.sin(elev)[:, None], (H, W))], axis=-1)

    def solid_angles(self) -> np.ndarray:
        """(H, W) solid angle (sr) of each texel; they sum to 4 pi."""
        H, W = self.shape
        e = np.linspace(-0.5 * math.pi, 0.5 * math.pi, H + 1)
        band = (np.sin(e[1:]) - np.sin(e[:-1])) * (2.0 * math.pi / W)
        return np.broadcast_to(band[:, None], (H, W))

    def irradiance_up(self) -> np.ndarray:
        """(3,) irradiance (W/m^2) on an unshadowed surface facing +Z (a closed form to test with)."""
        cos = np.maximum(self.directions()[..., 2], 0.0)
        return np.einsum("hw,hwc->c", self.solid_angles() * cos, self.radiance)

    def split_suns(self, name: str = "World") -> tuple:
        """(suns, rest): the map's suns as engine.lamps.Lamp (kind SUN: strength = the texels'
        radiance x solid angle, W/m^2; direction their power-weighted mean; angle the cone
        holding them), and the map without them (an EnvironmentMap)."""
        if self.is_uniform:
            return [], self
        from scipy import ndimage

        om = self.solid_angles()
        lum = self.radiance @ LUMA
        mean = float(np.sum(lum * om) / (4.0 * math.pi))
        if mean <= 0:
            return [], self
        bright = lum > BRIGHT * mean
        if not bright.any():
            return [], self
        labels, n = ndimage.label(bright)
        dirs = self.directions()
        rest = self.radiance.copy()
        suns = []
        H, W = self.shape
        texel_angle = math.pi / H
        for k in range(1, n + 1):
            sel = labels == k
            power = np.einsum("i,ic->c", om[sel], self.radiance[sel])  # W/m^2 at normal incidence
            wgt = om[sel] * lum[sel]
            d = np.einsum("i,ic->c", wgt, dirs[sel])
            d /= max(np.linalg.norm(d), 1e-300)
            spread = float(np.max(np.arccos(np.clip(dirs[sel] @ d, -1.0, 1.0))))
            angle = 2.0 * spread + texel_angle  # the cone through the texels' centres, plus one texel
            if angle > SUN_MAX_ANGLE:
                continue
            t1, t2 = (t[0] for t in _tangents(d[None, :]))
            suns.append(Lamp(name=f"{name} (sun in the texture)", kind="SUN", position=np.zeros(3), direction=-d,
                             axis_u=t1, axis_v=t2, power=power, angle=angle))
            rest[sel] = 0.0
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
    g = _Geometry(patches, rays_per_patch, sampler=sampler)
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
        local = _cosine_directions(u[..., 0].ravel(), u[..., 1].ravel())
        t1, t2 = _tangents(ny)
        d = local[:, :1] * t1 + local[:, 1:2] * t2 + local[:, 2:3] * ny
        o = (y + ny * sm.offset).astype(np.float32)
        escaped = np.asarray(sm.first_hit(o, d.astype(np.float32))) == -1
        if uniform is not None:
            out[s] += np.pi * escaped.reshape(m, k).mean(axis=1)[:, None] * uniform[None, :]
        else:
            L = np.zeros((m * k, 3))
            L[escaped] = rest.lookup(d[escaped])
            out[s] += np.pi * L.reshape(m, k, 3).mean(axis=1)
    return out
