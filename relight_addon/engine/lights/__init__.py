"""The light model: every light, whatever its kind, is a *source* (no bpy).

A light is described by what it puts into the scene before the first reflection, per unit of
its strength: an exitance on the patches it covers (a surface light: a light cell, a group of
cells, a whole polygon; strength in W/m^2), or a direct irradiance on the patches it reaches (a
lamp, the sun, the world; strength in W). Its column of the transfer matrix T is then A^-1
applied to that source (engine.inverse): A^-1 (I + D) e for an exitance, A^-1 diag(rho) H for
an irradiance. Everything after the transport (the inverse problem, the reduction, the
distributions, the curve, the report, the stored result, the scene) works per light through
:class:`LightSet` and the kinds' :class:`LightKind` entries only.

A kind is one file here that registers a LightKind in ``LIGHT_KINDS`` (engine.registry), plus
its writer in the Blender layer (docs/architecture.md, "Adding a light kind").

- ``kind.py``: LightKind, the interface; ``lightset.py``: LightSet, candidate_mask.
- ``surface.py``: what the surface kinds share; ``cell.py``, ``group.py``, ``polygon.py``.
- ``lamp.py``: the scene's own Point, Spot and Area lamps (``lamp``), irradiance sources of the
  direct-lighting mode.
- Lamp kinds (``kind.py``'s LampKind: a LightKind that is also what an engine.lamps.Lamp *is*, its
  whole behaviour in one file): ``sun.py`` (a scene's Sun lamps), ``spot.py``, ``area.py``,
  ``point.py`` (``point_source.py``: what point and spot lamps share; ``placed.py``: what the lamps
  a solve places share: candidate lights beside the cells, engine/candidate_lamps.py, written as
  real Blender lights). A lamp kind registered at run time (a LampKind subclass in LIGHT_KINDS)
  is a lamp like these. ``photometric.py``: a scene's Point lamp with an IES Texture node (a
  measured distribution, engine/photometry/); ``photometric_spot.py``: a Spot lamp with one (its
  cone x the distribution). ``fixture.py``: a catalogue fixture of a fixture library
  (engine/photometry/library.py) placed by the solve, written with an IES Texture node.
  ``photometric_area.py``: an Area lamp with one (its Lambertian emission times the distribution).
"""
from . import cell, group, polygon, lamp, sun, spot, area, point, photometric, photometric_spot, fixture, photometric_area  # noqa: F401  (registration order = the stored kind codes)
from .kind import Capability, LampKind, LightKind, lamp_kind_of_type, lamp_kinds
from .lightset import LightSet, append_lamps, candidate_mask, kind_code, lights_from_groups

__all__ = ["Capability", "LampKind", "LightKind", "lamp_kind_of_type", "lamp_kinds", "LightSet", "append_lamps", "candidate_mask", "kind_code", "lights_from_groups"]
