"""Non-negative least squares on T per channel (beyond the paper): a physical configuration
(e >= 0) at the cost of a residual when the targets are not reachable with positive lights.
Also the all-positive bound: no set of non-negative lights can do better."""
from __future__ import annotations

import numpy as np
import scipy.optimize as sopt

from .common import SolverOutput
from ..registry import SOLVERS


@SOLVERS.register("nnls", "Non-negative (NNLS)",
                  "Non-negative least squares on T: no negative exitances (beyond the paper)",
                  cost="transfer", nonnegative=True)
def solve_nnls(problem, rcond=None, svd_driver="auto"):
    T = problem.transfer
    e = np.zeros((problem.n_lights, 3))
    for c in range(3):
        e[:, c], _ = sopt.nnls(T[c], problem.b_target[:, c], maxiter=50 * T[c].shape[1])
    return SolverOutput(e, int((e.max(axis=1) > 0).sum()), None)
