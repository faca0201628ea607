"""Memory and time estimate of a solve, before any work (no bpy).

``estimate_cost(n_patches, rays_per_patch, n_candidates, n_targets)`` adds up the big
terms of a solve (jobs.run_solve) from the sizes alone:

- form factors F: float32, dense P x P (4 P^2 bytes) when P <= DENSE_LIMIT, else CSR with at
  most min(P, rays per patch) non-zeros per row (float32 value + int32 column: 8 bytes
  each); ray casting time = P x rays per patch / RAYS_PER_SECOND.
- the radiosity system A = I - rho F per colour channel: a dense float64 copy and its LU
  factors (scipy lu_factor / splu; sparse F gives nearly dense LU factors once filled in,
  so both are counted dense): 3 x 8 P^2 bytes kept (the three factorisations) plus one
  8 P^2 working copy; 3 x 2/3 P^3 flops.
- the transfer matrix T (rows P, columns C of A^-1; solvers registered with cost="transfer"): 3 x 8 m C
  bytes, 3 x 2 P^2 min(m, C) flops of triangular solves, and its minimum-norm solve (Gram
  matrix m x m: m^2 C + m^3/3 flops per channel).
- the paper's formulation (a solver registered with cost="paper": "svd") instead builds M = [A_U | -I_C] (P x (P - m + C))
  and its Gram matrix P x P: 8 P (P - m + C) + 8 P^2 bytes, P^2 (P - m + C) + P^3/3 flops
  per channel.
The reduction (selection x distribution) and the curve are not counted: they scale with the
candidates and are small next to the terms above for the paper's scenes.

Rates: RAYS_PER_SECOND = 3e6 (docs/benchmarks.md "Form factors": 2.1 to 4.6 M rays/s on
2 cores under load) and FLOPS = 5e9 (scipy LU of a 2000 x 2000 matrix on the 2-core test
machine under load: 7 GFLOP/s). The estimate is meant to be right to a factor of a few.
Thresholds: MEMORY_WARNING_BYTES (4 GB) and SECONDS_WARNING (60 s) give a warning text.
"""
from __future__ import annotations

from .formfactors import DENSE_LIMIT
from .registry import SOLVERS

__all__ = ["estimate_cost", "estimate_patches_cost", "format_bytes", "MEMORY_WARNING_BYTES", "SECONDS_WARNING",
           "RAYS_PER_SECOND", "FLOPS"]

RAYS_PER_SECOND = 3.0e6
FLOPS = 5.0e9
MEMORY_WARNING_BYTES = 4 * 1024 ** 3
SECONDS_WARNING = 60.0


def format_bytes(n: float) -> str:
    for unit, size in (("GB", 1024 ** 3), ("MB", 1024 ** 2), ("kB", 1024)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} B"


def _count(name, value):
    try:
        v = int(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}") from None
    if v < 0 or v != value:
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    return v


def estimate_cost(n_patches: int, rays_per_patch: int, n_candidates: int, n_targets: int,
                  solver: str = "reduced", rays_per_second: float = RAYS_PER_SECOND, flops: float = FLOPS,
                  memory_limit: float = MEMORY_WARNING_BYTES, seconds_limit: float = SECONDS_WARNING,
                  dense_limit: int = DENSE_LIMIT) -> dict:
    """Peak memory (bytes) and time (s) estimate of a solve; see the module docstring.

    Returns ``{"memory_bytes", "seconds", "warnings": [str], "parts": {name: (bytes, seconds)}}``;
    ``warnings`` is empty unless memory > ``memory_limit`` or time > ``seconds_limit``.
    """
    P = _count("n_patches", n_patches)
    N = _count("rays_per_patch", rays_per_patch)
    C = _count("n_candidates", n_candidates)
    m = _count("n_targets", n_targets)
    kind = SOLVERS[solver].get("cost", "transfer")  # ValueError for an unknown solver
    if not (rays_per_second > 0 and flops > 0):
        raise ValueError("rays_per_second and flops must be positive")
    P2 = float(P) * P
    parts = {}
    ff_bytes = 4.0 * P2 if P <= dense_limit else 8.0 * P * min(P, N) + 8.0 * (P + 1)
    parts["form_factors"] = (ff_bytes, float(P) * N / rays_per_second)
    parts["lu"] = (3 * 8.0 * P2 + 8.0 * P2, 3 * (2.0 / 3.0) * P2 * P / flops)
    k = min(m, C)
    if kind == "paper":
        cols = P - m + C
        parts["inverse"] = (8.0 * P * cols + 8.0 * P2, 3 * (P2 * cols + P2 * P / 3.0) / flops)
    else:
        parts["inverse"] = (3 * 8.0 * m * C + 8.0 * P * k + 8.0 * m * m,
                            3 * (2.0 * P2 * k + float(m) * m * C + float(m) ** 3 / 3.0) / flops)
    memory = sum(b for b, _ in parts.values())
    seconds = sum(s for _, s in parts.values())
    warnings = []
    if memory > memory_limit:
        warnings.append(f"this solve needs about {format_bytes(memory)} of memory ({P} patches); "
                        "use a larger patch size (fewer patches) to reduce it")
    if seconds > seconds_limit:
        warnings.append(f"this solve may take about {seconds:.0f} s ({P} patches, {N} rays per patch); "
                        "use a larger patch size or fewer rays per patch to speed it up")
    return {"memory_bytes": float(memory), "seconds": float(seconds), "warnings": warnings, "parts": parts}


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
