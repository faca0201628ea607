"""An area lamp placed by the solve: a rectangle (or a disk) of a size, facing a direction, one-sided,
of Blender's Spread (180 degrees: Lambertian; narrower: Cycles' soft-box grid, engine.lamps); its
strength is its power per channel (W)."""
from __future__ import annotations

import math

from ..lamps import Lamp
from .placed import UNIT_POWER, check_length, frame, register_placed_kind

AREA = register_placed_kind("area", "Area Lamp",
                            "An area lamp placed and aimed by the solve: its power per channel (W)", shape="area")


def area_lamp(name, position, direction, size_u, size_v=None, ellipse=False, spread=math.pi) -> Lamp:
    """The engine.lamps.Lamp of a placed area lamp (1 W per channel), of sides ``size_u`` along its
    X and ``size_v`` (default ``size_u``) along its Y (m, > 0), a disk / ellipse with ``ellipse``,
    emitting along ``direction``, of ``spread`` (rad, Blender's Spread: the full angle, in (0, pi];
    pi = Lambertian). ValueError for a size that is not a positive length or a spread out of range."""
    su = check_length(size_u, "an area lamp's size")
    sv = su if size_v is None else check_length(size_v, "an area lamp's size")
    if not (0.0 < float(spread) <= math.pi):
        raise ValueError(f"an area lamp's spread (Blender's Spread, the full angle) must be in (0, pi] radians, "
                         f"got {spread!r}")
    d, u, v = frame(direction)
    return Lamp(name, "AREA", position, d, u, v, UNIT_POWER, size_u=su, size_v=sv, ellipse=bool(ellipse),
                spread=float(spread))


def blender_shape(lamp) -> str:
    """Blender's area-light shape of a Lamp: SQUARE, RECTANGLE, DISK or ELLIPSE."""
    same = abs(lamp.size_u - lamp.size_v) <= 1e-9 * max(lamp.size_u, lamp.size_v)
    return ("DISK" if same else "ELLIPSE") if lamp.ellipse else ("SQUARE" if same else "RECTANGLE")
