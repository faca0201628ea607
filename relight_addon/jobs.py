"""Relight jobs: FaceSet -> engine -> report dict. Shared by the CLI and the add-on operators.

No bpy here: export.py exports the scene, results.py writes results back.

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

from .engine.cost import estimate_patches_cost
from .engine.formfactors import Cancelled
from .engine.geometry import group_mean, group_sum, triangle_areas
from .engine.inverse import InverseProblem, InverseResult, direct_lighting_problem, solve_inverse
from .engine.lights import LightSet, candidate_mask
from .engine.options import JobOptions
from .engine.radiosity import solve_radiosity
from .engine.reduction import ReductionResult, reduce_lights
from .engine.registry import ESTIMATORS, PATCH_MODELS
from .engine.scene import FaceSet, PatchSet, SceneError, face_mean

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


def face_areas(faces: FaceSet) -> np.ndarray:
    """(F,) world-space area of every FaceSet face (m^2)."""
    return group_sum(faces.triangle_face, triangle_areas(faces.vertices[faces.triangles]), faces.n_faces)


def per_polygon(faces: FaceSet, face_values: np.ndarray, polygon_counts: dict | None = None):
    """Per object, the area-weighted mean of ``face_values`` (F, k) over each base polygon.

    Several FaceSet faces can come from one base polygon (modifiers); faces with
    ``face_index`` -1 are left out. Returns (values dict, areas dict).
    """
    vals = np.asarray(face_values, dtype=np.float64).reshape(faces.n_faces, -1)
    counts = []
    for oi, name in enumerate(faces.object_names):
        n = polygon_counts.get(name) if polygon_counts else None
        if n is None:
            idx = faces.face_index[(faces.face_object == oi) & (faces.face_index >= 0)]
            n = int(idx.max()) + 1 if len(idx) else 0
        counts.append(n)
    offset = np.concatenate([[0], np.cumsum(counts)])
    pid = np.where(faces.face_index >= 0, offset[faces.face_object] + faces.face_index, -1)
    area = face_areas(faces)
    mean = group_mean(pid, vals, int(offset[-1]), area)  # zero-area polygons: plain mean
    tot = group_sum(pid, area, int(offset[-1]))
    out = {name: mean[offset[k]:offset[k + 1]] for k, name in enumerate(faces.object_names)}
    areas = {name: tot[offset[k]:offset[k + 1]] for k, name in enumerate(faces.object_names)}
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
    patches = mesh_for_job(faces, options, default_max_patch_size)
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
        ff_progress = (lambda f: progress("form_factors", f)) if progress is not None else None
        F = ESTIMATORS[options.estimator](patches, options, progress=ff_progress, cancel=cancel)
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


# ---------------------------------------------------------------------------- inverse lighting

#: configurations kept re-appliable in the .blend: every one up to this many lights, and
#: about STORE_LOG_POINTS log-spaced ones above (plus e_x and the final one); the chart and
#: the report keep the whole curve
STORE_ALL_UP_TO = 32
STORE_LOG_POINTS = 40

BACKGROUND_NOTE = ("the scene's own emitters ({n} face(s)) are kept as fixed background light; "
                   "the solve lights what they leave to the targets")


def check_solvable(faces: FaceSet, mode: str = "inverse"):
    """Fail early, before any work, on problems the user can fix."""
    if mode == "inverse":
        if not np.any(faces.target):
            raise SceneError("no target: paint a radiosity on at least one face (relight_target, alpha >= 0.5)")
        if np.all(faces.forbidden):
            raise SceneError("no candidate light: every face is forbidden")
    elif not np.any(faces.exitance > 0):
        raise SceneError("the scene has no emitter to reduce (no material with emission)")


def _stage(progress, name, lo, hi):
    if progress is None:
        return None
    return lambda f: progress(name, lo + (hi - lo) * float(f))


def patch_model(options: JobOptions, default_max_patch_size=None):
    """The job's patch model (engine/patch_models/), built from its options."""
    return PATCH_MODELS[options.patch_model].impl(options, default_max_patch_size)


def mesh_for_job(faces: FaceSet, options: JobOptions, default_max_patch_size=None) -> PatchSet:
    return patch_model(options, default_max_patch_size).mesh(faces)


def solve_cost(patches: PatchSet, options: JobOptions) -> dict:
    """Memory and time estimate of a solve (engine.cost), with warnings when they are high."""
    return estimate_patches_cost(patches, options.rays_per_patch, options.solver)


