"""Memory and time estimate of a solve, before any work (no bpy).

``estimate_cost(n_patches, rays_per_patch, n_candidates, n_targets)`` adds up the big
terms of a solve (jobs.run_solve) from the sizes alone:

- form factors F: float32, dense P x P (4 P^2 bytes) when P <= DENSE_LIMIT, else CSR with at
  most min(P, rays per patch) non-zeros per row (float32 value + int32 column: 8 bytes
  each); ray casting time = P x rays per patch / RAYS_PER_SECOND.
- the radiosity system A = I - rho F per colour channel and its LU factors. Dense (P <=
  DENSE_LIMIT, scipy lu_factor): 3 x 8 P^2 bytes kept (the three factorisations) plus one
  8 P^2 working copy; 3 x 2/3 P^3 flops. Sparse (splu): A has nnz = P x min(P, HIT_FRACTION x
  rays per patch) (the distinct patches a patch's rays hit), its factors about LU_FILL times
  that (at most P^2): 12 bytes per non-zero (value + index), nnz(LU)^2 / P flops at FLOPS x
  SPLU_SPEED, per channel. Measured (benchmarks/bench_sparse_lu.py, docs/benchmarks.md "Sparse
  LU"): nnz(A)/P = 0.53-0.71 x 1024 rays, fill 10.1-14.7, LU memory within 0.7-1.15 x the model,
  splu's time 0.35-3 x the model on the Cornell box and the staircase at 6-13 k patches (their
  factors fill to near dense; scenes with much occlusion fill less: pessimistic there).
- ray casting's working set: RAY_BYTES per ray in flight, at least one patch's rays (or
  formfactors.CHUNK_RAYS) per thread.
- the transfer matrix T (rows P, columns C of A^-1; solvers registered with cost="transfer"): 3 x 8 m C
  bytes, 3 x 2 nnz(LU) min(m, C) flops of triangular solves (nnz(LU) = P^2 when dense), and its
  minimum-norm solve (Gram matrix m x m: m^2 C + m^3/3 flops per channel).
- the paper's formulation (a solver registered with cost="paper": "svd") instead builds M = [A_U | -I_C] (P x (P - m + C))
  and its Gram matrix P x P: 8 P (P - m + C) + 8 P^2 bytes, P^2 (P - m + C) + P^3/3 flops
  per channel.
The reduction (selection x distribution) and the curve are not counted: they scale with the
candidates and are small next to the terms above for the paper's scenes.

Rates: RAYS_PER_SECOND = 3e6 (docs/benchmarks.md "Form factors": 2.1 to 4.6 M rays/s on
2 cores under load) and FLOPS = 5e9 (scipy LU of a 2000 x 2000 matrix on the 2-core test
machine under load: 7 GFLOP/s). The estimate is meant to be right to a factor of a few.
Thresholds: MEMORY_WARNING_BYTES (4 GB) and SECONDS_WARNING (60 s) give a warning text.

``memory_floor_bytes``: what the solve allocates for sure (the patches, the form factors'
minimum, dense matrices when P <= DENSE_LIMIT, one patch's rays): the callers refuse a job
whose floor exceeds the machine's memory, before any work; ``memory_bytes`` (which may be
pessimistic) only warns.
"""
from __future__ import annotations

from .formfactors import DENSE_LIMIT
from .registry import SOLVERS

__all__ = ["estimate_cost", "estimate_patches_cost", "format_bytes", "MEMORY_WARNING_BYTES", "SECONDS_WARNING",
           "RAYS_PER_SECOND", "FLOPS"]

RAYS_PER_SECOND = 3.0e6
FLOPS = 5.0e9
#: sparse systems: distinct patches hit per ray cast, fill-in of the LU factors, and splu's
#: speed relative to FLOPS (measured, see the module docstring)
HIT_FRACTION = 0.6
LU_FILL = 12.0
SPLU_SPEED = 0.5
#: working memory per ray in flight (origins, directions, hits, sample pool), bytes
RAY_BYTES = 96
#: memory per patch of the meshed scene (triangles, attributes, maps), bytes
PATCH_BYTES = 400
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


