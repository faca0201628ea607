"""A photometric spot: a Spot lamp whose emission strength is an IES Texture node (no bpy).

Cycles multiplies a spot's cone attenuation (spot.py: smoothstep of Blender's Spot Size and
Blend) and its shader's value, so its intensity is the photometric lamp's (photometric.py:
c P S cd / 177.83 W/sr along the direction in the lamp's frame) times the cone. Its irradiance
is the spot's (spot.py: its cone's edge sampled again, narrow cones integrated over their
directions), its attenuation the cone x the profile along the direction from the lamp's centre
(a lamp of a Radius evaluates the profile from its sampled point: the two agree to about the
radius over the distance). A scene's lamp of this kind is fixed light or a reduce light, as the
photometric Point lamp; it is never offered nor refined (option ""; not PLACEABLE).
"""
from __future__ import annotations

from dataclasses import dataclass

from ..registry import LIGHT_KINDS
from .kind import Capability
from .photometric import check_profile, local_directions
from .spot import SpotKind, _spot_attenuation

__all__ = ["PHOTOMETRIC_SPOT", "PhotometricSpotKind"]


@dataclass(frozen=True)
class PhotometricSpotKind(SpotKind):
    """Blender's Spot light with an IES Texture node (see the module docstring)."""

    blender_type = "SPOT"
    flags = Capability.AIMED
    option = ""
    parameters = ()
    measured = True

    def check(self, lamp) -> None:
        check_profile(lamp)

    def attenuation(self, lamp, w_from_lamp):
        return _spot_attenuation(lamp, w_from_lamp) * lamp.profile.along(local_directions(lamp, w_from_lamp))

    def per_position(self, n_clusters, work=False) -> int:
        return 0

    def report_fields(self, lamp) -> dict:
        return {**super().report_fields(lamp), "photometric": True}


PHOTOMETRIC_SPOT = PhotometricSpotKind(
    "photometric_spot", "Photometric spot", "A scene's Spot lamp with an IES Texture node (a measured luminaire): its "
    "power per channel (W)", source="irradiance", strength_unit="W", shape="spot", writer="lamp")
LIGHT_KINDS.register(PHOTOMETRIC_SPOT.name, PHOTOMETRIC_SPOT.label, PHOTOMETRIC_SPOT.description)(PHOTOMETRIC_SPOT)
