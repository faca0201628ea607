"""Relight jobs: FaceSet -> engine -> report dict. Shared by the CLI and the add-on operators.

No bpy here: export.py exports the scene, results.py writes results back. This module composes
the stages (pipeline.checks, pipeline.meshing, pipeline.model, pipeline.stages) and nothing else;
each job is its own composition:

- ``run_radiosity``: the forward job ("radiosity" command): mesh the faces into patches, ray-cast
  form factors, solve B = e + rho F B for the scene's own emitters and lamps, and report the
  per-polygon mean radiosity (W/m^2) of every exported object. A scene without emitters is not an
  error: every radiosity is 0 and the report carries a warning (no form factors are computed);
- ``run_solve`` (``solve_model``): inverse lighting of the painted targets: build_inverse_model ->
  solve_stage -> reduce_stage -> direct_stage -> certificate -> refine_stage -> assemble_curve ->
  report.solve_report;
- ``run_reduce`` (``reduce_model``): the direct-lighting mode, the scene's emitters reduced:
  build_direct_model -> reduce_stage -> assemble_curve -> report.solve_report;
- ``solve_stroke``: a Live stroke's re-solve of a retargeted model (pipeline.model.retarget_model):
  reduce_stage's quick search -> certificate -> assemble_curve -> report.solve_report.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from ..engine.bounds import certificate, positive_bound
from ..engine.cost import check_memory
from ..engine.first_reflection import first_bounce
from ..engine.inverse import InverseError
from ..engine.options import JobOptions, check_light_kinds
from ..engine.radiosity import solve_radiosity
from ..engine.registry import ESTIMATORS, SELECTIONS
from ..engine.sampling import Cancelled, check_cancel
from ..engine.scene import FaceSet, PatchSet, SceneError, face_mean
from ..engine.scene_light import has_scene_light, placed_light_at, scene_light, scene_light_at, scene_light_excess
from . import notes as texts
from .checks import check_reducible, check_solvable
from .meshing import mesh_for_job, radiosity_cost
from .model import Model, build_direct_model, build_inverse_model, transport_named
from .polygons import PolygonMap
from .report import json_safe, radiosity_report, solve_report
from .stages import assemble_curve, direct_stage, fixed_light, reduce_stage, refine_stage, solve_stage
from .stored import StoredResult

__all__ = ["Cancelled", "RadiosityResult", "SolveOutcome", "run_radiosity", "run_solve", "run_reduce",
           "solve_model", "reduce_model", "solve_stroke", "PolygonMap", "JobOptions"]

#: below this many rays per patch, "no light reaches the targets" may be sampling, not geometry
FEW_RAYS = 256
#: a live re-solve's curve covers the Max Lights and this many more (the chart's neighbourhood; the
#: later answers bring the whole curve). The quick search's swaps grow with k: at 4 more the living
#: room's strokes took 65-128 ms, at 2 46-95 ms, the same final configurations to the bit
#: (docs/benchmarks.md, "Live's quick answer: its curve's neighbourhood")
LIVE_CURVE_EXTRA = 2


@dataclass
class RadiosityResult:
    patches: PatchSet
    patch_radiosity: np.ndarray  # (P, 3) W/m^2
    face_radiosity: np.ndarray  # (F, 3) W/m^2, per FaceSet face
    polygon_radiosity: dict  # object name -> (n_polygons, 3) W/m^2, base-mesh polygon order
    polygon_area: dict  # object name -> (n_polygons,) m^2 (world space; 0 for unreported polygons)
    form_factors: object = None
    scene_light: np.ndarray = None  # (P, n, 3) W/m^2: each lamp's and the World's direct light (scene_light)


def _forward_radiosity(faces: FaceSet, patches: PatchSet, options: JobOptions, progress, cancel) -> tuple:
    """(F, B (P, 3) W/m^2, the solve's info, H: the scene's light) of the scene's emitters and lamps."""
    ff_progress = (lambda f: progress("form_factors", f)) if progress is not None else None
    F = ESTIMATORS[options.estimator](patches, options, progress=ff_progress, cancel=cancel)
    check_cancel(cancel, "radiosity cancelled")
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
    return F, B, info, H, time.perf_counter() - t1


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
    check_cancel(cancel, "radiosity cancelled")
    warnings = list(faces.warnings) + [w for w in cost["warnings"] if w not in faces.warnings]
    F = H = None
    t_ff = t_solve = 0.0
    info = {}
    if not np.any(patches.exitance > 0) and not has_scene_light(faces):
        warnings.append(texts.NO_EMITTER_WARNING)
        B = np.zeros((patches.n_patches, 3))
    else:
        F, B, info, H, t_solve = _forward_radiosity(faces, patches, options, progress, cancel)
        t_ff = F.seconds
        warnings.extend(w for w in info.get("warnings", []) if w not in warnings)
        if not info.get("converged", True):
            warnings.append(texts.not_converged_note(info.get('message', '')))
    if not np.all(np.isfinite(B)):
        raise SceneError("the radiosity solve produced NaN or infinite values")
    if progress is not None:
        progress("solve", 1.0)
    shown = B  # an emitter's face shows its exitance over its whole area, as a bake does
    if getattr(F, "emission_share", None) is not None:
        shown = B + (1.0 - F.emission_share)[:, None] * patches.exitance
    pmap = PolygonMap(faces, patches, polygon_counts)
    poly, areas = pmap.split(pmap.mean(shown)), pmap.split(pmap.area)
    timings = {"export": 0.0, "meshing": t_mesh, "form_factors": t_ff, "solve": t_solve, "apply": 0.0,
               "total": time.perf_counter() - t0}
    report = radiosity_report(faces, patches, options, F, info, poly, cost, warnings, timings)
    return report, RadiosityResult(patches, B, face_mean(patches, shown), poly, areas, F, H)


