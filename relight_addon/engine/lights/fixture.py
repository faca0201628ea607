"""A catalogue fixture placed by the solve: a luminaire of a fixture library (engine/photometry/library.py)
hung at a mounting position, aimed where it can be, dimmed between 0 and 100 % of its rated flux (no bpy).

Its light is the photometric lamp's (photometric.py: a point source times the fixture's distribution as
Cycles renders a Point lamp with an IES Texture node), with the distribution scaled to a radiant flux of
1 W per channel, so that its strength is its radiant power per channel (W), as every placed lamp's
(placed.py: ``watts`` 1; the least-power programme compares it with the spots'). Its Lamp keeps that
scaled distribution (``Lamp.profile``: a ``FixtureProfile``, which names the fixture) and a gain
g = flux / (4 pi) of the fixture's own table as Cycles holds it (engine.units.CYCLES_IES_CANDELA_FACTOR):
Blender's Power P with the IES node (Strength 1, white) emits P g W, so the writer's Power is the
strength / g (engine.lights.lamp.blender_values with the record's gain). In lumens (Relight's 683 lm/W,
Rec.709 weights) a strength s gives 683 x luminance(s) lm, so the fixture's dimming is that over its
rated lumens (the flux its table renders, library.Fixture.lumens): Cycles renders that flux from the
LM-63 text written in the IES node at Power P = s / g (units.cycles_ies_candela).

Offered (``option`` "fixtures": a library folder or "builtin"; ``offered`` binds the library) at the
mounting positions of engine/candidate_lamps.py: a symmetric fixture that is not aimable hangs along the
mounting surface's normal (a downlight from a ceiling, a batwing); an aimable one (a track or gimbal
fixture) points at each of the first FIXTURE_CLUSTERS target clusters the position sees; an asymmetric one
hangs along the normal with its C0 plane (the lamp's -Y, where Cycles' IES node puts C0) turned towards
each of those clusters (a wall washer's throw towards the painted wall). Refined (engine/lamp_refinement.py,
``refinement_parameters``) in its position on the mounting surface, in its aim only if aimable (a downlight
or a batwing keeps hanging along its mounting normal), and in its turn about its axis if asymmetric.
Dimmed within 0-100 % (``strength_upper``: every selection and fit keeps its strength at most the rated
flux's). Written (writer
"placed") as a Point Light whose node tree is an IES Texture node holding the fixture's LM-63 as an
internal text (``blender_ies``), so the .blend carries it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..lamps import Lamp
from ..photometry.library import BUILTIN, load_library
from ..registry import LIGHT_KINDS
from ..units import LUMENS_PER_WATT, luminance_weighted
from .kind import Capability
from .photometric import PhotometricKind
from .placed import UNIT_POWER, WRITER, frame

__all__ = ["FIXTURE", "FixtureKind", "FixtureProfile", "fixture_lamp", "FIXTURE_CLUSTERS", "dimming"]

#: the target clusters an aimable or asymmetric fixture is offered for at each position (the first it sees)
FIXTURE_CLUSTERS = 2
#: a patch is near a fixture within this many of its bounding radii (light_patches), and gets this many
#: times the receiver points
NEAR_RADII = 4.0
NEAR_POINTS = 64
#: a fixture's irradiance work in a spot's (engine.cost): each sample interpolates its profile
#: (measured: 0.31 s a fixture against 0.13 s a spot, docs/benchmarks.md, "Catalogue fixtures as candidates")
FIXTURE_WORK = 2.4
#: the turn about its axis (rad) of one unit of an asymmetric fixture's refinement (``turn``)
TURN_STEP = math.radians(15.0)
#: the radiant flux (W) the scaled distribution integrates to: an isotropic Point lamp's 4 pi x 1 / (4 pi)
FULL_TURN = 4.0 * math.pi


@dataclass(frozen=True)
class FixtureProfile:
    """A fixture's distribution as the engine evaluates it: its Cycles profile (library.Fixture.profile)
    times ``scale`` = 4 pi / its flux, so that it emits 1 W per W of strength; ``fixture`` names it."""

    fixture: object
    scale: float

    @classmethod
    def of(cls, fixture) -> "FixtureProfile":
        return cls(fixture, FULL_TURN / fixture.profile.flux())

    def along(self, local) -> np.ndarray:
        return self.fixture.profile.along(local) * self.scale

    @property
    def gain(self) -> float:
        """What Cycles multiplies the Light's colour x Power by with this fixture's IES node: flux / (4 pi)."""
        return 1.0 / self.scale


def dimming(strength, lumens) -> float:
    """The share of its rated ``lumens`` a fixture gives at ``strength`` (3,) W per channel (1 = 100 %)."""
    return float(LUMENS_PER_WATT * luminance_weighted(np.asarray(strength, dtype=np.float64)) / lumens)


def _turned(direction, towards):
    """(u, v): the frame of a lamp along ``direction`` whose -Y (v = -towards, made perpendicular to the
    direction) points at ``towards``; frame()'s where ``towards`` is along the direction."""
    d = np.asarray(direction, dtype=np.float64)
    t = np.asarray(towards, dtype=np.float64)
    t = t - (t @ d) * d
    n = float(np.linalg.norm(t))
    if not n > 1e-9:
        _, u, v = frame(d)
        return u, v
    v = -t / n
    return np.cross(v, -d), v