@dataclass
class Model:
    """Stage 1, the problem: patches, lights, form factors and the inverse problem."""

    mode: str  # "inverse" (solve) or "direct" (reduce)
    faces: FaceSet
    patches: PatchSet
    lights: LightSet
    form_factors: object
    problem: InverseProblem
    background: np.ndarray  # (P, 3) W/m^2 the scene's own emitters (inverse mode), fixed
    background_radiosity: np.ndarray  # (P, 3) W/m^2 the radiosity they give
    e_start: np.ndarray | None  # direct mode: the emitters' exitance per light
    warnings: list
    cost: dict
    seconds: dict


@dataclass
class Curve:
    """Stage 4, the curve assembled per base-mesh polygon: the configurations kept re-appliable
    (``keep``: indices into the reduction's curve) and everything needed to show them."""

    keep: np.ndarray
    final_row: int  # row of the final configuration among ``keep``
    light_object: np.ndarray  # per light polygon: object index
    light_face: np.ndarray  # ... base-mesh polygon index
    light_area: np.ndarray
    light_center: np.ndarray
    light_normal: np.ndarray
    light_exitance: np.ndarray  # (kept points, light polygons, 3) W/m^2
    radiosity_object: np.ndarray  # per polygon: object index
    radiosity_face: np.ndarray
    radiosity: np.ndarray  # (kept points, polygons, 3) W/m^2
    polygon_radiosity: dict  # object -> (n_polygons, kept points * 3)
    seconds: float


@dataclass
class SolveOutcome:
    """Everything a solve produced: the JSON report, the curve for the UI and what to store."""

    report: dict
    curve: list  # rows kept re-appliable: [{"n_lights", "error", "relative_error", "n_negative", "curve_index"}]
    final_index: int  # row of the final configuration in ``curve``
    warnings: list
    stored: dict  # curve_store.pack_curve input: every configuration, re-appliable
    faces: FaceSet
    patches: PatchSet
    problem: object
    inverse: object
    reduction: object


def build_model(faces: FaceSet, options: JobOptions, mode="inverse", default_max_patch_size=None,
                progress=None, cancel=None, patches: PatchSet | None = None) -> Model:
    """Stage 1: mesh the faces (the patch model), choose the candidate lights, estimate the form
    factors and set up the inverse problem (inverse: the painted targets, with the scene's own
    emitters as fixed background; direct: the paper's direct-lighting mode)."""
    t0 = time.perf_counter()
    pm = patch_model(options, default_max_patch_size)
    if patches is None:
        patches = pm.mesh(faces)
    t_mesh = time.perf_counter() - t0
    warnings = list(faces.warnings)
    cost = solve_cost(patches, options)
    warnings.extend(cost["warnings"])
    mask = candidate_mask(patches, mode)
    lights = pm.lights(patches, mask)
    pairs = (np.flatnonzero(patches.target), lights.patches) if mode == "inverse" else None
    F = ESTIMATORS[options.estimator](patches, options, progress=_stage(progress, "form factors", 0.0, 0.7),
                                      cancel=cancel, pairs=pairs)
    if cancel is not None and cancel():
        raise Cancelled("solve cancelled")
    t1 = time.perf_counter()
    background = np.zeros_like(patches.exitance)
    B_background = np.zeros_like(patches.exitance)
    e_start = None
    if mode == "inverse":
        problem = InverseProblem(F, patches.area, patches.reflectance, patches.target, patches.target_radiosity,
                                 mask, patches.center, patches.normal, light_basis=lights.basis)
        emitting = np.any(patches.exitance > 0, axis=1)
        if emitting.any():
            background = patches.exitance.copy()
            B_background = problem.forward_radiosity(background)
            problem.b_target = problem.b_target - B_background[problem.targets]
            warnings.append(BACKGROUND_NOTE.format(n=int(len(np.unique(patches.face[emitting])))))
    else:
        problem, e_start = direct_lighting_problem(F, patches.area, patches.reflectance, patches.exitance,
                                                   patches.center, patches.normal, light_basis=lights.basis)
    return Model(mode, faces, patches, lights, F, problem, background, B_background, e_start, warnings, cost,
                 {"meshing": t_mesh, "form_factors": F.seconds, "problem": time.perf_counter() - t1})


def solve_stage(model: Model, options: JobOptions) -> tuple:
    """Stage 2: the configuration the reduction starts from, e_x (n_lights, 3), and the inverse
    result (None in direct mode, where e_x is the scene's emitters)."""
    if model.mode != "inverse":
        return model.e_start, None
    inv = solve_inverse(model.problem, options.solver)
    return inv.exitance, inv


