"""A photometric area lamp: an Area lamp whose emission strength is an IES Texture node (no bpy).

What Cycles does (intern/cycles, read for issue 39): a light's shader is evaluated at the point sampled
on the light with the normal ``ls->Ng`` its sampling gives (kernel/light/sample.h,
``light_sample_shader_eval``: ``shader_setup_from_sample(..., P, Ng, -ray_D, ...)``). An area light's
``Ng`` is its plane's normal ``klight->area.dir`` for every point and every direction
(kernel/light/area.h: ``ls->Ng = Ng``), unlike a point light's, whose normal is the direction the light
leaves its sphere. The IES Texture node's Vector defaults to the texture coordinate Normal (Cycles'
``IESLightNode``: LINK_TEXTURE_NORMAL), taken into the lamp's frame (geom/object.h,
``object_inverse_normal_transform``: ``lamp_fetch_transform`` for a PRIMITIVE_LAMP): (0, 0, -1), its -Z.
``svm_node_ies`` then reads the profile at v = acos(-z) = 0: its value straight along the lamp's axis,
the same for every direction. So an Area lamp with an IES node (Vector unlinked, blender/ies_nodes.py)
is the area lamp of area.py (Lambertian, its Spread) times one constant, the profile's value at v = 0
(h = atan2(0, 0) + pi = pi, as Cycles computes it for an exact (0, 0, -1)): its distribution over
directions is *not* the file's. ``NADIR`` is that direction in the lamp's frame.

Its irradiance is area.py's times that value (``nadir_value``). A scene's lamp of this kind is fixed
light in solve and radiosity, and a light of the direct-lighting mode (writer "lamp": its Power and
colour set) in reduce; never offered nor refined (option ""; not PLACEABLE). An IES node whose Vector is
linked (a Geometry Incoming, a Mapping) is not read (blender/ies_nodes.py: the lamp is named).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..registry import LIGHT_KINDS
from .area import AreaKind
from .kind import Capability
from .photometric import check_profile

__all__ = ["PHOTOMETRIC_AREA", "PhotometricAreaKind", "NADIR", "nadir_value"]

#: the IES node's default Vector on an Area lamp, in the lamp's frame: its normal, -Z
NADIR = np.array([[0.0, 0.0, -1.0]])


def nadir_value(lamp) -> float:
    """The IES node's value on the Area lamp ``lamp`` for every direction: its profile at v = 0."""
    return float(lamp.profile.along(NADIR)[0])


@dataclass(frozen=True)
class PhotometricAreaKind(AreaKind):
    """Blender's Area light with an IES Texture node (see the module docstring)."""

    blender_type = "AREA"
    flags = Capability.AIMED | Capability.EMITTING_AREA
    option = ""
    parameters = ()
    measured = True

    def check(self, lamp) -> None:
        super().check(lamp)
        check_profile(lamp)

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        e, w, t, ref = super().irradiance_at(lamp, y, n, u, far)
        c = nadir_value(lamp)
        return e * c, w, t, (None if ref is None else ref * c)

    def per_position(self, n_clusters, work=False) -> int:
        return 0

    def report_fields(self, lamp) -> dict:
        return {**super().report_fields(lamp), "photometric": True, "ies_value": nadir_value(lamp)}


PHOTOMETRIC_AREA = PhotometricAreaKind(
    "photometric_area", "Photometric area", "A scene's Area lamp with an IES Texture node: Cycles reads the profile "
    "along the lamp's normal only (a constant factor): its power per channel (W)", source="irradiance",
    strength_unit="W", shape="area", writer="lamp")
LIGHT_KINDS.register(PHOTOMETRIC_AREA.name, PHOTOMETRIC_AREA.label, PHOTOMETRIC_AREA.description)(PHOTOMETRIC_AREA)
