"""A point lamp placed by the solve: a position and a radius (soft falloff), shining every way; its
strength is its power per channel (W)."""
from __future__ import annotations

from ..lamps import Lamp
from .placed import UNIT_POWER, check_length, frame, register_placed_kind

POINT = register_placed_kind("point", "Point", "A point lamp placed by the solve: its power per channel (W)",
                             shape="point")


def point_lamp(name, position, radius=0.0) -> Lamp:
    """The engine.lamps.Lamp of a placed point lamp (1 W per channel), ``radius`` (m, >= 0); its
    frame is the world's, pointing down (a point lamp has no direction: it only orients the object)."""
    d, u, v = frame((0.0, 0.0, -1.0))
    return Lamp(name, "POINT", position, d, u, v, UNIT_POWER,
                radius=check_length(radius, "a point lamp's radius", False))
