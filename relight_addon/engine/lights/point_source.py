"""What point and spot lamps share (no bpy): a point (a small disk facing the shading point, with
Blender's soft falloff) of an intensity, times a kind's attenuation (a spot's cone).

Cycles' point light (engine.lamps' docstring): radiant intensity I = c P / (4 pi) W/sr; radius
0: E = I cos(theta) / d^2; radius r > 0: a disk of radius r facing the shading point, of radiance
I / (pi r^2), sampled over the disk. Its patch means use the bare point lamp's exact mean (I x
the patch's solid angle / its area) as a control variate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import unit
from ..lamps import LAMP_SAMPLES, _disk_offsets, _solid_angles
from ..units import TINY
from .kind import LampKind

__all__ = ["PointSourceKind"]


@dataclass(frozen=True)
class PointSourceKind(LampKind):
    """A lamp kind whose light leaves a point (see the module docstring); not registered."""

    def samples_per_point(self, lamp) -> int:
        return LAMP_SAMPLES if lamp.radius > 0 else 1

    def point_means(self, lamp, sampler, todo, restricted, n_patches):
        """The bare point lamp's patch means per W: I x solid angle / area."""
        tri = slice(None) if not restricted else np.flatnonzero(np.isin(sampler.tri_patch, todo))
        om = np.bincount(sampler.tri_patch[tri], weights=_solid_angles(sampler.tv[tri].astype(np.float64),
                                                                       lamp.position), minlength=n_patches)
        return om / (4.0 * math.pi * np.maximum(sampler.area, TINY))

    def attenuation(self, lamp, w_from_lamp):
        """Its radiance's factor along the unit directions from it (None: 1 everywhere)."""
        return None

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        toy = y - lamp.position  # from the lamp to the points, and its unit direction
        nd = unit(toy)
        q = np.broadcast_to(lamp.position, y.shape)
        if lamp.radius > 0:  # the disk facing the shading point (soft falloff)
            q = q + _disk_offsets(u, lamp.radius, nd)
        d = q - y
        t = np.linalg.norm(d, axis=1)
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
