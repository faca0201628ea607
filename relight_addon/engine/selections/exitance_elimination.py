"""ExitanceElimination (the paper's choice for inverse lighting): re-sort after every step and
remove the lowest light -- lights with a negative channel first (most negative power first),
then the weakest positive -- redistributing cumulatively (e_p <- e'_p). Runs down to one light.
The only paper heuristic that is guaranteed to end with no negative exitances."""
from __future__ import annotations

import numpy as np

from ..registry import SELECTIONS


@SELECTIONS.register("exitance-elimination", "Exitance Elimination",
                     "Remove the lowest-power light at each step (the paper's choice)", paper=True, gauss_seidel=True)
def exitance_elimination(s):
    A = s.problem.light_watts
    k = s.problem.n_lights
    S = np.arange(k)
    e = s.e_x.copy()
    s.record(S, e)
    while len(S) > 1 and not s.step(k - len(S), k - 1):
        ph = e * A[S][:, None]
        i = int(np.lexsort((ph.sum(1), ~(e < 0).any(1)))[0])
        drop = S[i]
        keep = np.arange(len(S)) != i
        S, e = S[keep], s.dist.distribute(e[keep], S[keep], [drop], ph[i:i + 1])
        s.record(S, e, drop)
