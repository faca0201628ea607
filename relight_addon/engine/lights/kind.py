"""The interface of a kind of light (no bpy): see engine/lights/__init__.py."""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from ..registry import LIGHT_KINDS
from ..units import TINY

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

    def strength_upper(self, lamp) -> float:
        """The largest strength per channel a light of this kind may take (inf: no bound; ``lamp``
        its engine.lamps.Lamp, None for a surface light): every selection, fit and programme keeps
        0 <= strength <= it (engine.best_lights, engine.light_colour)."""
        return math.inf


class Capability(enum.Flag):
    """What a lamp kind has, as its callers ask it (``LampKind.flags``).

    AIMED: a direction it shines along (its -Z; a point lamp's frame only orients its object);
    DISTANT: it lights from a direction, from no position (a sun: its light arrives along
    -direction everywhere); EMITTING_AREA: it emits from a surface of an area (m^2, ``LampKind.area``);
    PLACEABLE: a solve may place it as a new Blender Light (offered, refined, written, kept).
    """

    NONE = 0
    AIMED = enum.auto()
    DISTANT = enum.auto()
    EMITTING_AREA = enum.auto()
    PLACEABLE = enum.auto()


#: the fields of a lamp record, whatever its kind (``LampKind.record``: the stored result's JSON)
RECORD_GEOMETRY = ("radius", "spot_size", "spot_blend", "size_u", "size_v", "ellipse", "spread")


