"""Refinement of the chosen lamps (issue 17, item 3; no bpy).

Best k Lights chooses among a finite set of candidate lamps (engine/candidate_lamps.py): a few
mounting positions, a cone or a size per target cluster. Once a configuration is chosen, each of
its placed lamps' continuous parameters is refined to lower the configuration's true error (Eq. 1
over the targets, with every light's strength re-fitted by non-negative least squares per channel):

- a spot: its aim (two angles about its axis), its Spot Size (log scale), its Blend and its
  position on the mounting surface;
- an area lamp: its aim, its size (log scale, each side) and its position;
- a point lamp: its position.

A lamp stays valid: a cone within (0, pi], a blend within [0, 1], a size within
[SIZE_RANGE] x its first size, and its position ``drop`` in front of a surface that may hold lights
(a ray from the lamp back along the mounting normal hits a candidate patch facing it, with
nothing closer than the drop): it slides along the surface it hangs from and never into a wall
or past a forbidden face.

The transfer is linear in the powers: a lamp's column of T is rows P of A^-1 diag(rho) h for its
direct irradiance h (engine.lamps, LAMP_POINTS receiver points per patch, shadow rays), so one
evaluation costs one lamp's shadow rays on the patches its light can reach, a (P, m) product per
channel and k-column NNLS fits (the lamp's first reflection at the albedo of its incidence, as
the solve's: engine.incidence.lamp_albedo_excess). The lamps are refined one at a time (the others fixed) by scipy's
Nelder-Mead on parameters scaled to unit steps, at most MAX_EVALUATIONS evaluations each, for
ROUNDS rounds, and BUDGET evaluations for all the configurations of a solve; a lamp's refinement is kept only when it lowers the error.
The rounds take the slide in turn two ways (AIM_ROUNDS): the first moves a lamp with its direction
kept, the second turns a slid lamp to keep its axis on the point it met (a spot slid along the
ceiling keeps its beam on the picture it lights), a new search from the first's lamp in other
coordinates. The search's receiver points and
lamp samples are each patch's own (lamps.PatchDraws of the seed, drawn once): the same at every
evaluation whichever patches the moved lamp reaches, so the error is a deterministic function of
the parameters that changes only as the lamp does (drawn in turn from one stream, a patch's points
changed whenever the patches before it did: the objective jumped at each step; measured at five
seeds on three scenes, docs/benchmarks.md), and a result is reproducible. The lamp kept is
evaluated as every lamp is (LAMP_POINTS, its own stream).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize as sopt
import scipy.sparse as sp

from .light_colour import fit_columns
from .geometry import unit
from .candidate_lamps import LAMP_POINTS, lamp_reach, patch_radius
from .lamps import PatchDraws, lamp_irradiance
from .lights.placed import frame
from .sampling import check_cancel

__all__ = ["Transport", "Mount", "refine_configuration", "RefinedLamp"]

#: receiver points per patch of a lamp's irradiance while searching (the lamp kept takes
#: candidate_lamps.LAMP_POINTS)
SEARCH_POINTS = 4
#: samples of a lamp with an extent per glossy viewed point of its highlight while searching (a
#: camera-view target's lamp_terms; the lamp kept takes the kind's own, view_lamps.LAMP_VIEW_SAMPLES)
SEARCH_SAMPLES = 4
#: Nelder-Mead evaluations per lamp and round, and rounds over the configuration's lamps
MAX_EVALUATIONS = 60
ROUNDS = 2
#: evaluations of a whole solve at most (its configurations' lamps share them: jobs.refine_stage)
BUDGET = 8 * MAX_EVALUATIONS
#: a round that lowers the relative error by less than this stops the refinement
MIN_GAIN = 1e-4
#: per round (in turn): whether a lamp slid along its surface keeps aiming at the point its axis met
#: (True) or keeps its direction (False). The second round's search from the first's lamp in the
#: other coordinates: the final error 0.2-7 % lower on the view target, 18-30 % on the gallery, the
#: staircase within -0.6 / +1.6 %, at five seeds each (docs/benchmarks.md, "a slid lamp keeps its aim")
AIM_ROUNDS = (False, True)
#: a size stays within this range of factors of its first size
SIZE_RANGE = (0.25, 4.0)


class Transport:
    """Rows P (the targets) of A^-1 per channel, from an InverseProblem's solvers, and the albedo of
    each patch's first reflection: the targets' radiosity per unit of a lamp's direct irradiance on
    each patch (``column``). ``albedo_excess(lamp)``: (P, 3) R(mu) - rho of the lamp's first
    reflection (engine.incidence.lamp_albedo_excess), None for none."""

    def __init__(self, problem, albedo_excess=None):
        facs = problem.factors()
        self.rho = problem.reflectance
        self.albedo_excess = albedo_excess
        self.rows = problem.target_rows
        self.Y = []
        done = {}
        for c in range(3):
            if id(facs[c]) not in done:
                # (P, m): Y^T = R A^-1, row-major (a lamp's column gathers the rows it lights)
                done[id(facs[c])] = np.ascontiguousarray(problem.inverse_rows(facs[c]))
            self.Y.append(done[id(facs[c])])

    def column(self, h, lamp=None, samples=None) -> np.ndarray:
        """(m, 3): the targets' radiosity per unit strength of ``lamp`` whose direct irradiance is
        ``h`` (P,): rows P of A^-1 ((rho + x) h), x its first reflection's excess albedo; plus what
        the lamp adds to the rows beyond B (TargetRows.lamp_terms: its highlight on a camera-view
        target's glossy pixels, computed for the lamp as it is now, with ``samples``)."""
        nz = np.flatnonzero(h)
        albedo = self.rho[nz]
        x = None if self.albedo_excess is None or lamp is None else self.albedo_excess(lamp)
        if x is not None:
            albedo = albedo + x[nz]
        # (a sparse row of the lit patches times Y: it reads their rows of Y in place, 2-3 x quicker
        # than gathering them on the view target's 941 rows)
        P, ptr = len(h), np.array([0, len(nz)])
        col = np.stack([(sp.csr_matrix((albedo[:, c] * h[nz], nz, ptr), shape=(1, P)) @ self.Y[c])[0]
                        for c in range(3)], axis=1)
        X = None if lamp is None else self.rows.lamp_terms([lamp], h.reshape(-1, 1), samples)
        return col if X is None else col + X[:, 0, :]  # (a view target's highlight of the moved lamp)


@dataclass
class Mount:
    """Where a lamp may hang: ``drop`` (m) in front of the candidate patches ``candidates`` (P,)
    bool, on ``sampler`` (the solve's Embree scene)."""

    patches: object
    candidates: np.ndarray
    drop: float
    sampler: object

    def normal_at(self, position) -> np.ndarray | None:
        """The normal of the candidate surface ``position`` hangs from: of the candidate patches
        whose plane lies ``drop`` behind it along their normal, the nearest to the foot of the
        drop, if the lamp ``holds`` there; else None."""
        C = np.flatnonzero(self.candidates)
        if not len(C):
            return None
        n, c = self.patches.normal[C], self.patches.center[C]
        height = np.einsum("ij,ij->i", position[None, :] - c, n)
        on = np.flatnonzero(np.abs(height - self.drop) <= 1e-6 * max(self.drop, 1.0) + 1e-9)
        if not len(on):
            return None
        foot = position[None, :] - self.drop * n[on]
        i = on[int(np.argmin(np.linalg.norm(foot - c[on], axis=1)))]
        return n[i].copy() if self.holds(position, n[i]) else None

    def holds(self, position, normal) -> bool:
        """Whether a lamp at ``position`` hangs ``drop`` in front of a candidate patch facing ``normal``."""
        o = np.asarray(position, dtype=np.float32).reshape(1, 3)
        d = (-np.asarray(normal, dtype=np.float32)).reshape(1, 3)
        hit = int(self.sampler.front_hit_patches(o, d)[0])
        if hit >= self.patches.n_patches or not self.candidates[hit] or self.patches.normal[hit] @ normal < 0.99:
            return False
        return bool(self.sampler.visible(o, d, np.array([0.95 * self.drop], dtype=np.float32))[0])


@dataclass
class RefinedLamp:
    """A lamp of a configuration after refinement: its position ``index`` in the configuration,
    ``lamp`` (engine.lamps.Lamp) and its direct irradiance per W ``irradiance`` (P,)."""

    index: int
    lamp: object
    irradiance: np.ndarray


class _LampParameters:
    """A lamp's refined parameters (its kind's ``refinement_parameters``: slide_u / slide_v along the surface it
    hangs from, ``mount``'s Mount.normal_at, if any; aim_u / aim_v about its axis; the kind's own,
    which its ``refined`` applies) as a vector x scaled to unit steps (x = 0: the lamp as it is).
    ``keep_aim``: a slid lamp turns to keep its axis on the point it met (``aim_point``), the aim's
    angles taken about that line; else it keeps its direction (AIM_ROUNDS)."""

    size_range = SIZE_RANGE

    def __init__(self, lamp, mount, step_length, keep_aim=False):
        normal = mount.normal_at(lamp.position)
        self.lamp, self.mount, self.normal = lamp, mount, normal
        names = lamp.kind.refinement_parameters(lamp)
        self.names = names if normal is not None else tuple(p for p in names if not p.startswith("slide"))
        self.mount_u = self.mount_v = None
        if normal is not None:  # tangents u and n x u (frame's second axis is -n x u)
            _, self.mount_u, v = frame(normal)
            self.mount_v = -v
        self.step_length = float(step_length)
        self.aim_point = _aimed_point(lamp, mount.sampler) if keep_aim and normal is not None \
            and "aim_u" in self.names else None
        half = lamp.kind.aim_half_angle(lamp)
        self.step_angle = 0.25 * half  # radians of aim per unit
        self.step_log = 0.15
        self.step_blend = 0.2

    def lamp_at(self, x):
        """The engine.lamps.Lamp at parameters ``x``; None when the lamp would not be valid."""
        lamp, values = self.lamp, dict(zip(self.names, x))
        position = lamp.position.copy()
        slid = bool(values.get("slide_u", 0.0) or values.get("slide_v", 0.0))
        if slid:
            position = position + self.step_length * (values["slide_u"] * self.mount_u + values["slide_v"] * self.mount_v)
            if not self.mount.holds(position, self.normal):
                return None
        direction, axis_u, axis_v = lamp.direction, lamp.axis_u, lamp.axis_v
        if slid and self.aim_point is not None:  # (turned to its aim, unless it hangs at that point)
            to_aim = self.aim_point - position
            if np.linalg.norm(to_aim) > 1e-6 * self.step_length:
                direction, axis_u, axis_v = frame(to_aim)
        if "aim_u" in values:
            direction = unit((direction + math.tan(self.step_angle * values["aim_u"]) * axis_u
                              + math.tan(self.step_angle * values["aim_v"]) * axis_v)[None, :])[0]
            if self.normal is not None and direction @ self.normal <= 0:
                return None  # aimed behind its mounting surface
        d, u, v = frame(direction)
        return lamp.kind.refined(replace(lamp, position=position, direction=d, axis_u=u, axis_v=v, notes=[]),
                                 values, self)


def _aimed_point(lamp, sampler):
    """The point the lamp's axis meets first (its aim, on ``sampler``'s triangles), None when it
    meets nothing ahead."""
    o = np.asarray(lamp.position, dtype=np.float32).reshape(1, 3)
    d = np.asarray(lamp.direction, dtype=np.float32).reshape(1, 3)
    tri = int(np.asarray(sampler.first_hit(o, d))[0])
    if tri < 0:
        return None
    n = sampler.tn[tri]
    den = float(n @ lamp.direction)
    if abs(den) < 1e-9:
        return None
    t = float(n @ (sampler.tv[tri, 0] - lamp.position)) / den
    return lamp.position + t * lamp.direction if t > 0 else None


def refine_configuration(problem, lamps: dict, columns, transport: Transport, mount: Mount, step_length: float,
                         seed=0, max_evaluations=None, rounds=None, budget=None, cancel=None, exitance=None,
                         upper=None, halt=None) -> tuple:
    """Refine the placed lamps ``lamps`` {position in the configuration: engine.lamps.Lamp (1 W per
    channel)} of a configuration whose lights' transfer columns are ``columns`` (3 arrays (m, k))
    (see the module docstring). ``step_length``: the slide of one unit (m). Returns ([RefinedLamp] of the lamps whose
    refinement lowered the error, the columns with theirs replaced, the relative error before and
    after, evaluations). ``budget``: the evaluations it may use at most (default BUDGET). ``exitance``
    (k, 3): the configuration's strengths, whose colours a constrained light colour keeps; ``upper`` (k,):
    the lights' largest strength per channel (their kinds' strength_upper; None: none), kept in every fit.
    ``cancel()`` is asked before each lamp's search (True: the lamps refined so far are returned);
    ``halt()`` at each of its evaluations (True: sampling.Cancelled, a newer stroke not kept waiting)."""
    max_evaluations = MAX_EVALUATIONS if max_evaluations is None else int(max_evaluations)
    rounds = ROUNDS if rounds is None else int(rounds)
    budget = BUDGET if budget is None else int(budget)
    search = _Search(problem, transport, mount, seed, exitance, upper, halt)
    cols = [np.array(c, dtype=np.float64, copy=True) for c in columns]
    start = search.error(cols)
    best, evaluations, refined = start, 0, {}
    current = dict(lamps)
    for rnd in range(rounds):
        round_start = best
        for j in list(current):
            if (cancel is not None and cancel()) or evaluations >= budget:
                break
            params = _LampParameters(current[j], mount, step_length, keep_aim=AIM_ROUNDS[rnd % len(AIM_ROUNDS)])
            lowered, cand, used = search.minimize(params, cols, j, min(max_evaluations, budget - evaluations))
            evaluations += used
            if cand is not None and lowered:  # kept if it lowers the error at the full points
                h = search.irradiance(cand, LAMP_POINTS, searching=False)
                kept = search.with_column(cols, j, h, cand)
                err = search.error(kept)
                if err < best:
                    cols, best, current[j] = kept, err, cand
                    refined[j] = RefinedLamp(j, cand, h)
        if round_start - best < MIN_GAIN * max(round_start, 1e-12):
            break
    return list(refined.values()), cols, start, best, evaluations


class _Search:
    """What refine_configuration evaluates: a configuration's relative error (the best strengths of
    the problem's light colour: NNLS per channel when free), a lamp's irradiance on the patches it
    reaches (one seed: the same receiver points at every evaluation), and its column of T.
    ``halt()`` returning True stops a search at its next evaluation (sampling.Cancelled)."""

    def __init__(self, problem, transport, mount, seed, exitance, upper=None, halt=None):
        self.problem, self.transport, self.mount, self.seed, self.exitance = problem, transport, mount, seed, exitance
        self.upper, self.halt = upper, halt
        self.norm = problem.target_norm if problem.target_norm > 0 else 1.0
        self.radius = patch_radius(mount.patches, mount.sampler)
        self.draws = PatchDraws(seed)  # (the search's receiver points: each patch's own, drawn once)

    def error(self, cs):
        return fit_columns(self.problem, cs, self.exitance, refit=False, upper=self.upper)[1] / self.norm

    def irradiance(self, lamp, points=SEARCH_POINTS, searching=True):
        """``lamp``'s direct irradiance per W (P,) from ``points`` receiver points a patch on the
        patches it can reach; ``searching``: each patch's points and lamp samples its own
        (lamps.PatchDraws, kept), else as every lamp kept is computed (a stream per lamp)."""
        patches = self.mount.patches
        return lamp_irradiance(patches, [lamp], sampler=self.mount.sampler, seed=self.seed, points_per_patch=points,
                               only=lamp_reach(patches, [lamp], self.radius),
                               per_patch=self.draws if searching else None)[:, 0, 0]

    def with_column(self, cs, j, h, lamp, samples=None):
        col = self.transport.column(h, lamp, samples)
        out = [c.copy() for c in cs]
        for c in range(3):
            out[c][:, j] = col[:, c]
        return out

    def minimize(self, params, cols, j, max_evaluations) -> tuple:
        """Nelder-Mead on lamp ``j``'s parameters (``params``, _LampParameters), at most
        ``max_evaluations``: (whether the lamp it found lowers the error, that lamp or None, evaluations)."""
        seen = {}

        def f(x):
            check_cancel(self.halt)
            key = tuple(np.round(x, 9))
            if key not in seen:
                cand = params.lamp_at(x)
                h = None if cand is None else self.irradiance(cand)
                val = (self.error(self.with_column(cols, j, h, cand, SEARCH_SAMPLES))
                       if h is not None and np.any(h > 0) else math.inf)
                seen[key] = (val, cand)
            return seen[key][0]

        x0 = np.zeros(len(params.names))
        base = f(x0)  # this lamp as it is, with the search's receiver points
        res = sopt.minimize(f, x0, method="Nelder-Mead",
                            options={"maxfev": max_evaluations, "initial_simplex": np.vstack([x0, np.eye(len(x0))]),
                                     "xatol": 1e-2, "fatol": 1e-5 * max(base, 1e-12)})
        val, cand = seen.get(tuple(np.round(res.x, 9)), (math.inf, None))
        return val < base - 1e-12, cand, len(seen)
