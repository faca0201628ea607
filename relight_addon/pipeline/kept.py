"""Kept lights (issue 20, items 3 and 4; no bpy): the lamps of an earlier answer held at their
place and power while a solve finds the rest.

A kept lamp becomes a lamp of the scene: the solve counts its light as the scene's own (fixed
light, subtracted from the targets, as the lamps the user hung), so the selection, the
certificate and the curve are of the *rest*: Max Lights new lights beside the kept ones, and the
certificate's bound is the best any that many more candidate lights can do with the kept ones on.
The kept lamps are written as the scene's lamps (the CLI's --out copy, the add-on's Keep Lamps),
never removed as Relight's.

``kept_lamps(report)`` reads the final configuration of a report (the CLI's JSON) into lamp
records (a lamp kind's record: engine/lights/kind.py, ``record_geometry``) that
blender/results.new_lamp makes; surface lights (emissive cells and polygons) are not
kept, and named.
"""
from __future__ import annotations

import json
import os

import numpy as np

from ..engine.lights import Capability, LampKind, lamp_kind_of_type
from ..engine.registry import LIGHT_KINDS

__all__ = ["KEPT_SUFFIX", "kept_lamps", "read_kept", "foreign_notes"]

#: the kept lamps' names: the answer's name and this
KEPT_SUFFIX = " (kept)"


