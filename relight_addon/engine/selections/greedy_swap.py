"""Best k lights (beyond the paper): for every number of lights k = 1 .. max(32, max lights), the
best non-negative configuration found by greedy pursuit on the true error (each candidate
scored from the Gram matrix T^T T, the promising ones refitted exactly by NNLS per channel),
then local search swapping one light at a time while the error drops (engine.best_lights),
seeded with the exact optima of the certificate where the subsets are few enough to enumerate.
The curve is monotone (never worse with more lights), every point non-negative; among equal
errors the least total power wins. Works over the multi-scale candidates (cells, groups, whole
polygons), so a light is as large or as small as the targets need. With candidate lamps beside
the surface lights (engine/candidate_lamps.py), the surface lights' own curve is found as well and
kept wherever it is better (``never_worse``): the curve with lamps is never worse than the cells'
alone, at any number of lights."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..best_lights import EQUAL_ERROR_RTOL, best_k_curve, best_k_with_certificate, column_subset
from ..registry import SELECTIONS
from ..units import TINY


def surface_lights(problem) -> np.ndarray:
    """Indices of the problem's lights of exitance kinds (the surface cells, groups, polygons)."""
    kinds = problem.lights
    return np.array([j for j in range(problem.n_lights) if kinds.kind_of(j).source == "exitance"], dtype=np.int64)

#: the curve covers at least this many lights
CURVE_LIGHTS = 32
#: a stroke's quick search (Live): swap rounds per k
QUICK_SWAP_ROUNDS = 2


@SELECTIONS.register("greedy-swap", "Best k Lights",
                     "For every number of lights, the best non-negative configuration found: greedy pursuit "
                     "on the true error with NNLS refits, then swaps (beyond the paper)",
                     distributes=False, multiscale=True)
def greedy_swap(s):
    p = s.problem
    stroke = s.stroke  # a stroke's re-solve (Live): its curve length, the quick search and its starts
    curve_lights = stroke.curve_lights if stroke is not None else None
    k_max = min(p.n_lights, curve_lights or max(CURVE_LIGHTS, s.max_lights or 0, s.max_steps or 0))
    stop = {"cancel": False}
    surface = surface_lights(p)
    # cells and lamps: the cells' own curve too (a stroke's quick re-solve starts from the earlier
    # answer's configurations instead)
    both = 0 < len(surface) < p.n_lights and stroke is None

    def progress(done, total, part=0):
        stop["cancel"] = s.step(done + part * total, (2 if both else 1) * total)

    starts = (stroke.initial if stroke is not None else None) or {}
    initial = {k: v for k, v in starts.items() if k <= k_max and np.all(np.asarray(v) < p.n_lights)}
    # quick: the swap search from the best start only, 2 rounds (the earlier answer's
    # configurations are starts: measured on the living room and the staircase, the same final
    # error as the full search at 60-75 % of its time; docs/benchmarks.md, "Live"), the Gram
    # matrices' rows computed as the search reads them (best_lights.GramRows)
    quick = dict(swap_all=False, max_swap_rounds=QUICK_SWAP_ROUNDS, lazy_gram=True) if stroke is not None else {}
    curve, bounds = best_k_with_certificate(p.transfer, p.b_target, k_max, p.light_watts, initial=initial,
                                            cancel=lambda: stop["cancel"], progress=progress,
                                            nnls_start=stroke.nnls_start if stroke is not None else None,
                                            upper=p.light_upper, halt=s.cancel, **quick)
    if both and not stop["cancel"]:
        T = column_subset(p.transfer, surface)
        cells = best_k_curve(T, p.b_target, min(k_max, len(surface)), p.light_watts[surface], upper=p.light_upper[surface],
                             cancel=lambda: stop["cancel"], progress=lambda d, t: progress(d, t, 1))
        curve = never_worse(curve, cells, surface, tol=EQUAL_ERROR_RTOL * max(float(np.linalg.norm(p.b_target)),
                                                                              TINY))
    s.certificate = bounds  # the reduction's result carries it to the certificate stage
    for pt in curve:
        on = pt.exitance.max(axis=1) > 0
        s.record(pt.lights[on], pt.exitance[on], pt.changed)


def never_worse(curve, other, columns, tol=0.0) -> list:
    """Per k the better of ``curve``'s point and ``other``'s (a curve over the lights ``columns``
    only, its lights mapped back), then monotone again (a point no better than the one before is
    replaced by it): a curve no worse than either at any k."""
    by_k = {pt.k: pt for pt in other}
    out = []
    for pt in curve:
        alt = by_k.get(pt.k)
        if alt is not None and alt.error < pt.error - tol:
            pt = replace(alt, lights=np.asarray(columns)[alt.lights], source="surface")
        if out and out[-1].error <= pt.error:
            prev = out[-1]
            pt = replace(prev, k=pt.k, source="fewer") if prev.error < pt.error else pt
        out.append(pt)
    return out
