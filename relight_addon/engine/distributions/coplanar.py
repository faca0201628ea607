"""CoplanarDistribute: w = 1/n over the n remaining lights coplanar with the suppressed one
(same facing normal within ``coplanar_tolerance`` and in-plane within ``coplanar_tolerance`` times the
lights' extent); uniform when there is none."""
from __future__ import annotations

import numpy as np

from ..registry import DISTRIBUTIONS, Param


@DISTRIBUTIONS.register("coplanar", "Coplanar", "Suppressed power is shared by the coplanar lights (uniform if none)",
                        params=(Param("coplanar_tolerance", float, 1e-3, min=0.0, max=1.0, label="Coplanar Tolerance",
                                      soft_max=0.1, description="Two lights are coplanar when their normals' "
                                      "dot product exceeds 1 - this and each lies within this fraction of the "
                                      "lights' extent of the other's plane"),))
class Coplanar:
    def __init__(self, problem, coplanar_tolerance):
        n = problem.light_normal
        c = problem.light_center
        extent = float(np.linalg.norm(np.ptp(c, axis=0))) or 1.0
        same_facing = n @ n.T > 1.0 - coplanar_tolerance
        offset = np.abs(np.einsum("ik,ijk->ij", n, c[None, :, :] - c[:, None, :]))
        self.pair = same_facing & (offset <= coplanar_tolerance * extent)

    def raw(self, src, lights, valid):
        co = self.pair[np.ix_(src, lights)] & valid
        none = ~co.any(axis=1)
        co[none] = valid[none]
        return co.astype(np.float64)
