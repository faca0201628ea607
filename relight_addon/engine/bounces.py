"""How many bounces a path tracer needs to show the converged radiosity, and what fewer cost
(pure math, no bpy).

The radiosity B = e + rho F B is the Neumann series B = sum_k (rho F)^k e: the term k is the
light that reflected k times (the k-th reflection at the face itself). Cycles with a Diffuse
bounce limit D keeps the terms k <= D + 1: its kernel limit is the setting + 1
(scene/integrator.cpp), a path stops after that many diffuse bounces and only collects the
emission it then hits (kernel/integrator/path_state.h ``path_state_next``, shade_surface.h),
and the last vertex's emission completes the term D + 1 (next-event estimation at the vertex
before). Checked against Cycles on a closed emitting box (tests/test_light_paths.py):
limit 1 renders 1 + rho + rho^2 times the emission, limit 2 adds rho^3.

- ``required_bounces(rho_max)``: the smallest Diffuse bounce setting D with
  rho_max^(D + 2) <= tail (default 0.5 %): in a closed scene of reflectance rho the missing
  tail B - B_(D+1) is rho^(D+2) B; rho_max (the largest reflectance) bounds the spectral radius
  of rho F, so the tail is at most that everywhere.
- ``truncated_radiosity(F, rho, B, n)``: B_n = sum_{k<=n} (rho F)^k e from the converged B
  (e = B - rho F B), n products with F.
- ``bounce_deficit``: B_n against B on chosen patches (area-weighted mean and the worst patch).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["TAIL", "MAX_BOUNCES", "kept_terms", "required_bounces", "exitance_of", "truncated_radiosity", "bounce_deficit",
           "matvec"]

TAIL = 0.005
#: Cycles' largest bounce limit
MAX_BOUNCES = 1024


def kept_terms(limit: int) -> int:
    """Neumann terms (reflections) Cycles keeps with a bounce limit ``limit``: limit + 1."""
    return int(limit) + 1


def required_bounces(rho_max: float, tail: float = TAIL) -> int:
    """Smallest bounce setting D >= 1 with rho_max^(D + 2) <= tail (capped at MAX_BOUNCES)."""
    rho = float(rho_max)
    if not rho > 0:
        return 1
    if rho >= 1:
        return MAX_BOUNCES
    n = math.ceil(math.log(tail) / math.log(rho) - 1e-12)  # rho^n <= tail
    return int(min(MAX_BOUNCES, max(1, n - 2)))


def matvec(F, x):
    """F x in float64 (F: an operator with ``matvec``, or a dense or sparse matrix). A float32 F
    multiplies x in float32 (numpy would otherwise copy the whole of F to float64 for each product:
    a dense F of 2,300 patches is 21 MB), its result rounded to 1e-7 relative."""
    if hasattr(F, "matvec"):
        return F.matvec(x)
    if getattr(F, "dtype", None) == np.float32:
        return np.asarray(F @ np.asarray(x, dtype=np.float32), dtype=np.float64)
    return np.asarray(F @ x, dtype=np.float64)


def exitance_of(F, reflectance, B) -> np.ndarray:
    """(P, 3) e = B - rho F B: the exitance that gives the converged radiosity B."""
    return np.asarray(B, dtype=np.float64) - np.asarray(reflectance, dtype=np.float64) * matvec(F, B)


def truncated_radiosity(F, reflectance, B, n: int, exitance=None) -> np.ndarray:
    """(P, 3) sum_{k=0}^{n} (rho F)^k e with e = B - rho F B (the exitance that gives the
    converged radiosity B; ``exitance``: it, when the caller has it): what a path tracer keeping
    n reflections shows (Cycles: a bounce limit of n - 1, ``kept_terms``)."""
    rho = np.asarray(reflectance, dtype=np.float64)
    term = exitance_of(F, rho, B) if exitance is None else np.asarray(exitance, dtype=np.float64)
    total = term.copy()
    for _ in range(int(n)):
        term = rho * matvec(F, term)
        total += term
    return total


def bounce_deficit(F, reflectance, B, n: int, mask=None, area=None, exitance=None) -> dict:
    """Relative difference (B_n - B) / B of the truncated radiosity on the patches ``mask``
    (default: all): ``mean`` the area-weighted one over them (RGB summed) and ``min`` the worst
    patch (most negative). ``exitance``: truncated_radiosity's."""
    B = np.asarray(B, dtype=np.float64)
    P = len(B)
    mask = np.ones(P, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    area = np.ones(P) if area is None else np.asarray(area, dtype=np.float64)
    Bn = truncated_radiosity(F, reflectance, B, n, exitance)
    b, bn = B[mask].sum(axis=1), Bn[mask].sum(axis=1)
    a = area[mask]
    lit = b > 0
    if not np.any(lit):
        return {"reflections": int(n), "mean": 0.0, "min": 0.0}
    mean = float(np.sum(a[lit] * bn[lit]) / np.sum(a[lit] * b[lit]) - 1.0)
    worst = float(np.min(bn[lit] / b[lit] - 1.0))
    return {"reflections": int(n), "mean": mean, "min": worst}
