"""Stage 1 of a solve or a reduce, the problem (no bpy): ``Model`` (patches, lights, form factors,
the inverse problem, the scene's fixed light) built for a solve (``build_inverse_model``: the
painted targets, the scene's own light kept fixed, the candidate surfaces and lamps, the adaptive
model's refinement passes) or for a reduce (``build_direct_model``: the paper's direct-lighting
mode, the scene's emitters and lamps the lights). A solved model is followed, not rebuilt, when
only the paint changed (``retarget_model``, Live's strokes) or the scene's lamps moved
(``move_scene_light``).
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..engine.candidate_lamps import offer_lamps, offered_kinds
from ..engine.cost import check_memory
from ..engine.first_reflection import first_bounce, lights_excess
from ..engine.inverse import DivergentTransport, InverseProblem, direct_lighting_problem
from ..engine.lights import LightSet, candidate_mask
from ..engine.options import REFINE_RAY_FRACTION, JobOptions, OptionError
from ..engine.patch_models.adaptive import refinement_measure
from ..engine.registry import ESTIMATORS, LIGHT_COLOURS, SELECTIONS
from ..engine.sampling import SceneSampler, check_cancel
from ..engine.scene import FaceSet, PatchSet
from ..engine.targets import target_aims
from ..engine.targets import scene_targets
from ..engine.scene_light import direct_lights, has_scene_light, scene_light, scene_light_excess
from . import notes as texts
from .meshing import check_before_meshing, patch_model, rays_per_patch, solve_cost
from .polygons import PolygonMap

__all__ = ["Model", "build_inverse_model", "build_direct_model", "retarget_model", "move_scene_light",
           "transport_named", "light_colour_of", "progress_slice"]


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
    polygons: PolygonMap = None  # the curve's patches -> polygons map (paint-independent: a retargeted
    #                              model keeps it)


def progress_slice(progress, name, lo, hi):
    """``progress`` of stage ``name`` mapped onto [lo, hi] of the whole job (None: None)."""
    if progress is None:
        return None
    return lambda f: progress(name, lo + (hi - lo) * float(f))


@contextmanager
def transport_named(patches: PatchSet, faces: FaceSet):
    """A DivergentTransport raised inside names the objects of its patches."""
    try:
        yield
    except DivergentTransport as exc:
        if exc.names:
            raise
        raise exc.named(faces.object_names, patches.object) from None


def _mesh(faces, options, pm, patches, default_max_patch_size, mode, remesh):
    """(patches, seconds, the checked cost): the faces meshed (``patches``: the caller's, meshed
    again when ``remesh``: a refining model keeps its state from its own first mesh), the solve's
    cost refused before any more work when it cannot fit in memory."""
    t0 = time.perf_counter()
    if patches is None:
        check_before_meshing(faces, options, default_max_patch_size, mode)
        patches = pm.mesh(faces)
    elif remesh:  # (same patches: deterministic)
        patches = pm.mesh(faces)
    t_mesh = time.perf_counter() - t0
    cost = check_memory(solve_cost(patches, options, len(faces.triangles), mode),
                        f"this solve ({patches.n_patches} patches)")
    return patches, t_mesh, cost


def _surface_lights(pm, patches, mask, scales):
    """The patch model's lights over the candidate patches ``mask``."""
    return pm.lights(patches, mask, scales) if hasattr(pm, "refine") else pm.lights(patches, mask)


def _form_factors(faces, patches, options, estimate, pairs, progress, cancel, warnings):
    """The estimator's form factors (``estimate``: a prepared scene's, else the option's); the
    pairs the kernel could not compute named in ``warnings``."""
    F = (estimate or ESTIMATORS[options.estimator])(patches, options, progress=progress, cancel=cancel, pairs=pairs)
    if getattr(F, "kernel_unfit", None):
        n, objs = F.kernel_unfit
        warnings.append(texts.kernel_unfit_note(n, [faces.object_names[o] for o in objs]))
    check_cancel(cancel)
    return F


def _no_light_error(options):
    return OptionError("no candidate light: the cells are off (--no-surface-lights) and no candidate lamp "
                       f"({', '.join(offered_kinds(options))}) lights any face",
                       f"no candidate light: Cells is off under Offer and no candidate lamp "
                       f"({', '.join(offered_kinds(options))}) lights any face")