# ---------------------------------------------------------------------------- solve, reduce, a stroke

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


@contextmanager
def _few_rays_named(options: JobOptions):
    """An InverseError saying no light reaches a target, with fewer than FEW_RAYS rays per patch,
    says to cast more rays before concluding the targets are occluded."""
    try:
        yield
    except InverseError as exc:
        rays = options.rays_per_patch
        if "reaches any target" in str(exc) and rays is not None and rays < FEW_RAYS:
            raise InverseError(f"no ray from a candidate light reached a target with {rays} ray(s) per patch: "
                               f"cast more rays per patch (at least {FEW_RAYS}; --rays-per-patch, or 0 = automatic) "
                               "before concluding the targets are occluded") from None
        raise


def run_solve(faces: FaceSet, options: JobOptions | None = None, polygon_counts=None,
              default_max_patch_size: float | None = None, progress=None, cancel=None,
              patches: PatchSet | None = None, notes: dict | None = None, estimate=None, offer=None) -> SolveOutcome:
    """Inverse lighting ("solve") of ``faces``: targets are the painted faces; candidates as
    ``engine.lights.candidate_mask``; the scene's own emitters, lamps and World are fixed background
    light (subtracted from the targets). The inverse system is solved (``options.solver``), then
    reduced (``options.selection`` x ``options.distribution``) over the whole curve; the stop
    criteria pick the final configuration. ``progress(stage, fraction)`` with fraction in [0, 1]
    over the whole job; ``cancel()`` returning True raises Cancelled. ``patches``: the meshed faces
    when the caller already has them (the operator meshes first to estimate the cost). ``notes``:
    export's notes, repeated in the errors they explain (checks.check_solvable). ``estimate``:
    and ``offer``: build_inverse_model's. Returns a SolveOutcome."""
    options = (options or JobOptions()).validate()
    check_solvable(faces, notes)
    check_light_kinds(options)
    with _few_rays_named(options):
        t0 = time.perf_counter()
        model = build_inverse_model(faces, options, default_max_patch_size, progress, cancel, patches, estimate,
                                    offer)
        with transport_named(model.patches, faces):
            return solve_model(model, options, polygon_counts, progress, cancel, t0)


