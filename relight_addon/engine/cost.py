"""Memory and time estimate of a solve, before any work (no bpy).

``estimate_cost(...)`` adds up the big terms of jobs.run_solve from the sizes alone (P patches,
N rays per patch, C candidate patches, L candidate lights, m targets, T triangles):

- scene and meshing: BASE_BYTES, plus about BYTES_PER_TRIANGLE per triangle (the FaceSet, the
  patch triangles, Embree's BVH and the meshing temporaries);
- form factors: every pass casts P x N rays (the refinement passes of the adaptive model cast
  N / REFINE_RAY_FRACTION each) at RAYS_PER_SECOND; F is float32, dense P x P up to DENSE_LIMIT
  patches, else CSR with about min(P, N / 4 + 64) entries per row (8 bytes each; measured);
- the radiosity system A = I - rho F per distinct reflectance channel group g (1 for grey
  scenes, up to 3): up to DIRECT_SOLVE_LIMIT patches a dense float64 copy and its LU factors
  (8 P^2 bytes each, 2/3 P^3 flops); above, no factorisation: iterative sweeps of one sparse
  product each (ITERATIVE_SWEEPS x nnz(F) x right-hand sides x 2 flops);
- the transfer matrix T: min(m, C) right-hand sides through A (2 P^2 flops each dense), T itself
  3 x 8 m L bytes; the solver: reduced/nnls m^2 L + m^3/3 flops per channel; the paper's
  formulation a P x P Gram matrix (8 P (P - m + L) + 8 P^2 bytes, P^2 (P - m + L) + P^3 / 3 flops);
- the kernel estimator: m x C (target x candidate patch) pairs at KERNEL_SECONDS_PER_PAIR; the
  curve's lights' direct light again (pipeline.jobs.direct_stage): Max Lights + 1 lights, each P x
  its patches pairs, a fixed DIRECT_SECONDS_PER_LIGHT and DIRECT_SECONDS_PER_TRIANGLE per triangle;
- the candidate lamps (engine/candidate_lamps.py, at most their bound): each lamp's irradiance at
  LAMP_POINTS points on every patch it may reach (bounded by all), LAMP_SECONDS_PER_POINT each
  for a spot's (one shadow ray a point), ``lamp_work`` spots' worth in all (an area lamp takes 4
  rays a point, a beam 4 times the points: candidate_lamps.lamp_bound(work=True)); they add to L;
  offering them costs LAMP_SECONDS_PER_TRIANGLE per triangle; the refinement of the chosen lamps
  (engine/lamp_refinement.py): REFINE_EVALUATIONS_EXPECTED evaluations (fewer when at most k (k + 1)
  / 2 lamps for k = Max Lights would make fewer), each REFINE_SECONDS_PER_PATCH per patch and
  REFINE_SECONDS_PER_TRIANGLE per triangle, and the targets' rows of A^-1 (3 x 8 P m bytes);
- the reduction: about L^2 m flops, REDUCTION_SECONDS and REDUCTION_SECONDS_PER_LIGHT per candidate
  light; the curve: STORED_POINTS forward solves (2 P^2 each);
- the light colour's blackbody relaxation (Automatic, Blackbody): 3 m x CONE_POINTS L stacked
  columns, RELAXATION_COPIES times, RELAXATION_SECONDS_PER_ENTRY an entry;
- ray casting's working set: RAY_BYTES per ray in flight, at least one patch's rays (or
  formfactors.CHUNK_RAYS) per thread (measured with tracemalloc: 71-140 bytes per ray).

Rates measured on the 2-core test machine (docs/benchmarks.md, "Cost estimate": the estimate
against measured runs): RAYS_PER_SECOND, FLOPS (numpy/LAPACK, dense), and the per-triangle
costs. The estimate is meant to be right within a factor of 2 (measured 0.5-1.1 x on
benchmarks/bench_cost.py's scenes, issue 19; within 3 is the acceptance).
``check_memory`` refuses a solve whose estimate exceeds the machine's available memory.
"""
from __future__ import annotations

import os

import numpy as np

from .candidate_lamps import LAMP_POINTS
from .lamp_refinement import BUDGET as REFINE_BUDGET, MAX_EVALUATIONS as REFINE_EVALUATIONS, ROUNDS as REFINE_ROUNDS
from .lamp_refinement import SEARCH_POINTS
from .light_colour import CONE_POINTS, RELAXATION_BYTES
from .formfactors import CHUNK_RAYS, DENSE_LIMIT
from .inverse import DIRECT_SOLVE_LIMIT
from .options import REFINE_RAY_FRACTION, STORE_ALL_UP_TO, STORE_LOG_POINTS
from .patch_models.adaptive import CLUSTER_BELOW
from .registry import SOLVERS
from .extent import decisive_region, face_sizes, is_beyond, quad_cells, triangle_measures
from .scene import default_max_patch_size as scene_patch_size

