"""The reduced formulation: b_P = T e on the targets, T = rows P, columns C of A^-1 (from an LU
factorisation of A, never forming the inverse); the minimum-norm least-squares solution of
``T e = b_P`` (m x n_lights) per channel. A different minimum-norm solution from the paper's
formulation; both reproduce feasible targets to solver precision."""
from __future__ import annotations

import numpy as np

from .common import SolverOutput, default_rcond, lstsq_min_norm
from ..registry import SOLVERS
from ..sampling import run_cancellable


@SOLVERS.register("reduced", "Reduced (T)",
                  "Minimum-norm solve of b_P = T e_C, T from an LU factorisation of A (fast, exact)",
                  cost="transfer")
def solve_reduced(problem, rcond=None, svd_driver="auto"):
    T = problem.transfer
    e = np.zeros((problem.n_lights, 3))
    ranks, used = [], None
    for c in range(3):
        used = default_rcond(rcond, T[c].shape)
        # (a cancel does not wait for the factorisation: it ends in the background, dropped)
        X, rank = run_cancellable(lambda: lstsq_min_norm(T[c], problem.b_target[:, c:c + 1], used, svd_driver),
                                  getattr(problem, "cancel", None), "solve cancelled")
        e[:, c] = X[:, 0]
        ranks.append(rank)
    return SolverOutput(e, min(ranks), used)
