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
import os
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize as sopt
import scipy.sparse as sp

from .engine.best_lights import lower_bounds
from .engine.cost import check_memory, estimate_cost, estimate_patches_cost
from .engine.formfactors import auto_rays_per_patch
from .engine.incidence import first_bounce_matrices, incidence_tables
from .engine.inverse import InverseError, InverseProblem, InverseResult, direct_lighting_problem, solve_inverse
from .engine.lights import KINDS, LightSet, candidate_mask
from .engine.options import JobOptions
from .engine.radiosity import solve_radiosity
from .engine.reduction import ReductionResult, reduce_lights
from .engine.registry import ESTIMATORS, PATCH_MODELS, SELECTIONS
from .engine.sampling import Cancelled
from .engine.scene import FaceSet, PatchSet, SceneError, default_max_patch_size as _default_patch_size, face_mean

__all__ = ["Cancelled", "RadiosityResult", "run_radiosity", "run_solve", "PolygonMap", "JobOptions"]

NO_EMITTER_WARNING = "the scene has no emitter (no material with emission): every radiosity is 0"


@dataclass
class RadiosityResult:
    patches: PatchSet
    patch_radiosity: np.ndarray  # (P, 3) W/m^2
    face_radiosity: np.ndarray  # (F, 3) W/m^2, per FaceSet face
    polygon_radiosity: dict  # object name -> (n_polygons, 3) W/m^2, base-mesh polygon order
    polygon_area: dict  # object name -> (n_polygons,) m^2 (world space; 0 for unreported polygons)
    form_factors: object = None