__all__ = ["estimate_cost", "estimate_patches_cost", "format_bytes", "available_memory", "check_memory",
           "MEMORY_WARNING_BYTES", "SECONDS_WARNING", "RAYS_PER_SECOND", "FLOPS"]

RAYS_PER_SECOND = 3.0e6
#: dense LAPACK/BLAS on 2 threads (re-calibrated quiet, issue 7's staircase work: 5e9 had been
#: set under load; three 943-patch LUs run at about 4e10)
FLOPS = 1.0e10
#: meshing + Embree BVH + the scene arrays, per triangle (bytes) and its time (s)
BYTES_PER_TRIANGLE = 700.0
SECONDS_PER_TRIANGLE = 4e-6
ITERATIVE_SWEEPS = 25  # measured: the sweeps stop well before the worst case (rate^n < tol)
#: sparse F: distinct receivers per row, measured about N/6 + 1 (154 for N = 1024 in a room)
NNZ_PER_RAY = 0.25
#: the job's fixed memory (the engine's modules, Embree's device) over the scene
BASE_BYTES = 60 * 2 ** 20
#: the kernel estimator per target x candidate pair at its defaults (100 penumbra points x 2 rays;
#: measured 1-2e-5 on the 2-core machine, issue 19; 4e-5 at 256 x 4)
KERNEL_SECONDS_PER_PAIR = 1.5e-5
#: the curve's surface lights whose direct light on every patch the kernel computes again (at most;
#: pipeline.jobs.direct_stage); measured: Max Lights + 1 at most on the bench_cost scenes (2-5)
DIRECT_LIGHTS = 48
#: a surface light of at least this many patches (a cluster's, a polygon's: spread) keeps the
#: ray-cast form factors' gather of its direct light, which many rays make: the kernel's differs
#: from it by 1.6-2.3 % on the living room's lights of 96-180 patches, against 4-35 % on its
#: lights of 1-6 patches, and costs its patches x every patch in kernel pairs (13 s of a 21 s
#: solve there after three strokes, 271 s of 291 s on the 1M-triangle room; docs/benchmarks.md,
#: "Live"). On the staircase every light is one patch.
DIRECT_SPREAD_PATCHES = 16
#: the blackbody relaxation (light colour Automatic's choice, Blackbody's certificate:
#: light_colour.relaxed_bound): its stacked columns, 3 m rows x CONE_POINTS L (at most
#: light_colour.RELAXATION_BYTES), about RELAXATION_COPIES times in memory (the columns, the
#: reachable ones, NNLS's own) and RELAXATION_SECONDS_PER_ENTRY a column entry. Measured, Automatic
#: against Free, one run each: the 32 x 32 ceiling's 432 x 10,413 columns +153 MB and +1.37 s; the
#: living room 22k's 180 x 7,641 +0.3 s, the staircase's 132 x 6,858 +0.2 s (their peak elsewhere)
RELAXATION_COPIES = 4.25
RELAXATION_SECONDS_PER_ENTRY = 3.0e-7
#: per such light: a fixed part (the kernel's set-up) and a part per triangle of the scene (the
#: receivers' quadrature, triangle by triangle) (s; measured, issue 19)
DIRECT_SECONDS_PER_LIGHT = 0.05
DIRECT_SECONDS_PER_TRIANGLE = 2e-6
#: a candidate lamp's irradiance per receiver point (sampling, the lamp's light, its shadow ray; measured)
LAMP_SECONDS_PER_POINT = 3e-7
#: offering the candidate lamps, per triangle of the scene (their reach and mounting; measured)
LAMP_SECONDS_PER_TRIANGLE = 7e-6
#: the lamp refinement: the evaluations a solve makes (measured 120 for one refined lamp, 359 for
#: three; BUDGET at most) and each one's cost per patch (its receiver points, the (P, m) products) and
#: per triangle (a lamp's solid angle over every triangle it reaches) (measured, issue 19)
REFINE_EVALUATIONS_EXPECTED = 180
REFINE_SECONDS_PER_PATCH = 4.6e-6
REFINE_SECONDS_PER_TRIANGLE = 4.2e-7
#: the reduction (Best k Lights' search and its certificate): a fixed part and per candidate light (s)
REDUCTION_SECONDS = 0.2
REDUCTION_SECONDS_PER_LIGHT = 5e-4
STORED_POINTS = STORE_ALL_UP_TO + STORE_LOG_POINTS  # at most, up to the ~40 log-spaced ones
#: working memory per ray in flight (origins, directions, hits, the Sobol pool), bytes
RAY_BYTES = 96
MEMORY_WARNING_BYTES = 4 * 1024 ** 3
SECONDS_WARNING = 60.0


