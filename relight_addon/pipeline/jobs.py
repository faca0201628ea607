"""Relight jobs: FaceSet -> engine -> report dict. Shared by the CLI and the add-on operators.

No bpy here: export.py exports the scene, results.py writes results back.

``run_radiosity(faces, options)`` is the forward job ("radiosity" command): mesh the faces
into patches, ray-cast form factors, solve B = e + rho F B for the scene's own emitters,
and report the per-polygon mean radiosity (W/m^2) of every exported object.
A scene without emitters is not an error: every radiosity is 0 and the report carries a
warning (the form factors are then not computed).
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..engine.light_colour import channel_error, colour_problem, fit_columns, fit_lights, lower_bounds_of
from ..engine.candidate_lamps import default_drop, lamp_bound, offer_lamps, offered_kinds
from ..engine.lamp_refinement import BUDGET as REFINE_BUDGET, ROUNDS as LAMP_ROUNDS, Mount, Transport, \
    refine_configuration
from ..engine.lights.placed import WRITER as PLACED
from ..engine.cost import DIRECT_LIGHTS, DIRECT_SPREAD_PATCHES, check_memory, estimate_cost, estimate_patch_count, estimate_patches_cost
from ..engine.formfactors import auto_rays_per_patch
from ..engine.kernel_transfer import lights_direct_correction
from ..engine.incidence import first_bounce_matrices, incidence_tables, lamp_albedo_excess, lamp_excess
from ..engine.inverse import (DivergentTransport, InverseError, InverseProblem, InverseResult, direct_lighting_problem,
                              solve_inverse)
from ..engine.lamps import lamp_irradiance
from ..engine.world import world_irradiance
from ..engine.lights import LightSet, append_lamps, candidate_mask
from ..engine.lights.lamp import add_lamps
from ..engine.options import REFINE_RAY_FRACTION, JobOptions, OptionError, check_light_kinds
from ..engine.patch_models.adaptive import refinement_measure
from ..engine.plausibility import MIN_UTILISATION
from ..engine.radiosity import solve_radiosity
from ..engine.reduction import ReductionResult, reduce_lights
from ..engine.registry import ESTIMATORS, LIGHT_COLOURS, PATCH_MODELS, SELECTIONS
from ..engine.sampling import Cancelled, SceneSampler
from ..engine.scene import FaceSet, PatchSet, SceneError, face_mean
from ..engine.targets import scene_targets
from .polygons import PolygonMap
from .report import json_safe, radiosity_report, solve_report
from .stored import StoredResult, stored_points

__all__ = ["Cancelled", "RadiosityResult", "run_radiosity", "run_solve", "PolygonMap", "JobOptions"]

NO_EMITTER_WARNING = "the scene has no emitter (no lamp, no material with emission): every radiosity is 0"


@dataclass
class RadiosityResult:
    patches: PatchSet
    patch_radiosity: np.ndarray  # (P, 3) W/m^2
    face_radiosity: np.ndarray  # (F, 3) W/m^2, per FaceSet face
    polygon_radiosity: dict  # object name -> (n_polygons, 3) W/m^2, base-mesh polygon order
    polygon_area: dict  # object name -> (n_polygons,) m^2 (world space; 0 for unreported polygons)
    form_factors: object = None
    scene_light: np.ndarray = None  # (P, n, 3) W/m^2: each lamp's and the World's direct light (jobs.scene_light)


def run_radiosity(faces: FaceSet, options: JobOptions | None = None, polygon_counts=None,
                  default_max_patch_size: float | None = None, progress=None, cancel=None,
                  patches: PatchSet | None = None, notes: dict | None = None):
    """Forward radiosity of ``faces`` lit by their own exitance.

    ``options``: JobOptions (rays_per_patch, max_patch_size, seed, threads are used).
    ``polygon_counts``: per object index (a list; None = a group that is not reported, e.g.
    instances), or object name -> polygons of its base mesh (report rows); default
    max(face_index) + 1. ``default_max_patch_size``: used when options.max_patch_size is
    None (e.g. the scene's ``relight_max_patch_size``); None = engine default.
    ``progress(stage, fraction)``: optional; ``cancel()`` returning True raises Cancelled.
    Returns ``(report, RadiosityResult)``; the report has no export/apply timings (the
    caller adds them) and ``total`` covers this job only. ``patches``: the meshed faces when the
    caller already has them (to print the estimate first); ``notes``: unused (export's notes).
    A job that cannot fit in memory is refused before any work (``check_memory``).
    """
    options = (options or JobOptions()).validate()
    t0 = time.perf_counter()
    if patches is None:
        patches = mesh_for_job(faces, options, default_max_patch_size, mode="direct")
    t_mesh = time.perf_counter() - t0
    cost = check_memory(radiosity_cost(patches, options), f"this job ({patches.n_patches} patches)")
    if cancel is not None and cancel():
        raise Cancelled("radiosity cancelled")
    warnings = list(faces.warnings) + [w for w in cost["warnings"] if w not in faces.warnings]
    P = patches.n_patches
    F = None
    t_ff = t_solve = 0.0
    info = {}
    if not np.any(patches.exitance > 0) and not has_scene_light(faces):
        warnings.append(NO_EMITTER_WARNING)
        B = np.zeros((P, 3))
    else:
        ff_progress = (lambda f: progress("form_factors", f)) if progress is not None else None
        F = ESTIMATORS[options.estimator](patches, options, progress=ff_progress, cancel=cancel)
        t_ff = F.seconds
        if cancel is not None and cancel():
            raise Cancelled("radiosity cancelled")
        t1 = time.perf_counter()
        # a partly buried emitter sends the exitance of its visible part (InverseProblem.emission_share)
        share = getattr(F, "emission_share", None)
        source = patches.exitance if share is None else patches.exitance * share[:, None]
        D = first_bounce(faces, patches, F, np.any(source > 0, axis=1))
        if D is not None:  # the emitters' first reflection with the albedo of its incidence
            source = source + np.stack([D[c] @ source[:, c] for c in range(3)], axis=1)
        H = scene_light(faces, patches, F, options.seed)[0] if has_scene_light(faces) else None
        if H is not None:  # the lamps' and the World's light; the lamps' first reflection at its incidence
            source = source + patches.reflectance * H.sum(axis=1)
            excess = scene_light_excess(faces, patches, H)
            source = source if excess is None else source + excess
        B, info = solve_radiosity(F, patches.reflectance, source)
        t_solve = time.perf_counter() - t1
        warnings.extend(w for w in info.get("warnings", []) if w not in warnings)
        if not info.get("converged", True):
            warnings.append(f"the radiosity solve did not converge: {info.get('message', '')}".strip())
    if not np.all(np.isfinite(B)):
        raise SceneError("the radiosity solve produced NaN or infinite values")
    if progress is not None:
        progress("solve", 1.0)
    shown = B  # an emitter's face shows its exitance over its whole area, as a bake does
    if getattr(F, "emission_share", None) is not None:
        shown = B + (1.0 - F.emission_share)[:, None] * patches.exitance
    B_face = face_mean(patches, shown)
    pmap = PolygonMap(faces, patches, polygon_counts)
    poly, areas = pmap.split(pmap.mean(shown)), pmap.split(pmap.area)
    timings = {"export": 0.0, "meshing": t_mesh, "form_factors": t_ff, "solve": t_solve, "apply": 0.0,
               "total": time.perf_counter() - t0}
    report = radiosity_report(faces, patches, options, F, info, poly, cost, warnings, timings)
    result = RadiosityResult(patches, B, B_face, poly, areas, F, None if F is None else H)
    return report, result


# ---------------------------------------------------------------------------- inverse lighting

BACKGROUND_NOTE = ("the scene's own light ({lamps} lamp(s){world}, {n} emissive face(s)) is kept as fixed background light; "
                   "the solve lights what they leave to the targets")


def _with_notes(text, notes):
    notes = [n for n in (notes or []) if n]
    return text + ("; " + "; ".join(notes) if notes else "")


def face_areas(faces: FaceSet) -> np.ndarray:
    """(F,) world-space area of every face (m^2)."""
    T = faces.vertices[faces.triangles]
    a = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    return np.bincount(faces.triangle_face, weights=a, minlength=faces.n_faces)


def check_solvable(faces: FaceSet, mode: str = "inverse", notes: dict | None = None, area=None):
    """Fail early, before any work, on problems the user can fix. ``notes`` (export: what the
    scene holds but Relight does not use) are repeated in the message they explain. ``area``:
    face_areas(faces), when the caller keeps it (a prepared scene)."""
    notes = notes or {}
    area = face_areas(faces) if area is None else area
    scale = float(np.linalg.norm(np.ptp(faces.vertices, axis=0))) if len(faces.vertices) else 0.0
    has_area = area > (1e-10 * max(scale, 1e-300)) ** 2
    if mode == "inverse":
        if not np.any(faces.target):
            raise SceneError(_with_notes("no target: paint a radiosity on at least one face (relight_target, "
                                         "alpha >= 0.5)", notes.get("target")))
        if not np.any(faces.target & has_area):
            raise SceneError(_with_notes("no target: every painted face has no area", notes.get("candidates")))
        if not np.any(faces.target_radiosity[faces.target & has_area] > 0):
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
    elif not np.any(faces.exitance > 0) and not faces.lamps:
        dark = notes.get("emitters")
        if dark:
            raise SceneError(f"the scene has no emitter to reduce: no material emits, and its {len(dark)} lamp(s) "
                             f"emit nothing: {', '.join(dark[:10])}{' ...' if len(dark) > 10 else ''}; give them a "
                             "Power (a reduction lowers or switches off the lamps that emit)")
        raise SceneError("the scene has no emitter to reduce (no lamp, no material with emission)")


def _stage(progress, name, lo, hi):
    if progress is None:
        return None
    return lambda f: progress(name, lo + (hi - lo) * float(f))


def patch_model(options: JobOptions, default_max_patch_size=None):
    """The job's patch model (engine/patch_models/), built from its options."""
    return PATCH_MODELS[options.patch_model].impl(options, default_max_patch_size)


def mesh_for_job(faces: FaceSet, options: JobOptions, default_max_patch_size=None, mode="inverse") -> PatchSet:
    """The faces meshed by the job's patch model, after checking (from the faces alone) that the
    patches would fit in this machine's memory."""
    check_before_meshing(faces, options, default_max_patch_size, mode)
    return patch_model(options, default_max_patch_size).mesh(faces)


def uses_kernel_pairs(options: JobOptions, mode: str = "inverse") -> bool:
    """Whether the job's estimator computes the light-to-target pairs by the kernel (inverse mode)."""
    return mode == "inverse" and bool(ESTIMATORS[options.estimator].get("kernel_pairs", False))


def rays_per_patch(options: JobOptions, n_patches: int, mode: str = "inverse") -> int:
    """The option, or the automatic quality for this many patches (formfactors.auto_rays_per_patch)."""
    return int(options.rays_per_patch or auto_rays_per_patch(n_patches, kernel=uses_kernel_pairs(options, mode)))


def solve_cost(patches: PatchSet, options: JobOptions, n_triangles: int = 0, mode: str = "inverse") -> dict:
    """Memory and time estimate of a solve (engine.cost), with warnings when they are high; the
    candidate lamps counted at their bound (engine.candidate_lamps.lamp_bound)."""
    passes = options.param("refine_passes", 0)  # 0 unless the chosen patch model declares it
    cand = candidate_mask(patches, mode)
    lamps, work = (lamp_bound(patches, cand, options), lamp_bound(patches, cand, options, work=True)) \
        if mode == "inverse" else (0, 0)
    k = min(options.max_lights, lamps) if lamps and options.param("refine_lamps", False) else 0
    pm = patch_model(options)
    per_light = pm.patches_per_light(patches, cand) if hasattr(pm, "patches_per_light") and cand.any() else 1.0
    return estimate_patches_cost(patches, rays_per_patch(options, patches.n_patches, mode), options.solver,
                                 n_triangles=n_triangles, refine_passes=passes, kernel=uses_kernel_pairs(options, mode),
                                 threads=options.threads, n_lamps=lamps, lamp_work=work,
                                 lamp_refinements=k * (k + 1) // 2, max_lights=options.max_lights,
                                 patches_per_light=per_light,
                                 colour_relaxation=mode == "inverse"
                                 and bool(LIGHT_COLOURS[options.light_colour].get("relaxation", False)))


def radiosity_cost(patches: PatchSet, options: JobOptions) -> dict:
    """Memory and time estimate of a forward radiosity job (no inverse problem)."""
    rays = rays_per_patch(options, patches.n_patches, "radiosity")
    return estimate_cost(patches.n_patches, rays, 0, 0, threads=options.threads)  # no inverse terms


# ---------------------------------------------------------------------------- memory guard

def check_before_meshing(faces: FaceSet, options: JobOptions, default_max_patch_size=None, mode="inverse") -> dict:
    """Refuse (engine.cost.check_memory) before any allocation a job that cannot fit in memory:
    the estimate of the patches the faces certainly give (``estimate_patch_count(certain=True)``;
    the inverse problem's terms left out: a lower bound of the estimate checked after meshing)."""
    P = estimate_patch_count(faces, options, default_max_patch_size, certain=True)
    Pi = int(P)
    rays = rays_per_patch(options, Pi, mode)
    passes = options.param("refine_passes", 0) if mode == "inverse" else 0
    cost = estimate_cost(Pi, int(rays), 0, 0, n_triangles=len(faces.triangles), refine_passes=passes,
                         threads=options.threads)
    size = options.max_patch_size if options.max_patch_size is not None else default_max_patch_size
    where = f"about {P:.3g} patch(es)" + (f" at a patch size of {size:g} m" if size is not None else "")
    return check_memory(cost, f"this job ({where}, {int(rays)} rays per patch)")


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
    e_start: np.ndarray | None  # direct mode: the emitters' exitance per light
    warnings: list
    cost: dict
    seconds: dict
    refinement: dict = None  # adaptive model: passes made and the target change after each
    lamp_irradiance: np.ndarray = None  # (P, n, 3) W/m^2: the fixed light's direct irradiance: each lamp's and
    #                                     the World's (inverse mode), the World's (direct mode: the lamps are lights)
    lamp_names: list = None  # [(name, kind, power)] per column of lamp_irradiance
    lamp_lights: tuple = None  # direct mode: (light indices, faces.lamps indices) of the lamps being reduced
    lamp_refinement: dict = None  # refine_stage: the chosen lamps' refinement, per curve point
    direct: dict = None  # direct_stage: the curve's lights' direct light by the kernel
    polygons: PolygonMap = None  # assemble_curve's patches -> polygons map (paint-independent: a retargeted
    #                              model keeps it)


@dataclass
class Curve:
    """Stage 4, the curve assembled for the scene: the configurations kept re-appliable (``keep``:
    indices into the reduction's curve), each light's exitance and every patch's radiosity per
    kept configuration, and the map to base-mesh polygons."""

    keep: np.ndarray
    final_row: int  # row of the final configuration among ``keep``
    exitance: np.ndarray  # (kept points, n_lights, 3) W/m^2
    radiosity: np.ndarray  # (kept points, P, 3) W/m^2, background included
    polygons: PolygonMap
    light_polygons: sp.csr_matrix  # (n_lights, n_polygons): the polygons each light lies on
    seconds: float

    def final_polygon_radiosity(self):
        return self.polygons.mean(self.radiosity[self.final_row])


@dataclass
class SolveOutcome:
    """Everything a solve produced: the JSON report, the curve for the UI and what to store."""

    report: dict
    curve: list  # rows kept re-appliable: [{"n_lights", "error", "relative_error", "n_negative", "curve_index"}]
    final_index: int  # row of the final configuration in ``curve``
    warnings: list
    stored: StoredResult  # every configuration, re-appliable (packed into the .blend by results.py)
    faces: FaceSet
    patches: PatchSet
    problem: object
    inverse: object
    reduction: object
    scene_light: np.ndarray = None  # (P, n, 3) W/m^2: each lamp's and the World's direct light (fixed)
    placed_light: list = None  # [(Lamp, (P, 3) W/m^2)]: the final configuration's placed lamps' direct light
    model: Model = None  # the solve's model (a prepared scene re-solves from it: pipeline.prepared)


def build_model(faces: FaceSet, options: JobOptions, mode="inverse", default_max_patch_size=None,
                progress=None, cancel=None, patches: PatchSet | None = None, estimate=None) -> Model:
    """Stage 1: mesh the faces (the patch model), choose the candidate lights, estimate the form
    factors and set up the inverse problem (inverse: the painted targets, with the scene's own
    emitters as fixed background; direct: the paper's direct-lighting mode). ``estimate``: the
    form-factor estimator to call instead of ``options.estimator``'s, with its signature (a
    prepared scene's: pipeline.prepared)."""
    t0 = time.perf_counter()
    pm = patch_model(options, default_max_patch_size)
    refines = mode == "inverse" and hasattr(pm, "refine") and options.refine_passes > 0
    if patches is None:
        check_before_meshing(faces, options, default_max_patch_size, mode)
        patches = pm.mesh(faces)
    elif refines:  # a refining model keeps its state from its own first mesh (same patches: deterministic)
        patches = pm.mesh(faces)
    t_mesh = time.perf_counter() - t0
    warnings = list(faces.warnings)
    cost = check_memory(solve_cost(patches, options, len(faces.triangles), mode),
                        f"this solve ({patches.n_patches} patches)")  # refuse before any more work
    warnings.extend(cost["warnings"])
    passes = options.refine_passes if (mode == "inverse" and hasattr(pm, "refine")) else 0
    t_ff = t_problem = t_lamps = 0.0
    history = []
    # the paper's heuristics redistribute between lights that partition the candidates: single-scale;
    # direct-lighting mode reduces the scene's own lamps: one light per emitter polygon
    scales = None if SELECTIONS[options.selection].get("multiscale") else ("cell",)
    if mode == "direct":
        scales = ("polygon",)
    for p in range(passes + 1):
        mask = candidate_mask(patches, mode)
        lights = None  # direct mode: the emitter polygons, if any (the lamps are added below)
        if mode == "inverse" or mask.any():
            lights = pm.lights(patches, mask, scales) if hasattr(pm, "refine") else pm.lights(patches, mask)
            if mode == "inverse" and not options.param("surface_lights", True):  # lamps only
                lights = LightSet(lights.patches, sp.csr_matrix((len(lights.patches), 0)), np.zeros(0, dtype=np.int8),
                                  np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
        pairs = (np.flatnonzero(patches.target), lights.patches) if mode == "inverse" else None
        lo, hi = 0.7 * p / (passes + 1), 0.7 * (p + 1) / (passes + 1)
        # a model that will be refined only ranks patches by importance: a quarter of the rays
        rays = rays_per_patch(options, patches.n_patches, mode)
        opts = options if p == passes else replace(options, rays_per_patch=max(64, rays // REFINE_RAY_FRACTION))
        F = (estimate or ESTIMATORS[options.estimator])(patches, opts, progress=_stage(progress, "form factors", lo, hi),
                                                        cancel=cancel, pairs=pairs)
        t_ff += F.seconds
        if getattr(F, "kernel_unfit", None):
            n, objs = F.kernel_unfit
            warnings.append(f"{n} light-to-target form factor(s) could not be computed by the kernel (a point on a "
                            f"face's edge: coincident or degenerate faces of {', '.join(repr(faces.object_names[o]) for o in objs[:6])}"
                            f"{' ...' if len(objs) > 6 else ''}): taken from the rays' estimate")
        if cancel is not None and cancel():
            raise Cancelled("solve cancelled")
        if mode == "inverse" and offered_kinds(options):  # the candidate lamps, beside the cells
            t1 = time.perf_counter()
            sampler = getattr(F, "sampler", None) or SceneSampler(patches)
            lamp_notes = []
            lights, _ = offer_lamps(lights, patches, mask, options, sampler, options.seed,
                                    _stage(progress, "lamps", hi, hi + 0.05 / (passes + 1)), notes=lamp_notes)
            warnings.extend(n for n in lamp_notes if n not in warnings)
            t_lamps += time.perf_counter() - t1
            if cancel is not None and cancel():
                raise Cancelled("solve cancelled")
        if lights is not None and lights.n_lights == 0:
            raise OptionError("no candidate light: the cells are off (--no-surface-lights) and no candidate lamp "
                              f"({', '.join(offered_kinds(options))}) lights any face",
                              f"no candidate light: Cells is off under Offer and no candidate lamp "
                              f"({', '.join(offered_kinds(options))}) lights any face")
        t1 = time.perf_counter()
        background = np.zeros_like(patches.exitance)
        lamp_H, lamp_names = np.zeros((patches.n_patches, 0, 3)), []
        e_start = None
        lamp_lights = None
        with transport_named(patches, faces):  # (the radiosity system is factorised here)
            if mode == "inverse":
                emitting = np.any(patches.exitance > 0, axis=1)
                if emitting.any():
                    background = patches.exitance.copy()
                lamp_H, lamp_names = scene_light(faces, patches, F, options.seed)
                problem = InverseProblem(F, patches.area, patches.reflectance, scene_targets(faces, patches),
                                         mask, patches.center, patches.normal, lights=lights,
                                         first_bounce=first_bounce(faces, patches, F, mask | emitting),
                                         background=background, background_irradiance=lamp_H.sum(axis=1),
                                         lamp_excess=lights_excess(faces, patches, lights),
                                         background_excess=scene_light_excess(faces, patches, lamp_H))
            else:
                lights, lamp_lights, lamp_H, lamp_names, notes = direct_lights(faces, patches, F, lights, options.seed)
                warnings.extend(n for n in notes if n not in warnings)
                problem, e_start = direct_lighting_problem(F, patches.area, patches.reflectance, patches.exitance,
                                                           patches.center, patches.normal, lights=lights,
                                                           first_bounce=first_bounce(faces, patches, F, mask),
                                                           strength=np.array([faces.lamps[i].power for i in lamp_lights[1]])
                                                           .reshape(-1, 3),
                                                           background_irradiance=lamp_H.sum(axis=1) if lamp_names else None,
                                                           lamp_excess=lights_excess(faces, patches, lights))
        t_problem += time.perf_counter() - t1
        if p == passes:
            break
        t2 = time.perf_counter()
        change, importance = refinement_measure(problem, history)
        t_problem += time.perf_counter() - t2
        if change is not None and change < options.refine_tolerance:
            break
        t3 = time.perf_counter()
        if not pm.refine(faces, patches, importance):
            break
        patches = pm.mesh(faces)
        check_memory(solve_cost(patches, options, len(faces.triangles), mode),
                     f"this solve ({patches.n_patches} patches after refinement pass {p + 1})")
        t_mesh += time.perf_counter() - t3
    if mode == "inverse":  # the lights' colour (an automatic mode chooses it on the final problem)
        problem.colour, note = light_colour_of(problem, options)
        if note:
            warnings.append(note)
    if mode == "inverse" and (np.any(background > 0) or has_scene_light(faces)):
        emitting = np.any(patches.exitance > 0, axis=1)
        warnings.append(BACKGROUND_NOTE.format(n=int(len(np.unique(patches.face[emitting]))), lamps=len(faces.lamps),
                                               world=", the World" if faces.world_radiance is not None else ""))
    if mode == "direct" and lamp_names:
        warnings.append(DIRECT_FIXED_NOTE.format(_fixed_names(lamp_names)))
    refinement = {"passes": len(history), "target_change": [h[2] for h in history[1:]]}
    return Model(mode, faces, patches, lights, F, problem, background, e_start, warnings, cost,
                 {"meshing": t_mesh, "form_factors": t_ff, "problem": t_problem, "lamps": t_lamps}, refinement,
                 lamp_H, lamp_names, lamp_lights)


DIRECT_FIXED_NOTE = ("kept as fixed light, which a reduction cannot switch off: {}; its light is part of the scene's "
                     "radiosity and of every configuration's")


def _fixed_names(names) -> str:
    """The direct mode's fixed light in words: the World, the lamps of negative power."""
    return ", ".join(f"the World ({n})" if kind == "world" else f"lamp {n!r} (negative power)" for n, kind, _ in names)


def direct_lights(faces: FaceSet, patches: PatchSet, F, surface, seed=0) -> tuple:
    """Direct-lighting mode: the lights to reduce -- the emitter polygons (``surface``, a LightSet,
    or None without any) followed by the scene's lamps (engine/lights/lamp.py: each a light whose
    source is its direct irradiance per unit of its power) -- and the fixed light (the World).
    Returns (lights, (light indices, faces.lamps indices) of the lamps, H (P, n, 3) W/m^2 and
    [(name, kind, power)] of the fixed light, warnings). A lamp that lights no face is left out
    of the reduction (named; the written copy leaves it as it is); a lamp of negative power
    (Cycles renders it as negative light: blender/lamps.py) is fixed light, as the World is."""
    P = patches.n_patches
    H, names = scene_light(faces, patches, F, seed) if has_scene_light(faces) else (np.zeros((P, 0, 3)), [])
    n = len(faces.lamps)
    negative = [i for i, lamp in enumerate(faces.lamps) if np.any(lamp.power < 0)]
    unit = np.zeros((P, n))
    for i, lamp in enumerate(faces.lamps):  # H is the lamp's irradiance per W times its power per channel
        if i not in negative:
            c = int(np.argmax(lamp.power))
            unit[:, i] = H[:, i, c] / lamp.power[c]
    lit = np.flatnonzero(unit.max(axis=0) > 0) if n else np.zeros(0, dtype=np.int64)
    notes = []
    dark = [faces.lamps[i].name for i in range(n) if i not in set(lit.tolist()) and i not in negative]
    if dark:
        notes.append(f"{len(dark)} lamp(s) light no face ({', '.join(dark[:5])}{' ...' if len(dark) > 5 else ''}): "
                     "left out of the reduction, and left as they are in the written copy")
    if surface is None and not len(lit):
        neg = [repr(faces.lamps[i].name) for i in negative]
        raise SceneError("nothing to reduce: no material emits and no lamp lights any face"
                         + (f" ({', '.join(dark[:5])}{' ...' if len(dark) > 5 else ''})" if dark else "")
                         + (f"; lamp(s) of negative power are not reduced: {', '.join(neg[:5])}" if neg else ""))
    C = np.flatnonzero(candidate_mask(patches, "direct"))
    n0 = 0 if surface is None else surface.n_lights
    lights = add_lamps(surface, C, P, [faces.lamps[i] for i in lit], unit[:, lit], patches.area)
    fixed = negative + list(range(n, H.shape[1]))
    return lights, (n0 + np.arange(len(lit)), lit), H[:, fixed], [names[k] for k in fixed], notes


def scene_light_at(model: Model, strength) -> np.ndarray:
    """(P, n, 3) W/m^2: the direct light of ``faces.lamps`` and then of the World (jobs.scene_light's
    columns) in the configuration ``strength`` (n_lights, 3): in direct mode each lamp at its
    strength in that configuration (0 when reduced away; a lamp outside the reduction as it is)."""
    if model.mode == "inverse" or model.lamp_lights is None:
        return model.lamp_irradiance
    faces, P = model.faces, model.patches.n_patches
    cols = np.zeros((P, len(faces.lamps), 3))
    H = sp.csc_matrix(model.lights.irradiance)
    for j, i in zip(*model.lamp_lights):
        cols[:, i] = H[:, j].toarray() * np.asarray(strength, dtype=np.float64)[j][None, :]
    index = {lamp.name: i for i, lamp in enumerate(faces.lamps)}
    fixed = [(k, index[name]) for k, (name, kind, _) in enumerate(model.lamp_names or []) if kind != "world"]
    for k, i in fixed:  # a lamp of negative power: fixed light, in its own column
        cols[:, i] = model.lamp_irradiance[:, k]
    rest = [k for k in range(model.lamp_irradiance.shape[1]) if k not in {k for k, _ in fixed}]
    return np.concatenate([cols, model.lamp_irradiance[:, rest]], axis=1)


def solve_stage(model: Model, options: JobOptions) -> tuple:
    """Stage 2: the configuration the reduction starts from, e_x (n_lights, 3), and the inverse
    result (None in direct mode, where e_x is the scene's emitters)."""
    if model.mode != "inverse":
        return model.e_start, None
    inv = solve_inverse(model.problem, options.solver)
    return inv.exitance, inv


def reduce_stage(model: Model, e_x, options: JobOptions, progress=None, cancel=None,
                 curve_lights=None, initial=None, nnls_start=None) -> ReductionResult:
    """Stage 3: the selection x distribution over the whole curve; the stop criteria pick the
    final point. ``curve_lights``, ``initial``: a stroke's re-solve (Live; reduce_lights': a
    per-k curve to ``curve_lights``, the quick search, from the configurations ``initial``)."""
    by_lp = SELECTIONS[options.selection].get("needs_tolerance")  # the programme decides, not the stop criteria
    red = reduce_lights(model.problem, e_x, selection=options.selection, distribution=options.distribution,
                        max_lights=None if by_lp else options.max_lights,
                        relative_error_threshold=None if by_lp else options.error_threshold,
                        require_positive=options.require_positive, tolerance=options.param("tolerance"),
                        uniformity=options.param("uniformity"),
                        coplanar_tol=options.param("coplanar_tolerance", 1e-3), curve_lights=curve_lights,
                        initial=initial, quick=curve_lights is not None, nnls_start=nnls_start,
                        progress=(lambda d, t: progress("reduction", 0.8 + 0.15 * d / max(t, 1)))
                        if progress is not None else None, cancel=cancel)
    if red.cancelled:
        raise Cancelled("solve cancelled")
    return red


def light_colour_of(problem, options) -> tuple:
    """(the problem's light colour mode, None for free colours; a note): the option's mode, or
    the one an automatic mode chooses for this problem (engine/colours/auto.py)."""
    mode, note = LIGHT_COLOURS[options.light_colour](options), None
    if hasattr(mode, "choose"):
        mode, note = mode.choose(problem)
    return (None if mode.free else mode), note


def _fit(problem, ids, e=None):
    """The best non-negative strengths (len(ids), 3) of the lights ``ids`` on T, of the problem's
    light colour (NNLS per channel for free colours; ``e``: their strengths now, whose colours a
    refit starts from), and their error (W/m^2)."""
    return fit_lights(problem, ids, e)


def _error(problem, ids, e):
    """Eq. 1 of the lights ``ids`` at strengths ``e`` (len(ids), 3), through T (W/m^2)."""
    T = problem.transfer
    return channel_error([t[:, ids] for t in T], e, problem.b_target)


def _least_squares_change(problem, ids, e):
    """(len(ids), 3): the least-norm change of the strengths ``e`` of the lights ``ids`` that
    minimises Eq. 1 again on T (per channel; a configuration with negatives, e.g. e_x, stays exact
    where it was)."""
    T, b = problem.transfer, problem.b_target
    return np.stack([np.linalg.lstsq(T[c][:, ids], b[:, c] - T[c][:, ids] @ e[:, c], rcond=None)[0]
                     for c in range(3)], axis=1)


def direct_stage(model: Model, red: ReductionResult, options: JobOptions, cancel=None) -> dict | None:
    """Stage 3a: the direct light of the curve's surface lights on every patch by the kernel
    (engine.kernel_transfer.lights_direct_correction; the ray-cast F gathers a small bright cell's
    light with a few per cent of noise, which the reflections carry to the targets: on the
    staircase the 3-light answer's prediction moved by 1.2 % from seed to seed): the non-negative
    configurations of at most ``max_lights`` (or the final one's) lights, the smaller first, up to
    DIRECT_LIGHTS lights; a light of DIRECT_SPREAD_PATCHES patches or more keeps F's gather
    (engine/cost.py: many rays make it). Their columns of T and the forward solves
    take it (InverseProblem.correct_direct); each configuration's strengths are re-fitted (NNLS per
    channel, the same lights) and its error follows. Returns what the report says (None: nothing)."""
    if model.mode != "inverse" or model.form_factors is None:
        return None
    problem, lights, patches = model.problem, model.lights, model.patches
    top = max(int(options.max_lights), red.final.n_lights)  # the rows above it are not the answer's
    order = sorted((i for i, pt in enumerate(red.curve) if pt.n_negative == 0 and pt.n_lights <= top),
                   key=lambda i: red.curve[i].n_lights)
    todo, spread = [], set()
    for i in order:
        for j in red.curve[i].lights:
            if int(j) in todo or int(j) in spread or lights.lamp(int(j)) is not None or len(todo) >= DIRECT_LIGHTS:
                continue
            if len(lights.members(int(j))) >= DIRECT_SPREAD_PATCHES:  # F's gather of it stays (cost.py)
                spread.add(int(j))
            else:
                todo.append(int(j))
    if not todo:
        return None if not spread else {"lights": 0, "spread_lights": len(spread), "seconds": 0.0}
    t0 = time.perf_counter()
    ff = model.form_factors
    skip = problem.targets if uses_kernel_pairs(options) else None
    dH = lights_direct_correction(patches, problem.F, todo, lights.members, getattr(ff, "send", None), skip,
                                  seed=options.seed, sampler=getattr(ff, "sampler", None), cancel=cancel)
    problem.correct_direct(todo, dH)
    norm = problem.target_norm or 1.0
    before = [float(pt.relative_error) for pt in red.curve]
    refit = SELECTIONS[options.selection].get("refit")  # a selection's own programme (least-power's LP)
    corrected, notes = set(todo), []
    for i, pt in enumerate(red.curve):
        ids = np.asarray(pt.lights, dtype=np.int64)
        if not corrected.intersection(ids.tolist()):
            continue
        e = np.asarray(pt.exitance, dtype=np.float64)
        if pt.n_negative:  # the inverse solution e_x (all the lights): the least change that fits
            # again; the selection's other configurations with negatives keep their strengths
            e = e + _least_squares_change(problem, ids, e) if len(ids) == problem.n_lights else e
        elif refit is not None:
            view = colour_problem(problem, problem.colour, ids, e)  # (the configuration's colours kept)
            e, note = refit(view or problem, ids, options.param("tolerance"), options.param("uniformity"))
            e = view.exitance_of(ids, e) if view is not None else e
            notes += [note] if i == red.final_index and note else []
            on = e.max(axis=1) > 0
            ids, e = ids[on], e[on]
        else:
            fit, _ = _fit(problem, ids, e)
            e = fit if np.all(fit.max(axis=1) > 0) else e
        error = _error(problem, ids, e)
        red.curve[i] = replace(pt, n_lights=len(ids), lights=ids, exitance=e, error=error,
                               relative_error=error / norm, n_negative=int((e < 0).any(axis=1).sum()))
    if notes:  # the selection's message of the final configuration, as it is now
        red.warnings = notes + [w for w in red.warnings if w not in red.notes]
        red.notes = notes
    carry_refined(problem, red, {}, every=True)  # the curve never rises
    red.certificate = None  # the certificate is of the T the configurations are now measured on
    return {"lights": len(todo), "spread_lights": len(spread), "seconds": time.perf_counter() - t0,
            "final_relative_error_before": before[red.final_index],
            "final_relative_error_after": float(red.final.relative_error)}


def _refining(progress, cancel, n_done, n_todo, n_lamps):
    """The cancel check refine_configuration makes before each lamp of each round, reporting the
    progress too: a configuration's refinement takes seconds, and the bar said "reduction 95 %"
    meanwhile (issue 36)."""
    calls = [0]

    def check():
        if progress is not None:
            within = min(1.0, calls[0] / max(1, LAMP_ROUNDS * n_lamps))
            progress("refining lamps", 0.95 + 0.03 * (n_done + within) / max(n_todo, 1))
        calls[0] += 1
        return cancel is not None and cancel()
    return check


def refine_stage(model: Model, red: ReductionResult, options: JobOptions, progress=None, cancel=None) -> dict:
    """Stage 3b: the placed lamps of the final configuration and of the curve's smaller ones refined
    (engine.lamp_refinement), the final one first, then from the largest down while its BUDGET
    lasts: each refined lamp becomes a new light of the problem (its kind, its column of T), the
    point's lights and strengths (NNLS per channel) and error follow. Returns what the report says of it (``None`` when nothing was refined).
    A selection with its own programme (``refit``: least power within a tolerance, and its uniformity goal)
    is not refined: the refinement lowers the error and refits by least squares, which broke the
    programme's band and goal (the gallery's strip: U0 0.563 reported against the 0.6 'met')."""
    if model.mode != "inverse" or not options.param("refine_lamps", False) or not offered_kinds(options) \
            or SELECTIONS[options.selection].get("refit") is not None:
        return None
    problem, lights, patches = model.problem, model.lights, model.patches
    todo = [i for i, pt in enumerate(red.curve)
            if (pt.n_lights <= red.final.n_lights or i == red.final_index) and pt.n_negative == 0
            and any(lights.lamp(j) is not None and lights.kind_of(j).writer == PLACED for j in pt.lights)]
    # the final configuration first, then the smaller ones from the largest, while the budget lasts
    todo.sort(key=lambda i: (i != red.final_index, -red.curve[i].n_lights))
    if not todo:
        return None
    t0 = time.perf_counter()
    sampler = getattr(model.form_factors, "sampler", None) or SceneSampler(patches)
    drop = float(options.lamp_drop if options.lamp_drop is not None else default_drop(patches))
    mount = Mount(patches, problem.candidate_mask, drop, sampler)
    inc = _incidence(model.faces, patches) if problem.lamp_excess is not None else None
    transport = Transport(problem, None if inc is None else
                          (lambda lamp: lamp_albedo_excess(lamp, patches.center, patches.normal, *inc)))
    step = float(patches.light_size or patches.max_patch_size)
    T = problem.transfer
    new_lamps, new_kinds, new_H, new_cols = [], [], [], [[], [], []]
    rows, evaluations = [], 0
    carried = {}  # the final configuration's refined lamps: candidate light -> its refined light
    for n_done, i in enumerate(todo):
        if cancel is not None and cancel():
            raise Cancelled("solve cancelled")
        if evaluations >= REFINE_BUDGET:
            break
        pt = red.curve[i]
        placed = {pos: lights.lamp(j) for pos, j in enumerate(pt.lights)
                  if lights.lamp(j) is not None and lights.kind_of(j).writer == PLACED}
        refined, cols, before, after, n_eval = refine_configuration(
            problem, placed, [T[c][:, pt.lights] for c in range(3)], transport, mount, step,
            seed=options.seed, budget=REFINE_BUDGET - evaluations, exitance=pt.exitance,
            cancel=_refining(progress, cancel, n_done, len(todo), len(placed)))
        evaluations += n_eval
        rows.append({"n_lights": pt.n_lights, "relative_error_before": before, "relative_error_after": after,
                     "lamps_refined": len(refined), "evaluations": n_eval})
        if refined:
            ids = np.array(pt.lights, dtype=np.int64)
            for r in refined:
                ids[r.index] = lights.n_lights + len(new_lamps)
                if i == red.final_index:
                    carried[int(pt.lights[r.index])] = int(ids[r.index])
                new_lamps.append(r.lamp)
                new_kinds.append(lights.kind_names[int(pt.lights[r.index])])
                new_H.append(r.irradiance)
                for c in range(3):
                    new_cols[c].append(cols[c][:, r.index])
            e, error = fit_columns(problem, cols, pt.exitance)  # (of the light colour)
            order = np.argsort(ids, kind="stable")
            on = e[order].max(axis=1) > 0
            red.curve[i] = replace(pt, n_lights=int(on.sum()), lights=ids[order][on], exitance=e[order][on],
                                   error=error, relative_error=error / (problem.target_norm or 1.0))
        if progress is not None:
            progress("refining lamps", 0.95 + 0.03 * (n_done + 1) / len(todo))
    offered = lights.count_by_kind()
    if new_lamps:
        area = np.array([lamp.kind.area(lamp) for lamp in new_lamps])
        model.lights = append_lamps(lights, lights.patches, patches.n_patches, new_lamps, new_kinds,
                                    np.stack(new_H, axis=1), area)
        H_new = np.stack(new_H, axis=1)
        problem.add_lights(model.lights, [np.stack(new_cols[c], axis=1) for c in range(3)],
                           lights_excess(model.faces, patches, None, new_lamps, H_new))
        carry_refined(problem, red, carried)
    return {"points": rows, "offered": offered, "lamps_refined": len(new_lamps), "evaluations": evaluations,
            "seconds": time.perf_counter() - t0}


def carry_refined(problem, red: ReductionResult, carried: dict, every=False) -> None:
    """The configurations with more lights than the final one hold its lamps as offered (they are
    not refined): each takes the final one's refined lamps in their place (``carried``: candidate
    light -> refined light), or else the configuration before it and one of its own lights, its
    strengths re-fitted (NNLS per channel), when that lowers its error, or else the configuration
    before it (as the selections' own curves do) -- so that the curve never rises after a refined
    configuration (NNLS on more lights is never worse). ``every``: all the
    configurations, not only those above the final one (after direct_stage re-fitted them all)."""
    norm = problem.target_norm or 1.0

    def fit(ids):
        ids = np.unique(np.asarray(ids, dtype=np.int64))
        e, error = _fit(problem, ids)
        on = e.max(axis=1) > 0
        return error, ids[on], e[on]

    for i, pt in enumerate(red.curve):
        if i == 0 or (pt.n_lights <= red.final.n_lights and not every) or pt.n_negative:
            continue
        prev = red.curve[i - 1]
        if every and not carried and pt.error <= prev.error:
            continue
        tries = [[carried.get(int(j), int(j)) for j in pt.lights]] if any(int(j) in carried for j in pt.lights) else []
        if prev.n_negative == 0 and prev.n_lights == pt.n_lights - 1:
            had = set(prev.lights.tolist())  # (a refined lamp's candidate is not added beside it)
            tries += [list(prev.lights) + [int(j)] for j in pt.lights
                      if int(j) not in had and carried.get(int(j)) not in had]
        best = None
        for ids in tries:
            error, on, e = fit(ids)
            if len(on) == pt.n_lights and error < (pt.error if best is None else best[0]):
                best = (error, on, e)
        if best is not None:
            red.curve[i] = replace(pt, lights=best[1], exitance=best[2], error=best[0], relative_error=best[0] / norm)
        elif pt.error > prev.error and prev.n_negative == 0 and prev.n_lights < pt.n_lights:
            # no such fit keeps all its lights on: the configuration before it (fewer lights do)
            red.curve[i] = replace(pt, n_lights=prev.n_lights, lights=prev.lights.copy(), exitance=prev.exitance.copy(),
                                   error=prev.error, relative_error=prev.relative_error)


#: the certificate (lower bounds) covers the curve up to this many lights; above, the NNLS bound
CERTIFICATE_LIGHTS = 32


def certificate(problem: InverseProblem, red: ReductionResult):
    """Lower bounds on the best error any non-negative configuration of at most k of the candidate
    lights can reach (engine.best_lights.lower_bounds: exact by exhaustive search where small
    enough, else the all-lights NNLS bound; ``bounds.at(k)``, W/m^2)."""
    k_top = int(min(problem.n_lights, max(min(CERTIFICATE_LIGHTS, max(p.n_lights for p in red.curve)), 1)))
    bounds = red.certificate  # the greedy-swap selection computed it already
    if bounds is None or len(bounds.bound) < k_top:
        bounds = lower_bounds_of(problem, k_top)
    return bounds


def certificate_notes(problem, bounds, final, refined=None) -> list:
    """How good the final configuration is against the certificate (of the candidate lights;
    ``refined``: refine_stage's account, whose lamps may take the error below it)."""
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    k = final.n_lights
    exact = 1 <= k <= len(bounds.exact) and bool(bounds.exact[k - 1])
    lb = bounds.at(k) / norm
    if final.n_negative or final.relative_error <= 1e-9:
        return []
    if refined and refined["lamps_refined"] and final.relative_error < lb * (1 - 1e-6):
        return [f"{k} light(s): relative error {final.relative_error:.3g}, below the {lb:.3g} that no {k} of the "
                f"candidate lights can go below{' (exact optimum)' if exact else ''}: the chosen lamps' aim, cone, "
                "size and position were refined"]
    if exact and final.relative_error <= lb * (1 + 1e-6) + 1e-12:
        return [f"{k} light(s): the best possible with {k} non-negative lights (exhaustive search), "
                f"relative error {final.relative_error:.3g}"]
    return [f"{k} light(s): relative error {final.relative_error:.3g}; no {k} non-negative lights can go below "
            f"{lb:.3g}{' (exact optimum)' if exact else ''}, and no number of them below {bounds.nnls / norm:.3g}"]


#: a target object whose fixed light alone exceeds the painted radiosity by more than this is named
ALREADY_BRIGHTER = 0.05


def fixed_light(model: Model) -> tuple:
    """The scene's own light that the solve keeps: per lamp, the World and per emissive object
    (inverse mode; direct mode: the World) its share of the targets' radiosity (painted; direct
    mode: the scene's), area-weighted, channels summed, and (inverse mode) a warning for each
    target object that this light alone already makes brighter than painted."""
    problem, patches, faces = model.problem, model.patches, model.faces
    tg = problem.targets
    w = problem.area[tg]
    painted = float(np.sum(w[:, None] * (problem.b_target + problem.background_radiosity[tg])))
    zero = np.zeros((patches.n_patches, 3))

    def share(B):
        return float(np.sum(w[:, None] * B[tg]) / painted) if painted > 0 else None

    rows = []
    for i, (name, kind, power) in enumerate(model.lamp_names or []):
        excess = scene_light_excess(faces, patches, model.lamp_irradiance, i) if model.mode == "inverse" else None
        B = problem.forward_radiosity(zero, model.lamp_irradiance[:, i], excess)
        rows.append({"name": name, "kind": kind, "power": power, "share": share(B)})
    emitting = np.any(model.background > 0, axis=1)
    for oi in np.unique(patches.object[emitting]):
        e = np.where((patches.object == oi)[:, None], model.background, 0.0)
        rows.append({"name": faces.object_names[oi], "kind": "emission", "power": None,
                     "share": share(problem.forward_radiosity(e))})
    notes = []
    B_bg = problem.background_radiosity
    for oi in np.unique(patches.object[tg]) if model.mode == "inverse" else ():
        sel = tg[patches.object[tg] == oi]
        want = float(np.sum(problem.area[sel, None] * patches.target_radiosity[sel]))
        got = float(np.sum(problem.area[sel, None] * B_bg[sel]))
        if want > 0 and got > want * (1 + ALREADY_BRIGHTER):
            notes.append(f"{faces.object_names[oi]}: its targets are already {100 * (got / want - 1):.0f} % brighter "
                         "than painted without any new light (the scene's own lamps, World and emitters)")
    return rows, notes


def scene_light(faces: FaceSet, patches: PatchSet, F, seed=0) -> tuple:
    """The light the scene already has, besides its emissive materials: (H (P, n, 3) W/m^2, the
    direct irradiance of each lamp and of the World (engine.lamps); [(name, kind, power)] per
    column). Shadow and sky rays are cast on the form factors' sampler (one Embree scene)."""
    sampler = getattr(F, "sampler", None)
    cols = [lamp_irradiance(patches, faces.lamps, sampler=sampler, seed=seed)]
    names = [(lamp.name, lamp.kind.blender_type.lower(), lamp.power) for lamp in faces.lamps]
    if faces.world_radiance is not None:
        M = getattr(F, "matrix", F)
        rows = np.asarray(M.sum(axis=1), dtype=np.float64).reshape(-1)
        cols.append(world_irradiance(patches, faces.world_radiance, sampler=sampler, seed=seed,
                                     sky_share=1.0 - rows)[:, None, :])
        names.append((faces.world_name or "World", "world", None))
    return np.concatenate(cols, axis=1), names


def has_scene_light(faces: FaceSet) -> bool:
    """Whether the scene has lamps or a World that lights it (engine.lamps)."""
    return bool(faces.lamps) or faces.world_radiance is not None


def first_bounce(faces: FaceSet, patches: PatchSet, F, sources):
    """engine.incidence's D per channel for the light leaving ``sources`` (a patch mask), from the
    faces' materials; None when the FaceSet has none or none depends on the incidence."""
    inc = _incidence(faces, patches)
    return None if inc is None else first_bounce_matrices(F, patches.center, patches.normal, *inc,
                                                          np.flatnonzero(sources))


def _incidence(faces: FaceSet, patches: PatchSet):
    """(per-patch material, incidence tables) of the faces' materials, None without any."""
    if faces.face_material is None or not faces.material_lobes:
        return None
    return np.asarray(faces.face_material, dtype=np.int64)[patches.face], incidence_tables(faces.material_lobes)


def lights_excess(faces: FaceSet, patches: PatchSet, lights, lamps=None, H=None):
    """engine.incidence.lamp_excess of the lights of irradiance kinds (their Lamp in
    ``lights.lamps``; or of ``lamps`` with irradiance ``H``): their first reflection with the albedo
    of its incidence; None without lamps or without a direction-dependent material."""
    inc = _incidence(faces, patches)
    if lamps is None:
        if lights is None or lights.irradiance is None or lights.lamps is None:
            return None
        lamps, H = lights.lamps, lights.irradiance
    return None if inc is None else lamp_excess(lamps, H, patches.center, patches.normal, *inc)


def scene_light_excess(faces: FaceSet, patches: PatchSet, H, only=None):
    """(P, 3) W/m^2: the scene's lamps' first reflection beyond rho H (``H`` jobs.scene_light's, the
    lamps' columns first; the World's light, from every direction, has none), of lamp ``only``
    alone when given; None without it."""
    inc = _incidence(faces, patches)
    which = range(len(faces.lamps)) if only is None else [only] if only < len(faces.lamps) else []
    if inc is None or not which:
        return None
    return sum(lamp_albedo_excess(faces.lamps[i], patches.center, patches.normal, *inc) * H[:, i] for i in which)


def assemble_curve(model: Model, red: ReductionResult, polygon_counts=None) -> Curve:
    """Stage 4: the kept configurations and the radiosity each gives, B = B_background + A^-1 e
    (one LU solve for all the points at once), and the patches -> polygons map."""
    t0 = time.perf_counter()
    problem, patches = model.problem, model.patches
    C = problem.candidates
    keep = stored_points([p.n_lights for p in red.curve], red.final_index)
    n_pts, P = len(keep), patches.n_patches
    E = np.zeros((n_pts, problem.n_lights, 3))
    for k, ci in enumerate(keep):
        pt = red.curve[ci]
        E[k, pt.lights] = pt.exitance
    B = np.empty((n_pts, P, 3))
    T_all = problem.prepared_rows_transfer()
    if T_all is not None:  # a retargeted problem (Live): every light's radiosity on every patch, kept
        on = np.flatnonzero(E.any(axis=(0, 2)))  # the curve's lights (a few of the columns)
        for c in range(3):
            B[:, :, c] = (T_all[c][:, on] @ np.ascontiguousarray(E[:, on, c].T)
                          + problem.background_radiosity[:, c:c + 1]).T
    else:
        H = problem.lights.irradiance
        if problem.direct_correction is not None:  # the curve's lights' direct light by the kernel (direct_stage)
            H = problem.direct_correction if H is None else (sp.csc_matrix(H) + problem.direct_correction).tocsc()
        facs = problem.factors()
        E_patch = np.zeros((P, n_pts, 3))
        for k in range(n_pts):  # the lights' exitance on their patches
            E_patch[C, k] = problem.light_basis @ E[k]
        S = problem.source(E_patch)
        for c in range(3):  # every light's source (engine.lights), transported
            src = S[:, :, c]
            if H is not None:
                src = src + patches.reflectance[:, c:c + 1] * np.asarray(H @ E[:, :, c].T)
            if problem.lamp_excess is not None:
                src = src + np.asarray(problem.lamp_excess[c] @ E[:, :, c].T)
            B[:, :, c] = (facs[c].solve(src) + problem.background_radiosity[:, c:c + 1]).T
    if not np.all(np.isfinite(B)):
        raise SceneError("the solve produced NaN or infinite values")
    pmap = model.polygons if model.polygons is not None else PolygonMap(model.faces, patches, polygon_counts)
    model.polygons = pmap
    cells = (pmap.pairs[:, C] > 0).astype(np.float64)  # polygons x candidate patches
    light_polygons = (cells @ problem.light_basis).T.tocsr()
    light_polygons.data[:] = 1.0
    return Curve(keep, int(np.searchsorted(keep, red.final_index)), E, B, pmap, light_polygons,
                 time.perf_counter() - t0)


def run_solve(faces: FaceSet, options: JobOptions | None = None, polygon_counts=None,
              default_max_patch_size: float | None = None, progress=None, cancel=None, mode="inverse",
              patches: PatchSet | None = None, notes: dict | None = None, estimate=None):
    """Inverse lighting ("solve") or direct-lighting reduction ("reduce") of ``faces``:
    build_model -> solve_stage -> reduce_stage -> certificate -> assemble_curve -> report.solve_report.

    inverse: targets are the painted faces; candidates as ``engine.lights.candidate_mask``;
    the scene's own emitters are fixed background light (subtracted from the targets). The
    inverse system is solved (``options.solver``), then reduced (``options.selection`` x
    ``options.distribution``) over the whole curve; the stop criteria pick the final
    configuration. direct ("reduce"): the candidates are the scene's emitters and every other
    patch is a target at the radiosity they give it (the paper's direct-lighting mode).
    ``progress(stage, fraction)`` with fraction in [0, 1] over the whole job; ``cancel()``
    returning True raises Cancelled. ``patches``: the meshed faces when the caller already
    has them (the operator meshes first to estimate the cost). ``notes``: export's notes, repeated
    in the errors they explain (check_solvable). ``estimate``: build_model's. Returns a SolveOutcome.
    """
    options = (options or JobOptions()).validate()
    check_solvable(faces, mode, notes)
    if mode == "inverse":
        check_light_kinds(options)
    try:
        return _run_solve(faces, options, polygon_counts, default_max_patch_size, progress, cancel, mode, patches,
                          estimate)
    except InverseError as exc:
        rays = options.rays_per_patch
        if "reaches any target" in str(exc) and rays is not None and rays < FEW_RAYS:
            raise InverseError(f"no ray from a candidate light reached a target with {rays} ray(s) per patch: "
                               f"cast more rays per patch (at least {FEW_RAYS}; --rays-per-patch, or 0 = automatic) "
                               "before concluding the targets are occluded") from None
        raise


#: below this many rays per patch, "no light reaches the targets" may be sampling, not geometry
FEW_RAYS = 256


def _run_solve(faces, options, polygon_counts, default_max_patch_size, progress, cancel, mode, patches, estimate):
    t0 = time.perf_counter()
    model = build_model(faces, options, mode, default_max_patch_size, progress, cancel, patches, estimate)
    with transport_named(model.patches, faces):
        return solve_model(model, options, polygon_counts, progress, cancel, t0)


def unmet_note(model: Model) -> list:
    """The painted targets no candidate light reaches (InverseProblem.unmet), by object, and the
    candidate lights left out as implausible (InverseProblem.implausible)."""
    out = []
    left = getattr(model.problem, "implausible", None)
    if left is not None and left.any():
        out.append(f"{int(left.sum())} candidate light(s) left out: each would reach the painted targets with "
                   f"less than {MIN_UTILISATION:.1%} of its light (others reach them with more than ten times that), "
                   "so lighting them would take a power far beyond what they receive")
    bad = getattr(model.problem, "unmet", None)
    if bad is None or not len(bad):
        return out
    obj, count = np.unique(model.patches.object[bad], return_counts=True)
    order = np.argsort(-count, kind="stable")
    names = ", ".join(f"{count[i]} of {model.faces.object_names[obj[i]]!r}" for i in order[:5])
    return out + [f"{len(bad)} target patch(es) cannot be met, no candidate light reaches them ({names}"
            f"{', ...' if len(obj) > 5 else ''}): no allowed surface or candidate lamp sends them light"]


@contextmanager
def transport_named(patches: PatchSet, faces: FaceSet):
    """A DivergentTransport raised inside names the objects of its patches."""
    try:
        yield
    except DivergentTransport as exc:
        if exc.names:
            raise
        raise exc.named(faces.object_names, patches.object) from None


#: a live re-solve's curve covers the Max Lights and this many more (the chart's neighbourhood)
LIVE_CURVE_EXTRA = 4
LIVE_NOTE = ("live answer from the prepared transport ({why}): Solve & Reduce gives the full solve")


def retarget_model(model: Model, faces: FaceSet, patches: PatchSet) -> Model:
    """A solved model (inverse mode) with the paint of ``faces`` on its own patches (``patches``:
    the model's mesh, each patch its face's target): the same lights (the lamps offered and
    refined for the earlier targets among them), form factors, solvers and fixed light; the
    problem retargeted (InverseProblem.retarget: rows of the transfer to every patch)."""
    t0 = time.perf_counter()
    problem = model.problem.retarget(scene_targets(faces, patches))
    return replace(model, faces=faces, patches=patches, problem=problem, warnings=list(model.warnings),
                   seconds={"meshing": 0.0, "form_factors": 0.0, "lamps": 0.0, "problem": time.perf_counter() - t0},
                   refinement={"passes": 0, "target_change": []}, lamp_refinement=None, direct=None)


def move_scene_light(model: Model, faces: FaceSet, seed=0) -> Model:
    """A solved model (inverse mode) whose scene's lamps or World changed (``faces``: the same
    scene with its new lamps): their direct light cast again on the model's patches (scene_light,
    on its Embree scene) and the fixed light's radiosity through the model's factorisation
    (InverseProblem.with_background); the lights, form factors and transfer kept."""
    patches, F = model.patches, model.form_factors
    lamp_H, lamp_names = scene_light(faces, patches, F, seed)  # (as build_model casts it)
    problem = model.problem.with_background(model.background, lamp_H.sum(axis=1),
                                            scene_light_excess(faces, patches, lamp_H))
    return replace(model, faces=faces, problem=problem, lamp_irradiance=lamp_H, lamp_names=lamp_names)


def solve_model(model: Model, options: JobOptions, polygon_counts=None, progress=None, cancel=None, t0=None,
                live=False, initial=None, nnls_start=None):
    """Stages 2-5 on a built model (build_model's): the inverse solve, the reduction, the direct
    light, the certificate, the lamp refinement, the curve and the report; a SolveOutcome.
    ``t0``: when the job started (perf_counter), for the report's total. ``live``: a stroke's
    re-solve on a retargeted model (retarget_model): no inverse solution e_x when the selection
    does not read it (Best k Lights, NNLS greedy, least power), the curve to Max Lights + LIVE_CURVE_EXTRA,
    without the kernel's direct light of lights the model has not corrected yet and without the
    lamp refinement (the model's lamps, refined for the earlier targets, are candidates), no per-face
    block in its report (the scene holds them), the
    selection's quick search from the configurations ``initial`` {n_lights: lights}, its
    certificate's all-lights NNLS from ``nnls_start`` (an earlier stroke's, the same optimum)."""
    mode = model.mode
    t0 = time.perf_counter() if t0 is None else t0
    t1 = time.perf_counter()
    if live and not SELECTIONS[options.selection].get("distributes", True):  # (the selection never reads e_x)
        e_x, inv = np.zeros((model.problem.n_lights, 3)), None
    else:
        e_x, inv = solve_stage(model, options)
    t_inverse = time.perf_counter() - t1 + model.seconds["problem"]
    if progress is not None:
        progress("inverse", 0.8)
    if cancel is not None and cancel():
        raise Cancelled("solve cancelled")
    t2 = time.perf_counter()
    red = reduce_stage(model, e_x, options, progress, cancel,
                       curve_lights=int(options.max_lights) + LIVE_CURVE_EXTRA if live else None,
                       initial=initial if live else None, nnls_start=nnls_start if live else None)
    t_direct = time.perf_counter()
    model.direct = None if live else direct_stage(model, red, options, cancel)
    t_direct = time.perf_counter() - t_direct
    bounds = point_bounds = positive = None
    if mode == "inverse":  # of the candidate lights (the refined lamps are found after, outside them)
        bounds = red.certificate = certificate(model.problem, red)  # (of the T the curve is measured on)
        positive = positive_bound(model.problem, inv, red.final, bounds)
    t_refine = time.perf_counter()
    model.lamp_refinement = None if live else refine_stage(model, red, options, progress, cancel)
    t_refine = time.perf_counter() - t_refine
    t_reduce = time.perf_counter() - t2 - t_refine - t_direct
    warnings = list(model.warnings)
    if mode == "inverse":
        point_bounds = np.array([bounds.at(p.n_lights) for p in red.curve])
        warnings.extend(_positivity_notes(positive, red.final, model.problem.colour, red.selection))
        warnings.extend(certificate_notes(model.problem, bounds, red.final, refined=model.lamp_refinement))
    fixed = None
    if mode == "inverse" or model.lamp_names:
        fixed, notes = fixed_light(model)
        warnings.extend(notes)
    warnings.extend(w for w in model.problem.warnings + unmet_note(model) + (inv.warnings if inv else [])
                    + red.warnings if w not in warnings)
    curve = assemble_curve(model, red, polygon_counts)
    timings = {"export": 0.0, "meshing": model.seconds["meshing"], "form_factors": model.seconds["form_factors"],
               "lamps": model.seconds["lamps"], "inverse": t_inverse, "reduction": t_reduce, "direct_light": t_direct,
               "lamp_refinement": t_refine,
               "curve": curve.seconds,
               "solve": t_inverse + t_reduce + t_direct + t_refine, "apply": 0.0, "total": time.perf_counter() - t0}
    report = solve_report(model, options, inv, red, curve, warnings, timings, bounds, point_bounds, fixed,
                          per_face=not live)
    rows = [{"n_lights": red.curve[i].n_lights, "error": red.curve[i].error,
             "relative_error": red.curve[i].relative_error, "n_negative": red.curve[i].n_negative,
             "curve_index": int(i)} for i in curve.keep]
    stored = StoredResult.from_solve(model, red, curve, report)
    final = curve.exitance[curve.final_row]
    return SolveOutcome(json_safe(report), rows, curve.final_row, warnings, stored, model.faces, model.patches,
                        model.problem, inv, red, scene_light_at(model, final), placed_light_at(model, final),
                        model)


def placed_light_at(model: Model, strength) -> list:
    """[(engine.lamps.Lamp, (P, 3) W/m^2)]: the direct light of each placed lamp (engine/lights/
    spot.py, area.py, point.py) that is on in the configuration ``strength`` (n_lights, 3)."""
    lights = model.lights
    if lights.irradiance is None:
        return []
    H = sp.csc_matrix(lights.irradiance)
    out = []
    for j in np.flatnonzero(np.any(np.asarray(strength) > 0, axis=1)):
        if lights.kind_of(j).writer == "placed":
            out.append((lights.lamp(j), H[:, j].toarray() * np.asarray(strength, dtype=np.float64)[j][None, :]))
    return out


#: above this relative error, the final configuration is compared with the best positive one
POSITIVE_GAP = 0.1


def positive_bound(problem, inv, final, bounds=None):
    """NNLS on T when ``final`` misses the targets by more than POSITIVE_GAP (the best any set of
    the candidate lights, non-negative, can do: an InverseResult), else None. ``bounds``: the
    certificate of the same T, whose all-lights NNLS it is when it has it."""
    if not final.relative_error > POSITIVE_GAP:
        return None
    if inv is not None and inv.solver == "nnls":
        return inv
    e = getattr(bounds, "nnls_exitance", None)
    if e is None or e.shape != (problem.n_lights, 3):
        return solve_inverse(problem, "nnls")
    err = problem.error(e)
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    return InverseResult(solver="nnls", exitance=e, rank=int((e.max(axis=1) > 0).sum()), error=err,
                         relative_error=err / norm, n_negative=0, seconds=0.0)


def colour_text(colour) -> str:
    """A light colour mode in words ("white", "blackbody 2700-6500 K")."""
    rec = colour.summary()
    return rec["mode"] + (f" {rec['range_K'][0]:.0f}-{rec['range_K'][1]:.0f} K" if "range_K" in rec else "")


#: the selection the positivity note advises (the best configurations the project finds)
BEST_SELECTION = "greedy-swap"


def _positivity_notes(bound, final, colour=None, selection=None):
    """Say so when the final configuration misses the targets by much: whether no positive
    lighting can do better (targets brighter or darker than light can make them) or whether
    more lights / another selection would (never the selection already used). ``bound``:
    positive_bound's."""
    if bound is None or not final.relative_error > POSITIVE_GAP:
        return []
    n_pos = int((bound.exitance.max(axis=1) > 0).sum())
    if bound.relative_error > POSITIVE_GAP:
        best = ("the best any non-negative set of the candidate lights can do is" if colour is None else
                f"no non-negative set of the candidate lights, {colour_text(colour)}, goes below")
        return [f"no positive lighting meets these targets: {best} a relative error of {bound.relative_error:.3g} "
                f"(NNLS, {n_pos} lights); the final configuration's is {final.relative_error:.3g}"]
    other = "" if selection == BEST_SELECTION else f", or use the {BEST_SELECTION} selection (Best k Lights)"
    return [f"the final configuration misses the targets by {final.relative_error:.3g} (relative error) with "
            f"{final.n_lights} light(s); positive lights can reach {bound.relative_error:.3g} with {n_pos}: allow "
            f"more lights{other}"]
