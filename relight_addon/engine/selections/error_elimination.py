"""ErrorElimination: remove the light whose removal (after redistribution) gives the smallest
error; cumulative. All trials of a step are evaluated at once with matrix products on T."""
from __future__ import annotations

import numpy as np

from ..registry import SELECTIONS


@SELECTIONS.register("error-elimination", "Error Elimination",
                     "Remove the light whose removal gives the smallest error", paper=True)
def error_elimination(s):
    """ErrorElimination, every trial of a step at once.

    Removing light i from S (exitances e) and giving its power Phi_i to the
    others with weights W[i, :] changes the targets' radiosity to
    b - T_S[:, i] e_i + (T_S / A_S) W[i, :]^T Phi_i, so for all trials
    B_c = b_c 1^T - T_S diag(e_c) + ((T_S / A_S) W^T) diag(Phi_c)  (m x |S|).
    """
    problem, e_x, dist, record, step_hook = s.problem, s.e_x, s.dist, s.record, s.step
    A = problem.light_watts
    T, b = problem.transfer, problem.b_target
    k = len(e_x)
    S = np.arange(k)
    e = e_x.copy()
    record(S, e)
    uniq = {}
    for c in range(3):
        uniq.setdefault(id(T[c]), []).append(c)
    while len(S) > 1 and not step_hook(k - len(S), k - 1):
        n = len(S)
        W = dist.weights(S, S, valid=~np.eye(n, dtype=bool))
        phi = e * A[S][:, None]
        sq = np.zeros(n)
        for chans in uniq.values():
            TS = T[chans[0]][:, S]
            G = (TS / A[S][None, :]) @ W.T  # (m, n)
            for c in chans:
                bc = TS @ e[:, c]
                Bt = (bc - b[:, c])[:, None] - TS * e[None, :, c] + G * phi[None, :, c]
                sq += np.einsum("ij,ij->j", Bt, Bt)
        i = int(np.argmin(sq))
        keep = np.arange(n) != i
        e = e[keep] + (W[i, keep][:, None] * phi[i][None, :]) / A[S[keep]][:, None]
        s = S[i]
        S = S[keep]
        record(S, e, s)