@dataclass(frozen=True)
class LampKind(LightKind):
    """A kind of lamp: a LightKind (an irradiance source of the light set) that is also what an
    engine.lamps.Lamp *is* (``Lamp.kind``): the whole behaviour of one kind of emitter, as
    Mitsuba's emitters and pbrt's lights, in one file of engine/lights/ (point.py, spot.py,
    area.py, sun.py). Its direct irradiance on patches (engine.lamps.lamp_irradiance calls
    ``samples_per_point``, ``point_means``, ``irradiance_at`` and ``light_patches``), what it
    reaches (``reach``), how the solve offers it (``per_position``, ``offer_at``,
    ``offer_for``), its refinement space (``parameters``, ``refined``), its report fields
    (``report_fields``) and its Blender Light (``blender_light``: a plain description that one
    writer in blender/results.py applies; ``blender_type``: Blender's Light type).

    The defaults are an isotropic emitter at a position that lights every patch: a new kind
    overrides what differs.
    """

    #: Blender's Light type of this kind's lamps (POINT, SPOT, AREA, SUN)
    blender_type = "POINT"
    flags = Capability.NONE
    #: the LightKind of a scene lamp of this kind in direct-lighting mode ("lamp", or itself)
    scene_kind = "lamp"
    #: the job option that offers it as a candidate lamp (engine/options.py; "" = never offered)
    option = ""

    # -- geometry --------------------------------------------------------------------------
    def check(self, lamp) -> None:
        """ValueError when ``lamp`` (engine.lamps.Lamp, being made) cannot emit as this kind."""

    def area(self, lamp) -> float:
        """Its emitting area (m^2): 0 but for a kind with EMITTING_AREA."""
        return float(lamp.area) if self.flags & Capability.EMITTING_AREA else 0.0

    def light_area(self, lamp, lit) -> float:
        """The area (m^2) of its light in the light set (LightKind.watts reads it): its emitting
        area; a DISTANT lamp's ``lit`` area (its strength is in W/m^2)."""
        return lit if self.flags & Capability.DISTANT else self.area(lamp)

    def normal(self, lamp) -> np.ndarray:
        """Its light's normal in the light set and the report: its direction, none (0) when not AIMED."""
        return lamp.direction if self.flags & Capability.AIMED else np.zeros(3)

    def towards(self, lamp, points) -> np.ndarray:
        """(n, 3) unit directions from ``points`` (n, 3) towards its light."""
        if self.flags & Capability.DISTANT:
            return np.broadcast_to(-np.asarray(lamp.direction, dtype=np.float64), points.shape)
        w = np.asarray(lamp.position, dtype=np.float64)[None, :] - points
        return w / np.maximum(np.linalg.norm(w, axis=1), TINY)[:, None]

    # -- irradiance (engine.lamps.lamp_irradiance) ----------------------------------------
    def samples_per_point(self, lamp) -> int:
        """Lamp samples per receiver point: 1 for a delta lamp."""
        return 1

    def point_means(self, lamp, sampler, todo, restricted, n_patches):
        """(P,) exact patch means of a control variate per unit power (engine.lamps), or None."""
        return None

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        """(E (n,) per unit power at points y (n, 3) of normals n from uniforms u (n, 2), the unit
        directions to the lamp (n, 3), their distances (n,) for the shadow rays, the control
        variate's values (n,) or None)."""
        raise NotImplementedError(f"lamp kind {self.name!r} has no irradiance")

    def light_patches(self, lamp, job) -> None:
        """Compute its means on ``job.todo`` (engine.lamps._LampJob): by default ``job.run`` with
        ``job.k`` points per patch."""
        job.run(job.todo, job.k)

    def reach(self, lamp, patches, radius) -> np.ndarray:
        """The patches its light can reach (``radius`` (P,): their bounding radii): all."""
        return np.arange(patches.n_patches)

    # -- candidates (engine/candidate_lamps.py) --------------------------------------------
    def per_position(self, n_clusters, work=False) -> int:
        """The lamps of this kind a mounting position holds for ``n_clusters`` clusters (at most
        candidate_lamps.MAX_CLUSTERS), or ``work``: their receiver-point work in spots'."""
        return 0

    def offered(self, options):
        """What offers its lamps for a job of ``options`` (``per_position``, ``offer_at``,
        ``offer_for``, ``name``): itself; a kind whose offer depends on the job (a fixture library,
        fixture.py) returns one bound to it."""
        return self

    def offer_at(self, mount) -> None:
        """Offer its lamps at a mounting position (``mount.add``, candidate_lamps.Mounting)."""

    def offer_for(self, mount, rank, cluster, axis, half) -> None:
        """Offer its lamps at a mounting position for the ``rank``-th cluster it sees, whose
        enclosing cone from there is (``axis``, ``half``)."""

    # -- refinement (engine/lamp_refinement.py) --------------------------------------------
    #: the parameters refined (besides slide_u, slide_v, aim_u, aim_v: see lamp_refinement)
    parameters = ()

    def refinement_parameters(self, lamp) -> tuple:
        """The parameters of ``lamp`` its refinement moves (engine.lamp_refinement; default the kind's
        ``parameters``: a kind whose lamps differ, e.g. a fixture aimable or not, says so per lamp)."""
        return self.parameters

    def aim_half_angle(self, lamp) -> float:
        """The half-angle (rad) whose quarter is one unit of aim."""
        return 0.25

    def refined(self, lamp, values, steps):
        """``lamp`` (already moved and turned) with its own parameters ``values`` {name: x};
        ``steps``: lamp_refinement's unit steps. None when it would not be valid."""
        return lamp

    # -- records ---------------------------------------------------------------------------
    def record(self, lamp) -> dict:
        """The lamp as the stored result keeps it (JSON; pipeline.stored), whatever its kind: name,
        type (Blender's Light type), energy (Blender's Power, W; a sun's Strength, W/m^2), color, gain
        [r, g, b] (what Cycles multiplies colour x Power by: the Light's Exposure, Temperature,
        Normalize; engine.lamps.Lamp), power [r, g, b] = colour x energy x gain (what it emits),
        position (m), direction (its -Z), axis_u / axis_v (its X and Y) and every RECORD_GEOMETRY
        field: radius (m), spot_size and spot_blend (rad, Blender's), size_u / size_v (m), ellipse
        and spread (rad, Blender's). Its versions: records stored before the spread was kept lack
        it (their area lamps were 180 degrees), before the gain was kept, it (1); their readers
        (``blender_light``, blender/results.py) take those defaults. pipeline.kept makes the same
        record from a report's light (``record_geometry``), and blender/results.new_lamp writes it."""
        def vec(v):
            return [float(x) for x in v]
        return {"name": lamp.name, "type": self.blender_type, "energy": float(lamp.energy), "color": vec(lamp.color),
                "gain": vec(lamp.gain), "power": vec(lamp.power), "position": vec(lamp.position),
                "direction": vec(lamp.direction),
                "axis_u": vec(lamp.axis_u), "axis_v": vec(lamp.axis_v), "radius": float(lamp.radius),
                "spot_size": float(lamp.spot_size), "spot_blend": float(lamp.spot_blend),
                "size_u": float(lamp.size_u), "size_v": float(lamp.size_v), "ellipse": bool(lamp.ellipse),
                "spread": float(lamp.spread)}

    def record_geometry(self, light) -> dict:
        """The RECORD_GEOMETRY fields of a lamp from a report's light ``light`` (its
        ``report_fields``; what it lacks at Blender's defaults)."""
        size = light.get("size") or [0.0, 0.0]
        return {"radius": float(light.get("radius", 0.0)), "spot_size": float(light.get("spot_size", math.pi)),
                "spot_blend": float(light.get("spot_blend", 0.0)), "size_u": float(size[0]),
                "size_v": float(size[1]), "ellipse": str(light.get("shape", "")).upper() in ("DISK", "ELLIPSE"),
                "spread": float(light.get("spread", math.pi))}

    def report_fields(self, lamp) -> dict:
        """Its own fields in the report's light (pipeline.report.placed_record)."""
        return {}

    def blender_light(self, record) -> dict:
        """Its Blender Light's own settings from a record (``record``), {attribute: value} in the
        order they are set (blender/results.new_lamp sets them)."""
        return {}

    def blender_ies(self, record):
        """(an internal text's name, its LM-63 text) that its Blender Light's IES Texture node holds
        (blender/results.new_lamp writes the node), None for a Light without one."""
        return None

    # -- a scene's Blender Light read (blender/lamps.py; ``light``: a bpy Light, read by attribute) --
    def blender_settings(self, light, matrix) -> tuple:
        """({Lamp field: value} of its own settings, [notes on what is not modelled]) of a Blender
        Light ``light`` of this kind on an object of world matrix ``matrix`` (4, 4)."""
        return {}, []

    def blender_dark(self, light, matrix):
        """(warning, why it is dark) when Cycles renders no light from ``light`` whatever its Power,
        else None."""
        return None

    def cycles_area(self, light, matrix) -> float:
        """Cycles' ``Light::area`` (intern/cycles/scene/light.cpp): what it divides the Light's
        strength by when Normalize is on (blender/lamps.cycles_gain)."""
        return 1.0


def lamp_kinds() -> list:
    """The registered lamp kinds (LIGHT_KINDS' LampKind entries), in registration order."""
    return [m.impl for m in LIGHT_KINDS if isinstance(m.impl, LampKind)]


def lamp_kind_of_type(blender_type: str, placeable=False):
    """The lamp kind of a Blender Light type (the first registered; ``placeable``: of the PLACEABLE
    kinds only), None when there is none."""
    for kind in lamp_kinds():
        if kind.blender_type == blender_type and (not placeable or kind.flags & Capability.PLACEABLE):
            return kind
    return None
