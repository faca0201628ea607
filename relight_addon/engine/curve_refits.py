"""A reduction's curve re-fitted after the transfer of some of its lights changed (no bpy): the
kernel's direct light of the curve's lights (pipeline.stages.direct_stage) or lamps refined
(pipeline.stages.refine_stage). Every function returns a new curve (a list of CurvePoint) and
leaves the one it was given as it was.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .light_colour import channel_error, colour_problem, fit_lights

__all__ = ["configuration_error", "least_squares_change", "refit_curve", "carry_refined"]


def configuration_error(problem, ids, e):
    """Eq. 1 of the lights ``ids`` at strengths ``e`` (len(ids), 3), through T (W/m^2)."""
    T = problem.transfer
    return channel_error([t[:, ids] for t in T], e, problem.b_target)


def least_squares_change(problem, ids, e):
    """(len(ids), 3): the least-norm change of the strengths ``e`` of the lights ``ids`` that
    minimises Eq. 1 again on T (per channel; a configuration with negatives, e.g. e_x, stays exact
    where it was)."""
    T, b = problem.transfer, problem.b_target
    return np.stack([np.linalg.lstsq(T[c][:, ids], b[:, c] - T[c][:, ids] @ e[:, c], rcond=None)[0]
                     for c in range(3)], axis=1)


def _refit_point(problem, pt, ids, refit):
    """(lights, strengths, the refit's note) of one configuration on the problem's T."""
    e, note = np.asarray(pt.exitance, dtype=np.float64), None
    if pt.n_negative:  # the inverse solution e_x (all the lights): the least change that fits
        # again; the selection's other configurations with negatives keep their strengths
        e = e + least_squares_change(problem, ids, e) if len(ids) == problem.n_lights else e
    elif refit is not None:
        view = colour_problem(problem, problem.colour, ids, e)  # (the configuration's colours kept)
        e, note = refit(view or problem, ids)
        e = view.exitance_of(ids, e) if view is not None else e
        on = e.max(axis=1) > 0
        ids, e = ids[on], e[on]
    else:
        fit, _ = fit_lights(problem, ids, e)
        e = fit if np.all(fit.max(axis=1) > 0) else e
    return ids, e, note


def refit_curve(problem, curve, final_index, changed, refit=None) -> tuple:
    """(the curve, the refit's note of the final configuration or []): each configuration that
    holds one of the lights ``changed`` re-fitted on the problem's T (NNLS per channel, the same
    lights; ``refit(problem, ids) -> (e, note)``: a selection's own programme instead), its error
    following."""
    norm = problem.target_norm or 1.0
    changed, out, notes = set(changed), list(curve), []
    for i, pt in enumerate(curve):
        ids = np.asarray(pt.lights, dtype=np.int64)
        if not changed.intersection(ids.tolist()):
            continue
        ids, e, note = _refit_point(problem, pt, ids, refit)
        notes += [note] if i == final_index and note else []
        error = configuration_error(problem, ids, e)
        out[i] = replace(pt, n_lights=len(ids), lights=ids, exitance=e, error=error,
                         relative_error=error / norm, n_negative=int((e < 0).any(axis=1).sum()))
    return out, notes


def _carried_fit(problem, pt, prev, carried):
    """The best fit (error, lights, strengths) of ``pt``'s lights with the final configuration's
    refined lamps in place of theirs, or of ``prev`` and one of its own lights; None when none
    keeps all its lights on below its error."""
    tries = [[carried.get(int(j), int(j)) for j in pt.lights]] if any(int(j) in carried for j in pt.lights) else []
    if prev.n_negative == 0 and prev.n_lights == pt.n_lights - 1:
        had = set(prev.lights.tolist())  # (a refined lamp's candidate is not added beside it)
        tries += [list(prev.lights) + [int(j)] for j in pt.lights
                  if int(j) not in had and carried.get(int(j)) not in had]
    best = None
    for ids in tries:
        ids = np.unique(np.asarray(ids, dtype=np.int64))
        e, error = fit_lights(problem, ids)
        on = e.max(axis=1) > 0
        if len(ids[on]) == pt.n_lights and error < (pt.error if best is None else best[0]):
            best = (error, ids[on], e[on])
    return best


def carry_refined(problem, curve, final_index, carried: dict, every=False) -> list:
    """The configurations with more lights than the final one hold its lamps as offered (they are
    not refined): each takes the final one's refined lamps in their place (``carried``: candidate
    light -> refined light), or else the configuration before it and one of its own lights, its
    strengths re-fitted (NNLS per channel), when that lowers its error, or else the configuration
    before it (as the selections' own curves do) -- so that the curve never rises after a refined
    configuration (NNLS on more lights is never worse). ``every``: all the
    configurations, not only those above the final one (after the direct light re-fitted them all)."""
    norm = problem.target_norm or 1.0
    out = list(curve)
    final = curve[final_index]
    for i, pt in enumerate(curve):
        if i == 0 or (pt.n_lights <= final.n_lights and not every) or pt.n_negative:
            continue
        prev = out[i - 1]
        if every and not carried and pt.error <= prev.error:
            continue
        best = _carried_fit(problem, pt, prev, carried)
        if best is not None:
            out[i] = pt = replace(pt, lights=best[1], exitance=best[2], error=best[0], relative_error=best[0] / norm)
        if pt.error > prev.error and prev.n_negative == 0 and prev.n_lights < pt.n_lights:
            # no fit of its lights all on comes below the configuration before it (whose carried
            # lamps improved it more): that one (fewer lights do)
            out[i] = replace(pt, n_lights=prev.n_lights, lights=prev.lights.copy(), exitance=prev.exitance.copy(),
                             error=prev.error, relative_error=prev.relative_error)
    return out
