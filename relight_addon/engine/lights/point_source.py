"""What point and spot lamps share (no bpy): a point (a small disk facing the shading point, with
Blender's soft falloff) of an intensity, times a kind's attenuation (a spot's cone).

Cycles' point light (engine.lamps' docstring): radiant intensity I = c P / (4 pi) W/sr; radius
0: E = I cos(theta) / d^2; radius r > 0: a disk of radius r facing the shading point, of radiance
I / (pi r^2), sampled over the disk. Its patch means use the bare point lamp's exact mean (I x
the patch's solid angle / its area) as a control variate: the solid angle of every triangle of the
patches it lights, seen from the lamp (``_solid_angles``), kept per sampler for the last
KEPT_POSITIONS positions (the candidate lamps of a mounting position share them: issue 37).
"""
from __future__ import annotations

import math
import os
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..geometry import unit
from ..kernel_transfer import _ragged
from ..lamps import LAMP_SAMPLES, _disk_offsets
from ..units import TINY
from .kind import LampKind

__all__ = ["PointSourceKind"]

#: lamp positions whose patches' solid angles a sampler keeps (the candidate lamps hang at a few
#: mounting positions, several spots each; a refined lamp at each position it tries): P floats each
KEPT_POSITIONS = 32
#: triangles per block of ``_solid_angles_of``: a block's temporaries stay in the cache (about 2 x
#: faster than one pass over 400,000 triangles), the blocks shared among the CPUs (numpy releases
#: the GIL): 3 x on 2 cores; each triangle's value is computed alone, so the bits are the same
SOLID_ANGLE_BLOCK = 32768


def _solid_angles(tv, x):
    """(T,) solid angle (sr) of each triangle tv (T, 3, 3) seen from point x (3,), 0 when x lies
    behind the triangle's plane (Van Oosterom and Strackee), in float64. The cross product and
    the norms are written out per component (numpy's np.cross and np.linalg.norm build several
    temporaries of every triangle; the same operations in the same order: the same bits)."""
    tv = np.asarray(tv, dtype=np.float64)
    a, b, c = tv[:, 0] - x, tv[:, 1] - x, tv[:, 2] - x
    la, lb, lc = (np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2]) for v in (a, b, c))
    bc = np.empty_like(b)
    bc[:, 0] = b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1]
    bc[:, 1] = b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2]
    bc[:, 2] = b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]
    num = np.einsum("ij,ij->i", a, bc)
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb + \
        np.einsum("ij,ij->i", b, c) * la
    omega = 2.0 * np.arctan2(np.abs(num), den)
    # the lamp must be in front: on the side of the triangle's normal (e1 x e2)
    return np.where(num < 0, omega, 0.0)  # num = a . (b x c) < 0 <=> x on the normal's side


def _solid_angles_of(tv, tri, x) -> np.ndarray:
    """``_solid_angles(tv[tri], x)`` in blocks of SOLID_ANGLE_BLOCK triangles, on the CPUs."""
    blocks = [tri[i:i + SOLID_ANGLE_BLOCK] for i in range(0, len(tri), SOLID_ANGLE_BLOCK)]
    if len(blocks) <= 1:
        return _solid_angles(tv[tri], x)
    with ThreadPoolExecutor(max_workers=min(len(blocks), os.cpu_count() or 1)) as ex:
        return np.concatenate(list(ex.map(lambda t: _solid_angles(tv[t], x), blocks)))


