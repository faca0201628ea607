"""Light-source reduction (the paper's sections 3 and 4).

Starting from a configuration e_x on the candidates of an
:class:`~.inverse.InverseProblem`, a *selection* procedure picks a subset of
lights and an *energy conservation* (``XDistribute``) gives the power of the
suppressed lights to the remaining ones. Every configuration visited is
recorded as a :class:`CurvePoint` (the paper's error curve, Fig. 11); the final
configuration is chosen on that curve by the stop criteria.

Selections (``selection=``)
- ``exitance-elimination`` (the paper's choice): re-sort after every step and
  remove the lowest light -- lights with a negative channel first (most
  negative power first), then the weakest positive -- redistributing
  cumulatively (``e_p <- e'_p``). Runs down to one light.
- ``exitance-construction``: add lights in DecreasingOrder of e_x; each
  configuration is e_x on the selected lights plus the original power of every
  not-yet-selected light distributed over them (not cumulative, as in Fig. 3).
- ``error-elimination``: remove the light whose removal (after redistribution)
  gives the smallest error; cumulative. All trials of a step are evaluated at
  once with matrix products on T.
- ``error-construction``: add the light whose addition gives the smallest error.
- ``greedy-swap`` (beyond the paper; the default, "Best k Lights", engine/best_lights.py): for
  every number of lights k, greedy pursuit on the true error with NNLS refits, then swaps; with a
  certificate (a lower bound on any k non-negative lights).
- ``least-power`` (beyond the paper): the non-negative lights of least total power that keep
  every target within a tolerance (a linear programme, HiGHS).
- ``nnls-greedy`` (beyond the paper): non-negative orthogonal matching pursuit
  on T -- add the candidate most correlated with the residual, refit all
  selected lights with NNLS. Every configuration is non-negative; ignores e_x
  and the distribution.

DecreasingOrder sorts by the power Phi = e * A summed over the channels, signed.

Distributions (``distribution=``), weights w_l summing to 1 over the receiving
lights, light l gets ``Phi_s[channel] * w_l / A_l`` so the power per channel is
conserved exactly:
- ``uniform``: w = 1/p over the p remaining lights.
- ``coplanar``: w = 1/n over the n remaining lights coplanar with s (same facing
  normal within ``coplanar_tolerance`` and in-plane within ``coplanar_tolerance`` times the
  candidates' extent); uniform when there is none.
- ``local``: all weight to the light(s) nearest in form-factor-row distance
  d_l = ||F_s - F_l||; ties (relative 1e-9) share equally.
- ``distance``: lights whose centre distance d_l is below the threshold (the
  mean distance to the remaining lights) get w proportional to 1/d_l. When no
  light is strictly below the mean -- one light left, or all at the same
  distance -- every remaining light takes part (weights 1/d). A light at
  distance 0 (coincident centres) takes everything.

The final configuration is chosen on the whole curve (which the UI shows) by the stop
criteria given (max_lights, require_positive, error_threshold /
relative_error_threshold):
- with an error threshold: the fewest lights among the points meeting every criterion
  (ties: smaller error), the paper's "reduce while the error stays acceptable";
- with a number of lights and no threshold: the point where the paper's loop would stop,
  i.e. the most lights not above max_lights among the points meeting the other criteria
  (ties: smaller error);
- with neither: the smallest error among the points meeting require_positive.
When no point meets them all, the error criterion is relaxed first (smallest
error among the rest), and the result says so in ``warnings``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .inverse import InverseProblem
from .light_colour import channel_error, colour_problem
from . import distributions, selections  # noqa: F401  (register the methods reduce_lights dispatches to)
from .registry import DISTRIBUTIONS, SELECTIONS

__all__ = [
    "SELECTIONS",
    "DISTRIBUTIONS",
    "Selection",
    "StopCriteria",
    "StrokeStart",
    "ERROR_ROUTES",
    "CurvePoint",
    "ReductionResult",
    "Distributor",
    "reduce_lights",
    "select_final",
]

ERROR_ROUTES = ("transfer", "gauss-seidel")


@dataclass
class CurvePoint:
    """One configuration of the error curve.

    lights: indices of the problem's lights (ascending; a light is a candidate patch, or a
    group of them, see InverseProblem's light_groups); exitance (k, 3) W/m^2
    aligned with them. changed: the candidate added/removed at this step (-1 at
    the start). error: Eq. 1 (W/m^2); relative_error = error / ||b_P||.
    n_negative: lights with at least one negative channel.
    """

    n_lights: int
    error: float
    relative_error: float
    n_negative: int
    lights: np.ndarray
    exitance: np.ndarray
    changed: int = -1


@dataclass
class ReductionResult:
    curve: list
    final_index: int
    selection: str
    distribution: str
    seconds: float
    cancelled: bool = False
    gs_iterations: list = None  # Gauss-Seidel sweeps per curve point (sum over channels), warm start
    gs_cold_iterations: list = None  # the same from a cold start (when compared)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)  # the selection's own messages (also in ``warnings``)
    #: best_lights.LowerBounds, when the selection computed the certificate on the way (greedy-swap)
    certificate: object = None

    @property
    def final(self) -> CurvePoint:
        return self.curve[self.final_index]

    def patch_exitance(self, problem, index=None):
        """Full (P, 3) exitance of curve point ``index`` (default: the final one)."""
        pt = self.curve[self.final_index if index is None else index]
        e = np.zeros((problem.n_lights, 3))
        e[pt.lights] = pt.exitance
        return problem.patch_exitance(e)


class Distributor:
    """XDistribute weights between lights: the registered rule ``distribution`` (engine/distributions/;
    with its parameters), its pairwise data precomputed once, rows normalised to 1 (power conserved
    per channel)."""

    def __init__(self, problem: InverseProblem, distribution="distance"):
        rule = DISTRIBUTIONS.bound(distribution)  # a name (its declared defaults) or DISTRIBUTIONS[name].bind(...)
        self.kind = rule.name
        self.rule = rule(problem)
        self.area = problem.light_watts

    @property
    def pair(self):
        """The rule's pairwise data between lights (distances, or the coplanarity matrix)."""
        return getattr(self.rule, "pair", None)

    def weights(self, src, lights, valid=None):
        """W (len(src), len(lights)), rows summing to 1: how each source's power is shared.

        ``valid`` (same shape, bool) excludes receivers (e.g. a light receiving its own power).
        """
        src = np.asarray(src, dtype=np.int64)
        lights = np.asarray(lights, dtype=np.int64)
        if valid is None:
            valid = np.ones((len(src), len(lights)), dtype=bool)
        M = self.rule.raw(src, lights, valid)
        s = M.sum(axis=1, keepdims=True)
        return M / np.where(s > 0, s, 1.0)

    def distribute(self, e_lights, lights, src, phi_src):
        """e' = e + sum over sources of Phi_s w_l / A_l (cumulative into a copy)."""
        if len(src) == 0:
            return e_lights.copy()
        W = self.weights(src, lights)
        return e_lights + (W.T @ phi_src) / self.area[lights][:, None]


