"""The scene's own lamps as lights of the direct-lighting mode ("reduce"; no bpy).

A lamp is an *irradiance* source: its column of ``LightSet.irradiance`` is its direct irradiance
on the patches per unit of its strength (engine.lamps, shadows included), and its column of T is
A^-1 diag(rho) H (engine.inverse). Two kinds, written alike (writer "lamp": the Blender layer
sets the Light's Power or Strength and colour, or disables the lamp, restorably):

- ``lamp``: a Point, Spot or Area lamp. Strength: its power per channel in W, what Cycles emits
  (engine.lamps.Lamp.power: the scene's own configuration is the lamp as the user set it);
  ``watts`` = 1.
- ``sun``: a Sun lamp (engine/lights/sun.py, registered after this one). Strength: what it emits in
  W/m^2 per channel (Lamp.power). Its ``area`` is the area it lights (m^2: the sum over the patches of
  its irradiance per unit strength x their area), so that its power (``watts`` x strength) is the
  power it puts on the scene's faces.

Which of the two a scene lamp is: its kind's ``scene_kind`` (engine.lamps.Lamp.kind, a LampKind).

A Blender Light has one Power and one colour: ``blender_values`` turns a strength per channel
into them (the user's colour kept when the reduction scaled every channel alike), through what
Cycles multiplies them by (the Light's Exposure, Temperature and Normalize: Lamp.gain).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..registry import LIGHT_KINDS
from .kind import LightKind
from .lightset import LightSet, append_lamps

__all__ = ["LAMP", "add_lamps", "blender_values"]

LAMP = LightKind("lamp", "Lamp", "One of the scene's Point, Spot or Area lamps: its power per channel (W)",
                 source="irradiance", strength_unit="W", shape="lamp", writer="lamp")
LIGHT_KINDS.register(LAMP.name, LAMP.label, LAMP.description)(LAMP)


def add_lamps(lights: LightSet | None, candidates, n_patches: int, lamps, irradiance, patch_area) -> LightSet:
    """The surface ``lights`` (None: there are none; ``candidates`` are then their (empty) patches)
    followed by one light per lamp of ``lamps`` (engine.lamps.Lamp), whose column of
    ``irradiance`` (P, n_lamps) is its direct irradiance (W/m^2) per unit of strength.
    ``patch_area`` (P,) m^2 gives a sun its lit area."""
    H = sp.csc_matrix(np.asarray(irradiance, dtype=np.float64).reshape(n_patches, len(lamps)))
    lit = np.asarray(H.T @ np.asarray(patch_area, dtype=np.float64)).reshape(-1)
    area = np.array([lamp.kind.light_area(lamp, lit[i]) for i, lamp in enumerate(lamps)], dtype=np.float64)
    return append_lamps(lights, candidates, n_patches, lamps, [lamp.kind.scene_kind for lamp in lamps], H, area)


#: relative difference between channels' scale factors below which a lamp keeps its colour
SAME_FACTOR = 1e-6


def blender_values(strength, energy, color, gain=None) -> tuple:
    """(Power, colour (3,)) of a Blender Light that makes Cycles emit ``strength`` (3,) per channel
    (W; for a sun W/m^2), from its own ``energy`` and ``color`` and what Cycles multiplies colour x
    Power by, ``gain`` (3,; engine.lamps.Lamp.gain, default 1): colour x Power = strength / gain.
    When that is the lamp's own colour x Power scaled alike in every channel it emits, its colour is
    kept and its Power scaled; otherwise Power = the largest channel, colour = (strength / gain) /
    Power (each channel's power as predicted; the colour changes). A strength of 0 gives (0,
    colour). ValueError when a channel the lamp cannot emit (gain 0: a low Temperature's blue) must."""
    s = np.maximum(np.asarray(strength, dtype=np.float64).reshape(3), 0.0)
    c = np.asarray(color, dtype=np.float64).reshape(3)
    g = np.ones(3) if gain is None else np.asarray(gain, dtype=np.float64).reshape(3)
    if np.any((g <= 0) & (s > 0)):
        names = [ch for ch, bad in zip(("red", "green", "blue"), (g <= 0) & (s > 0)) if bad]
        raise ValueError(f"it cannot emit {' or '.join(names)} (its Temperature's colour has none), and this "
                         f"configuration gives it {', '.join(f'{x:.4g}' for x in s[(g <= 0) & (s > 0)])} there")
    s = np.divide(s, g, out=np.zeros(3), where=g > 0)
    p0 = c * float(energy)
    if not np.any(s > 0):
        return 0.0, c.copy()
    on = (p0 > 0) & (g > 0)  # the channels it emits as the user set it
    if on.any() and not np.any(s[~on] > 0):
        f = s[on] / p0[on]
        if f.max() - f.min() <= SAME_FACTOR * f.max():
            return float(energy) * float(f.mean()), c.copy()
    top = float(s.max())
    return top, s / top
