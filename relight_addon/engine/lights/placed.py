"""What the lamps a solve places share (no bpy): Spot, Area and Point lamps that Relight offers as
candidate lights beside the surface cells (engine/candidate_lamps.py makes them) and writes back as
real Blender lights (results.py, writer "placed": Light objects in a collection Relight owns).

Each is an *irradiance* source (engine/lights/__init__.py): its column of ``LightSet.irradiance``
is its direct irradiance on the patches per W (engine.lamps, Cycles' conventions, shadows
included), so its column of T is A^-1 diag(rho) H. Strength: its power per channel in W --
Blender's colour x Power (``watts`` = 1); the writer sets Power = the largest channel and colour =
the strength / Power, so that Cycles emits the solved power in every channel.

A placed lamp is an engine.lamps.Lamp of power 1 W per channel (so ``H`` is per W) in Blender's
frame: ``direction`` its -Z (where a spot or an area lamp points), ``axis_u`` / ``axis_v`` its X
and Y (``frame``), right-handed. ``LightSet.lamps`` keeps it: the report and the writer read its
geometry there.
"""
from __future__ import annotations

import numpy as np

from ..geometry import unit

__all__ = ["frame", "check_length", "UNIT_POWER", "WRITER"]

#: the writer of the placed lamps in the Blender layer (results.py)
WRITER = "placed"
#: the power per channel of a placed lamp's Lamp: its irradiance is per W
UNIT_POWER = np.ones(3)


def frame(direction) -> tuple:
    """(direction, axis_u, axis_v): the unit ``direction`` (a lamp's -Z) and the lamp's X and Y
    axes, X the world X made perpendicular to it (the world Y where the direction is along X), so
    that X x Y = -direction (Blender's right-handed object frame). ValueError for a zero or
    non-finite direction."""
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(d))
    if not (np.isfinite(n) and n > 0):
        raise ValueError(f"a lamp's direction must be a non-zero finite vector, got {d.tolist()}")
    d = d / n
    ref = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = unit((ref - (ref @ d) * d)[None, :])[0]
    v = np.cross(-d, u)
    return d, u, v


def check_length(value, what, positive=True) -> float:
    """``value`` as a float (m): finite and > 0 (``positive``) or >= 0; ValueError naming ``what``."""
    v = float(value)
    if not np.isfinite(v) or (v <= 0 if positive else v < 0):
        raise ValueError(f"{what} must be a {'positive' if positive else 'non-negative'} finite length in metres, "
                         f"got {value!r}")
    return v
