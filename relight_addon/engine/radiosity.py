"""Forward radiosity: solve B = e + rho * F B per RGB channel.

For each channel c, (I - diag(rho_c) F) B_c = e_c, with B and e in W/m^2
(radiosity and self-exitance) and rho the diffuse reflectance.

Methods:
- ``"direct"``: LU factorisation (scipy.linalg.lu_factor) of the dense
  system; sparse systems use scipy.sparse.linalg.splu.
- ``"gauss-seidel"``: B_{k+1} = (D + L)^{-1} (e - U B_k), one triangular solve
  per sweep (scipy.linalg.solve_triangular / scipy.sparse.linalg.spsolve_triangular),
  warm-started from ``x0``; stops when the relative residual
  ||e - A B||_2 / ||e||_2 <= ``tol`` in every channel.
- ``"auto"``: direct for dense F with P <= ``DIRECT_LIMIT`` patches, else Gauss-Seidel.

Failure modes (documented contract):
- Gauss-Seidel hitting ``max_iter`` returns ``converged=False`` with a
  message in ``info["message"]`` (the best iterate is returned).
- Divergence (residual growing past 1e3 x its start, or non-finite values) and
  any NaN/inf in the result raise :class:`RadiosityError` (a ValueError).
- Reflectance above ``max_reflectance`` (units.MAX_REFLECTANCE, 0.99) is clamped -- rho >= 1 makes a
  closed scene's system singular -- and a warning goes to ``info["warnings"]``.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .units import MAX_REFLECTANCE

__all__ = [
    "DIRECT_LIMIT",
    "lossless_patches",
    "RadiosityError",
    "radiosity_matrix",
    "solve_radiosity",
]

#: "auto" uses the direct LU solve for dense systems up to this many patches.
DIRECT_LIMIT = 1500


class RadiosityError(ValueError):
    """The radiosity system could not be solved; the message is meant for the user."""


def _matrix(F):
    m = getattr(F, "matrix", F)
    if sp.issparse(m):
        return m.tocsr()
    m = np.asarray(m)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ValueError(f"form factors must be a square (P, P) matrix, got shape {m.shape}")
    return m


def radiosity_matrix(F, rho_channel) -> np.ndarray | sp.csr_matrix:
    """The radiosity operator A = I - diag(rho) F for one channel (float64).

    ``F`` is a FormFactors or a (P, P) dense/sparse matrix, ``rho_channel`` (P,).
    Dense in, dense out; sparse in, CSR out.
    """
    M = _matrix(F)
    P = M.shape[0]
    rho = np.asarray(rho_channel, dtype=np.float64).reshape(-1)
    if len(rho) != P:
        raise ValueError(f"reflectance has {len(rho)} entries for {P} patches")
    if sp.issparse(M):
        return (sp.identity(P, format="csr") - sp.diags(rho) @ M.astype(np.float64)).tocsr()
    A = -(rho[:, None] * M.astype(np.float64))
    A[np.diag_indices(P)] += 1.0
    return A


#: a row of F within this of 1 keeps all its patch's rays (float32 rounding of the weighted
#: reciprocity is about 1e-7; one escaped ray of 262,144 is 3.8e-6)
CLOSED_TOL = 1e-6


def lossless_patches(F, rho_channel, tol: float = CLOSED_TOL) -> np.ndarray:
    """(P,) bool: the patches that never lose light -- reflectance exactly 1, every ray caught by
    the scene (row sum of F within ``tol`` of 1) -- and that send light only to patches that
    never lose it either. rho F is substochastic, so I - rho F is singular exactly when such a
    closed class exists (Perron-Frobenius); this finds it from the structure of F, not from LU
    pivots that rounding makes nonzero."""
    M = _matrix(F)
    keep = np.asarray(rho_channel, dtype=np.float64).reshape(-1) >= 1.0
    if not keep.any():  # the usual scene: no row sums needed
        return keep
    keep &= np.asarray(M.sum(axis=1), dtype=np.float64).reshape(-1) >= 1.0 - tol
    while keep.any():
        leak = (M @ (~keep).astype(np.float32)).reshape(-1) > 0  # sends light to a patch that loses it
        drains = keep & np.asarray(leak)
        if not drains.any():
            break
        keep &= ~drains
    return keep


def _check_inputs(M, reflectance, exitance, max_reflectance):
    P = M.shape[0]
    rho = np.asarray(reflectance, dtype=np.float64)
    e = np.asarray(exitance, dtype=np.float64)
    if rho.shape == (P,):
        rho = np.repeat(rho[:, None], 3, axis=1)
    if e.shape == (P,):
        e = np.repeat(e[:, None], 3, axis=1)
    if rho.shape != (P, 3) or e.shape != (P, 3):
        raise ValueError(f"reflectance and exitance must be (P, 3) = ({P}, 3); got {rho.shape} and {e.shape}")
    if not np.all(np.isfinite(rho)) or not np.all(np.isfinite(e)):
        raise RadiosityError("reflectance or exitance contains NaN or infinite values")
    if np.any(rho < 0):
        raise RadiosityError(f"reflectance must be >= 0 (found {rho.min():.4g})")
    warnings = []
    over = rho > max_reflectance
    if over.any():
        warnings.append(
            f"{int(over.any(axis=1).sum())} patch(es) have reflectance above {max_reflectance} "
            f"(max {rho.max():.4g}); clamped to {max_reflectance} (reflectance >= 1 creates energy)")
        rho = np.minimum(rho, max_reflectance)
    return rho, e, warnings


def _residual(A, x, e):
    r = e - A @ x
    ne = np.linalg.norm(e)
    return float(np.linalg.norm(r) / ne) if ne > 0 else float(np.linalg.norm(r))


def solve_radiosity(
    F,
    reflectance,
    exitance,
    method: str = "auto",
    tol: float = 1e-6,
    max_iter: int = 1000,
    x0=None,
    max_reflectance: float = MAX_REFLECTANCE,
):
    """Solve (I - diag(rho_c) F) B_c = e_c for the three channels.

    ``F``: FormFactors or (P, P) matrix (dense or sparse). ``reflectance``,
    ``exitance``: (P, 3) (or (P,) for grey). ``x0``: (P, 3) warm start for
    Gauss-Seidel (default: e). Returns ``(B, info)``: B (P, 3) float64 W/m^2;
    info = {method, iterations (list per channel; 0 for direct), residual (max
    relative residual over channels), converged, warnings, message}.
    """
    M = _matrix(F)
    P = M.shape[0]
    rho, e, warnings = _check_inputs(M, reflectance, exitance, max_reflectance)
    sparse = sp.issparse(M)
    if method == "auto":
        method = "direct" if (not sparse and P <= DIRECT_LIMIT) else "gauss-seidel"
    if method not in ("direct", "gauss-seidel"):
        raise ValueError(f"unknown method {method!r}; use 'auto', 'direct' or 'gauss-seidel'")
    if not (tol > 0):
        raise ValueError(f"tol must be positive, got {tol}")
    if not (int(max_iter) >= 1):
        raise ValueError(f"max_iter must be >= 1, got {max_iter}")
    if x0 is not None:
        x0 = np.asarray(x0, dtype=np.float64)
        if x0.shape == (P,):
            x0 = np.repeat(x0[:, None], 3, axis=1)
        if x0.shape != (P, 3) or not np.all(np.isfinite(x0)):
            raise ValueError(f"x0 must be a finite (P, 3) = ({P}, 3) array, got shape {x0.shape}")
    if method == "direct":
        B, iterations, residuals = _direct(M, rho, e)
        converged, message = True, ""
    else:
        B, iterations, residuals, converged, message = _gauss_seidel(M, rho, e, x0, tol, max_iter)
    if not np.all(np.isfinite(B)):
        raise RadiosityError("radiosity contains NaN or infinite values")
    info = {
        "method": method,
        "iterations": iterations,
        "residual": float(max(residuals)),
        "converged": converged,
        "warnings": warnings,
        "message": message,
    }
    return B, info


def _direct(M, rho, e):
    """(B, iterations, residuals): each channel by an LU factorisation of A (sparse or dense)."""
    P = M.shape[0]
    sparse = sp.issparse(M)
    B = np.zeros((P, 3))
    iterations, residuals = [], []
    for c in range(3):
        A = radiosity_matrix(M, rho[:, c])
        with np.errstate(all="ignore"):
            if sparse:
                try:
                    B[:, c] = spla.splu(A.tocsc()).solve(e[:, c])
                except RuntimeError as exc:
                    raise RadiosityError(f"the radiosity system is singular ({exc})") from None
            else:
                try:
                    B[:, c] = sla.lu_solve(sla.lu_factor(A, check_finite=False), e[:, c], check_finite=False)
                except (sla.LinAlgError, ValueError) as exc:
                    raise RadiosityError(f"the radiosity system is singular ({exc})") from None
        if not np.all(np.isfinite(B[:, c])):
            raise RadiosityError("the radiosity system is singular (non-finite solution); "
                                 "check reflectances and form factors")
        iterations.append(0)
        residuals.append(_residual(A, B[:, c], e[:, c]))
    return B, iterations, residuals


def _gauss_seidel(M, rho, e, x0, tol, max_iter):
    """(B, iterations, residuals, converged, message): each channel by Gauss-Seidel sweeps from
    x0 (default e) until the relative residual is below tol or after max_iter sweeps."""
    P = M.shape[0]
    sparse = sp.issparse(M)
    B = np.zeros((P, 3))
    iterations, residuals = [], []
    converged, message = True, ""
    Mf = M.astype(np.float64)
    lowerF = sp.tril(Mf, format="csr") if sparse else np.tril(Mf)
    upperF = sp.triu(Mf, k=1, format="csr") if sparse else np.triu(Mf, k=1)
    for c in range(3):
        rc = rho[:, c]
        ec = e[:, c]
        A = radiosity_matrix(Mf, rc)
        if sparse:
            DL = (sp.identity(P, format="csr") - sp.diags(rc) @ lowerF).tocsr()
            U = (sp.diags(rc) @ upperF).tocsr()  # -U of A
        else:
            DL = -(rc[:, None] * lowerF)
            DL[np.diag_indices(P)] += 1.0
            U = rc[:, None] * upperF
        if np.any(DL.diagonal() <= 0):
            raise RadiosityError("Gauss-Seidel needs rho_i F_ii < 1 on every patch")
        x = (x0[:, c] if x0 is not None else ec).copy()
        ne = np.linalg.norm(ec)
        if ne == 0:  # no light: B = 0 is the solution
            B[:, c] = 0.0
            iterations.append(0)
            residuals.append(0.0)
            continue
        x, it, res = _sweeps(A, DL, U, x, ec, ne, tol, max_iter, lambda: (
            f"channel {'RGB'[c]}", float(np.max(np.abs(U @ np.ones(P) + rc * (lowerF @ np.ones(P)))))))
        B[:, c] = x
        iterations.append(it)
        residuals.append(float(res))
        if res > tol:
            converged = False
            message = (f"Gauss-Seidel did not reach tol={tol:g} in {max_iter} sweeps "
                       f"(relative residual {max(residuals):.3g}); raise max_iter or use method='direct'")
    return B, iterations, residuals, converged, message


def _sweeps(A, DL, U, x, ec, ne, tol, max_iter, diverged):
    """(x, sweeps, relative residual) of Gauss-Seidel on A x = ec (A = DL - U, DL lower
    triangular) from x; RadiosityError when it diverges (``diverged()``: the channel's name and
    the largest row sum of rho F, for the message)."""
    r0 = np.linalg.norm(ec - A @ x) / ne
    res = r0
    it = 0
    while res > tol and it < max_iter:
        rhs = ec + U @ x
        if sp.issparse(DL):
            x = spla.spsolve_triangular(DL, rhs, lower=True)
        else:
            x = sla.solve_triangular(DL, rhs, lower=True, check_finite=False)
        it += 1
        res = np.linalg.norm(ec - A @ x) / ne
        if not np.isfinite(res) or res > 1e3 * max(r0, 1.0):
            channel, row_sum = diverged()
            raise RadiosityError(
                f"Gauss-Seidel diverged in {channel} after {it} sweeps "
                f"(relative residual {res:.3g}); form-factor row sums times reflectance "
                f"must stay below 1 (max {row_sum:.4g})")
    return x, it, res