def estimate_cost(n_patches: int, rays_per_patch: int, n_candidates: int, n_targets: int,
                  solver: str = "reduced", rays_per_second: float = RAYS_PER_SECOND, flops: float = FLOPS,
                  memory_limit: float = MEMORY_WARNING_BYTES, seconds_limit: float = SECONDS_WARNING,
                  dense_limit: int = DENSE_LIMIT, threads: int | None = None) -> dict:
    """Peak memory (bytes) and time (s) estimate of a solve; see the module docstring.

    Returns ``{"memory_bytes", "memory_floor_bytes", "seconds", "warnings": [str], "parts":
    {name: (bytes, seconds)}}``; ``warnings`` is empty unless memory > ``memory_limit`` or time
    > ``seconds_limit``. Counts may be floats (estimates before meshing).
    """
    P = _count("n_patches", n_patches)
    N = _count("rays_per_patch", rays_per_patch)
    C = _count("n_candidates", n_candidates)
    m = _count("n_targets", n_targets)
    kind = SOLVERS[solver].get("cost", "transfer")  # ValueError for an unknown solver
    if not (rays_per_second > 0 and flops > 0):
        raise ValueError("rays_per_second and flops must be positive")
    import os

    from .formfactors import CHUNK_RAYS

    P2 = float(P) * P
    parts = {}
    dense = P <= dense_limit
    row = min(float(P), HIT_FRACTION * N + 1.0)  # non-zeros per row of a sparse F (A: + the diagonal)
    ff_bytes = 4.0 * P2 if dense else 8.0 * P * row + 8.0 * (P + 1)
    parts["form_factors"] = (ff_bytes, float(P) * N / rays_per_second)
    if dense:
        parts["lu"] = (3 * 8.0 * P2 + 8.0 * P2, 3 * (2.0 / 3.0) * P2 * P / flops)
    else:
        nnz_lu = min(P2, LU_FILL * P * row)
        parts["lu"] = (3 * 12.0 * nnz_lu + 12.0 * P * row, 3 * nnz_lu * nnz_lu / max(P, 1) / (flops * SPLU_SPEED))
    in_flight = float(max(N, CHUNK_RAYS)) * (threads or os.cpu_count() or 1)
    parts["rays"] = (RAY_BYTES * in_flight, 0.0)
    parts["patches"] = (PATCH_BYTES * float(P), 0.0)
    k = min(m, C)
    if kind == "paper":
        cols = P - m + C
        parts["inverse"] = (8.0 * P * cols + 8.0 * P2, 3 * (P2 * cols + P2 * P / 3.0) / flops)
    else:
        solve = P2 if dense else min(P2, LU_FILL * P * row)  # flops/2 of one solve with the factors
        parts["inverse"] = (3 * 8.0 * m * C + 8.0 * P * k + 8.0 * m * m,
                            3 * (2.0 * solve * k + float(m) * m * C + float(m) ** 3 / 3.0) / flops)
    memory = sum(b for b, _ in parts.values())
    seconds = sum(s for _, s in parts.values())
    floor = PATCH_BYTES * float(P) + RAY_BYTES * float(N) + (4.0 * P2 + 8.0 * P2 if dense else 12.0 * P)
    warnings = []
    if memory > memory_limit:
        warnings.append(f"this solve needs about {format_bytes(memory)} of memory ({P} patches); "
                        "use a larger patch size (fewer patches) to reduce it")
    if seconds > seconds_limit:
        warnings.append(f"this solve may take about {seconds:.0f} s ({P} patches, {N} rays per patch); "
                        "use a larger patch size or fewer rays per patch to speed it up")
    return {"memory_bytes": float(memory), "memory_floor_bytes": float(floor), "seconds": float(seconds),
            "warnings": warnings, "parts": parts}


def estimate_patches_cost(patches, rays_per_patch=None, solver: str = "reduced", **kw) -> dict:
    """:func:`estimate_cost` of a meshed PatchSet: candidates = patches not forbidden and not
    emitting (engine.lights.candidate_mask), targets = target patches; ``rays_per_patch`` None = the
    automatic quality, or a formfactors.QUALITY name."""
    import numpy as np

    from .formfactors import QUALITY, auto_rays_per_patch
    from .lights import candidate_mask

    P = patches.n_patches
    if rays_per_patch is None:
        rays_per_patch = auto_rays_per_patch(P)
    elif isinstance(rays_per_patch, str):
        if rays_per_patch not in QUALITY:
            raise ValueError(f"unknown quality {rays_per_patch!r}; use one of {sorted(QUALITY)}")
        rays_per_patch = QUALITY[rays_per_patch]
    n_candidates = int(np.sum(candidate_mask(patches, "inverse")))
    return estimate_cost(P, int(rays_per_patch), n_candidates, int(np.sum(patches.target)), solver=solver, **kw)
