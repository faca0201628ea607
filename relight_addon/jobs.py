"""Relight jobs: FaceSet -> engine -> report dict. Shared by the CLI and the add-on operators.

No bpy here: the bridge exports the scene and writes results back.

``run_radiosity(faces, options)`` is the forward job ("radiosity" command): mesh the faces
into patches, ray-cast form factors, solve B = e + rho F B for the scene's own emitters,
and report the per-polygon mean radiosity (W/m^2) of every exported object.
A scene without emitters is not an error: every radiosity is 0 and the report carries a
warning (the form factors are then not computed).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .engine.formfactors import Cancelled, compute_form_factors
from .engine.options import JobOptions
from .engine.radiosity import solve_radiosity
from .engine.scene import FaceSet, PatchSet, SceneError, face_mean, mesh_patches

__all__ = ["Cancelled", "RadiosityResult", "run_radiosity", "per_polygon", "JobOptions"]

NO_EMITTER_WARNING = "the scene has no emitter (no material with emission): every radiosity is 0"


@dataclass
class RadiosityResult:
    patches: PatchSet
    patch_radiosity: np.ndarray  # (P, 3) W/m^2
    face_radiosity: np.ndarray  # (F, 3) W/m^2, per FaceSet face
    polygon_radiosity: dict  # object name -> (n_polygons, 3) W/m^2, base-mesh polygon order
    polygon_area: dict  # object name -> (n_polygons,) m^2 (world space; 0 for unreported polygons)
    form_factors: object = None


def _face_areas(faces: FaceSet) -> np.ndarray:
    v = faces.vertices[faces.triangles]
    a = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    return np.bincount(faces.triangle_face, weights=a, minlength=faces.n_faces)


def per_polygon(faces: FaceSet, face_values: np.ndarray, polygon_counts: dict | None = None):
    """Per object, the area-weighted mean of ``face_values`` (F, k) over each base polygon.

    Several FaceSet faces can come from one base polygon (modifiers); faces with
    ``face_index`` -1 are left out. Returns (values dict, areas dict).
    """
    vals = np.asarray(face_values, dtype=np.float64).reshape(faces.n_faces, -1)
    area = _face_areas(faces)
    out, areas = {}, {}
    for oi, name in enumerate(faces.object_names):
        sel = (faces.face_object == oi) & (faces.face_index >= 0)
        idx = faces.face_index[sel]
        n = polygon_counts.get(name) if polygon_counts else None
        if n is None:
            n = int(idx.max()) + 1 if len(idx) else 0
        a = np.bincount(idx, weights=area[sel], minlength=n)
        s = np.stack([np.bincount(idx, weights=area[sel] * vals[sel, k], minlength=n)
                      for k in range(vals.shape[1])], axis=1)
        # faces mapped to a zero-area polygon: plain mean
        cnt = np.bincount(idx, minlength=n)
        plain = np.stack([np.bincount(idx, weights=vals[sel, k], minlength=n)
                          for k in range(vals.shape[1])], axis=1) / np.maximum(cnt, 1)[:, None]
        out[name] = np.where(a[:, None] > 0, s / np.where(a > 0, a, 1.0)[:, None], plain)
        areas[name] = a
    return out, areas


def _json_safe(x):
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return _json_safe(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def run_radiosity(faces: FaceSet, options: JobOptions | None = None, polygon_counts: dict | None = None,
                  default_max_patch_size: float | None = None, progress=None, cancel=None):
    """Forward radiosity of ``faces`` lit by their own exitance.

    ``options``: JobOptions (rays_per_patch, max_patch_size, seed, threads are used).
    ``polygon_counts``: object name -> polygons of its base mesh (report rows); default
    max(face_index) + 1. ``default_max_patch_size``: used when options.max_patch_size is
    None (e.g. the scene's ``relight_max_patch_size``); None = engine default.
    ``progress(stage, fraction)``: optional; ``cancel()`` returning True raises Cancelled.
    Returns ``(report, RadiosityResult)``; the report has no export/apply timings (the
    caller adds them) and ``total`` covers this job only.
    """
    options = (options or JobOptions()).validate()
    t0 = time.perf_counter()
    size = options.max_patch_size if options.max_patch_size is not None else default_max_patch_size
    patches = mesh_patches(faces, size)
    t_mesh = time.perf_counter() - t0
    if cancel is not None and cancel():
        raise Cancelled("radiosity cancelled")
    warnings = list(faces.warnings)
    P = patches.n_patches
    F = None
    t_ff = t_solve = 0.0
    info = {}
    if not np.any(patches.exitance > 0):
        warnings.append(NO_EMITTER_WARNING)
        B = np.zeros((P, 3))
    else:
        kw = {}
        if options.rays_per_patch is not None:
            kw["rays_per_patch"] = int(options.rays_per_patch)
        ff_progress = (lambda f: progress("form_factors", f)) if progress is not None else None
        F = compute_form_factors(patches, seed=options.seed, threads=options.threads,
                                 progress=ff_progress, cancel=cancel, **kw)
        t_ff = F.seconds
        if cancel is not None and cancel():
            raise Cancelled("radiosity cancelled")
        t1 = time.perf_counter()
        B, info = solve_radiosity(F, patches.reflectance, patches.exitance)
        t_solve = time.perf_counter() - t1
        warnings.extend(w for w in info.get("warnings", []) if w not in warnings)
        if not info.get("converged", True):
            warnings.append(f"the radiosity solve did not converge: {info.get('message', '')}".strip())
    if not np.all(np.isfinite(B)):
        raise SceneError("the radiosity solve produced NaN or infinite values")
    if progress is not None:
        progress("solve", 1.0)
    B_face = face_mean(patches, B)
    poly, areas = per_polygon(faces, B_face, polygon_counts)
    report = {
        "command": "radiosity",
        "units": {"radiosity": "W/m^2", "length": "m"},
        "scene": {"objects": len(faces.object_names), "faces": int(faces.n_faces), "patches": int(P)},
        "timings_s": {"export": 0.0, "meshing": t_mesh, "form_factors": t_ff, "solve": t_solve, "apply": 0.0,
                      "total": time.perf_counter() - t0},
        "options": {"rays_per_patch": None if F is None else int(F.rays_per_patch),
                    "max_patch_size": float(patches.max_patch_size), "seed": int(options.seed)},
        "solver": {k: v for k, v in info.items() if k != "warnings"},
        "objects": {name: {"radiosity": poly[name]} for name in faces.object_names},
        "warnings": warnings,
    }
    result = RadiosityResult(patches, B, B_face, poly, areas, F)
    return _json_safe(report), result
