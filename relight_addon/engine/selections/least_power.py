"""Least power within a tolerance (after Castro, del Acebo and Sbert): the non-negative lights
that keep every target within +-tolerance of its painted value with the least total power
(sum over lights and channels of exitance x area, W), a linear programme solved by scipy's
HiGHS (engine.best_lights.least_power_within_tolerance). When no non-negative lights can, the
min-max deviation programme says which tolerance is reachable, and that configuration is kept."""
from __future__ import annotations

import numpy as np

from ..best_lights import least_power_within_tolerance
from ..registry import SELECTIONS, Param


def refit(problem, ids, tolerance):
    """The programme again on the chosen lights ``ids`` alone, after their columns of T changed
    (pipeline.jobs.direct_stage: their direct light by the kernel), so that the band holds on the T
    the configuration is measured on: (exitance (len(ids), 3), the programme's message)."""
    ids = np.asarray(ids, dtype=np.int64)
    res = least_power_within_tolerance([t[:, ids] for t in problem.transfer], problem.b_target,
                                       np.asarray(problem.light_watts)[ids], tolerance)
    return res.exitance, res.message


@SELECTIONS.register("least-power", "Least Power within Tolerance",
                     "The non-negative lights with the least total power that keep every target within "
                     "the tolerance of its painted value (a linear programme)",
                     distributes=False, multiscale=True, nonnegative=True, needs_tolerance=True, refit=refit,
                     params=(Param("tolerance", float, 0.1, min=0.0, label="Tolerance", soft_max=1.0,
                                   description="Every target within +-this fraction of its painted value "
                                               "(0.1 = +-10 %); when no non-negative lights can, the reachable "
                                               "tolerance is reported and used"),))
def least_power(s):
    p = s.problem
    if s.tolerance is None:
        raise ValueError("the least-power selection needs a tolerance (e.g. --tolerance 0.1 for +-10 %)")
    s.step(0, 1)
    res = least_power_within_tolerance(p.transfer, p.b_target, p.light_watts, s.tolerance)
    on = np.flatnonzero(res.exitance.max(axis=1) > 0)
    s.record(on, res.exitance[on])
    s.step(1, 1)
    return [res.message] if res.message else []
