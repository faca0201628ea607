"""Best k lights (beyond the paper): for every number of lights k = 1 .. max(32, max lights), the
best non-negative configuration found by greedy pursuit on the true error (each candidate
scored from the Gram matrix T^T T, the promising ones refitted exactly by NNLS per channel),
then local search swapping one light at a time while the error drops (engine.best_lights),
seeded with the exact optima of the certificate where the subsets are few enough to enumerate.
The curve is monotone (never worse with more lights), every point non-negative; among equal
errors the least total power wins. Works over the multi-scale candidates (cells, groups, whole
polygons), so a light is as large or as small as the targets need."""
from __future__ import annotations

from ..best_lights import best_k_with_certificate
from ..registry import SELECTIONS

#: the curve covers at least this many lights
CURVE_LIGHTS = 32


@SELECTIONS.register("greedy-swap", "Best k Lights",
                     "For every number of lights, the best non-negative configuration found: greedy pursuit "
                     "on the true error with NNLS refits, then swaps (beyond the paper)",
                     distributes=False, multiscale=True, nonnegative=True)
def greedy_swap(s):
    p = s.problem
    k_max = min(p.n_lights, max(CURVE_LIGHTS, s.max_lights or 0, s.max_steps or 0))
    stop = {"cancel": False}

    def progress(done, total):
        stop["cancel"] = s.step(done, total)

    curve, bounds = best_k_with_certificate(p.transfer, p.b_target, k_max, p.light_watts,
                                            cancel=lambda: stop["cancel"], progress=progress)
    s.certificate = bounds  # the reduction's result carries it to the certificate stage
    for pt in curve:
        on = pt.exitance.max(axis=1) > 0
        s.record(pt.lights[on], pt.exitance[on], pt.changed)
