"""A spot lamp placed by the solve: a position, a direction, Blender's Spot Size (the cone's full
angle) and Blend, a radius (soft falloff); its strength is its power per channel (W)."""
from __future__ import annotations

import math

from ..lamps import Lamp
from .placed import UNIT_POWER, check_length, frame, register_placed_kind

SPOT = register_placed_kind("spot", "Spot", "A spot lamp placed and aimed by the solve: its power per channel (W)",
                            shape="spot")


def spot_lamp(name, position, direction, spot_size, spot_blend=0.0, radius=0.0) -> Lamp:
    """The engine.lamps.Lamp of a placed spot (1 W per channel): cone of full angle ``spot_size``
    (rad, Blender's Spot Size, in (0, pi]) and ``spot_blend`` (Blender's Blend, in [0, 1]),
    ``radius`` (m, >= 0). ValueError for a value Blender could not hold."""
    if not (0.0 < float(spot_size) <= math.pi):
        raise ValueError(f"a spot's size (its cone's full angle) must be in (0, pi] radians, got {spot_size!r}")
    if not (0.0 <= float(spot_blend) <= 1.0):
        raise ValueError(f"a spot's blend must be in [0, 1], got {spot_blend!r}")
    d, u, v = frame(direction)
    return Lamp(name, "SPOT", position, d, u, v, UNIT_POWER, radius=check_length(radius, "a spot's radius", False),
                spot_size=float(spot_size), spot_blend=float(spot_blend))