def fixture_lamp(name, fixture, position, direction, towards=None) -> Lamp:
    """The engine.lamps.Lamp of a placed fixture (1 W of radiant power per channel: its strength is its
    power), shining along ``direction`` (its -Z), its C0 plane turned towards ``towards`` (optional)."""
    prof = FixtureProfile.of(fixture)
    d, u, v = frame(direction)
    if towards is not None:
        u, v = _turned(d, towards)
    return Lamp(name, FIXTURE, position, d, u, v, UNIT_POWER, profile=prof, gain=np.full(3, prof.gain))


class _Offer:
    """The fixture kind bound to a job's library (``FixtureKind.offered``): what engine/candidate_lamps.py
    asks of an offered kind (``name``, ``per_position``, ``offer_at``, ``offer_for``)."""

    def __init__(self, kind, fixtures):
        self.kind, self.fixtures, self.name = kind, tuple(fixtures), kind.name
        self.along = [f for f in self.fixtures if f.symmetric and not f.aimable]
        self.per_cluster = [f for f in self.fixtures if f.aimable or not f.symmetric]

    def per_position(self, n_clusters, work=False) -> int:
        n = len(self.along) + len(self.per_cluster) * min(n_clusters, FIXTURE_CLUSTERS)
        return int(math.ceil(FIXTURE_WORK * n)) if work else n

    def offer_at(self, mount) -> None:
        for f in self.along:
            mount.add(self.kind, fixture_lamp(f"Relight {f.name} {mount.count + 1}", f, mount.position, mount.normal))

    def offer_for(self, mount, rank, cluster, axis, half) -> None:
        if rank >= FIXTURE_CLUSTERS:
            return
        for f in self.per_cluster:
            if f.aimable:
                lamp = fixture_lamp(f"Relight {f.name} {mount.count + 1}", f, mount.position, axis)
            else:
                lamp = fixture_lamp(f"Relight {f.name} {mount.count + 1}", f, mount.position, mount.normal,
                                    towards=cluster.center - mount.position)
            mount.add(self.kind, lamp)


