"""A photometric lamp: a point source whose intensity follows a measured distribution, as Cycles
renders a Point lamp whose emission strength is an IES Texture node (no bpy).

Cycles (engine/photometry/distribution.py's docstring, engine.units.CYCLES_IES_CANDELA_FACTOR):
a Point lamp of Power P, colour c (and its gain, engine.lamps.Lamp.power) emits the radiant
intensity P c / (4 pi) times its shader's value; an IES Texture node of Strength S feeding the
Emission's Strength makes that value S x the profile's value along the direction the light
leaves, in the lamp's frame (X = axis_u, Y = axis_v, Z = -direction): v = acos(-z) from the lamp's
-Z, h = atan2(x, y) + pi. So I(dir) = c P S cd(dir) / 177.83 W/sr per channel, cd the file's
candela with its multipliers. The node's Strength and the Emission's colour are in the lamp's
gain (blender/ies_nodes.py); ``Lamp.profile`` is the engine.photometry.CyclesProfile.

Its irradiance is point_source.py's (the soft radius, the shadow rays, the bare point lamp's
exact patch means as a control variate) times the profile along each lamp sample's direction to
the receiver point (the direction Cycles evaluates the node at: from the sampled point of the lamp).
A scene's lamp of this kind is fixed background light in solve and radiosity, and a light of the
direct-lighting mode (writer "lamp": its Power and colour set) in reduce.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..registry import LIGHT_KINDS
from .kind import lamp_kinds
from .point_source import PointSourceKind

__all__ = ["PHOTOMETRIC", "PhotometricKind", "local_directions", "measured_kind", "check_profile"]


def local_directions(lamp, w_out) -> np.ndarray:
    """(n, 3) directions ``w_out`` (n, 3, world) in the lamp's frame (X, Y, Z = -direction)."""
    return np.column_stack([w_out @ lamp.axis_u, w_out @ lamp.axis_v, -(w_out @ lamp.direction)])


def measured_kind(blender_type):
    """The registered lamp kind of a Blender Light type with an IES Texture node (a kind whose
    ``measured`` is True: this one, photometric_spot.py's), None when there is none."""
    return next((k for k in lamp_kinds() if getattr(k, "measured", False) and k.blender_type == blender_type), None)


def check_profile(lamp) -> None:
    """ValueError when ``lamp`` has no distribution (Lamp.profile)."""
    if not callable(getattr(lamp.profile, "along", None)):
        raise ValueError(f"lamp {lamp.name!r}: a photometric lamp needs its distribution "
                         "(Lamp.profile: an engine.photometry.CyclesProfile)")


@dataclass(frozen=True)
class PhotometricKind(PointSourceKind):
    """Blender's Point light with an IES Texture node (see the module docstring)."""

    blender_type = "POINT"
    #: a lamp kind of a Light with an IES Texture node (measured_kind)
    measured = True

    def check(self, lamp) -> None:
        check_profile(lamp)

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        e, w, t, ref = super().irradiance_at(lamp, y, n, u, far)
        return e * lamp.profile.along(local_directions(lamp, -w)), w, t, ref

    def report_fields(self, lamp) -> dict:
        return {"radius": float(lamp.radius), "photometric": True}


PHOTOMETRIC = PhotometricKind("photometric", "Photometric",
                              "A scene's Point lamp with an IES Texture node (a measured luminaire): its power "
                              "per channel (W)", source="irradiance", strength_unit="W", shape="point", writer="lamp")
LIGHT_KINDS.register(PHOTOMETRIC.name, PHOTOMETRIC.label, PHOTOMETRIC.description)(PHOTOMETRIC)
