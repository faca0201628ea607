"""What the registered solvers share (no bpy): their output, the pseudo-inverse's cut-off, the
minimum-norm least squares (SVD, or the Gram matrix's Cholesky when that is exact) and the
grouping of channels with identical reflectance."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

__all__ = ["GRAM_MAX_COND", "SolverOutput", "channel_groups", "default_rcond", "lstsq_min_norm"]

#: the Gram-matrix route of the pseudo-inverse is used below this condition number of M
GRAM_MAX_COND = 1e5

def channel_groups(reflectance):
    """Group the channels whose reflectance vectors are identical (grey scenes: one group)."""
    groups = []
    for c in range(3):
        for g in groups:
            if np.array_equal(reflectance[:, g[0]], reflectance[:, c]):
                g.append(c)
                break
        else:
            groups.append([c])
    return groups


def lstsq_min_norm(M, R, rcond, driver):
    """Minimum-norm least squares through the SVD with relative cut-off rcond. Returns (X, rank).

    driver "auto": when M (rows <= cols) has full row rank well above the cut-off, its
    pseudo-inverse is exactly M^T (M M^T)^-1 -- no singular value is cut -- so the same
    minimum-norm solution comes from a Cholesky factorisation of the Gram matrix M M^T
    (rows x rows), tens of times cheaper than an SVD of M. Full row rank is accepted when
    the factorisation succeeds and M's condition number (bounded from above by
    ||M||_F^2 / lambda_min(M M^T), lambda_min by inverse iteration) is below
    GRAM_MAX_COND = 1e5: then no singular value is near the
    cut-off and squaring the condition number in the Gram matrix still leaves the solution
    accurate to about 1e-6 relative or better. Otherwise the explicit SVD with the cut-off
    ("gelsd") is used. The staircase's M has a condition number of about 10.
    """
    if driver == "auto":
        X = gram_min_norm(M, R, rcond)
        if X is not None:
            return X, int(M.shape[0])
        driver = "gelsd"
    if driver == "gelsd":
        X, _, rank, _ = sla.lstsq(M, R, cond=rcond, lapack_driver="gelsd", check_finite=False)
        return X, int(rank)
    if driver == "svd":
        U, s, Vt = sla.svd(M, full_matrices=False, check_finite=False, lapack_driver="gesdd")
        keep = s > rcond * (s[0] if len(s) else 0.0)
        X = Vt[keep].T @ ((U[:, keep].T @ R) / s[keep][:, None])
        return X, int(keep.sum())
    raise ValueError(f"unknown SVD driver {driver!r}; use 'gelsd' or 'svd'")


def gram_min_norm(M, R, rcond):
    """M^T (M M^T)^-1 R when M has full row rank with margin over the cut-off, else None."""
    rows, cols = M.shape
    if rows > cols:
        return None
    G = sla.blas.dsyrk(1.0, np.asfortranarray(M), lower=1)  # lower triangle of M M^T
    try:
        L, lower = sla.cho_factor(G, lower=True, check_finite=False, overwrite_a=True)
    except np.linalg.LinAlgError:
        return None
    rng = np.random.default_rng(0)
    x = rng.standard_normal(rows)
    for _ in range(8):  # inverse iteration: smallest eigenvalue of G (from above)
        x = sla.cho_solve((L, lower), x / np.linalg.norm(x), check_finite=False)
    lam_min = 1.0 / np.linalg.norm(x)
    # largest eigenvalue of G from above: its trace, ||M||_F^2 (at most rows x too large, so the
    # test below can only be stricter than cond(M) < GRAM_MAX_COND)
    lam_max = float(np.einsum("ij,ij->", M, M))
    if not (np.isfinite(lam_min) and lam_min > 0 and lam_max / lam_min < GRAM_MAX_COND ** 2):
        return None
    Y = sla.cho_solve((L, lower), R, check_finite=False)
    return M.T @ Y



@dataclass
class SolverOutput:
    """What a registered solver returns: exitance (n_lights, 3) W/m^2, the rank used, the
    cut-off used (None when not applicable) and its own warnings."""

    exitance: np.ndarray
    rank: int
    rcond: float | None = None
    warnings: list = field(default_factory=list)


def default_rcond(rcond, shape):
    """The pseudo-inverse cut-off: ``rcond`` when given, else max(rows, cols) * machine eps."""
    return rcond if rcond is not None else max(shape) * np.finfo(float).eps
