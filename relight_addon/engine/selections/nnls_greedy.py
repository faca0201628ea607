"""NNLS greedy (beyond the paper): non-negative orthogonal matching pursuit on T -- add the
candidate most correlated with the residual, refit all selected lights with NNLS. Every
configuration is non-negative; ignores e_x and the distribution."""
from __future__ import annotations

import numpy as np
import scipy.optimize as sopt

from ..best_lights import _bounded
from ..registry import SELECTIONS
from ..units import TINY


@SELECTIONS.register("nnls-greedy", "NNLS Greedy",
                     "Greedy non-negative sparse selection with NNLS refits (beyond the paper)", distributes=False,
                     multiscale=True)
def nnls_greedy(s):
    """Non-negative orthogonal matching pursuit on T (all channels share the support)."""
    problem, record, step_hook, max_steps = s.problem, s.record, s.step, s.max_steps
    T, b = problem.transfer, problem.b_target
    k = problem.n_lights
    upper = getattr(problem, "light_upper", None)
    colnorm = np.sqrt(sum((t * t).sum(0) for t in T))
    colnorm = np.where(colnorm > 0, colnorm, np.inf)
    sel = []
    r = b.copy()
    steps = k if max_steps is None else min(k, int(max_steps))
    e = np.zeros((0, 3))
    for p in range(1, steps + 1):
        corr = sum(T[c].T @ r[:, c] for c in range(3)) / colnorm
        corr[sel] = -np.inf
        j = int(np.argmax(corr))
        if not corr[j] > 1e-12 * max(float(np.abs(b).max()), TINY):
            break  # no candidate can lower the residual any more
        sel.append(j)
        S = np.asarray(sel)
        ub = None if upper is None else upper[S]
        if ub is not None and np.isfinite(ub).any():  # (lights of a bounded strength: bounded least squares)
            e = np.stack([_bounded(T[c][:, S], b[:, c], ub) for c in range(3)], axis=1)
        else:
            e = np.stack([sopt.nnls(T[c][:, S], b[:, c], maxiter=50 * len(S) + 50)[0] for c in range(3)], axis=1)
        r = b - np.stack([T[c][:, S] @ e[:, c] for c in range(3)], axis=1)
        on = e.max(axis=1) > 0
        record(S[on], e[on], j)
        if step_hook(p, steps):
            break
