"""ExitanceConstruction: add lights in DecreasingOrder of e_x; each configuration is e_x on the
selected lights plus the original power of every not-yet-selected light distributed over them
(not cumulative, as in the paper's Fig. 3)."""
from __future__ import annotations

import numpy as np

from ..registry import SELECTIONS


def decreasing_order(e, area):
    """DecreasingOrder: indices sorted by signed power sum_channels(e) * A, largest first (stable)."""
    power = np.asarray(e, dtype=np.float64).sum(axis=1) * np.asarray(area, dtype=np.float64)
    return np.argsort(-power, kind="stable")


@SELECTIONS.register("exitance-construction", "Exitance Construction",
                     "Add lights in decreasing power until the error is acceptable", paper=True, gauss_seidel=True)
def exitance_construction(s):
    A = s.problem.light_watts
    k = s.problem.n_lights
    phi_x = s.e_x * A[:, None]
    order = decreasing_order(s.e_x, A)
    steps = k if s.max_steps is None else min(k, int(s.max_steps))
    for p in range(1, steps + 1):
        S, Q = order[:p], order[p:]
        s.record(S, s.dist.distribute(s.e_x[S], S, Q, phi_x[Q]), order[p - 1])
        if s.step(p, steps):
            break