def format_bytes(n: float) -> str:
    if n >= 1024 ** 6:  # beyond any machine: an order of magnitude is enough
        return f"{n / 1024 ** 5:.2g} PB"
    for unit, size in (("PB", 1024 ** 5), ("TB", 1024 ** 4), ("GB", 1024 ** 3), ("MB", 1024 ** 2), ("kB", 1024)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} B"


def _count(name, value):
    try:
        v = int(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}") from None
    if v < 0 or v != value:
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    return v


def _solve_parts(parts, kind, P, m, L, k, g, nnz, passes, flops) -> float:
    """estimate_cost's parts of the radiosity system's factorisation (or iterative sweeps) and of the
    inverse problem (the paper's, or the transfer of the ``k`` targets' rows); returns the time of
    one right-hand side's solve (flops)."""
    P2 = float(P) * P
    if P <= DIRECT_SOLVE_LIMIT:
        parts["lu"] = (g * 8.0 * P2 + 8.0 * P2, g * (2.0 / 3.0) * P2 * P * (passes + 1) / flops)
        t_rhs = 2.0 * P2
    else:  # iterative sweeps: F in float64 (and its transpose) plus the iterates
        parts["lu"] = (16.0 * nnz, 0.0)
        t_rhs = ITERATIVE_SWEEPS * 2.0 * nnz
    if kind == "paper":
        cols = P - m + L
        parts["inverse"] = (8.0 * P * cols + 8.0 * P2, g * (P2 * cols + P2 * P / 3.0) / flops)
    else:
        parts["inverse"] = (3 * 8.0 * m * L + 3 * 8.0 * P * k + 8.0 * m * m,
                            (g * t_rhs * k * (passes + 1) + 3 * (float(m) * m * L + float(m) ** 3 / 3.0)) / flops)
    return t_rhs


def _kernel_parts(parts, P, m, C, tris, passes, max_lights, patches_per_light) -> None:
    """estimate_cost's parts of the kernel transfer: its pairs, and the curve's lights' direct light
    on every patch (pipeline.jobs.direct_stage)."""
    pairs = float(m) * C
    parts["kernel"] = (8.0 * 4 * pairs, pairs * KERNEL_SECONDS_PER_PAIR * (passes + 1))
    n_direct = min(C, DIRECT_LIGHTS, max(int(max_lights), 1) + 1)
    pairs = float(P) * min(C, n_direct * min(max(float(patches_per_light), 1.0), DIRECT_SPREAD_PATCHES - 1))
    parts["direct_light"] = (8.0 * 2 * pairs, pairs * KERNEL_SECONDS_PER_PAIR
                             + n_direct * (DIRECT_SECONDS_PER_LIGHT + DIRECT_SECONDS_PER_TRIANGLE * tris))


def _lamp_parts(parts, P, m, n_lamps, lamp_work, refinements, tris, passes) -> None:
    """estimate_cost's parts of the candidate lamps (their direct irradiance: receiver points on
    every patch, a shadow ray each at most) and of their refinement (each evaluation a lamp's
    shadow rays on every patch and its light over the triangles)."""
    if n_lamps:
        points = float(lamp_work) * P * LAMP_POINTS
        parts["lamps"] = (8.0 * 3 * P * n_lamps + RAY_BYTES * P * LAMP_POINTS * 16,
                          (points * LAMP_SECONDS_PER_POINT + LAMP_SECONDS_PER_TRIANGLE * tris) * (passes + 1))
    if refinements:
        evaluations = min(float(refinements) * REFINE_ROUNDS * REFINE_EVALUATIONS, REFINE_BUDGET,
                          REFINE_EVALUATIONS_EXPECTED)
        parts["lamp_refinement"] = (3 * 8.0 * P * m, evaluations * (REFINE_SECONDS_PER_PATCH * P
                                                                    + REFINE_SECONDS_PER_TRIANGLE * tris))