@dataclass(frozen=True)
class StopCriteria:
    """The stop criteria that choose the final configuration on the curve (``select_final``): at
    most ``max_lights`` lights, an error at most ``error_threshold`` (W/m^2) and at most
    ``relative_error_threshold`` x ||b_P||, and no negative exitance with ``require_positive``."""

    max_lights: int | None = None
    error_threshold: float | None = None
    relative_error_threshold: float | None = None
    require_positive: bool = True

    def check(self):
        """ValueError naming the first criterion out of range."""
        if self.max_lights is not None and int(self.max_lights) < 1:
            raise ValueError(f"max_lights must be at least 1, got {self.max_lights}")
        for name in ("error_threshold", "relative_error_threshold"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a non-negative number, got {v}")


@dataclass(frozen=True)
class StrokeStart:
    """A stroke's re-solve (Live): the selections that build a curve per number of lights
    (greedy-swap) stop at ``curve_lights`` and run their quicker search (greedy-swap: without the
    surface lights' own curve) from the configurations ``initial`` {k: lights} (an earlier
    answer's); ``nnls_start`` (n_lights, 3): an earlier stroke's all-lights NNLS, the certificate's
    start."""

    curve_lights: int
    initial: dict | None = None
    nnls_start: object = None


@dataclass
class Selection:
    """What a registered selection works with (engine/selections/), besides its own parameters
    (given as keywords): the problem, the starting configuration e_x (n_lights, 3), the
    distributor (None for selections that do not redistribute), ``record(lights, exitance,
    changed)`` to add a configuration to the curve, ``step(done, total)`` returning True when
    cancelled (the curve stops where it is), ``cancel()`` the job's own (None: none; a step too
    long to wait for looks at it and raises sampling.Cancelled: the certificate's all-lights NNLS
    between channels, the curve's greedy additions and swap rounds), and ``max_steps`` for
    constructions. A selection that computes the certificate (lower bounds) on the way gives it in
    ``certificate``."""

    problem: InverseProblem
    e_x: np.ndarray
    dist: Distributor | None
    record: object
    step: object
    max_steps: int | None = None
    max_lights: int | None = None  # the stop criterion (selections that build a curve per k use it)
    certificate: object = None  # set by the selection: best_lights.LowerBounds, or left None
    stroke: StrokeStart | None = None  # a stroke's re-solve (Live): the selection's quicker search, where it has one
    cancel: object = None


class _ErrorEval:
    """Eq. 1 of configurations through T (exact) or the paper's Gauss-Seidel re-solve."""

    def __init__(self, problem, route, compare_cold=False, gs_tol=1e-8):
        self.p = problem
        self.T = problem.transfer
        self.b = problem.b_target
        self.route = route
        self.x = None
        self.iters = [] if route == "gauss-seidel" else None
        self.cold = [] if (route == "gauss-seidel" and compare_cold) else None
        self.gs_tol = gs_tol

    def __call__(self, lights, e):
        if self.route == "transfer":
            r = np.stack([self.T[c][:, lights] @ e[:, c] for c in range(3)], axis=1) - self.b
            return float(np.linalg.norm(r))
        from .radiosity import solve_radiosity

        full = np.zeros((self.p.n_lights, 3))
        full[lights] = e
        e_full = self.p.patch_exitance(full)
        B, info = solve_radiosity(self.p.F, self.p.reflectance, self.p.source(e_full), method="gauss-seidel",
                                  tol=self.gs_tol, max_iter=10000, x0=self.x)
        self.iters.append(int(sum(info["iterations"])))
        if self.cold is not None:
            _, info0 = solve_radiosity(self.p.F, self.p.reflectance, self.p.source(e_full), method="gauss-seidel",
                                       tol=self.gs_tol, max_iter=10000)
            self.cold.append(int(sum(info0["iterations"])))
        self.x = B
        return float(np.linalg.norm(self.p.target_rows.of(B) - self.b))


def in_colour(problem, view, colour, curve, refits=False) -> list:
    """A curve found on a colour view (engine.light_colour.ColourProblem) as the lights' exitance
    (their power times their colour), its errors on the problem's own T (the same values); with
    ``refits`` (the selections that fit by NNLS) each non-negative configuration's colours refitted
    (colour.fit: a blackbody light's temperature) where that lowers its error, and the curve kept
    from rising (a configuration no better than the one before it with fewer lights is replaced
    by that one)."""
    T, b = problem.transfer, problem.b_target
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    out = []
    for pt in curve:
        lights = np.asarray(pt.lights, dtype=np.int64)
        e = view.exitance_of(lights, pt.exitance)
        if refits and pt.n_negative == 0 and len(lights):
            e2, _ = colour.fit([T[c][:, lights] for c in range(3)], b, e, upper=_upper_of(problem, lights))
            on = e2.max(axis=1) > 0
            lights, e = lights[on], e2[on]
        err = channel_error([t[:, lights] for t in T], e, b)
        new = CurvePoint(len(lights), err, err / norm, _neg(e), lights, e.copy(), int(pt.changed))
        prev = out[-1] if out else None
        if refits and prev is not None and prev.n_negative == 0 and new.n_negative == 0 \
                and prev.n_lights <= new.n_lights and prev.error < new.error:
            new = replace(prev, lights=prev.lights.copy(), exitance=prev.exitance.copy())
        out.append(new)
    return out


def _upper_of(problem, lights):
    """(k,) the largest strength per channel of the problem's lights ``lights`` (None: none bounded)."""
    upper = getattr(problem, "light_upper", None)
    return None if upper is None else np.asarray(upper, dtype=np.float64)[np.asarray(lights, dtype=np.int64)]


def _neg(e):
    return int((e < 0).any(axis=1).sum())


def select_final(curve, target_norm=1.0, stop: StopCriteria = StopCriteria()):
    """Index of the final configuration on the curve under the stop criteria, and warnings."""
    max_lights, error_threshold = stop.max_lights, stop.error_threshold
    relative_error_threshold, require_positive = stop.relative_error_threshold, stop.require_positive
    n = np.array([p.n_lights for p in curve])
    err = np.array([p.error for p in curve])
    neg = np.array([p.n_negative for p in curve])
    ok_struct = np.ones(len(curve), dtype=bool)
    if max_lights is not None:
        ok_struct &= n <= max_lights
    if require_positive:
        ok_struct &= neg == 0
    thr = np.inf
    if error_threshold is not None:
        thr = min(thr, float(error_threshold))
    if relative_error_threshold is not None:
        thr = min(thr, float(relative_error_threshold) * target_norm)
    ok = ok_struct & (err <= thr)
    warns = []

    def best(mask, by_lights=True):
        idx = np.flatnonzero(mask)
        key = np.lexsort((err[idx], n[idx])) if by_lights else np.lexsort((n[idx], err[idx]))
        return int(idx[key[0]])

    if ok.any():
        if np.isfinite(thr):
            return best(ok), warns
        if max_lights is not None:
            idx = np.flatnonzero(ok)
            return int(idx[np.lexsort((err[idx], -n[idx]))[0]]), warns
        return best(ok, by_lights=False), warns
    if ok_struct.any():
        i = best(ok_struct, by_lights=False)
        warns.append(f"no configuration meets the error threshold under the other criteria; "
                     f"kept the smallest error {err[i]:.4g} W/m^2 with {n[i]} lights")
        return i, warns
    # no point meets the structural criteria: only positivity can fail that way (every curve
    # reaches a small number of lights), e.g. when a colour channel of e_x has a negative
    # total power. Keep the point with the fewest negatives within max_lights.
    within = np.ones(len(curve), dtype=bool) if max_lights is None else n <= max_lights
    if not within.any():
        within[:] = True
    idx = np.flatnonzero(within)
    i = int(idx[np.lexsort((err[idx], neg[idx]))[0]])
    warns.append(f"no configuration on this curve is free of negative exitances; kept the one with the fewest "
                 f"({neg[i]} of {n[i]} lights, error {err[i]:.4g} W/m^2). The nnls solver or the nnls-greedy "
                 "selection give non-negative lights")
    return i, warns


def reduce_lights(problem: InverseProblem, e_x, selection="exitance-elimination", distribution="distance",
                  stop: StopCriteria = StopCriteria(), *, error_route="transfer", max_steps=None,
                  gs_compare_cold=False, stroke: StrokeStart | None = None, progress=None, cancel=None):
    """Reduce the number of lights of configuration e_x (|C|, 3); returns a ReductionResult.

    ``selection`` and ``distribution``: a registered name (the method with its declared defaults)
    or a bound method with its parameters (``SELECTIONS[name].bind(options)``). The whole curve
    is computed (eliminations down to one light, constructions until every candidate is in or
    ``max_steps`` steps); the stop criteria ``stop`` only choose the final point. ``error_route``:
    'transfer' (exact, one product with T) or 'gauss-seidel' (the paper's ComputeError: forward
    re-solve warm-started from the previous radiosity; exitance-* selections only;
    ``gs_compare_cold``: the cold start's sweeps counted too). ``progress(done, total)`` is called
    every step; ``cancel()`` returning True stops the curve where it is (``result.cancelled``).
    ``stroke``: a stroke's re-solve (Live, :class:`StrokeStart`). Deterministic: ties go to the
    lower index.
    """
    selection = SELECTIONS.bound(selection)
    e_x = _checked_start(problem, e_x, selection, stop, error_route, max_steps)
    t0 = time.perf_counter()
    colour = getattr(problem, "colour", None)
    view = colour_problem(problem, colour)  # the problem with the lights' colours tied (engine.light_colour)
    work = problem
    if view is not None:
        if error_route == "gauss-seidel":
            raise ValueError(f"the Gauss-Seidel error route re-solves each channel on its own; with {colour.name} "
                             "lights use the 'transfer' route")
        # (the paper's selections start from the constrained problem's inverse solution; the others
        # do not read it)
        work, e_x = view, view.start() if selection.traits.distributes else np.zeros((problem.n_lights, 3))
    curve = _Curve(_ErrorEval(work, error_route, compare_cold=gs_compare_cold),
                   problem.target_norm if problem.target_norm > 0 else 1.0, progress, cancel)
    dist = Distributor(work, distribution) if selection.traits.distributes else None
    sel = Selection(work, e_x, dist, curve.record, curve.step, max_steps, stop.max_lights, stroke=stroke, cancel=cancel)
    notes = selection(sel) or []
    if not curve.points:
        raise ValueError("the reduction produced no configuration")
    points, certificate = curve.points, sel.certificate
    if view is not None:  # back to the lights' colours (refitted where the selection fits by NNLS)
        points, certificate = _in_colours(problem, view, colour, selection, points, certificate)
    idx, warns = select_final(points, problem.target_norm, stop)
    warns = list(notes) + warns
    if curve.cancelled:
        warns.append("cancelled: the curve is incomplete")
    return ReductionResult(curve=points, final_index=idx, selection=selection.name,
                           distribution=dist.kind if dist is not None else "none",
                           seconds=time.perf_counter() - t0, cancelled=curve.cancelled,
                           gs_iterations=curve.error.iters, gs_cold_iterations=curve.error.cold, warnings=warns,
                           notes=list(notes), certificate=certificate)


def _checked_start(problem, e_x, selection, stop, error_route, max_steps) -> np.ndarray:
    """e_x as a (n_lights, 3) float array, after checking the route, the stop criteria and
    ``max_steps`` (ValueError naming what is wrong)."""
    if error_route not in ERROR_ROUTES:
        raise ValueError(f"unknown error route {error_route!r}; choose one of {', '.join(ERROR_ROUTES)}")
    if error_route == "gauss-seidel" and not selection.traits.gauss_seidel:
        raise ValueError("the Gauss-Seidel error route re-solves the scene per configuration; it is only "
                         "offered for exitance-elimination and exitance-construction (use 'transfer')")
    stop.check()
    if max_steps is not None and int(max_steps) < 1:
        raise ValueError(f"max_steps must be at least 1, got {max_steps}")
    k = problem.n_lights
    e_x = np.asarray(e_x, dtype=np.float64)
    if e_x.shape != (k, 3):
        raise ValueError(f"e_x must have shape ({k}, 3) (one row per candidate), got {e_x.shape}")
    if not np.all(np.isfinite(e_x)):
        raise ValueError("e_x contains NaN or infinite values")
    return e_x


class _Curve:
    """The error curve as a selection records it (``record``), with its error evaluation and the
    progress and cancel hooks (``step``)."""

    def __init__(self, error: _ErrorEval, norm: float, progress, cancel):
        self.error, self.norm = error, norm
        self.progress, self.cancel = progress, cancel
        self.points = []
        self.cancelled = False

    def record(self, lights, e, changed=-1):
        lights = np.asarray(lights, dtype=np.int64)
        order = np.argsort(lights)
        lights, e = lights[order], np.asarray(e, dtype=np.float64)[order]
        if not np.all(np.isfinite(e)):
            raise ValueError("the reduction produced non-finite exitances")
        err = self.error(lights, e)
        self.points.append(CurvePoint(len(lights), err, err / self.norm, _neg(e), lights, e.copy(), int(changed)))

    def step(self, done, total):
        if self.progress is not None:
            self.progress(done, total)
        if self.cancel is not None and self.cancel():
            self.cancelled = True
        return self.cancelled


def _in_colours(problem, view, colour, selection, points, certificate) -> tuple:
    """(the curve, the certificate) found on the colour view, back in the lights' colours: each
    configuration refitted where the selection fits by NNLS (``in_colour``)."""
    refits = getattr(colour, "refits", False) and not selection.traits.distributes \
        and not selection.traits.needs_tolerance
    points = in_colour(problem, view, colour, points, refits)
    if certificate is not None:
        certificate = colour.certificate(problem, view, view.real_bounds(certificate), len(certificate.bound))
    return points, certificate
