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

__all__ = ["TAIL", "MAX_BOUNCES", "ColumnProducts", "kept_terms", "required_bounces", "exitance_of",
           "truncated_radiosity", "bounce_deficit", "matvec"]

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


class ColumnProducts:
    """(rho F) x and (rho F)^(n+1) x for every column x of a fixed basis ``T`` (3 arrays (P, L),
    one per channel: the transfer from every light to every patch) and for a fixed radiosity
    ``B0`` (P, 3). A Live stroke's radiosity is B = B0 + T e with a few lights on, so its exitance
    e = B - rho F B and its truncation B_n = B - (rho F)^(n+1) B (the telescoped Neumann sum:
    truncated_radiosity's) are sums of a few columns of two tables made once per n, in n + 1
    products of F with all 3 L columns together (``table``; Live's worker makes it before the
    first stroke). One product of a 2,305-patch F with 2,547 columns takes about what 6 products
    with 3 columns take (F is streamed once, a matrix product not a memory-bound matrix-vector
    one): the living room's table in 0.8 s; a stroke's check then needs no product with F
    (15-18 ms per stroke before, with new lights). The tables are kept in float32 (the products
    of a float32 F are float32: ``matvec``): 2 x 4 x P x 3 L bytes, 47 MB for the living room."""

    def __init__(self, F, reflectance, T):
        self.F, self.rho, self.T = F, np.asarray(reflectance, dtype=np.float64), T
        self.tables = {}  # n -> (rho F T, (rho F)^(n+1) T), each (P, 3, L) float32
        self.base = {}  # n -> (B0, its two products)

    def _products(self, X, n):
        """X (P, 3, k) per channel -> ((rho F) X, (rho F)^(n+1) X), one product with F a step."""
        P, _, k = X.shape
        first = cur = None
        for step in range(int(n) + 1):
            src = X if cur is None else cur
            cur = (self.rho[:, :, None] * matvec(self.F, src.reshape(P, 3 * k)).reshape(P, 3, k)).astype(X.dtype)
            if step == 0:
                first = cur
        return first, cur

    def table(self, n: int):
        """(rho F T, (rho F)^(n+1) T), each (P, 3, L) float32, made at the first call for ``n``."""
        n = int(n)
        if n not in self.tables:
            X = np.stack([np.asarray(t, dtype=np.float32) for t in self.T], axis=1)  # (P, 3, L)
            self.tables[n] = self._products(X, n)
        return self.tables[n]

    def of(self, B0, e, n: int):
        """(rho F B, (rho F)^(n+1) B) (P, 3) of B = B0 + T e (``e`` (L, 3): the lights' strengths)."""
        e = np.asarray(e, dtype=np.float64)
        first_t, tail_t = self.table(n)
        base = self.base.get(n)
        if base is None or base[0] is not B0:  # (the fixed light's: another after a lamp moved)
            first, tail = self._products(np.asarray(B0, dtype=np.float64)[:, :, None], n)
            base = self.base[n] = (B0, first[:, :, 0], tail[:, :, 0])
        on = np.flatnonzero(np.any(e != 0, axis=1))
        first = base[1] + np.einsum("pcl,lc->pc", first_t[:, :, on], e[on])
        tail = base[2] + np.einsum("pcl,lc->pc", tail_t[:, :, on], e[on])
        return first, tail


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


def bounce_deficit(F, reflectance, B, n: int, mask=None, area=None, exitance=None, truncated=None) -> dict:
    """Relative difference (B_n - B) / B of the truncated radiosity on the patches ``mask``
    (default: all): ``mean`` the area-weighted one over them (RGB summed) and ``min`` the worst
    patch (most negative). ``exitance``: truncated_radiosity's; ``truncated``: B_n itself, when
    the caller has it (ColumnProducts)."""
    B = np.asarray(B, dtype=np.float64)
    P = len(B)
    mask = np.ones(P, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    area = np.ones(P) if area is None else np.asarray(area, dtype=np.float64)
    Bn = truncated_radiosity(F, reflectance, B, n, exitance) if truncated is None else truncated
    b, bn = B[mask].sum(axis=1), Bn[mask].sum(axis=1)
    a = area[mask]
    lit = b > 0
    if not np.any(lit):
        return {"reflections": int(n), "mean": 0.0, "min": 0.0}
    mean = float(np.sum(a[lit] * bn[lit]) / np.sum(a[lit] * b[lit]) - 1.0)
    worst = float(np.min(bn[lit] / b[lit] - 1.0))
    return {"reflections": int(n), "mean": mean, "min": worst}
