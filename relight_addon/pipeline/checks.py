"""The checks a job makes from the faces alone, before any work (no bpy): what the user can fix
(nothing painted, no candidate surface, no emitter to reduce) is refused with a message that says
how, repeating export's notes that explain it.
"""
from __future__ import annotations

import numpy as np

from ..engine.scene import FaceSet, SceneError
from ..engine.units import TINY

__all__ = ["face_areas", "check_solvable", "check_reducible"]


def _with_notes(text, notes):
    notes = [n for n in (notes or []) if n]
    return text + ("; " + "; ".join(notes) if notes else "")


def face_areas(faces: FaceSet) -> np.ndarray:
    """(F,) world-space area of every face (m^2)."""
    T = faces.vertices[faces.triangles]
    a = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    return np.bincount(faces.triangle_face, weights=a, minlength=faces.n_faces)


def check_solvable(faces: FaceSet, notes: dict | None = None, area=None):
    """Fail early, before any work, on problems of a solve the user can fix. ``notes`` (export:
    what the scene holds but Relight does not use) are repeated in the message they explain.
    ``area``: face_areas(faces), when the caller keeps it (a prepared scene)."""
    notes = notes or {}
    area = face_areas(faces) if area is None else area
    scale = float(np.linalg.norm(np.ptp(faces.vertices, axis=0))) if len(faces.vertices) else 0.0
    has_area = area > (1e-10 * max(scale, TINY)) ** 2
    view = faces.view_target is not None  # (its pixels were checked when it was read)
    if not view and not np.any(faces.target):
        raise SceneError(_with_notes("no target: paint a radiosity on at least one face (relight_target, "
                                     "alpha >= 0.5)", notes.get("target")))
    if not view and not np.any(faces.target & has_area):
        raise SceneError(_with_notes("no target: every painted face has no area", notes.get("candidates")))
    if not view and not np.any(faces.target_radiosity[faces.target & has_area] > 0):
        raise SceneError(_with_notes("every target asks for radiosity 0 (painted black, or a target scale of "
                                     "0): there is nothing to light", notes.get("target")))
    free = ~faces.forbidden & ~np.any(faces.exitance > 0, axis=1)
    if not np.any(free):
        real = faces.face_index >= 0
        owners = sorted({faces.object_names[o] for o in np.unique(faces.face_object[real])})
        planes = [] if faces.passes is None else \
            sorted({faces.object_names[o] for o in np.unique(faces.face_object[real & faces.passes])})
        why = (f", on a work plane or already emits; a work plane holds no light (light passes through it): "
               f"{', '.join(map(repr, planes[:10]))}{' ...' if len(planes) > 10 else ''}; give the lights another "
               "surface (turn Work Plane off, or allow an object's faces)") if planes else " or already emits"
        raise SceneError(_with_notes(
            f"no candidate light: every face is forbidden (relight_forbidden, relight_no_lights){why}; objects: "
            f"{', '.join(owners[:10])}{' ...' if len(owners) > 10 else ''}", notes.get("candidates")))
    if not np.any(free & has_area):
        raise SceneError(_with_notes("no candidate light: the faces that may hold lights have no area",
                                     notes.get("candidates")))
    if not np.any(free & has_area & ~faces.target):
        raise SceneError(_with_notes("no candidate light: every face that may hold lights is painted, and a "
                                     "painted face asks for light, it does not hold it; allow a surface that "
                                     "is not painted (a ceiling, a wall)", notes.get("candidates")))


def check_reducible(faces: FaceSet, notes: dict | None = None):
    """Fail early, before any work, on a reduce of a scene without emitters (``notes``: export's)."""
    notes = notes or {}
    if not np.any(faces.exitance > 0) and not faces.lamps:
        dark = notes.get("emitters")
        if dark:
            raise SceneError(f"the scene has no emitter to reduce: no material emits, and its {len(dark)} lamp(s) "
                             f"emit nothing: {', '.join(dark[:10])}{' ...' if len(dark) > 10 else ''}; give them a "
                             "Power (a reduction lowers or switches off the lamps that emit)")
        raise SceneError("the scene has no emitter to reduce (no lamp, no material with emission)")