def reduce_stage(model: Model, e_x, options: JobOptions, progress=None, cancel=None) -> ReductionResult:
    """Stage 3: the selection x distribution over the whole curve; the stop criteria pick the final point."""
    red = reduce_lights(model.problem, e_x, selection=options.selection, distribution=options.distribution,
                        max_lights=options.max_lights, relative_error_threshold=options.error_threshold,
                        require_positive=options.require_positive,
                        progress=(lambda d, t: progress("reduction", 0.8 + 0.15 * d / max(t, 1)))
                        if progress is not None else None, cancel=cancel)
    if red.cancelled:
        raise Cancelled("solve cancelled")
    return red


def assemble_curve(model: Model, red: ReductionResult, polygon_counts=None) -> Curve:
    """Stage 4: every kept configuration of the curve per base-mesh polygon (area-weighted means
    of the patches: power-conserving) and the radiosity each gives: B = B_background + A^-1 e,
    one LU solve for all the points at once."""
    t0 = time.perf_counter()
    problem, patches, faces = model.problem, model.patches, model.faces
    C = problem.candidates
    keep = stored_points([p.n_lights for p in red.curve], red.final_index)
    n_pts = len(keep)
    P = patches.n_patches
    E = np.zeros((n_pts, problem.n_lights, 3))
    for k, ci in enumerate(keep):
        pt = red.curve[ci]
        E[k, pt.lights] = pt.exitance
    E_patch = np.zeros((P, n_pts, 3))
    for k in range(n_pts):  # a light's exitance on all its patches
        E_patch[C, k] = problem.light_basis @ E[k]
    facs = problem.factors()
    B_patch = np.empty((P, n_pts, 3))
    for c in range(3):
        B_patch[:, :, c] = facs[c].solve(E_patch[:, :, c]) + model.background_radiosity[:, c:c + 1]
    if not np.all(np.isfinite(B_patch)):
        raise SceneError("the solve produced NaN or infinite values")
    is_cand = np.zeros(P)
    is_cand[C] = 1.0
    face_cols = face_mean(patches, np.concatenate([
        E_patch.reshape(P, -1), B_patch.reshape(P, -1), is_cand[:, None],
        patches.center * is_cand[:, None], patches.normal * is_cand[:, None]], axis=1))
    poly, poly_area = per_polygon(faces, face_cols, polygon_counts)
    w = n_pts * 3
    l_obj, l_poly, l_area, l_E, l_c, l_n, r_obj, r_poly, r_B = ([] for _ in range(9))
    for oi, name in enumerate(faces.object_names):
        v = poly[name]
        npoly = len(v)
        r_obj.append(np.full(npoly, oi))
        r_poly.append(np.arange(npoly))
        r_B.append(v[:, w:2 * w].reshape(npoly, n_pts, 3))
        cand = np.flatnonzero(v[:, 2 * w] > 0.5)
        l_obj.append(np.full(len(cand), oi))
        l_poly.append(cand)
        l_area.append(poly_area[name][cand])
        l_E.append(v[cand, :w].reshape(len(cand), n_pts, 3))
        l_c.append(v[cand, 2 * w + 1:2 * w + 4])
        l_n.append(v[cand, 2 * w + 4:2 * w + 7])
    normal = np.concatenate(l_n)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-30)[:, None]
    return Curve(keep=keep, final_row=int(np.searchsorted(keep, red.final_index)),
                 light_object=np.concatenate(l_obj), light_face=np.concatenate(l_poly),
                 light_area=np.concatenate(l_area), light_center=np.concatenate(l_c), light_normal=normal,
                 light_exitance=np.concatenate(l_E).transpose(1, 0, 2),
                 radiosity_object=np.concatenate(r_obj), radiosity_face=np.concatenate(r_poly),
                 radiosity=np.concatenate(r_B).transpose(1, 0, 2),
                 polygon_radiosity={name: poly[name][:, w:2 * w] for name in faces.object_names},
                 seconds=time.perf_counter() - t0)


