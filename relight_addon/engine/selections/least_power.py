"""Least power within a tolerance (after Castro, del Acebo and Sbert): the non-negative lights
that keep every target within +-tolerance of its painted value with the least total power
(sum over lights and channels of exitance x area, W), a linear programme solved by scipy's
HiGHS (engine.best_lights.least_power_within_tolerance). When no non-negative lights can, the
min-max deviation programme says which tolerance is reachable, and that configuration is kept."""
from __future__ import annotations

import numpy as np

from ..best_lights import least_power_within_tolerance
from ..registry import SELECTIONS, Param


def refit(problem, ids, tolerance, uniformity=None):
    """The programme again on the chosen lights ``ids`` alone, after their columns of T changed
    (pipeline.jobs.direct_stage: their direct light by the kernel), so that the band (and the
    uniformity goal) holds on the T the configuration is measured on: (exitance (len(ids), 3), the
    programme's message)."""
    ids = np.asarray(ids, dtype=np.int64)
    goal, notes = uniformity_goal(problem, uniformity)
    res = least_power_within_tolerance([t[:, ids] for t in problem.transfer], problem.b_target,
                                       np.asarray(problem.light_watts)[ids], tolerance, uniformity=goal,
                                       upper=np.asarray(problem.light_upper)[ids])
    return res.exitance, "; ".join(notes + ([res.message] if res.message else []))


#: the note of a uniformity goal set without illuminance targets (the goal is then left out)
NO_UNIFORMITY_REGION = "the uniformity goal applies to illuminance targets (Fill Selected in lx), and there are none"


def uniformity_goal(problem, uniformity) -> tuple:
    """(the programme's uniformity goal (U0, regions) or None, [notes]): none without a goal, and
    none, with a note, when the problem has no illuminance target to hold it."""
    if not uniformity:
        return None, []
    regions = uniformity_regions(problem)
    if regions is None:
        return None, [NO_UNIFORMITY_REGION]
    return (float(uniformity), regions), []


@SELECTIONS.register("least-power", "Least Power within Tolerance",
                     "The non-negative lights with the least total power that keep every target within "
                     "the tolerance of its painted value (a linear programme)",
                     distributes=False, multiscale=True, needs_tolerance=True, refit=refit,
                     params=(Param("tolerance", float, 0.1, min=0.0, label="Tolerance", soft_max=1.0,
                                   description="Every target within +-this fraction of its painted value "
                                               "(0.1 = +-10 %); when no non-negative lights can, the reachable "
                                               "tolerance is reported and used"),
                             Param("uniformity", float, None, min=0.0, max=1.0, label="Uniformity U0", ui="toggle",
                                   ui_default=0.6, none="no goal",
                                   description="Illuminance targets: on each object's, the lowest illuminance at "
                                               "least this fraction of their mean (U0 = E_min / E_mean, EN 12464-1: "
                                               "0.6 on a desk); when it cannot be met, the reachable U0 is reported "
                                               "and used")))
def least_power(s, tolerance, uniformity):
    p = s.problem
    s.step(0, 1)
    goal, notes = uniformity_goal(p, uniformity)
    res = least_power_within_tolerance(p.transfer, p.b_target, p.light_watts, tolerance, uniformity=goal,
                                       upper=p.light_upper)
    on = np.flatnonzero(res.exitance.max(axis=1) > 0)
    s.record(on, res.exitance[on])
    s.step(1, 1)
    return notes + ([res.message] if res.message else [])


def uniformity_regions(p):
    """The uniformity goal's regions of problem ``p`` (its ``target_region``: per target row, the
    object of an illuminance target, -1 otherwise), per channel of the programme: [(rows, their
    reflectance, the fixed light's radiosity there, area), ...]; on a colour view (engine.
    light_colour: the channels stacked in channel 0) every channel's block in channel 0. None
    without illuminance targets."""
    reg = getattr(p, "target_region", None)
    if reg is None or not np.any(reg >= 0):
        return None
    tg = p.targets
    rho, bg, area, m = p.reflectance[tg], p.background_radiosity[tg], p.area[tg], len(tg)
    stacked = hasattr(p, "exitance_of")  # (a ColourProblem)
    out = [[], [], []]
    for r in np.unique(reg[reg >= 0]):
        rows = np.flatnonzero(reg == r)
        for c in range(3):
            out[0 if stacked else c].append((rows + c * m if stacked else rows, rho[rows, c], bg[rows, c],
                                             area[rows]))
    return out