def _patch_solid_angles(sampler, position, todo, n_patches) -> np.ndarray:
    """(n_patches,) the solid angle (sr) of each patch of ``todo`` seen from ``position`` (the sum
    over its triangles, in the sampler's order), kept on ``sampler`` per position
    (KEPT_POSITIONS, the least recently used dropped): a patch's triangles are summed once."""
    kept = sampler.__dict__.setdefault("_patch_solid_angles", OrderedDict())
    key = np.asarray(position, dtype=np.float64).tobytes()
    if key not in kept:
        kept[key] = (np.zeros(n_patches), np.zeros(n_patches, dtype=bool))
        while len(kept) > KEPT_POSITIONS:
            kept.popitem(last=False)
    kept.move_to_end(key)
    om, done = kept[key]
    new = todo[~done[todo]]
    if len(new):
        tri = _ragged(sampler.tstart[new], sampler.tcount[new])
        om[new] = np.bincount(sampler.tri_patch[tri] if len(tri) else np.zeros(0, dtype=np.int64),
                              weights=_solid_angles_of(sampler.tv, tri, position), minlength=n_patches)[new]
        done[new] = True
    return om


@dataclass(frozen=True)
class PointSourceKind(LampKind):
    """A lamp kind whose light leaves a point (see the module docstring); not registered."""

    def samples_per_point(self, lamp) -> int:
        return LAMP_SAMPLES if lamp.radius > 0 else 1

    def point_means(self, lamp, sampler, todo, restricted, n_patches):
        """The bare point lamp's patch means per W: I x solid angle / area (0 outside ``todo``)."""
        todo = np.unique(np.asarray(todo, dtype=np.int64)) if restricted else np.arange(n_patches)
        om = np.zeros(n_patches)
        om[todo] = _patch_solid_angles(sampler, lamp.position, todo, n_patches)[todo]
        return om / (4.0 * math.pi * np.maximum(sampler.area, TINY))

    def attenuation(self, lamp, w_from_lamp):
        """Its radiance's factor along the unit directions from it (None: 1 everywhere)."""
        return None

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        toy = y - lamp.position  # from the lamp to the points, and its unit direction
        if lamp.radius > 0:  # the disk facing the shading point (soft falloff)
            nd = unit(toy)
            d = np.broadcast_to(lamp.position, y.shape) + _disk_offsets(u, lamp.radius, nd) - y
            t = np.linalg.norm(d, axis=1)
        else:  # (the point itself: d = -toy, its length toy's, computed once; the same numbers)
            t = np.linalg.norm(toy, axis=1)
            nd = toy / np.where(t > 0, t, 1.0)[:, None]
            d = -toy
        w = d / np.maximum(t, TINY)[:, None]
        cos_r = np.einsum("ij,ij->i", n, w)
        if lamp.radius > 0:  # radiance I / (pi r^2) over the disk of area pi r^2, facing y
            cos_l = -np.einsum("ij,ij->i", w, nd)
            e = np.maximum(cos_r, 0.0) * np.maximum(cos_l, 0.0) / np.maximum(t * t, TINY)
        else:
            e = np.maximum(cos_r, 0.0) / np.maximum(t * t, TINY)
        e = e / (4.0 * math.pi)  # intensity P / (4 pi) per W
        d0 = np.maximum(np.einsum("ij,ij->i", toy, toy), TINY)
        ref = np.maximum(-np.einsum("ij,ij->i", n, toy), 0.0) / (4.0 * math.pi * d0 ** 1.5)
        a = self.attenuation(lamp, nd)
        if a is not None:
            e = e * a
        return e, w, t, ref

    def report_fields(self, lamp) -> dict:
        return {"radius": float(lamp.radius)}

    def blender_light(self, record) -> dict:
        return {"shadow_soft_size": float(record["radius"])}

    def blender_settings(self, light, matrix) -> tuple:
        """Its radius (Blender's Radius, ``shadow_soft_size``); soft falloff off: radius 0, named."""
        kw, notes = {"radius": float(light.shadow_soft_size)}, []
        if not getattr(light, "use_soft_falloff", True) and kw["radius"] > 0:
            notes.append("soft falloff off: modelled as a point lamp of the same intensity")
            kw["radius"] = 0.0
        return kw, notes

    def cycles_area(self, light, matrix) -> float:
        """4 pi r^2 (4 at r = 0)."""
        a = 4.0 * np.pi * float(light.shadow_soft_size) ** 2
        return a if a > 0 else 4.0