def make_report(model: Model, options: JobOptions, inv: InverseResult | None, red: ReductionResult,
                curve: Curve, warnings: list, timings: dict, polygon_counts=None) -> dict:
    """Stage 5: the JSON report (see README.md)."""
    faces, patches, problem = model.faces, model.patches, model.problem
    fi = curve.final_row
    final = red.curve[red.final_index]
    n_pts = len(curve.keep)
    lit = np.flatnonzero(np.any(curve.light_exitance[fi] != 0, axis=1))
    lights = [{"object": faces.object_names[curve.light_object[j]], "face": int(curve.light_face[j]),
               "exitance": curve.light_exitance[fi, j], "area": float(curve.light_area[j]),
               "center": curve.light_center[j]} for j in lit]
    bg_poly, _ = per_polygon(faces, face_mean(patches, model.background), polygon_counts)
    tgt_face = np.where(faces.target[:, None], faces.target_radiosity, np.nan)
    poly_t, _ = per_polygon(faces, tgt_face, polygon_counts)
    objects = {}
    for oi, name in enumerate(faces.object_names):
        e_poly = bg_poly[name].copy()
        sel = curve.light_object == oi
        e_poly[curve.light_face[sel]] += curve.light_exitance[fi][sel]
        objects[name] = {"radiosity": curve.polygon_radiosity[name].reshape(-1, n_pts, 3)[:, fi],
                         "target": _nan_to_none(poly_t[name]), "exitance": e_poly}
    n_targets_faces = int(np.sum(faces.target)) if model.mode == "inverse" else None
    return {
        "command": "solve" if model.mode == "inverse" else "reduce",
        "units": {"radiosity": "W/m^2", "exitance": "W/m^2", "length": "m"},
        "scene": {"objects": len(faces.object_names), "faces": int(faces.n_faces), "patches": int(patches.n_patches)},
        "timings_s": timings,
        "estimate": {"memory_bytes": model.cost["memory_bytes"], "seconds": model.cost["seconds"]},
        "options": {**options.to_dict(), "rays_per_patch": int(model.form_factors.rays_per_patch),
                    "max_patch_size": float(patches.max_patch_size)},
        "inverse": {
            "solver": inv.solver if inv else "direct-lighting",
            "n_targets": int(problem.m), "n_target_faces": n_targets_faces,
            "n_candidates": int(problem.n_lights),  # candidate lights
            "n_candidate_patches": int(len(problem.candidates)),
            "rank": inv.rank if inv else None,
            "rcond": inv.rcond if inv else None,
            "error": inv.error if inv else 0.0,
            "relative_error": inv.relative_error if inv else 0.0,
            "n_negative": inv.n_negative if inv else 0,
            "seconds": inv.seconds if inv else 0.0,
            "condition_estimate": float(problem.condition),
            "target_norm": problem.target_norm,
        },
        "reduction": {"selection": red.selection, "distribution": red.distribution, "seconds": red.seconds,
                      "final_index": red.final_index},
        "curve": [{"n_lights": p.n_lights, "error": p.error, "relative_error": p.relative_error,
                   "n_negative": p.n_negative} for p in red.curve],
        "final": {"n_lights": final.n_lights, "error": final.error, "relative_error": final.relative_error,
                  "n_negative": final.n_negative, "lights": lights},
        "objects": objects,
        "warnings": warnings,
    }


def stored_result(model: Model, red: ReductionResult, curve: Curve, report: dict) -> dict:
    """What the .blend keeps (curve_store.pack_curve): the whole curve and the kept configurations."""
    keep = curve.keep
    pts = red.curve
    return {
        "objects": list(model.faces.object_names),
        "light_object": curve.light_object, "light_face": curve.light_face, "light_area": curve.light_area,
        "light_center": curve.light_center, "light_normal": curve.light_normal,
        "curve_n_lights": np.array([p.n_lights for p in pts]),
        "curve_error": np.array([p.error for p in pts]),
        "curve_relative_error": np.array([p.relative_error for p in pts]),
        "curve_n_negative": np.array([p.n_negative for p in pts]),
        "point_index": keep,
        "n_lights": np.array([pts[i].n_lights for i in keep]),
        "error": np.array([pts[i].error for i in keep]),
        "relative_error": np.array([pts[i].relative_error for i in keep]),
        "n_negative": np.array([pts[i].n_negative for i in keep]),
        "exitance": curve.light_exitance,
        "radiosity_object": curve.radiosity_object, "radiosity_face": curve.radiosity_face,
        "radiosity": curve.radiosity,
        "final": np.array(red.final_index),
        "target_norm": np.array(model.problem.target_norm),
        "meta": {"command": report["command"], "options": _json_safe(report["options"])},
    }


