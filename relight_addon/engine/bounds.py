"""What the candidate lights can do at best, against which a solve's answer is measured (no bpy):
the certificate (lower bounds on the error of any non-negative configuration of at most k of
them) and, when the answer misses the targets by much, the best non-negative lighting of all of
them (NNLS), which says whether positive light can meet the targets at all.
"""
from __future__ import annotations

from .inverse import InverseProblem, InverseResult, solve_inverse
from .light_colour import lower_bounds_of
from .reduction import ReductionResult

__all__ = ["CERTIFICATE_LIGHTS", "POSITIVE_GAP", "certificate", "positive_bound"]

#: the certificate (lower bounds) covers the curve up to this many lights; above, the NNLS bound
CERTIFICATE_LIGHTS = 32
#: above this relative error, the final configuration is compared with the best positive one
POSITIVE_GAP = 0.1


def certificate(problem: InverseProblem, red: ReductionResult):
    """Lower bounds on the best error any non-negative configuration of at most k of the candidate
    lights can reach (engine.best_lights.lower_bounds: exact by exhaustive search where small
    enough, else the all-lights NNLS bound; ``bounds.at(k)``, W/m^2): the reduction's own when
    its selection computed them (greedy-swap) far enough."""
    k_top = int(min(problem.n_lights, max(min(CERTIFICATE_LIGHTS, max(p.n_lights for p in red.curve)), 1)))
    bounds = red.certificate  # the greedy-swap selection computed it already
    if bounds is None or len(bounds.bound) < k_top:
        bounds = lower_bounds_of(problem, k_top)
    return bounds


def positive_bound(problem, inv, final, bounds=None):
    """NNLS on T when ``final`` misses the targets by more than POSITIVE_GAP (the best any set of
    the candidate lights, non-negative, can do: an InverseResult), else None. ``bounds``: the
    certificate of the same T, whose all-lights NNLS it is when it has it."""
    if not final.relative_error > POSITIVE_GAP:
        return None
    if inv is not None and inv.solver == "nnls":
        return inv
    e = getattr(bounds, "nnls_exitance", None)
    if e is None or e.shape != (problem.n_lights, 3):
        return solve_inverse(problem, "nnls")
    err = problem.error(e)
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    return InverseResult(solver="nnls", exitance=e, rank=int((e.max(axis=1) > 0).sum()), error=err,
                         relative_error=err / norm, n_negative=0, seconds=0.0)
