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
- ``lamp.py``: the scene's own lamps (``lamp``: Point, Spot, Area; ``sun``), irradiance sources of the
  direct-lighting mode.
- ``placed.py``: what the lamps a solve places share; ``spot.py``, ``area.py``, ``point.py`` (candidate
  lights beside the cells, engine/candidate_lamps.py; written as real Blender lights).
"""
from . import cell, group, polygon, lamp, spot, area, point  # noqa: F401  (registration order = the stored kind codes)
from .kind import LightKind
from .lightset import LightSet, append_lamps, candidate_mask, kind_code, lights_from_groups

__all__ = ["LightKind", "LightSet", "append_lamps", "candidate_mask", "kind_code", "lights_from_groups"]
