"""A photometric area lamp: an Area lamp whose emission strength is an IES Texture node (no bpy).

What Cycles does (intern/cycles, read for issue 39, and checked against bpy 5.0.1's bake:
tests/test_cycles_photometric.py): a light's shader is evaluated at the point sampled on the light
(kernel/light/sample.h, ``light_sample_shader_eval_*``: ``shader_setup_from_sample(..., P, Ng, -ray_D,
...)``, so the shading point's incoming direction ``wi`` is the direction from that point of the light to
the point it lights). The IES Texture node's Vector defaults to Geometry > Incoming (scene/shader_nodes.cpp,
``IESLightNode``: LINK_TEXTURE_INCOMING), taken into the lamp's frame by a world-to-object normal transform
(scene/shader_graph.cpp's default inputs; geom/object.h: ``lamp_fetch_transform`` for a lamp), and
``svm_node_ies`` reads the profile at v = acos(-z), h = atan2(x, y) + pi. So an Area lamp's radiance is
area.py's (c P / (pi A), its Spread) times S x the profile along the direction from each point of it to
the receiver, in the lamp's frame: a distribution, as the photometric Point lamp's (photometric.py), on
a Lambertian emitter. (Cycles before the Incoming default, LINK_TEXTURE_NORMAL, read an area light's
profile at its normal, a constant: not this.)

Its irradiance is area.py's, each of the lamp's samples times the profile along its direction to the
receiver point. A scene's lamp of this kind is fixed light in solve and radiosity, and a light of the
direct-lighting mode (writer "lamp": its Power and colour set) in reduce; never offered nor refined
(option ""; not PLACEABLE). An IES node whose Vector is linked (a Mapping, a Geometry Normal) is not read
(blender/ies_nodes.py: the lamp is named).
"""
from __future__ import annotations

from dataclasses import dataclass


from ..registry import LIGHT_KINDS
from .area import AreaKind
from .kind import Capability
from .photometric import check_profile, local_directions

__all__ = ["PHOTOMETRIC_AREA", "PhotometricAreaKind"]


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
        e, w, t, ref = super().irradiance_at(lamp, y, n, u, far)  # (w: from the receiver to the sample)
        f = lamp.profile.along(local_directions(lamp, -w))
        return e * f, w, t, (None if ref is None else ref * f)

    def per_position(self, n_clusters, work=False) -> int:
        return 0

    def report_fields(self, lamp) -> dict:
        return {**super().report_fields(lamp), "photometric": True}


PHOTOMETRIC_AREA = PhotometricAreaKind(
    "photometric_area", "Photometric area", "A scene's Area lamp with an IES Texture node (a Lambertian emitter times "
    "a measured distribution): its power per channel (W)", source="irradiance",
    strength_unit="W", shape="area", writer="lamp")
LIGHT_KINDS.register(PHOTOMETRIC_AREA.name, PHOTOMETRIC_AREA.label, PHOTOMETRIC_AREA.description)(PHOTOMETRIC_AREA)