def _inverse_problem(faces, patches, F, mask, lights, background, lamp_H, cancel=None) -> InverseProblem:
    """The solve's InverseProblem: the painted targets, the candidate lights, their first reflection,
    the scene's own emitters (``background``) and lamps and World (``lamp_H``) as fixed light."""
    emitting = np.any(patches.exitance > 0, axis=1)
    return InverseProblem(F, patches.area, patches.reflectance, scene_targets(faces, patches, F),
                          mask, patches.center, patches.normal, lights=lights,
                          first_bounce=first_bounce(faces, patches, F, mask | emitting),
                          background=background, background_irradiance=lamp_H.sum(axis=1),
                          lamp_excess=lights_excess(faces, patches, lights),
                          background_excess=scene_light_excess(faces, patches, lamp_H), cancel=cancel)


def _offer(faces, lights, patches, mask, options, F, warnings, seconds, progress, cancel, offer=None):
    """The candidate lamps offered beside the surface lights (engine.candidate_lamps, aimed at the
    painted patches and at what the other target kinds ask: engine.targets.target_aims; ``offer``:
    offer_lamps' replacement, a prepared scene's that keeps the lamps' irradiance)."""
    t1 = time.perf_counter()
    sampler = getattr(F, "sampler", None) or SceneSampler(patches)
    lamp_notes = []

    def each_lamp(f):  # (after each lamp's irradiance: a cancel is heard within one lamp, not the stage)
        if progress is not None:
            progress(f)
        check_cancel(cancel)

    lights, _ = (offer or offer_lamps)(lights, patches, mask, options, sampler, options.seed, each_lamp,
                                       notes=lamp_notes, aims=target_aims(faces, patches, sampler))
    warnings.extend(n for n in lamp_notes if n not in warnings)
    seconds["lamps"] += time.perf_counter() - t1
    check_cancel(cancel)
    return lights