def estimate_cost(n_patches: int, rays_per_patch: int, n_candidates: int, n_targets: int,
                  solver: str = "reduced", n_lights: int | None = None, n_triangles: int = 0,
                  refine_passes: int = 0, channel_groups: int = 3, kernel: bool = False,
                  rays_per_second: float = RAYS_PER_SECOND,
                  flops: float = FLOPS, memory_limit: float = MEMORY_WARNING_BYTES,
                  seconds_limit: float = SECONDS_WARNING, dense_limit: int = DENSE_LIMIT,
                  threads: int | None = None, n_lamps: int = 0, lamp_work: int | None = None,
                  lamp_refinements: int = 0, max_lights: int = 3, patches_per_light: float = 1.0,
                  colour_relaxation: bool = False) -> dict:
    """Peak memory (bytes) and time (s) estimate of a solve; see the module docstring.

    ``lamp_work``: the candidate lamps' receiver-point work in spots' (default ``n_lamps``).
    ``max_lights``: Max Lights (the curve's lights whose direct light is computed again);
    ``patches_per_light``: the mean patches of a surface light (1: cells; a polygon's otherwise).
    ``colour_relaxation``: the light colour's blackbody relaxation runs (Automatic, Blackbody).
    Returns ``{"memory_bytes", "seconds", "warnings": [str], "parts": {name: (bytes, seconds)}}``;
    ``warnings`` is empty unless memory > ``memory_limit`` or time > ``seconds_limit``.
    """
    P = _count("n_patches", n_patches)
    N = _count("rays_per_patch", rays_per_patch)
    C = _count("n_candidates", n_candidates)
    m = _count("n_targets", n_targets)
    n_lamps = _count("n_lamps", n_lamps)
    lamp_work = n_lamps if lamp_work is None else _count("lamp_work", lamp_work)
    refinements = _count("lamp_refinements", lamp_refinements)
    L = (C if n_lights is None else _count("n_lights", n_lights)) + n_lamps
    tris = _count("n_triangles", n_triangles)
    passes = _count("refine_passes", refine_passes)
    g = max(1, min(3, int(channel_groups)))
    kind = SOLVERS[solver].traits.cost  # ValueError for an unknown solver
    if not (rays_per_second > 0 and flops > 0):
        raise ValueError("rays_per_second and flops must be positive")
    P2 = float(P) * P
    parts = {}
    parts["scene"] = (BASE_BYTES + BYTES_PER_TRIANGLE * tris, SECONDS_PER_TRIANGLE * tris * (passes + 1))
    nnz = P2 if P <= dense_limit else float(P) * min(P, NNZ_PER_RAY * N + 64)
    ff_bytes = 4.0 * P2 if P <= dense_limit else 8.0 * nnz + 8.0 * (P + 1)
    rays = float(P) * N * (1.0 + passes / REFINE_RAY_FRACTION)
    parts["form_factors"] = (ff_bytes, rays / rays_per_second)
    if kernel:
        _kernel_parts(parts, P, m, C, tris, passes, max_lights, patches_per_light)
    _lamp_parts(parts, P, m, n_lamps, lamp_work, refinements, tris, passes)
    t_rhs = _solve_parts(parts, kind, P, m, L, min(m, C), g, nnz, passes, flops)
    if colour_relaxation:
        columns = min(8.0 * 3 * m * CONE_POINTS * L, RELAXATION_BYTES)
        parts["light_colour"] = (RELAXATION_COPIES * columns, RELAXATION_SECONDS_PER_ENTRY * columns / 8.0)
    parts["reduction"] = (8.0 * L * L, float(L) * L * max(m, 1) * 8.0 / flops
                          + REDUCTION_SECONDS + REDUCTION_SECONDS_PER_LIGHT * L)
    parts["curve"] = (8.0 * 3 * STORED_POINTS * (P + L), g * STORED_POINTS * t_rhs / flops)
    parts["rays"] = (RAY_BYTES * float(max(N, CHUNK_RAYS)) * (threads or os.cpu_count() or 1), 0.0)
    memory = sum(b for b, _ in parts.values())
    seconds = sum(s for _, s in parts.values())
    warnings = []
    if memory > memory_limit:
        warnings.append(f"this solve needs about {format_bytes(memory)} of memory ({P} patches); "
                        "use a larger patch size or light size (fewer patches) to reduce it")
    if seconds > seconds_limit:
        warnings.append(f"this solve may take about {seconds:.0f} s ({P} patches, {N} rays per patch); "
                        "use a larger patch size or fewer rays per patch to speed it up")
    return {"memory_bytes": float(memory), "seconds": float(seconds), "warnings": warnings, "parts": parts}