def _frame(direction, axis_u=None):
    """Unit (axis_u, axis_v) of a lamp pointing along ``direction`` (its -Z): ``axis_u`` as
    recorded, else any axis perpendicular to the direction."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / (np.linalg.norm(d) or 1.0)
    if axis_u is None:
        a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        axis_u = np.cross(a, d)
    u = np.asarray(axis_u, dtype=np.float64)
    u = u - d * float(u @ d)
    u = u / (np.linalg.norm(u) or 1.0)
    v = np.cross(-d, u)  # X, Y, Z = -direction right-handed: Y = Z x X
    return u, v


def _lamp_kind(light):
    """The lamp kind a report's ``light`` is kept as: its own kind (``kind``: a lamp kind a solve
    can place), else that of its Blender ``type`` (a reduction's scene lamp); None for a surface light."""
    named = light.get("kind")
    kind = LIGHT_KINDS[named].impl if isinstance(named, str) and named in LIGHT_KINDS else None
    if isinstance(kind, LampKind) and kind.flags & Capability.PLACEABLE:
        return kind
    return lamp_kind_of_type(str(light.get("type", "")).upper(), placeable=True)


def kept_lamps(report: dict, source: str = "the report") -> tuple:
    """(records, notes): the lamps of ``report``'s final configuration as results.new_lamp makes
    them (name, type, kind, position, direction, axis_u, axis_v, radius, spot_size, spot_blend, size_u,
    size_v, ellipse, spread, energy, color, temperature_K), and what is not kept. Raises ValueError on a report
    that is not a solve's."""
    if not isinstance(report, dict) or report.get("command") not in ("solve", "reduce") \
            or not isinstance(report.get("final"), dict) or "lights" not in report["final"]:
        raise ValueError(f"{source} is not a Relight solve report (no final configuration)")
    records, surface, notes = [], [], []
    for i, li in enumerate(report["final"]["lights"]):
        kind = _lamp_kind(li)
        if kind is None or li.get("location") is None:
            surface.append(f"{li.get('object')} ({li.get('kind')}, polygons {li.get('polygons', [])[:4]})")
            continue
        try:
            u, v = _frame(li["direction"] if li.get("direction") is not None else (0.0, 0.0, -1.0), li.get("axis_u"))
            rec = {"name": f"{li['object']}{KEPT_SUFFIX}", "type": kind.blender_type, "kind": kind.name,
                   "position": [float(x) for x in li["location"]],
                   "direction": [float(x) for x in (li.get("direction") or (0.0, 0.0, -1.0))],
                   "axis_u": u.tolist(), "axis_v": v.tolist(), **kind.record_geometry(li),
                   "energy": float(li["energy"]), "color": [float(x) for x in li["color"]],
                   "power": float(li["power"]),
                   # a blackbody light's Temperature (its energy and color are with it)
                   "temperature_K": None if li.get("temperature_K") is None else float(li["temperature_K"])}
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{source}: light {i} ({li.get('object')}) lacks what a lamp needs ({exc})") from None
        if not all(np.all(np.isfinite(rec[k])) for k in ("position", "direction", "energy", "color")) \
                or rec["energy"] < 0:
            raise ValueError(f"{source}: light {i} ({li.get('object')}) has a non-finite or negative value")
        if kind.flags & Capability.EMITTING_AREA and li.get("axis_u") is None and abs(rec["size_u"] - rec["size_v"]) > 1e-9:
            notes.append(f"{rec['name']}: the report does not give the rectangle's orientation; kept turned "
                         "about its axis as Relight chose")
        records.append(rec)
    if surface:
        notes.append(f"{len(surface)} surface light(s) of {source} are not kept (only lamps are): "
                     f"{'; '.join(surface[:4])}{' ...' if len(surface) > 4 else ''}")
    if not records:
        raise ValueError(f"{source} has no lamp to keep in its final configuration"
                         + (f" ({notes[-1]})" if surface else ""))
    return records, notes


def read_kept(path: str) -> tuple:
    """kept_lamps of the JSON report at ``path`` and the scene it was solved for (its ``input``, or
    None): (records, notes, input). ValueError with the cause when it cannot be read."""
    try:
        with open(path) as fh:
            report = json.load(fh)
    except OSError as exc:
        raise ValueError(f"--keep: cannot read {path}: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"--keep: {path} is not JSON ({exc.msg}, line {exc.lineno})") from None
    except UnicodeDecodeError:
        raise ValueError(f"--keep: {path} is not JSON (not text: a .blend? give the report of a solve)") from None
    records, notes = kept_lamps(report, path)
    return records, notes, report.get("input") if isinstance(report.get("input"), str) else None


def foreign_notes(kept, fixed_light, vertices, source, solved_for=None, this_input=None) -> list:
    """Warnings about kept lamps that do not belong to this scene (issue 35, case 10: a report of
    another scene kept, its lamps above this room's ceiling, written without a word). ``kept``:
    [(the kept lamp's name, its position)]; ``fixed_light``: the solve report's rows (a lamp's
    ``share`` of the targets' light); ``vertices`` (V, 3): the scene's geometry. Named: the kept
    lamps that light no target (share 0), and those outside the scene's bounding box; with the
    scene the report was solved for when it is not this one. They are kept all the same (the
    user asked for them, and a lamp may light what is not painted): warned, not refused."""
    share = {r.get("name"): r.get("share") for r in fixed_light or []}
    dark = [name for name, _ in kept if share.get(name) is not None and not share[name] > 0]
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    outside = []
    if len(v):
        lo, hi = v.min(axis=0), v.max(axis=0)
        tol = 1e-6 * max(float(np.max(hi - lo)), 1e-12)
        outside = [name for name, p in kept
                   if np.any(np.asarray(p, dtype=np.float64) < lo - tol) or np.any(np.asarray(p) > hi + tol)]
    if not (dark or outside):
        return []

    def names(xs):
        return ", ".join(repr(x) for x in xs[:5]) + (" ..." if len(xs) > 5 else "")

    parts = ([f"{len(dark)} light no target ({names(dark)})"] if dark else []) + \
        ([f"{len(outside)} lie outside this scene's bounds ({names(outside)})"] if outside else [])
    other = (f"; {source} was solved for {solved_for}, not this scene"
             if solved_for and this_input and os.path.abspath(solved_for) != os.path.abspath(this_input) else "")
    return [f"--keep {source}: of its {len(kept)} kept lamp(s), {' and '.join(parts)}{other}: they are written as "
            "this scene's lamps all the same; delete them, or keep a report of this scene"]