class PolygonMap:
    """Patches -> base-mesh polygons: the reports' and the scene's rows.

    Every exported object's polygons are numbered globally (``offset[object] + polygon``);
    ``weights`` (n_polygons, P) CSR holds, per polygon, the area fractions of the patches its
    triangles lie on, so ``weights @ v`` is the area-weighted (power-conserving) mean of
    per-patch values over each polygon. Faces without a base polygon (face_index -1: made by a
    modifier, or instances) are left out; a polygon without area gets 0.
    """

    def __init__(self, faces: FaceSet, patches: PatchSet, polygon_counts=None):
        counts = []
        per_index = isinstance(polygon_counts, (list, tuple))
        if per_index and len(polygon_counts) != len(faces.object_names):
            raise ValueError(f"polygon_counts has {len(polygon_counts)} entries for {len(faces.object_names)} objects")
        for oi, name in enumerate(faces.object_names):
            if per_index:  # per object index: None = an unreported group (instances), no polygons
                n = 0 if polygon_counts[oi] is None else polygon_counts[oi]
            else:
                n = polygon_counts.get(name) if polygon_counts else None
            if n is None:
                idx = faces.face_index[(faces.face_object == oi) & (faces.face_index >= 0)]
                n = int(idx.max()) + 1 if len(idx) else 0
            counts.append(int(n))
        self.names = list(faces.object_names)
        #: indices of the objects the reports list (keyed by name): every one, except the
        #: unreported groups (None in a per-index ``polygon_counts``: instance groups)
        self.reported = [oi for oi in range(len(self.names))
                         if not (per_index and polygon_counts[oi] is None)]
        self.offset = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.n = int(self.offset[-1])
        face_pid = np.where(faces.face_index >= 0, self.offset[faces.face_object] + faces.face_index, -1)
        pid = face_pid[patches.tri_face]
        ok = pid >= 0
        ta = patches.tri_area[ok]
        A = sp.csr_matrix((ta, (pid[ok], patches.tri_patch[ok])), shape=(self.n, patches.n_patches))
        A.sum_duplicates()
        self.area = np.asarray(A.sum(axis=1)).reshape(-1)
        self.weights = (sp.diags(1.0 / np.where(self.area > 0, self.area, 1.0)) @ A).tocsr()
        self.pairs = A  # polygon x patch areas (m^2)

    def mean(self, patch_values) -> np.ndarray:
        """(n_polygons, k) area-weighted means of per-patch values (P, k)."""
        return np.asarray(self.weights @ np.asarray(patch_values, dtype=np.float64))

    def split(self, rows) -> dict:
        """Global polygon rows -> {object name: its rows}, for the reported objects (keys are
        unambiguous: real object names; groups without polygons are left out)."""
        out = {}
        for k in self.reported:  # real objects come first: a later group of the same name is left out
            out.setdefault(self.names[k], rows[self.offset[k]:self.offset[k + 1]])
        return out

    def object_of(self, pid) -> np.ndarray:
        return np.searchsorted(self.offset, np.asarray(pid), side="right") - 1


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
        source = patches.exitance
        D = first_bounce(faces, patches, F, np.any(source > 0, axis=1))
        if D is not None:  # the emitters' first reflection with the albedo of its incidence
            source = source + np.stack([D[c] @ source[:, c] for c in range(3)], axis=1)
        B, info = solve_radiosity(F, patches.reflectance, source)
        t_solve = time.perf_counter() - t1
        warnings.extend(w for w in info.get("warnings", []) if w not in warnings)
        if not info.get("converged", True):
            warnings.append(f"the radiosity solve did not converge: {info.get('message', '')}".strip())
    if not np.all(np.isfinite(B)):
        raise SceneError("the radiosity solve produced NaN or infinite values")
    if progress is not None:
        progress("solve", 1.0)
    B_face = face_mean(patches, B)
    pmap = PolygonMap(faces, patches, polygon_counts)
    poly, areas = pmap.split(pmap.mean(B)), pmap.split(pmap.area)
    report = {
        "command": "radiosity",
        "units": {"radiosity": "W/m^2", "length": "m"},
        "scene": {"objects": len(faces.object_names), "faces": int(faces.n_faces), "patches": int(P)},
        "timings_s": {"export": 0.0, "meshing": t_mesh, "form_factors": t_ff, "solve": t_solve, "apply": 0.0,
                      "total": time.perf_counter() - t0},
        "estimate": {"memory_bytes": cost["memory_bytes"], "seconds": cost["seconds"]},
        "options": {"rays_per_patch": None if F is None else int(F.rays_per_patch),
                    "max_patch_size": float(patches.max_patch_size), "seed": int(options.seed)},
        "solver": {k: v for k, v in info.items() if k != "warnings"},
        "objects": {name: {"radiosity": rows} for name, rows in poly.items()},
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

#: intermediate (to-be-refined) models get this fraction of the rays
REFINE_RAY_FRACTION = 4

BACKGROUND_NOTE = ("the scene's own emitters ({n} face(s)) are kept as fixed background light; "
                   "the solve lights what they leave to the targets")


def _with_notes(text, notes):
    notes = [n for n in (notes or []) if n]
    return text + ("; " + "; ".join(notes) if notes else "")


def face_areas(faces: FaceSet) -> np.ndarray:
    """(F,) world-space area of every face (m^2)."""
    T = faces.vertices[faces.triangles]
    a = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    return np.bincount(faces.triangle_face, weights=a, minlength=faces.n_faces)


def check_solvable(faces: FaceSet, mode: str = "inverse", notes: dict | None = None):
    """Fail early, before any work, on problems the user can fix. ``notes`` (export: what the
    scene holds but Relight does not use) are repeated in the message they explain."""
    notes = notes or {}
    area = face_areas(faces)
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
            owners = sorted({faces.object_names[o] for o in np.unique(faces.face_object[faces.face_index >= 0])})
            raise SceneError(_with_notes(
                "no candidate light: every face is forbidden (relight_forbidden, relight_no_lights) or already "
                f"emits; objects: {', '.join(owners[:10])}{' ...' if len(owners) > 10 else ''}",
                notes.get("candidates")))
        if not np.any(free & has_area):
            raise SceneError(_with_notes("no candidate light: the faces that may hold lights have no area",
                                         notes.get("candidates")))
    elif not np.any(faces.exitance > 0):
        raise SceneError("the scene has no emitter to reduce (no material with emission)")


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
    """Memory and time estimate of a solve (engine.cost), with warnings when they are high."""
    passes = options.refine_passes if PATCH_MODELS[options.patch_model].get("refines") else 0
    return estimate_patches_cost(patches, rays_per_patch(options, patches.n_patches, mode), options.solver,
                                 n_triangles=n_triangles, refine_passes=passes,
                                 kernel=uses_kernel_pairs(options, mode), threads=options.threads)


def radiosity_cost(patches: PatchSet, options: JobOptions) -> dict:
    """Memory and time estimate of a forward radiosity job (no inverse problem)."""
    rays = rays_per_patch(options, patches.n_patches, "radiosity")
    return estimate_cost(patches.n_patches, rays, 0, 0, threads=options.threads)  # no inverse terms


# ---------------------------------------------------------------------------- memory guard

#: estimates before meshing are capped here (a patch size of 1e-300 m would overflow)
_MAX_COUNT = 1e30
#: the adaptive model clusters faces below this fraction of their size (its CLUSTER_BELOW)
_CLUSTER_BELOW = 0.5


def estimate_patch_count(faces: FaceSet, options: JobOptions, default_max_patch_size=None,
                         certain: bool = False) -> float:
    """How many patches the job's patch model makes of ``faces``, from the faces alone (no
    meshing): a face no larger than its size is one patch, a larger quad an nu x nv grid, any
    other face k x k pieces per triangle (engine.scene.split_faces); exact for the polygon model.
    The adaptive model's candidate faces use the light size, and its faces below half their size
    are clustered: ``certain`` counts those as none (a lower bound), else one each (an upper one)."""
    size = options.max_patch_size if options.max_patch_size is not None else default_max_patch_size
    if size is None:
        size = _default_patch_size(faces.vertices)
    F = faces.n_faces
    s = np.full(F, float(size))
    if options.patch_model == "adaptive":
        cand = ~faces.forbidden & ~np.any(faces.exitance > 0, axis=1)
        s[cand] = float(options.light_size or size)
    V = faces.vertices
    with np.errstate(over="ignore", invalid="ignore"):
        T = V[faces.triangles]
        edge = np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(axis=1)
        tf = faces.triangle_face
        k = np.maximum(np.ceil(np.minimum(edge / s[tf], _MAX_COUNT)), 1.0)
        per_tri = np.bincount(tf, weights=np.minimum(k * k, _MAX_COUNT), minlength=F)
        face_edge = np.zeros(F)
        np.maximum.at(face_edge, tf, edge)
        count = np.where(face_edge <= s, 1.0, per_tri)
        if certain and options.patch_model == "adaptive":
            count[face_edge <= _CLUSTER_BELOW * s] = 0.0
        quad = np.flatnonzero((faces.loop_total == 4) & (face_edge > s))
        if len(quad):
            p = V[faces.loop_vertices[faces.loop_start[quad][:, None] + np.arange(4)]]
            d = lambda a, b: np.linalg.norm(p[:, a] - p[:, b], axis=1)  # noqa: E731
            nu = np.maximum(np.ceil(np.minimum(np.maximum(d(1, 0), d(2, 3)) / s[quad], _MAX_COUNT)), 1.0)
            nv = np.maximum(np.ceil(np.minimum(np.maximum(d(3, 0), d(2, 1)) / s[quad], _MAX_COUNT)), 1.0)
            count[quad] = np.minimum(nu * nv, _MAX_COUNT)
    return float(min(max(count.sum(), 1.0), _MAX_COUNT))


def check_before_meshing(faces: FaceSet, options: JobOptions, default_max_patch_size=None, mode="inverse") -> dict:
    """Refuse (engine.cost.check_memory) before any allocation a job that cannot fit in memory:
    the estimate of the patches the faces certainly give (``estimate_patch_count(certain=True)``;
    the inverse problem's terms left out: a lower bound of the estimate checked after meshing)."""
    P = estimate_patch_count(faces, options, default_max_patch_size, certain=True)
    Pi = int(P)
    rays = rays_per_patch(options, Pi, mode)
    passes = options.refine_passes if (mode == "inverse" and PATCH_MODELS[options.patch_model].get("refines")) else 0
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
    background_radiosity: np.ndarray  # (P, 3) W/m^2 the radiosity they give
    e_start: np.ndarray | None  # direct mode: the emitters' exitance per light
    warnings: list
    cost: dict
    seconds: dict
    refinement: dict = None  # adaptive model: passes made and the target change after each


def refinement_measure(problem: InverseProblem, B_background, history: list):
    """Importance of every patch for the targets and the change of the predicted target
    radiosity since the previous model.

    The reference configuration is the best non-negative one (NNLS on T) of the first model;
    its lights keep their indices across refinements (the patch model's canonical light order),
    so ``T e`` on each new model says how much the targets' prediction moved: the relative change
    is returned (None on the first model). Importance psi solves A^T psi = w, w the targets'
    area fractions, and weights the power each patch sends: psi_j A_j B_j (summed over the
    channels), with B the radiosity of the reference configuration.
    """
    if not history:
        e_ref = np.stack([sopt.nnls(problem.transfer[c], problem.b_target[:, c],
                                    maxiter=50 * problem.n_lights)[0] for c in range(3)], axis=1)
    else:
        e_ref = history[0][0]
    pred = problem.target_radiosity_of(e_ref)
    change = None
    if history:
        prev = history[-1][1]
        change = float(np.linalg.norm(pred - prev) / max(np.linalg.norm(prev), 1e-300))
    history.append((e_ref, pred, change))
    facs = problem.factors()
    w = np.zeros(problem.n_patches)
    w[problem.targets] = problem.area[problem.targets] / problem.area[problem.targets].sum()
    B = problem.forward_radiosity(problem.patch_exitance(e_ref)) + B_background
    importance = np.zeros(problem.n_patches)
    for c in range(3):
        psi = facs[c].solve(w, trans=True)
        importance += psi * problem.area * B[:, c]
    return change, importance


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
    t_ff = t_problem = 0.0
    history = []
    # the paper's heuristics redistribute between lights that partition the candidates: single-scale;
    # direct-lighting mode reduces the scene's own lamps: one light per emitter polygon
    scales = None if SELECTIONS[options.selection].get("multiscale") else ("cell",)
    if mode == "direct":
        scales = ("polygon",)
    for p in range(passes + 1):
        mask = candidate_mask(patches, mode)
        lights = pm.lights(patches, mask, scales) if hasattr(pm, "refine") else pm.lights(patches, mask)
        pairs = (np.flatnonzero(patches.target), lights.patches) if mode == "inverse" else None
        lo, hi = 0.7 * p / (passes + 1), 0.7 * (p + 1) / (passes + 1)
        # a model that will be refined only ranks patches by importance: a quarter of the rays
        rays = rays_per_patch(options, patches.n_patches, mode)
        opts = options if p == passes else replace(options, rays_per_patch=max(64, rays // REFINE_RAY_FRACTION))
        F = ESTIMATORS[options.estimator](patches, opts, progress=_stage(progress, "form factors", lo, hi),
                                          cancel=cancel, pairs=pairs)
        t_ff += F.seconds
        if cancel is not None and cancel():
            raise Cancelled("solve cancelled")
        t1 = time.perf_counter()
        background = np.zeros_like(patches.exitance)
        B_background = np.zeros_like(patches.exitance)
        e_start = None
        if mode == "inverse":
            problem = InverseProblem(F, patches.area, patches.reflectance, patches.target, patches.target_radiosity,
                                     mask, patches.center, patches.normal, light_basis=lights.basis)
            problem.first_bounce = first_bounce(faces, patches, F, mask | np.any(patches.exitance > 0, axis=1))
            emitting = np.any(patches.exitance > 0, axis=1)
            if emitting.any():
                background = patches.exitance.copy()
                B_background = problem.forward_radiosity(background)
                problem.b_target = problem.b_target - B_background[problem.targets]
        else:
            problem, e_start = direct_lighting_problem(F, patches.area, patches.reflectance, patches.exitance,
                                                       patches.center, patches.normal, light_basis=lights.basis,
                                                       first_bounce=first_bounce(faces, patches, F, mask))
        t_problem += time.perf_counter() - t1
        if p == passes:
            break
        t2 = time.perf_counter()
        change, importance = refinement_measure(problem, B_background, history)
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
    if mode == "inverse" and np.any(background > 0):
        emitting = np.any(patches.exitance > 0, axis=1)
        warnings.append(BACKGROUND_NOTE.format(n=int(len(np.unique(patches.face[emitting])))))
    refinement = {"passes": len(history), "target_change": [h[2] for h in history[1:]]}
    return Model(mode, faces, patches, lights, F, problem, background, B_background, e_start, warnings, cost,
                 {"meshing": t_mesh, "form_factors": t_ff, "problem": t_problem}, refinement)


def solve_stage(model: Model, options: JobOptions) -> tuple:
    """Stage 2: the configuration the reduction starts from, e_x (n_lights, 3), and the inverse
    result (None in direct mode, where e_x is the scene's emitters)."""
    if model.mode != "inverse":
        return model.e_start, None
    inv = solve_inverse(model.problem, options.solver)
    return inv.exitance, inv


def reduce_stage(model: Model, e_x, options: JobOptions, progress=None, cancel=None) -> ReductionResult:
    """Stage 3: the selection x distribution over the whole curve; the stop criteria pick the final point."""
    by_lp = SELECTIONS[options.selection].get("needs_tolerance")  # the programme decides, not the stop criteria
    red = reduce_lights(model.problem, e_x, selection=options.selection, distribution=options.distribution,
                        max_lights=None if by_lp else options.max_lights,
                        relative_error_threshold=None if by_lp else options.error_threshold,
                        require_positive=options.require_positive, tolerance=options.tolerance,
                        progress=(lambda d, t: progress("reduction", 0.8 + 0.15 * d / max(t, 1)))
                        if progress is not None else None, cancel=cancel)
    if red.cancelled:
        raise Cancelled("solve cancelled")
    return red


#: the certificate (lower bounds) covers the curve up to this many lights; above, the NNLS bound
CERTIFICATE_LIGHTS = 32


def certificate(problem: InverseProblem, red: ReductionResult):
    """Lower bounds on the best error any non-negative configuration of at most k lights can reach
    (engine.best_lights.lower_bounds: exact by exhaustive search where small enough, else the
    all-lights NNLS bound), and per curve point its bound (W/m^2)."""
    k_top = int(min(problem.n_lights, max(min(CERTIFICATE_LIGHTS, max(p.n_lights for p in red.curve)), 1)))
    bounds = getattr(problem, "certificate", None)  # the greedy-swap selection computed it already
    if bounds is None or len(bounds.bound) < k_top:
        bounds = lower_bounds(problem.transfer, problem.b_target, k_top)
    return bounds, np.array([bounds.at(p.n_lights) for p in red.curve])


def certificate_notes(problem, bounds, final) -> list:
    """How good the final configuration is against the certificate."""
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    k = final.n_lights
    exact = 1 <= k <= len(bounds.exact) and bool(bounds.exact[k - 1])
    lb = bounds.at(k) / norm
    if final.n_negative or final.relative_error <= 1e-9:
        return []
    if exact and final.relative_error <= lb * (1 + 1e-6) + 1e-12:
        return [f"{k} light(s): the best possible with {k} non-negative lights (exhaustive search), "
                f"relative error {final.relative_error:.3g}"]
    return [f"{k} light(s): relative error {final.relative_error:.3g}; no {k} non-negative lights can go below "
            f"{lb:.3g}{' (exact optimum)' if exact else ''}, and no number of them below {bounds.nnls_relative:.3g}"]


def first_bounce(faces: FaceSet, patches: PatchSet, F, sources):
    """engine.incidence's D per channel for the light leaving ``sources`` (a patch mask), from the
    faces' materials; None when the FaceSet has none or none depends on the incidence."""
    if faces.face_material is None or not faces.material_lobes:
        return None
    tables = incidence_tables(faces.material_lobes)
    material = np.asarray(faces.face_material, dtype=np.int64)[patches.face]
    return first_bounce_matrices(F, patches.center, patches.normal, material, tables,
                                 np.flatnonzero(sources))


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
    E_patch = np.zeros((P, n_pts, 3))
    for k in range(n_pts):  # the lights' exitance on their patches
        E_patch[C, k] = problem.light_basis @ E[k]
    facs = problem.factors()
    B = np.empty((n_pts, P, 3))
    for c in range(3):
        src = E_patch[:, :, c]
        if problem.first_bounce is not None:
            src = src + problem.first_bounce[c] @ src
        B[:, :, c] = (facs[c].solve(src) + model.background_radiosity[:, c:c + 1]).T
    if not np.all(np.isfinite(B)):
        raise SceneError("the solve produced NaN or infinite values")
    pmap = PolygonMap(model.faces, patches, polygon_counts)
    cells = (pmap.pairs[:, C] > 0).astype(np.float64)  # polygons x candidate patches
    light_polygons = (cells @ problem.light_basis).T.tocsr()
    light_polygons.data[:] = 1.0
    return Curve(keep, int(np.searchsorted(keep, red.final_index)), E, B, pmap, light_polygons,
                 time.perf_counter() - t0)


def light_records(model: Model, curve: Curve, row: int) -> list:
    """The lights of kept configuration ``row`` with a non-zero exitance, as the report lists
    them: object, polygons (base-mesh indices), kind, center and normal (world), area (m^2),
    exitance [r, g, b] (W/m^2) and power (W)."""
    lights = model.lights
    e = curve.exitance[row]
    out = []
    for j in np.flatnonzero(np.any(e != 0, axis=1)):
        pids = curve.light_polygons[j].indices
        obj = model.patches.object[lights.members(j)[0]]
        out.append({"object": model.faces.object_names[obj],
                    "polygons": np.sort(pids - curve.polygons.offset[obj]).tolist(),
                    "kind": KINDS[lights.kind[j]],
                    "center": lights.center[j], "normal": lights.normal[j], "area": float(lights.area[j]),
                    "exitance": e[j], "power": float(e[j].sum() * lights.area[j])})
    return out


def make_report(model: Model, options: JobOptions, inv: InverseResult | None, red: ReductionResult,
                curve: Curve, warnings: list, timings: dict, bounds=None, point_bounds=None) -> dict:
    """Stage 5: the JSON report (see README.md)."""
    faces, patches, problem = model.faces, model.patches, model.problem
    fi = curve.final_row
    final = red.curve[red.final_index]
    pmap = curve.polygons
    E_patch = model.lights.patch_exitance(curve.exitance[fi], patches.n_patches) + model.background
    radiosity = pmap.split(curve.final_polygon_radiosity())
    exitance = pmap.split(pmap.mean(E_patch))
    target = pmap.split(np.where(pmap.mean(patches.target.astype(float)[:, None]) > 0.5,
                                 pmap.mean(np.where(patches.target[:, None], patches.target_radiosity, 0.0)), np.nan))
    objects = {name: {"radiosity": radiosity[name], "target": _nan_to_none(target[name]), "exitance": exitance[name]}
               for name in radiosity}
    n_targets_faces = int(np.sum(faces.target)) if model.mode == "inverse" else None
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    return {
        "command": "solve" if model.mode == "inverse" else "reduce",
        "units": {"radiosity": "W/m^2", "exitance": "W/m^2", "power": "W", "length": "m"},
        "scene": {"objects": len(faces.object_names), "faces": int(faces.n_faces),
                  "triangles": int(len(faces.triangles)), "patches": int(patches.n_patches)},
        "timings_s": timings,
        "estimate": {"memory_bytes": model.cost["memory_bytes"], "seconds": model.cost["seconds"]},
        "options": {**options.to_dict(), "rays_per_patch": int(model.form_factors.rays_per_patch),
                    "max_patch_size": float(patches.max_patch_size),
                    "light_size": None if patches.light_size is None else float(patches.light_size)},
        "model": {"patch_model": options.patch_model, "estimator": options.estimator,
                  "lights_by_kind": {k: int(np.sum(model.lights.kind == i)) for i, k in enumerate(KINDS)},
                  "refinement": model.refinement},
        "inverse": {
            "solver": inv.solver if inv else "direct-lighting",
            "n_targets": int(problem.m), "n_target_faces": n_targets_faces,
            "n_candidates": int(problem.n_lights),  # candidate lights, at all scales
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
                   "n_negative": p.n_negative, "power": _power(problem, p),
                   "bound_relative_error": None if point_bounds is None else float(point_bounds[i] / norm)}
                  for i, p in enumerate(red.curve)],
        "certificate": None if bounds is None else {
            "nnls_relative_error": bounds.nnls_relative, "seconds": bounds.seconds,
            "by_lights": [{"n_lights": int(k), "bound_relative_error": float(r), "exact": bool(x)}
                          for k, r, x in zip(bounds.k, bounds.relative, bounds.exact)]},
        "final": {"n_lights": final.n_lights, "error": final.error, "relative_error": final.relative_error,
                  "n_negative": final.n_negative, "power": _power(problem, final),
                  "bound_relative_error": None if point_bounds is None else float(point_bounds[red.final_index] / norm),
                  "lights": light_records(model, curve, fi)},
        "objects": objects,
        "warnings": warnings,
    }


def _power(problem, point) -> float:
    """Total power (W) of a configuration: sum over its lights and channels of exitance x area."""
    return float(np.sum(point.exitance.sum(axis=1) * problem.light_area[point.lights]))


def stored_result(model: Model, red: ReductionResult, curve: Curve, report: dict) -> dict:
    """What the .blend keeps (curve_store.pack_curve): the whole curve, and per kept configuration
    the lights' exitance and the patches' radiosity, with what is needed to show them without the
    engine: the cells' triangles and reflectance, the light basis, the patches -> polygons map."""
    keep, pts = curve.keep, red.curve
    lights, patches, pmap = model.lights, model.patches, curve.polygons
    C = lights.patches
    in_c = np.full(patches.n_patches, -1)
    in_c[C] = np.arange(len(C))
    cell_of_tri = in_c[patches.tri_patch]
    sel = np.flatnonzero(cell_of_tri >= 0)
    sel = sel[np.argsort(cell_of_tri[sel], kind="stable")]
    W = pmap.weights.tocsr()
    lp = curve.light_polygons
    return {
        "objects": list(model.faces.object_names),
        "polygon_offset": pmap.offset,
        "light_object": model.patches.object[C[lights.basis.tocsc().indices[lights.basis.tocsc().indptr[:-1]]]],
        "light_kind": lights.kind, "light_area": lights.area, "light_center": lights.center,
        "light_normal": lights.normal, "light_polygons_indptr": lp.indptr, "light_polygons": lp.indices,
        "basis_indptr": lights.basis.indptr, "basis_indices": lights.basis.indices,
        "cell_triangles": patches.tri_vertices[sel].astype(np.float32),
        "cell_triangle_cell": cell_of_tri[sel], "cell_normal": patches.normal[C], "cell_patch": C,
        "cell_reflectance": patches.reflectance[C],
        "polygon_weights_indptr": W.indptr, "polygon_weights_patch": W.indices, "polygon_weights": W.data,
        "curve_n_lights": np.array([p.n_lights for p in pts]),
        "curve_error": np.array([p.error for p in pts]),
        "curve_relative_error": np.array([p.relative_error for p in pts]),
        "curve_n_negative": np.array([p.n_negative for p in pts]),
        "curve_power": np.array([c["power"] for c in report["curve"]]),
        # -1: no certificate (direct-lighting mode)
        "curve_bound_relative_error": np.array([-1.0 if c["bound_relative_error"] is None else
                                                c["bound_relative_error"] for c in report["curve"]]),
        "point_index": keep,
        "n_lights": np.array([pts[i].n_lights for i in keep]),
        "error": np.array([pts[i].error for i in keep]),
        "relative_error": np.array([pts[i].relative_error for i in keep]),
        "n_negative": np.array([pts[i].n_negative for i in keep]),
        "exitance": curve.exitance,
        "radiosity": curve.radiosity,
        "final": np.array(red.final_index),
        "target_patch": model.problem.targets,  # the painted patches and their painted radiosity (W/m^2)
        "target_value": patches.target_radiosity[model.problem.targets],
        "target_norm": np.array(model.problem.target_norm),
        "meta": {"command": report["command"], "options": _json_safe(report["options"])},
    }


def run_solve(faces: FaceSet, options: JobOptions | None = None, polygon_counts=None,
              default_max_patch_size: float | None = None, progress=None, cancel=None, mode="inverse",
              patches: PatchSet | None = None, notes: dict | None = None):
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
    has them (the operator meshes first to estimate the cost). ``notes``: export's notes, repeated
    in the errors they explain (check_solvable). Returns a SolveOutcome.
    """
    options = (options or JobOptions()).validate()
    check_solvable(faces, mode, notes)
    try:
        return _run_solve(faces, options, polygon_counts, default_max_patch_size, progress, cancel, mode, patches)
    except InverseError as exc:
        rays = options.rays_per_patch
        if "reaches any target" in str(exc) and rays is not None and rays < FEW_RAYS:
            raise InverseError(f"no ray from a candidate light reached a target with {rays} ray(s) per patch: "
                               f"cast more rays per patch (at least {FEW_RAYS}; --rays-per-patch, or 0 = automatic) "
                               "before concluding the targets are occluded") from None
        raise


#: below this many rays per patch, "no light reaches the targets" may be sampling, not geometry
FEW_RAYS = 256


def _run_solve(faces, options, polygon_counts, default_max_patch_size, progress, cancel, mode, patches):
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
    bounds = point_bounds = None
    if mode == "inverse":
        t3 = time.perf_counter()
        bounds, point_bounds = certificate(model.problem, red)
        t_reduce += time.perf_counter() - t3
        warnings.extend(_positivity_notes(model.problem, inv, red.final))
        warnings.extend(certificate_notes(model.problem, bounds, red.final))
    warnings.extend(w for w in model.problem.warnings + (inv.warnings if inv else []) + red.warnings
                    if w not in warnings)
    curve = assemble_curve(model, red, polygon_counts)
    timings = {"export": 0.0, "meshing": model.seconds["meshing"], "form_factors": model.seconds["form_factors"],
               "inverse": t_inverse, "reduction": t_reduce, "curve": curve.seconds, "solve": t_inverse + t_reduce,
               "apply": 0.0, "total": time.perf_counter() - t0}
    report = make_report(model, options, inv, red, curve, warnings, timings, bounds, point_bounds)
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
            f"lights can reach {bound.relative_error:.3g} (NNLS, {n_pos} lights): allow more lights, or use the "
            "greedy-swap selection (Best k Lights)"]


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
