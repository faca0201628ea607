"""LocalDistribute: all the weight to the light(s) nearest in form-factor-row distance
d_l = ||F_s - F_l||; ties (relative 1e-9) share equally."""
from __future__ import annotations

import numpy as np

from ..registry import DISTRIBUTIONS
from ..units import TINY


@DISTRIBUTIONS.register("local", "Local", "Suppressed power goes to the light(s) with the most similar form-factor row")
class Local:
    def __init__(self, problem):
        FC = problem.light_rows()
        g = (FC * FC).sum(1)
        self.pair = np.sqrt(np.maximum(g[:, None] + g[None, :] - 2.0 * FC @ FC.T, 0.0))

    def raw(self, src, lights, valid):
        D = np.where(valid, self.pair[np.ix_(src, lights)], np.inf)
        dmin = D.min(axis=1, keepdims=True)
        return (valid & (D <= dmin * (1 + 1e-9) + TINY)).astype(np.float64)