def run_reduce(faces: FaceSet, options: JobOptions | None = None, polygon_counts=None,
               default_max_patch_size: float | None = None, progress=None, cancel=None,
               patches: PatchSet | None = None, notes: dict | None = None) -> SolveOutcome:
    """The direct-lighting reduction ("reduce") of ``faces``: the candidates are the scene's
    emitters and lamps, and every other patch is a target at the radiosity they give it (the
    paper's direct-lighting mode); the arguments as run_solve's. Returns a SolveOutcome."""
    options = (options or JobOptions()).validate()
    check_reducible(faces, notes)
    with _few_rays_named(options):
        t0 = time.perf_counter()
        model = build_direct_model(faces, options, default_max_patch_size, progress, cancel, patches)
        with transport_named(model.patches, faces):
            return reduce_model(model, options, polygon_counts, progress, cancel, t0)


def _inverse_done(progress, cancel) -> None:
    if progress is not None:
        progress("inverse", 0.8)
    check_cancel(cancel)


def _listening(model: Model, cancel) -> None:
    """The model's problem hears this job's ``cancel`` (its factorisations and inverse solve look
    at it): a model retargeted for a Live stroke kept the cancel of the solve it was prepared by,
    which a later job never sets (its inverse solve could not be cancelled)."""
    if cancel is not None:
        model.problem.cancel = cancel


def solve_model(model: Model, options: JobOptions, polygon_counts=None, progress=None, cancel=None,
                t0=None) -> SolveOutcome:
    """Stages 2-5 of a solve on a built model (build_inverse_model's): the inverse solve, the
    reduction, the direct light, the certificate, the lamp refinement, the curve and the report.
    ``t0``: when the job started (perf_counter), for the report's total."""
    t0 = time.perf_counter() if t0 is None else t0
    _listening(model, cancel)
    t1 = time.perf_counter()
    e_x, inv = solve_stage(model, options)
    seconds = {"inverse": time.perf_counter() - t1 + model.seconds["problem"]}
    _inverse_done(progress, cancel)
    t2 = time.perf_counter()
    red = reduce_stage(model, e_x, options, progress, cancel)
    t3 = time.perf_counter()
    model, red = direct_stage(model, red, options, cancel)
    seconds["direct_light"] = time.perf_counter() - t3
    # the certificate of the candidate lights (the refined lamps are found after, outside them),
    # of the T the curve is measured on
    bounds = certificate(model.problem, red)
    red = replace(red, certificate=bounds)
    positive = positive_bound(model.problem, inv, red.final, bounds)
    t4 = time.perf_counter()
    model, red = refine_stage(model, red, options, progress, cancel)
    seconds["lamp_refinement"] = time.perf_counter() - t4
    seconds["reduction"] = time.perf_counter() - t2 - seconds["lamp_refinement"] - seconds["direct_light"]
    return _inverse_outcome(model, options, inv, red, bounds, positive, polygon_counts, seconds, t0, per_face=True)


def solve_stroke(model: Model, options: JobOptions, polygon_counts=None, progress=None, cancel=None, t0=None,
                 initial=None, nnls_start=None) -> SolveOutcome:
    """A Live stroke's re-solve of a retargeted model (pipeline.model.retarget_model): no inverse
    solution e_x when the selection does not read it (Best k Lights, NNLS greedy, least power),
    the curve to Max Lights + LIVE_CURVE_EXTRA by the selection's quick search from the
    configurations ``initial`` {n_lights: lights}, its certificate's all-lights NNLS from
    ``nnls_start`` (an earlier stroke's, the same optimum); without the kernel's direct light of
    lights the model has not corrected yet and without the lamp refinement (the model's lamps,
    refined for the earlier targets, are candidates); no per-face block in its report (the scene
    holds them)."""
    t0 = time.perf_counter() if t0 is None else t0
    _listening(model, cancel)
    t1 = time.perf_counter()
    if not SELECTIONS[options.selection].traits.distributes:  # (the selection never reads e_x)
        e_x, inv = np.zeros((model.problem.n_lights, 3)), None
    else:
        e_x, inv = solve_stage(model, options)
    seconds = {"inverse": time.perf_counter() - t1 + model.seconds["problem"], "direct_light": 0.0,
               "lamp_refinement": 0.0}
    _inverse_done(progress, cancel)
    t2 = time.perf_counter()
    red = reduce_stage(model, e_x, options, progress, cancel, curve_lights=int(options.max_lights) + LIVE_CURVE_EXTRA,
                       initial=initial, nnls_start=nnls_start)
    bounds = certificate(model.problem, red)
    red = replace(red, certificate=bounds)
    positive = positive_bound(model.problem, inv, red.final, bounds)
    seconds["reduction"] = time.perf_counter() - t2
    return _inverse_outcome(model, options, inv, red, bounds, positive, polygon_counts, seconds, t0, per_face=False)


