"""The interface of a kind of light (no bpy): see engine/lights/__init__.py."""
from __future__ import annotations

from dataclasses import dataclass

#: what a light puts into the scene before the first reflection
SOURCES = ("exitance", "irradiance")


@dataclass(frozen=True)
class LightKind:
    """One kind of light, as the engine, the report and the scene see it.

    source: "exitance" (it emits from candidate patches, W/m^2 per unit strength) or
    "irradiance" (it lights patches directly, W/m^2 of irradiance per unit strength).
    strength_unit: the unit of the solved strength (``LightSet.strength``): "W/m^2" for an
    exitance, "W" for a lamp's power. shape: how the scene shows it ("patches": the emitting
    patches' triangles; a lamp: "point", "spot", "rectangle", "disk"). writer: the name of its
    writer in the Blender layer (results.py), shared by kinds that are written alike.
    """

    name: str
    label: str
    description: str
    source: str = "exitance"
    strength_unit: str = "W/m^2"
    shape: str = "patches"
    writer: str = "surface"

    def __post_init__(self):
        if self.source not in SOURCES:
            raise ValueError(f"light kind {self.name!r}: source must be one of {SOURCES}")

    def watts(self, area):
        """Power (W) of one unit of strength in one channel, per light of this kind: the area
        (m^2) for an exitance, 1 for a strength in W."""
        return area if self.strength_unit == "W/m^2" else 1.0 + 0.0 * area
