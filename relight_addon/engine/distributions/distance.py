"""DistanceDistribute (the paper's choice): lights whose centre distance d_l is below the
threshold (the mean distance to the remaining lights) get w proportional to 1/d_l. When no
light is strictly below the mean -- one light left, or all at the same distance -- every
remaining light takes part (weights 1/d). A light at distance 0 (coincident centres) takes
everything."""
from __future__ import annotations

import numpy as np

from ..registry import DISTRIBUTIONS


@DISTRIBUTIONS.register("distance", "Distance",
                        "Suppressed power goes to nearby lights, weighted by 1/distance (the paper's choice)")
class Distance:
    def __init__(self, problem):
        c = problem.light_center
        d2 = (c * c).sum(1)
        self.pair = np.sqrt(np.maximum(d2[:, None] + d2[None, :] - 2.0 * c @ c.T, 0.0))

    def raw(self, src, lights, valid):
        D = self.pair[np.ix_(src, lights)]
        cnt = valid.sum(axis=1, keepdims=True)
        th = np.where(valid, D, 0.0).sum(axis=1, keepdims=True) / np.maximum(cnt, 1)
        below = valid & (D < th)
        none = ~below.any(axis=1)
        below[none] = valid[none]
        zero = valid & (D <= 0)
        hasz = zero.any(axis=1)
        below[hasz] = zero[hasz]
        return np.where(below, 1.0 / np.where(D > 0, D, 1.0), 0.0)