def run_solve(faces: FaceSet, options: JobOptions | None = None, polygon_counts: dict | None = None,
              default_max_patch_size: float | None = None, progress=None, cancel=None, mode="inverse",
              patches: PatchSet | None = None):
    """Inverse lighting ("solve") or direct-lighting reduction ("reduce") of ``faces``:
    build_model -> solve_stage -> reduce_stage -> assemble_curve -> make_report.

    inverse: targets are the painted faces; candidates as ``engine.lights.candidate_mask``;
    the scene's own emitters are fixed background light (subtracted from the targets). The
    inverse system is solved (``options.solver``), then reduced (``options.selection`` x
    ``options.distribution``) over the whole curve; the stop criteria pick the final
    configuration. direct ("reduce"): the candidates are the scene's emitters and every other
    patch is a target at the radiosity they give it (the paper's direct-lighting mode).
    ``progress(stage, fraction)`` with fraction in [0, 1] over the whole job; ``cancel()``
    returning True raises Cancelled. ``patches``: the meshed faces when the caller already
    has them (the operator meshes first to estimate the cost). Returns a SolveOutcome.
    """
    options = (options or JobOptions()).validate()
    check_solvable(faces, mode)
    t0 = time.perf_counter()
    model = build_model(faces, options, mode, default_max_patch_size, progress, cancel, patches)
    t1 = time.perf_counter()
    e_x, inv = solve_stage(model, options)
    t_inverse = time.perf_counter() - t1 + model.seconds["problem"]
    if progress is not None:
        progress("inverse", 0.8)
    if cancel is not None and cancel():
        raise Cancelled("solve cancelled")
    t2 = time.perf_counter()
    red = reduce_stage(model, e_x, options, progress, cancel)
    t_reduce = time.perf_counter() - t2
    warnings = list(model.warnings)
    if mode == "inverse":
        warnings.extend(_positivity_notes(model.problem, inv, red.final))
    warnings.extend(w for w in model.problem.warnings + (inv.warnings if inv else []) + red.warnings
                    if w not in warnings)
    curve = assemble_curve(model, red, polygon_counts)
    timings = {"export": 0.0, "meshing": model.seconds["meshing"], "form_factors": model.seconds["form_factors"],
               "inverse": t_inverse, "reduction": t_reduce, "curve": curve.seconds, "solve": t_inverse + t_reduce,
               "apply": 0.0, "total": time.perf_counter() - t0}
    report = make_report(model, options, inv, red, curve, warnings, timings, polygon_counts)
    rows = [{"n_lights": red.curve[i].n_lights, "error": red.curve[i].error,
             "relative_error": red.curve[i].relative_error, "n_negative": red.curve[i].n_negative,
             "curve_index": int(i)} for i in curve.keep]
    stored = stored_result(model, red, curve, report)
    return SolveOutcome(_json_safe(report), rows, curve.final_row, warnings, stored, faces, model.patches,
                        model.problem, inv, red)


#: above this relative error, the final configuration is compared with the best positive one
POSITIVE_GAP = 0.1


def _positivity_notes(problem, inv, final):
    """Say so when the final configuration misses the targets by much: whether no positive
    lighting can do better (targets brighter or darker than light can make them) or whether
    more lights / another selection would. The bound is NNLS on T: the best any set of
    non-negative lights can do."""
    if not final.relative_error > POSITIVE_GAP:
        return []
    bound = inv if inv is not None and inv.solver == "nnls" else solve_inverse(problem, "nnls")
    n_pos = int((bound.exitance.max(axis=1) > 0).sum())
    if bound.relative_error > POSITIVE_GAP:
        return [f"no positive lighting meets these targets: the best any non-negative lights can do is a "
                f"relative error of {bound.relative_error:.3g} (NNLS, {n_pos} lights); the final configuration's "
                f"is {final.relative_error:.3g}"]
    return [f"the final configuration misses the targets by {final.relative_error:.3g} (relative error); positive "
            f"lights can reach {bound.relative_error:.3g} (NNLS, {n_pos} lights): allow more lights, or try the "
            "nnls-greedy selection"]


def stored_points(n_lights, final_index):
    """Indices of the curve points kept re-appliable (see STORE_ALL_UP_TO), ascending."""
    n = np.asarray(n_lights)
    keep = n <= STORE_ALL_UP_TO
    if len(n) and n.max() > STORE_ALL_UP_TO:
        wanted = np.unique(np.rint(np.geomspace(STORE_ALL_UP_TO + 1, n.max(), STORE_LOG_POINTS)))
        for w in wanted:  # the point closest to each wanted count
            keep[int(np.argmin(np.abs(n - w)))] = True
    keep[0] = True  # e_x (or the first configuration)
    keep[final_index] = True
    return np.flatnonzero(keep)


def _nan_to_none(rows):
    return [None if np.isnan(r).any() else r for r in np.asarray(rows)]
