"""ErrorConstruction: add, at each step, the light whose addition (after redistribution of the
power of the lights not yet in) gives the smallest error."""
from __future__ import annotations

import numpy as np

from ..registry import SELECTIONS


@SELECTIONS.register("error-construction", "Error Construction",
                     "Add the light whose addition gives the smallest error", paper=True)
def error_construction(s):
    """ErrorConstruction: per step, try every remaining light (each trial vectorised over channels)."""
    problem, e_x, dist, record, step_hook = s.problem, s.e_x, s.dist, s.record, s.step
    phi_x = e_x * problem.light_watts[:, None]
    steps = problem.n_lights if s.max_steps is None else min(problem.n_lights, int(s.max_steps))
    T, b = problem.transfer, problem.b_target
    k = len(e_x)
    S = np.zeros(0, dtype=np.int64)
    Q = np.arange(k)
    for p in range(1, steps + 1):
        best = (np.inf, -1, None)
        for t, l in enumerate(Q):
            S2 = np.append(S, l)
            Q2 = np.delete(Q, t)
            e2 = dist.distribute(e_x[S2], S2, Q2, phi_x[Q2])
            r = np.stack([T[c][:, S2] @ e2[:, c] for c in range(3)], axis=1) - b
            sq = float(np.einsum("ij,ij->", r, r))
            if sq < best[0]:
                best = (sq, t, e2)
        _, t, e2 = best
        l = Q[t]
        S = np.append(S, l)
        Q = np.delete(Q, t)
        record(S, e2, l)
        if step_hook(p, steps):
            break