def estimate_patches_cost(patches, rays_per_patch=None, solver: str = "reduced", n_lights=None,
                          n_triangles=0, refine_passes=0, kernel=False, **kw) -> dict:
    """:func:`estimate_cost` of a meshed PatchSet: candidates as engine.lights.candidate_mask,
    targets = target patches; ``rays_per_patch`` None = the automatic quality, or a
    formfactors.QUALITY name."""
    import numpy as np

    from .formfactors import QUALITY, auto_rays_per_patch
    from .lights import candidate_mask

    P = patches.n_patches
    if rays_per_patch is None:
        rays_per_patch = auto_rays_per_patch(P, kernel=kernel)
    elif isinstance(rays_per_patch, str):
        if rays_per_patch not in QUALITY:
            raise ValueError(f"unknown quality {rays_per_patch!r}; use one of {sorted(QUALITY)}")
        rays_per_patch = QUALITY[rays_per_patch]
    n_candidates = int(np.sum(candidate_mask(patches, "inverse")))
    groups = len({tuple(patches.reflectance[:, c]) for c in range(3)}) if P else 1
    return estimate_cost(P, int(rays_per_patch), n_candidates, int(np.sum(patches.target)), solver=solver,
                         n_lights=n_lights, n_triangles=n_triangles, refine_passes=refine_passes,
                         channel_groups=groups, kernel=kernel, **kw)


def available_memory() -> float:
    """Bytes of memory available to a new solve: Linux MemAvailable, else the physical memory."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return float("inf")


def check_memory(cost: dict, what: str = "this solve"):
    """Raise ValueError (one line, for the user) when the estimate exceeds the available memory;
    returns ``cost``."""
    avail = available_memory()
    if cost["memory_bytes"] > avail:
        raise ValueError(f"{what} would need about {format_bytes(cost['memory_bytes'])} of memory "
                         f"(estimate), more than the {format_bytes(avail)} available: use a larger patch size "
                         "or light size, or fewer rays per patch")
    return cost


#: estimates before meshing are capped here (a patch size of TINY m would overflow)
_MAX_COUNT = 1e30


def estimate_patch_count(faces, options, default_max_patch_size=None,
                         certain: bool = False) -> float:
    """How many patches the job's patch model makes of ``faces``, from the faces alone (no
    meshing): a face no larger than its size is one patch, a larger quad an nu x nv grid, any
    other face k x k pieces per triangle (engine.scene.split_faces); exact for the polygon model.
    The adaptive model's candidate faces use the light size, and its faces below half their size
    are clustered: ``certain`` counts those as none (a lower bound), else one each (an upper one)."""
    size = options.max_patch_size if options.max_patch_size is not None else default_max_patch_size
    if size is None:
        size = scene_patch_size(faces)
    F = faces.n_faces
    s = np.full(F, float(size))
    if options.patch_model == "adaptive":
        cand = ~faces.forbidden & ~np.any(faces.exitance > 0, axis=1)
        s[cand] = float(options.light_size or size)
    s = face_sizes(faces, s)
    V = faces.vertices
    m = triangle_measures(faces)  # the meshing's own (shared, not measured again)
    edge, face_edge = m.edge, m.face_edge
    with np.errstate(over="ignore", invalid="ignore"):
        tf = faces.triangle_face
        k = np.maximum(np.ceil(np.minimum(edge / s[tf], _MAX_COUNT)), 1.0)
        per_tri = np.bincount(tf, weights=np.minimum(k * k, _MAX_COUNT), minlength=F)
        count = np.where(face_edge <= s, 1.0, per_tri)
        if certain and options.patch_model == "adaptive":
            count[face_edge <= CLUSTER_BELOW * s] = 0.0
        quad = np.flatnonzero((faces.loop_total == 4) & (face_edge > s))
        if len(quad):
            p = V[faces.loop_vertices[faces.loop_start[quad][:, None] + np.arange(4)]]
            d = lambda a, b: np.linalg.norm(p[:, a] - p[:, b], axis=1)  # noqa: E731
            nu = np.maximum(np.ceil(np.minimum(np.maximum(d(1, 0), d(2, 3)) / s[quad], _MAX_COUNT)), 1.0)
            nv = np.maximum(np.ceil(np.minimum(np.maximum(d(3, 0), d(2, 1)) / s[quad], _MAX_COUNT)), 1.0)
            count[quad] = np.minimum(nu * nv, _MAX_COUNT)
            region = decisive_region(faces)
            for i in np.flatnonzero(np.maximum(np.maximum(d(1, 0), d(2, 3)), np.maximum(d(3, 0), d(2, 1)))
                                    > region.diagonal):  # larger than the region: its quadtree
                if is_beyond(region, p[i]):
                    count[quad[i]] = len(quad_cells(region, p[i], s[quad[i]]))
    return float(min(max(count.sum(), 1.0), _MAX_COUNT))