def reduce_model(model: Model, options: JobOptions, polygon_counts=None, progress=None, cancel=None,
                 t0=None) -> SolveOutcome:
    """Stages 3-5 of a reduce on a built model (build_direct_model's): the reduction from the
    scene's emitters, the fixed light's share, the curve and the report."""
    t0 = time.perf_counter() if t0 is None else t0
    seconds = {"inverse": model.seconds["problem"], "direct_light": 0.0, "lamp_refinement": 0.0}
    _inverse_done(progress, cancel)
    t2 = time.perf_counter()
    red = reduce_stage(model, model.e_start, options, progress, cancel)
    seconds["reduction"] = time.perf_counter() - t2
    warnings, fixed = list(model.warnings), None
    if model.lamp_names:
        fixed, notes = fixed_light(model)
        warnings.extend(notes)
    return _outcome(model, options, None, red, warnings, (None, None, fixed), polygon_counts, seconds, t0,
                    per_face=True)


def _inverse_outcome(model, options, inv, red, bounds, positive, polygon_counts, seconds, t0, per_face):
    """A solve's or a stroke's outcome: how the final configuration stands against the certificate
    and the best positive lighting, and the scene's fixed light, in its warnings."""
    warnings = list(model.warnings)
    point_bounds = np.array([bounds.at(p.n_lights) for p in red.curve])
    warnings.extend(texts.positivity_notes(positive, red.final, model.problem.colour, red.selection))
    warnings.extend(texts.certificate_notes(model.problem, bounds, red.final, refined=model.lamp_refinement))
    fixed, notes = fixed_light(model)
    warnings.extend(notes)
    return _outcome(model, options, inv, red, warnings, (bounds, point_bounds, fixed), polygon_counts, seconds, t0,
                    per_face)


def _outcome(model, options, inv, red, warnings, judged, polygon_counts, seconds, t0, per_face) -> SolveOutcome:
    """The curve assembled (stage 4), the report (stage 5), the stored result and the outcome.
    ``judged``: (the certificate, its bound per curve point, the fixed light's rows)."""
    warnings.extend(w for w in model.problem.warnings + texts.unmet_notes(model.problem, model.patches, model.faces)
                    + (inv.warnings if inv else []) + red.warnings if w not in warnings)
    curve = assemble_curve(model, red, polygon_counts)
    model = replace(model, polygons=curve.polygons)  # (paint-independent: a retargeted model keeps it)
    timings = {"export": 0.0, "meshing": model.seconds["meshing"], "form_factors": model.seconds["form_factors"],
               "lamps": model.seconds["lamps"], "inverse": seconds["inverse"], "reduction": seconds["reduction"],
               "direct_light": seconds["direct_light"], "lamp_refinement": seconds["lamp_refinement"],
               "curve": curve.seconds, "solve": seconds["inverse"] + seconds["reduction"] + seconds["direct_light"]
               + seconds["lamp_refinement"], "apply": 0.0, "total": time.perf_counter() - t0}
    report = solve_report(model, options, inv, red, curve, warnings, timings, *judged, per_face=per_face)
    rows = [{"n_lights": red.curve[i].n_lights, "error": red.curve[i].error,
             "relative_error": red.curve[i].relative_error, "n_negative": red.curve[i].n_negative,
             "curve_index": int(i)} for i in curve.keep]
    stored = StoredResult.from_solve(model, red, curve, report)
    final = curve.exitance[curve.final_row]
    lit = scene_light_at(model.faces, model.lights, model.lamp_lights, model.lamp_irradiance, model.lamp_names,
                         final)
    return SolveOutcome(json_safe(report), rows, curve.final_row, warnings, stored, model.faces, model.patches,
                        model.problem, inv, red, lit, placed_light_at(model.lights, final), model)