def _inverse_pass(faces, patches, options, pm, scales, estimate, p, passes, warnings, seconds, progress, cancel,
                  offer=None):
    """One pass of the solve's problem on ``patches``: (lights, F, problem, background, lamp_H,
    lamp_names)."""
    mask = candidate_mask(patches, "inverse")
    lights = _surface_lights(pm, patches, mask, scales)
    if not options.param("surface_lights", True):  # lamps only
        lights = LightSet(lights.patches, sp.csr_matrix((len(lights.patches), 0)), np.zeros(0, dtype=np.int8),
                          np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
    lo, hi = 0.7 * p / (passes + 1), 0.7 * (p + 1) / (passes + 1)
    # a model that will be refined only ranks patches by importance: a quarter of the rays
    rays = rays_per_patch(options, patches.n_patches, "inverse")
    opts = options if p == passes else replace(options, rays_per_patch=max(64, rays // REFINE_RAY_FRACTION))
    F = _form_factors(faces, patches, opts, estimate, (np.flatnonzero(patches.target), lights.patches),
                      progress_slice(progress, "form factors", lo, hi), cancel, warnings)
    seconds["form_factors"] += F.seconds
    if offered_kinds(options):  # the candidate lamps, beside the cells
        lights = _offer(faces, lights, patches, mask, options, F, warnings, seconds,
                        progress_slice(progress, "lamps", hi, hi + 0.05 / (passes + 1)), cancel, offer)
    if lights.n_lights == 0:
        raise _no_light_error(options)
    t1 = time.perf_counter()
    background = np.zeros_like(patches.exitance)
    with transport_named(patches, faces):  # (the radiosity system is factorised here)
        if np.any(patches.exitance > 0):
            background = patches.exitance.copy()
        lamp_H, lamp_names = scene_light(faces, patches, F, options.seed)
        problem = _inverse_problem(faces, patches, F, mask, lights, background, lamp_H, cancel)
    seconds["problem"] += time.perf_counter() - t1
    return lights, F, problem, background, lamp_H, lamp_names


def _refined_mesh(faces, patches, options, pm, problem, history, p, seconds):
    """The adaptive model's next mesh (refinement pass ``p + 1``), or None when it stops."""
    t2 = time.perf_counter()
    change, importance = refinement_measure(problem, history)
    seconds["problem"] += time.perf_counter() - t2
    if change is not None and change < options.refine_tolerance:
        return None
    t3 = time.perf_counter()
    if not pm.refine(faces, patches, importance):
        return None
    patches = pm.mesh(faces)
    check_memory(solve_cost(patches, options, len(faces.triangles), "inverse"),
                 f"this solve ({patches.n_patches} patches after refinement pass {p + 1})")
    seconds["meshing"] += time.perf_counter() - t3
    return patches


def build_inverse_model(faces: FaceSet, options: JobOptions, default_max_patch_size=None, progress=None,
                        cancel=None, patches: PatchSet | None = None, estimate=None, offer=None) -> Model:
    """Stage 1 of a solve: mesh the faces (the patch model), choose the candidate lights, estimate
    the form factors and set up the inverse problem (the painted targets, with the scene's own
    emitters, lamps and World as fixed background); the adaptive model's refinement passes.
    ``estimate``: the form-factor estimator to call instead of ``options.estimator``'s, with its
    signature (a prepared scene's: pipeline.prepared); ``offer``: the candidate lamps' offer
    (engine.candidate_lamps.offer_lamps' signature; a prepared scene's keeps their irradiance)."""
    pm = patch_model(options, default_max_patch_size)
    refines = hasattr(pm, "refine") and options.refine_passes > 0
    patches, t_mesh, cost = _mesh(faces, options, pm, patches, default_max_patch_size, "inverse", refines)
    warnings = list(faces.warnings) + list(cost["warnings"])
    passes = options.refine_passes if hasattr(pm, "refine") else 0
    seconds = {"meshing": t_mesh, "form_factors": 0.0, "problem": 0.0, "lamps": 0.0}
    history = []
    # the paper's heuristics redistribute between lights that partition the candidates: single-scale
    scales = None if SELECTIONS[options.selection].traits.multiscale else ("cell",)
    for p in range(passes + 1):
        lights, F, problem, background, lamp_H, lamp_names = _inverse_pass(
            faces, patches, options, pm, scales, estimate, p, passes, warnings, seconds, progress, cancel, offer)
        if p == passes:
            break
        refined = _refined_mesh(faces, patches, options, pm, problem, history, p, seconds)
        if refined is None:
            break
        patches = refined
    # the lights' colour (an automatic mode chooses it on the final problem)
    check_cancel(cancel)  # (the problem is factorised: a cancel is heard before the colour's choice)
    t_colour = time.perf_counter()
    problem.colour, note = light_colour_of(problem, options)
    # (an automatic mode's choice factorises the system and builds the transfer: the inverse stage's)
    seconds["problem"] += time.perf_counter() - t_colour
    check_cancel(cancel)
    problem.cancel = None  # (the model outlives this job: a later factorisation is not this job's to stop)
    if note:
        warnings.append(note)
    if np.any(background > 0) or has_scene_light(faces):
        emitting = np.any(patches.exitance > 0, axis=1)
        warnings.append(texts.background_note(int(len(np.unique(patches.face[emitting]))), len(faces.lamps),
                                              faces.world_radiance is not None))
    refinement = {"passes": len(history), "target_change": [h[2] for h in history[1:]]}
    return Model("inverse", faces, patches, lights, F, problem, background, None, warnings, cost, seconds,
                 refinement, lamp_H, lamp_names, None)


def build_direct_model(faces: FaceSet, options: JobOptions, default_max_patch_size=None, progress=None,
                       cancel=None, patches: PatchSet | None = None) -> Model:
    """Stage 1 of a reduce (the paper's direct-lighting mode): the candidates are the scene's
    emitters, one light per emitter polygon, then its lamps (engine.scene_light.direct_lights),
    and every other patch is a target at the radiosity they give it; the World and the lamps of
    negative power are fixed light."""
    pm = patch_model(options, default_max_patch_size)
    patches, t_mesh, cost = _mesh(faces, options, pm, patches, default_max_patch_size, "direct", False)
    warnings = list(faces.warnings) + list(cost["warnings"])
    mask = candidate_mask(patches, "direct")
    # direct-lighting mode reduces the scene's own lamps: one light per emitter polygon
    surface = _surface_lights(pm, patches, mask, ("polygon",)) if mask.any() else None
    F = _form_factors(faces, patches, options, None, None, progress_slice(progress, "form factors", 0.0, 0.7),
                      cancel, warnings)
    if surface is not None and surface.n_lights == 0:
        raise _no_light_error(options)
    t1 = time.perf_counter()
    with transport_named(patches, faces):  # (the radiosity system is factorised here)
        lights, lamp_lights, lamp_H, lamp_names, dark = direct_lights(faces, patches, F, surface, options.seed)
        if dark and texts.dark_lamps_note(dark) not in warnings:
            warnings.append(texts.dark_lamps_note(dark))
        strength = np.array([faces.lamps[i].power for i in lamp_lights[1]]).reshape(-1, 3)
        problem, e_start = direct_lighting_problem(F, patches.area, patches.reflectance, patches.exitance,
                                                   patches.center, patches.normal, lights=lights,
                                                   first_bounce=first_bounce(faces, patches, F, mask),
                                                   strength=strength,
                                                   background_irradiance=lamp_H.sum(axis=1) if lamp_names else None,
                                                   lamp_excess=lights_excess(faces, patches, lights))
    seconds = {"meshing": t_mesh, "form_factors": F.seconds, "problem": time.perf_counter() - t1, "lamps": 0.0}
    if lamp_names:
        warnings.append(texts.direct_fixed_note(lamp_names))
    return Model("direct", faces, patches, lights, F, problem, np.zeros_like(patches.exitance), e_start, warnings,
                 cost, seconds, {"passes": 0, "target_change": []}, lamp_H, lamp_names, lamp_lights)



def light_colour_of(problem, options) -> tuple:
    """(the problem's light colour mode, None for free colours; a note): the option's mode, or
    the one an automatic mode chooses for this problem (engine/colours/auto.py)."""
    mode, note = LIGHT_COLOURS[options.light_colour].bind(options)(), None
    if hasattr(mode, "choose"):
        mode, note = mode.choose(problem)
    return (None if mode.free else mode), note


def retarget_model(model: Model, faces: FaceSet, patches: PatchSet, kept=()) -> Model:
    """A solved model (inverse mode) with the paint of ``faces`` on its own patches (``patches``:
    the model's mesh, each patch its face's target): the same lights (the lamps offered and
    refined for the earlier targets among them), form factors, solvers and fixed light; the
    problem retargeted (InverseProblem.retarget: rows of the transfer to every patch). ``kept`` (an
    earlier stroke's targets) and its own are taken again where they serve, or what of them is the
    same (scene_targets; the last stroke's first: the nearest paint)."""
    t0 = time.perf_counter()
    problem = model.problem.retarget(scene_targets(faces, patches, model.form_factors,
                                                   kept=list(kept) + list(model.problem.target_rows.targets)))
    return replace(model, faces=faces, patches=patches, problem=problem, warnings=list(model.warnings),
                   seconds={"meshing": 0.0, "form_factors": 0.0, "lamps": 0.0, "problem": time.perf_counter() - t0},
                   refinement={"passes": 0, "target_change": []}, lamp_refinement=None, direct=None)


def move_scene_light(model: Model, faces: FaceSet, seed=0) -> Model:
    """A solved model (inverse mode) whose scene's lamps or World changed (``faces``: the same
    scene with its new lamps): their direct light cast again on the model's patches (scene_light,
    on its Embree scene) and the fixed light's radiosity through the model's factorisation
    (InverseProblem.with_background); the lights, form factors and transfer kept."""
    patches, F = model.patches, model.form_factors
    lamp_H, lamp_names = scene_light(faces, patches, F, seed)  # (as build_inverse_model casts it)
    problem = model.problem.with_background(model.background, lamp_H.sum(axis=1),
                                            scene_light_excess(faces, patches, lamp_H))
    return replace(model, faces=faces, problem=problem, lamp_irradiance=lamp_H, lamp_names=lamp_names)
