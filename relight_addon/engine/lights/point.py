"""A point lamp: a position and a radius (Blender's soft falloff), shining every way (no bpy).
Its light is a point source's (point_source.py). The solve places one per mounting position
(engine/candidate_lamps.py) and refines its position; its strength is its power per channel (W)."""
from __future__ import annotations

from dataclasses import dataclass

from ..lamps import Lamp
from ..registry import LIGHT_KINDS
from .kind import Capability
from .placed import UNIT_POWER, WRITER, check_length, frame
from .point_source import PointSourceKind


@dataclass(frozen=True)
class PointKind(PointSourceKind):
    """Blender's Point light."""

    blender_type = "POINT"
    flags = Capability.PLACEABLE
    option = "point_lamps"
    parameters = ("slide_u", "slide_v")

    def per_position(self, n_clusters, work=False) -> int:
        return 1

    def offer_at(self, mount) -> None:
        mount.add(self, point_lamp(f"Relight Point {mount.count + 1}", mount.position))


POINT = PointKind("point", "Point", "A point lamp placed by the solve: its power per channel (W)",
                  source="irradiance", strength_unit="W", shape="point", writer=WRITER)
LIGHT_KINDS.register(POINT.name, POINT.label, POINT.description)(POINT)


def point_lamp(name, position, radius=0.0) -> Lamp:
    """The engine.lamps.Lamp of a placed point lamp (1 W per channel), ``radius`` (m, >= 0); its
    frame is the world's, pointing down (a point lamp has no direction: it only orients the object)."""
    d, u, v = frame((0.0, 0.0, -1.0))
    return Lamp(name, POINT, position, d, u, v, UNIT_POWER,
                radius=check_length(radius, "a point lamp's radius", False))