@dataclass(frozen=True)
class FixtureKind(PhotometricKind):
    """A catalogue fixture placed by the solve (see the module docstring)."""

    blender_type = "POINT"
    flags = Capability.AIMED | Capability.PLACEABLE
    option = "fixtures"
    measured = False  # (a scene's Point lamp with an IES node is photometric.py's)
    #: (every fixture's; a lamp's own are ``refinement_parameters``)
    parameters = ("aim_u", "aim_v", "slide_u", "slide_v", "turn")

    def check(self, lamp) -> None:
        super().check(lamp)
        if not isinstance(lamp.profile, FixtureProfile):
            raise ValueError(f"lamp {lamp.name!r}: a fixture's distribution is a FixtureProfile (fixture_lamp)")

    def strength_upper(self, lamp) -> float:
        """Its rated flux as white light: a strength s gives 683 luminance(s) lm (``dimming``), so at most
        rated lumens / 683 W per channel (a dimmer, or a filter, only takes light away): every selection
        keeps it within 0-100 % of its rated lumens (white: exactly 100 %; a colour view bounds the
        luminance: engine.light_colour.ColourProblem)."""
        return float(lamp.profile.fixture.lumens) / LUMENS_PER_WATT

    def light_patches(self, lamp, job) -> None:
        """The patches near it (their centre within NEAR_RADII of their bounding radius from the lamp:
        the ceiling an uplight hangs under) get NEAR_POINTS x the points: there its distribution
        varies across the patch, which the bare point's control variate does not follow (an uplight
        0.15 m under a 0.5 m patch: +12.6 % of its flux with 16 points, +0.05 % with 4096); the
        others ``job.k`` points."""
        g, todo = job.g, job.todo
        d = np.linalg.norm(g.center[todo] - lamp.position, axis=1)
        near = d < NEAR_RADII * g.radius[todo]
        job.run(todo[~near], job.k)
        job.run(todo[near], job.k * NEAR_POINTS)

    def offered(self, options):
        """This kind bound to the job's fixture library (its ``option``: a folder, or "builtin")."""
        return _Offer(self, load_library(options.fixtures or BUILTIN))

    def refinement_parameters(self, lamp) -> tuple:
        """What a lighting designer may change of a hung fixture: an aimable one (track, gimbal) its aim;
        one that is not (a downlight, a batwing) keeps hanging along its mounting normal; every one slides
        on its mounting surface; an asymmetric one turns about its axis (``turn``: its C0 plane)."""
        f = lamp.profile.fixture
        return (("aim_u", "aim_v") if f.aimable else ()) + ("slide_u", "slide_v") + (() if f.symmetric else ("turn",))

    def refined(self, lamp, values, steps):
        """Turned as refinement aims it, its C0 plane kept where it was (the old -Y made perpendicular),
        then turned about its axis by ``turn`` x TURN_STEP."""
        u, v = _turned(lamp.direction, -steps.lamp.axis_v)
        t = TURN_STEP * float(values.get("turn", 0.0))
        if t:
            u, v = math.cos(t) * u + math.sin(t) * v, -math.sin(t) * u + math.cos(t) * v
        return replace(lamp, axis_u=u, axis_v=v)

    def record(self, lamp) -> dict:
        f = lamp.profile.fixture
        return {**super().record(lamp), "fixture": f.name, "ies": f.lm63}

    def record_geometry(self, light) -> dict:
        return {**super().record_geometry(light), "fixture": str(light["fixture"]), "ies": str(light["ies_lm63"])}

    def report_fields(self, lamp) -> dict:
        f = lamp.profile.fixture
        return {"radius": float(lamp.radius), "fixture": f.name, "fixture_description": f.description,
                "rated_lumens": float(f.lumens), "rated_watts": float(f.watts), "ies_lm63": f.lm63}

    def blender_ies(self, record):
        """(the internal text's name, the LM-63 text) of its IES Texture node."""
        return f"{record['fixture']}.ies", record["ies"]


FIXTURE = FixtureKind("fixture", "Fixture", "A catalogue fixture (a fixture library's LM-63 / EULUMDAT luminaire) "
                      "placed by the solve: its radiant power per channel (W)", source="irradiance",
                      strength_unit="W", shape="point", writer=WRITER)
LIGHT_KINDS.register(FIXTURE.name, FIXTURE.label, FIXTURE.description)(FIXTURE)
