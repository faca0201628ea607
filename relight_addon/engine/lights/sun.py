"""A sun: light from a direction, from no position (Blender's Sun light; no bpy).

Cycles' sun (engine.lamps' docstring): of strength S (W/m^2) and angle alpha, irradiance
c S cos(theta) at normal incidence, its directions sampled in the cone of half-angle alpha / 2;
its shadow rays go the scene's size and more. A scene's Sun lamps (and the suns found in a World
texture: engine.world) are lights of this kind in direct-lighting mode (``reduce``): strength what
it emits in W/m^2 per channel, its ``area`` the area it lights (m^2: the sum over the patches of
its irradiance per unit strength x their area, ``light_area``), so that its power (``watts`` x
strength) is the power it puts on the scene's faces; written as the scene's lamps are (writer
"lamp": engine/lights/lamp.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..lamps import LAMP_SAMPLES, _tangents
from ..registry import LIGHT_KINDS
from .kind import Capability, LampKind

__all__ = ["SUN", "SunKind"]


@dataclass(frozen=True)
class SunKind(LampKind):
    """Blender's Sun light (see the module docstring)."""

    blender_type = "SUN"
    flags = Capability.AIMED | Capability.DISTANT
    scene_kind = "sun"

    def samples_per_point(self, lamp) -> int:
        return LAMP_SAMPLES if lamp.angle > 0 else 1

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
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
        return e, w, np.full(len(y), far), None

    def blender_settings(self, light, matrix) -> tuple:
        return {"angle": float(light.angle)}, []

    def cycles_area(self, light, matrix) -> float:
        """pi sin^2(angle / 2) (1 at angle 0)."""
        angle = float(light.angle)
        return float(np.pi * np.sin(0.5 * angle) ** 2) if angle > 0 else 1.0


SUN = SunKind("sun", "Sun", "One of the scene's Sun lamps: its strength per channel (W/m^2)",
              source="irradiance", strength_unit="W/m^2", shape="sun", writer="lamp")
LIGHT_KINDS.register(SUN.name, SUN.label, SUN.description)(SUN)
