"""The paper's formulation ([Conte02]): the constraints substituted into A b - e = 0.

The unknowns are b on the unpainted patches U and e on the lights, so
``[A[:, U]  -S] [b_U; e] = -A[:, P] b_P`` (S: candidate patches -> lights), i.e. ``M x = r``
(n rows, |U| + n_lights columns); its minimum-norm least-squares solution through the SVD
pseudo-inverse, singular values below ``rcond * s_max`` cut off, gives e_x. By default
(``svd_driver="auto"``) M is never formed: see :class:`_PaperGram`.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .common import GRAM_MAX_COND, SolverOutput, channel_groups, default_rcond, lstsq_min_norm
from ..radiosity import radiosity_matrix
from ..registry import SOLVERS
from ..scene import SceneError


class _PaperGram:
    """The paper's system M x = r with M = [A[:, U], -S] (S: candidate patches -> lights),
    solved as x = M^T (M M^T)^-1 r without forming M. Per channel with reflectance rho,

        M M^T = diag(u) - T1 - T1^T + (rho rho^T) o K + S S^T,   K = F[:, U] F[:, U]^T,

    where u marks the unpainted patches and T1[U, :] = (F[:, U] o rho).T. K does not depend
    on rho, so one symmetric product serves the three channels; then x = M^T y is
    [y_U - F[:, U]^T (rho y); -S^T y]. The same minimum-norm solution as the SVD
    pseudo-inverse whenever M has full row rank with margin (checked as in _gram_min_norm);
    otherwise ``solve`` returns None and the caller uses the explicit M.
    """

    def __init__(self, problem, U):
        F = problem.F.toarray() if sp.issparse(problem.F) else np.asarray(problem.F)
        self.F = np.asarray(F, dtype=np.float64)
        self.U = U
        self.p = problem
        FU = np.asfortranarray(self.F[:, U])
        K = sla.blas.dsyrk(1.0, FU, lower=1)
        self.K = K + np.tril(K, -1).T
        n = problem.n_patches
        S = problem.source_basis
        self.same_light = (S @ S.T).toarray()  # S S^T on C x C
        self.u = np.zeros(n)
        self.u[U] = 1.0

    def solve(self, rho, b_target):
        p, F, U = self.p, self.F, self.U
        n = p.n_patches
        G = self.K * np.outer(rho, rho)
        T1 = np.zeros((n, n))
        T1[U, :] = (F[:, U] * rho[:, None]).T
        G -= T1
        G -= T1.T
        G[np.diag_indices(n)] += self.u
        C = p.candidates
        G[np.ix_(C, C)] += self.same_light
        # right-hand side: r = -A[:, P] b_P with A = I - diag(rho) F
        P = p.targets
        R = rho[:, None] * (F[:, P] @ b_target)
        R[P] -= b_target
        try:
            L, lower = sla.cho_factor(G, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            return None
        x = np.random.default_rng(0).standard_normal(n)
        for _ in range(8):
            x = sla.cho_solve((L, lower), x / np.linalg.norm(x), check_finite=False)
        lam_min = 1.0 / np.linalg.norm(x)
        lam_max = float(np.trace(G))  # >= the largest eigenvalue
        if not (np.isfinite(lam_min) and lam_min > 0 and lam_max / lam_min < GRAM_MAX_COND ** 2):
            return None
        Y = sla.cho_solve((L, lower), R, check_finite=False)
        # e = -S^T y: per light, minus the sum of y over its patches
        return -np.asarray(p.source_basis.T @ Y[p.candidates])



@SOLVERS.register("svd", "Paper (SVD)",
                  "The paper's formulation: constraints substituted into A b = e, SVD pseudo-inverse",
                  cost="paper")
def solve_paper(problem, rcond=None, svd_driver="auto"):
    n = problem.n_patches
    if not problem.target_rows.selects:
        raise SceneError("the paper's formulation substitutes the targets' patches: targets that mix patches "
                         "need the reduced or nnls solver")
    C, P = problem.candidates, problem.targets
    U = np.flatnonzero(~problem.target_mask)
    D = problem.first_bounce  # the lights' first reflection (engine.incidence): A b = (I + D) S e
    structured = _PaperGram(problem, U) if svd_driver == "auto" and D is None else None
    e = np.zeros((problem.n_lights, 3))
    ranks, used = [], None
    groups = channel_groups(problem.reflectance) if D is None else [[0], [1], [2]]
    for g in groups:
        if structured is not None:
            used = default_rcond(rcond, (n, len(U) + problem.n_lights))
            e_g = structured.solve(problem.reflectance[:, g[0]], problem.b_target[:, g])
            if e_g is not None:
                e[:, g] = e_g
                ranks.append(n)
                continue
        A = radiosity_matrix(problem.F, problem.reflectance[:, g[0]])
        if sp.issparse(A):
            A = A.toarray()
        M = np.zeros((n, len(U) + problem.n_lights), order="F")  # Fortran order for BLAS
        M[:, :len(U)] = A[:, U]
        M[np.ix_(C, len(U) + np.arange(problem.n_lights))] = -problem.source_basis.toarray()
        if D is not None:
            M[:, len(U):] -= (D[g[0]][:, C] @ problem.source_basis).toarray()
        R = -(A[:, P] @ problem.b_target[:, g])
        used = default_rcond(rcond, M.shape)
        X, rank = lstsq_min_norm(M, R, used, svd_driver)
        e[:, g] = X[len(U):]
        ranks.append(rank)
    return SolverOutput(e, min(ranks), used)
