"""A job's patches and what it will cost, before any work (no bpy): the patch model, the memory
guard before meshing (engine.cost.check_memory), the rays per patch and the cost estimates of a
solve, a reduce and a forward radiosity job. ``mode``: "inverse" (solve), "direct" (reduce) or
"radiosity" (the forward job): what the job's estimate counts.
"""
from __future__ import annotations

from ..engine.candidate_lamps import lamp_bound
from ..engine.cost import check_memory, estimate_cost, estimate_patch_count, estimate_patches_cost
from ..engine.extent import forget_measures
from ..engine.formfactors import auto_rays_per_patch
from ..engine.lights import candidate_mask
from ..engine.options import JobOptions
from ..engine.registry import ESTIMATORS, LIGHT_COLOURS, PATCH_MODELS
from ..engine.scene import FaceSet, PatchSet

__all__ = ["patch_model", "mesh_for_job", "check_before_meshing", "uses_kernel_pairs", "rays_per_patch",
           "solve_cost", "radiosity_cost"]


def patch_model(options: JobOptions, default_max_patch_size=None):
    """The job's patch model (engine/patch_models/), built from its options."""
    return PATCH_MODELS[options.patch_model].impl(options, default_max_patch_size)


def mesh_for_job(faces: FaceSet, options: JobOptions, default_max_patch_size=None, mode="inverse") -> PatchSet:
    """The faces meshed by the job's patch model, after checking (from the faces alone) that the
    patches would fit in this machine's memory. The check and the mesh share one measure of the
    faces' triangles (engine.extent.triangle_measures), dropped once the patches are made."""
    try:
        check_before_meshing(faces, options, default_max_patch_size, mode)
        return patch_model(options, default_max_patch_size).mesh(faces)
    finally:
        forget_measures(faces)


def uses_kernel_pairs(options: JobOptions, mode: str = "inverse") -> bool:
    """Whether the job's estimator computes the light-to-target pairs by the kernel (inverse mode)."""
    return mode == "inverse" and ESTIMATORS[options.estimator].traits.kernel_pairs


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
                                 and LIGHT_COLOURS[options.light_colour].traits.relaxation)


def radiosity_cost(patches: PatchSet, options: JobOptions) -> dict:
    """Memory and time estimate of a forward radiosity job (no inverse problem)."""
    rays = rays_per_patch(options, patches.n_patches, "radiosity")
    return estimate_cost(patches.n_patches, rays, 0, 0, threads=options.threads)  # no inverse terms


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
