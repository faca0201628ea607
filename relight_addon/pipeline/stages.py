"""Stages 2-4 of a solve or a reduce, on a built model (pipeline.model; no bpy). Each stage
returns new results and leaves the ones it was given as they were:

- ``solve_stage``: the inverse solution e_x and its InverseResult;
- ``reduce_stage``: the selection x distribution over the whole curve (a ReductionResult);
- ``direct_stage``: the curve's surface lights' direct light by the kernel: a new model (its
  problem corrected) and a new reduction (the curve re-fitted, no certificate);
- ``refine_stage``: the chosen placed lamps refined: a new model (its lights and problem with
  the refined lamps appended) and a new reduction (the curve re-fitted);
- ``fixed_light``: the scene's own light's share of the targets, and the notes it calls for;
- ``assemble_curve``: the kept configurations' radiosity and the polygon map (a ``Curve``).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..engine.candidate_lamps import default_drop, offered_kinds
from ..engine.cost import DIRECT_LIGHTS, DIRECT_SPREAD_PATCHES
from ..engine.curve_refits import carry_refined, refit_curve
from ..engine.first_reflection import lamp_excess_of, lights_excess
from ..engine.inverse import solve_inverse
from ..engine.kernel_transfer import lights_direct_correction
from ..engine.lamp_refinement import BUDGET as REFINE_BUDGET, ROUNDS as LAMP_ROUNDS, Mount, Transport, \
    refine_configuration
from ..engine.light_colour import fit_columns
from ..engine.lights import append_lamps
from ..engine.lights.placed import WRITER as PLACED
from ..engine.options import JobOptions
from ..engine.reduction import ReductionResult, StopCriteria, StrokeStart, reduce_lights
from ..engine.registry import DISTRIBUTIONS, SELECTIONS
from ..engine.sampling import Cancelled, SceneSampler, check_cancel
from ..engine.scene import SceneError
from ..engine.scene_light import brighter_than_painted, fixed_light_shares
from . import notes as texts
from .meshing import uses_kernel_pairs
from .model import Model
from .polygons import PolygonMap
from .stored import stored_points

__all__ = ["Curve", "solve_stage", "reduce_stage", "direct_stage", "refine_stage", "fixed_light", "assemble_curve"]


@dataclass
class Curve:
    """Stage 4, the curve assembled for the scene: the configurations kept re-appliable (``keep``:
    indices into the reduction's curve), each light's exitance and every patch's radiosity per
    kept configuration, and the map to base-mesh polygons."""

    keep: np.ndarray
    final_row: int  # row of the final configuration among ``keep``
    exitance: np.ndarray  # (kept points, n_lights, 3) W/m^2
    radiosity: np.ndarray  # (kept points, P, 3) W/m^2, background included
    polygons: PolygonMap
    light_polygons: sp.csr_matrix  # (n_lights, n_polygons): the polygons each light lies on
    seconds: float

    def final_polygon_radiosity(self):
        return self.polygons.mean(self.radiosity[self.final_row])


def solve_stage(model: Model, options: JobOptions) -> tuple:
    """Stage 2: the inverse solution e_x (n_lights, 3), the configuration the reduction starts
    from, and its InverseResult."""
    inv = solve_inverse(model.problem, options.solver)
    return inv.exitance, inv


def reduce_stage(model: Model, e_x, options: JobOptions, progress=None, cancel=None,
                 curve_lights=None, initial=None, nnls_start=None) -> ReductionResult:
    """Stage 3: the selection x distribution over the whole curve; the stop criteria pick the
    final point. ``curve_lights``, ``initial``: a stroke's re-solve (Live; reduce_lights': a
    per-k curve to ``curve_lights``, the quick search, from the configurations ``initial``)."""
    selection = SELECTIONS[options.selection]
    by_lp = selection.traits.needs_tolerance  # the programme decides, not the stop criteria
    red = reduce_lights(model.problem, e_x, selection.bind(options), DISTRIBUTIONS[options.distribution].bind(options),
                        StopCriteria(max_lights=None if by_lp else options.max_lights,
                                     relative_error_threshold=None if by_lp else options.error_threshold,
                                     require_positive=options.require_positive),
                        stroke=StrokeStart(curve_lights, initial, nnls_start) if curve_lights is not None else None,
                        progress=(lambda d, t: progress("reduction", 0.8 + 0.15 * d / max(t, 1)))
                        if progress is not None else None, cancel=cancel)
    if red.cancelled:
        raise Cancelled("solve cancelled")
    return red


def _direct_lights(model: Model, red: ReductionResult, options: JobOptions) -> tuple:
    """(the lights whose direct light the kernel computes, the lights F's gather keeps): the
    non-negative configurations' of at most ``max_lights`` (or the final one's) lights, the smaller
    first, up to DIRECT_LIGHTS lights; a light of DIRECT_SPREAD_PATCHES patches or more keeps F's."""
    lights = model.lights
    DC = model.problem.direct_correction  # (a re-solved stroke's model: the lights corrected already)
    done = set() if DC is None else set(np.flatnonzero(np.diff(DC.tocsc().indptr) > 0).tolist())
    top = max(int(options.max_lights), red.final.n_lights)  # the rows above it are not the answer's
    order = sorted((i for i, pt in enumerate(red.curve) if pt.n_negative == 0 and pt.n_lights <= top),
                   key=lambda i: red.curve[i].n_lights)
    todo, spread = [], set()
    for i in order:
        for j in red.curve[i].lights:
            if int(j) in todo or int(j) in spread or int(j) in done or lights.lamp(int(j)) is not None \
                    or len(todo) >= DIRECT_LIGHTS:
                continue
            if len(lights.members(int(j))) >= DIRECT_SPREAD_PATCHES:  # F's gather of it stays (cost.py)
                spread.add(int(j))
            else:
                todo.append(int(j))
    return todo, spread


def _own_transfer(problem):
    """A shallow copy of ``problem`` with its own copy of T (channels that share one array still
    share it): what InverseProblem.correct_direct changes in place."""
    new = copy.copy(problem)
    copies = {}
    new._transfer = [copies.setdefault(id(t), t.copy()) for t in problem.transfer]
    return new


def direct_stage(model: Model, red: ReductionResult, options: JobOptions, cancel=None) -> tuple:
    """Stage 3a: the direct light of the curve's surface lights on every patch by the kernel
    (engine.kernel_transfer.lights_direct_correction; the ray-cast F gathers a small bright cell's
    light with a few per cent of noise, which the reflections carry to the targets: on the
    staircase the 3-light answer's prediction moved by 1.2 % from seed to seed), for the lights
    ``_direct_lights`` chooses (engine/cost.py: many rays make a spread light's). Their columns of
    T and the forward solves take it (InverseProblem.correct_direct, on a copy of the problem);
    each configuration's strengths are re-fitted (NNLS per channel, the same lights) and its error
    follows. Returns (the model with the corrected problem and ``direct``: what the report says,
    the reduction re-fitted, without its certificate: it was of the T before)."""
    if model.form_factors is None:
        return model, red
    problem, patches = model.problem, model.patches
    todo, spread = _direct_lights(model, red, options)
    if not todo:
        return replace(model, direct=None if not spread else {"lights": 0, "spread_lights": len(spread),
                                                              "seconds": 0.0}), red
    t0 = time.perf_counter()
    ff = model.form_factors
    # (the receivers whose F entries with the lights are kernel estimates already: the painted
    # patches, build_inverse_model's kernel pairs; not the rows' first patches, which for a view
    # target are the pixels' patches, left with the rays' noise)
    skip = np.flatnonzero(patches.target) if uses_kernel_pairs(options) else None
    dH = lights_direct_correction(patches, problem.F, todo, model.lights.members, getattr(ff, "send", None), skip,
                                  seed=options.seed, sampler=getattr(ff, "sampler", None), cancel=cancel)
    problem = _own_transfer(problem)
    problem.correct_direct(todo, dH)
    before = [float(pt.relative_error) for pt in red.curve]
    selection = SELECTIONS[options.selection]
    refit = selection.traits.refit  # a selection's own programme (least-power's LP)
    own = None if refit is None else (lambda view, ids: refit(view, ids, **selection.bind(options).params))
    curve, notes = refit_curve(problem, red.curve, red.final_index, todo, own)
    warnings, kept_notes = red.warnings, red.notes
    if notes:  # the selection's message of the final configuration, as it is now
        warnings, kept_notes = notes + [w for w in red.warnings if w not in red.notes], notes
    curve = carry_refined(problem, curve, red.final_index, {}, every=True)  # the curve never rises
    # the certificate is of the T the configurations are now measured on
    red = replace(red, curve=curve, warnings=warnings, notes=kept_notes, certificate=None)
    direct = {"lights": len(todo), "spread_lights": len(spread), "seconds": time.perf_counter() - t0,
              "final_relative_error_before": before[red.final_index],
              "final_relative_error_after": float(red.final.relative_error)}
    return replace(model, problem=problem, direct=direct), red


def _refining(progress, cancel, n_done, n_todo, n_lamps):
    """The cancel check refine_configuration makes before each lamp of each round, reporting the
    progress too: a configuration's refinement takes seconds, and the bar said "reduction 95 %"
    meanwhile (issue 36)."""
    calls = [0]

    def check():
        if progress is not None:
            within = min(1.0, calls[0] / max(1, LAMP_ROUNDS * n_lamps))
            progress("refining lamps", 0.95 + 0.03 * (n_done + within) / max(n_todo, 1))
        calls[0] += 1
        return cancel is not None and cancel()
    return check


def _placed(lights, j) -> bool:
    """Whether light ``j`` is a placed lamp (a candidate lamp the solve offered)."""
    return lights.lamp(j) is not None and lights.kind_of(j).writer == PLACED


@dataclass
class _Refined:
    """What refine_stage's configurations made: the new lamps (their kinds, irradiance, columns of
    T), the final configuration's candidate -> refined light, the report's rows."""

    lamps: list
    kinds: list
    irradiance: list
    columns: list
    carried: dict
    rows: list
    evaluations: int = 0


def _refine_point(problem, lights, pt, is_final, setup, done: _Refined, check, halt=None):
    """The placed lamps of one configuration refined (engine.lamp_refinement), each refined lamp
    appended to ``done`` as a new light; the configuration with them, re-fitted (None: unchanged).
    A smaller configuration holding a lamp the final one refined (``done.carried``) starts from that
    refined lamp when it fits this configuration better than the lamp as offered, and searches one
    round from there (_carried_start)."""
    T, transport, mount, step, seed = setup
    placed = {pos: lights.lamp(j) for pos, j in enumerate(pt.lights) if _placed(lights, j)}
    cols = [T[c][:, pt.lights] for c in range(3)]
    ids = np.array(pt.lights, dtype=np.int64)
    carried, cols = ({}, cols) if is_final else _carried_start(problem, lights, pt, placed, cols, done)
    for pos, k in carried.items():
        placed[pos], ids[pos] = done.lamps[k], lights.n_lights + k
    refined, cols, before, after, n_eval = refine_configuration(
        problem, placed, cols, transport, mount, step, seed=seed, budget=REFINE_BUDGET - done.evaluations,
        exitance=pt.exitance, cancel=check(len(placed)), upper=problem.light_upper[pt.lights], halt=halt,
        rounds=1 if carried else None)
    done.evaluations += n_eval
    done.rows.append({"n_lights": pt.n_lights, "relative_error_before": pt.relative_error if carried else before,
                      "relative_error_after": after, "lamps_refined": len(refined), "lamps_carried": len(carried),
                      "evaluations": n_eval})
    if not refined and not carried:
        return None
    for r in refined:
        ids[r.index] = lights.n_lights + len(done.lamps)
        if is_final:
            done.carried[int(pt.lights[r.index])] = int(ids[r.index])
        done.lamps.append(r.lamp)
        done.kinds.append(lights.kind_names[int(pt.lights[r.index])])
        done.irradiance.append(r.irradiance)
        for c in range(3):
            done.columns[c].append(cols[c][:, r.index])
    e, error = fit_columns(problem, cols, pt.exitance, upper=problem.light_upper[pt.lights])  # (of the light colour)
    order = np.argsort(ids, kind="stable")
    on = e[order].max(axis=1) > 0
    return replace(pt, n_lights=int(on.sum()), lights=ids[order][on], exitance=e[order][on],
                   error=error, relative_error=error / (problem.target_norm or 1.0))


def _carried_start(problem, lights, pt, placed, cols, done: _Refined) -> dict:
    """({position in ``pt``: index in ``done.lamps``} of the placed lamps of configuration ``pt`` that
    the final configuration refined (``done.carried``), the columns with theirs in their place), when
    this configuration fits better with them than with the lamps as offered (columns ``cols``); else
    ({}, ``cols``)."""
    k = {pos: done.carried[int(pt.lights[pos])] - lights.n_lights for pos in placed
         if int(pt.lights[pos]) in done.carried}
    if not k:
        return {}, cols
    upper = problem.light_upper[pt.lights]
    swapped = [c.copy() for c in cols]
    for pos, i in k.items():
        for c in range(3):
            swapped[c][:, pos] = done.columns[c][i]
    as_offered = fit_columns(problem, cols, pt.exitance, refit=False, upper=upper)[1]
    better = fit_columns(problem, swapped, pt.exitance, refit=False, upper=upper)[1] < as_offered
    return (k, swapped) if better else ({}, cols)


def _refine_setup(model: Model, options: JobOptions) -> tuple:
    """(T, Transport, Mount, step, seed): what refining a configuration's lamps needs."""
    problem, patches = model.problem, model.patches
    sampler = getattr(model.form_factors, "sampler", None) or SceneSampler(patches)
    drop = float(options.lamp_drop if options.lamp_drop is not None else default_drop(patches))
    mount = Mount(patches, problem.candidate_mask, drop, sampler)
    transport = Transport(problem, lamp_excess_of(model.faces, patches) if problem.lamp_excess is not None else None)
    step = float(patches.light_size or patches.max_patch_size)
    return problem.transfer, transport, mount, step, options.seed


def _with_lamps(model: Model, done: _Refined) -> Model:
    """The model with the refined lamps appended to its lights and to (a copy of) its problem."""
    patches = model.patches
    area = np.array([lamp.kind.area(lamp) for lamp in done.lamps])
    H_new = np.stack(done.irradiance, axis=1)
    lights = append_lamps(model.lights, model.lights.patches, patches.n_patches, done.lamps, done.kinds, H_new, area)
    problem = copy.copy(model.problem)  # (add_lights replaces what it extends: the model's problem stays)
    problem.add_lights(lights, [np.stack(done.columns[c], axis=1) for c in range(3)],
                       lights_excess(model.faces, patches, None, done.lamps, H_new))
    return replace(model, lights=lights, problem=problem)


def refine_stage(model: Model, red: ReductionResult, options: JobOptions, progress=None, cancel=None) -> tuple:
    """Stage 3b: the placed lamps of the final configuration and of the curve's smaller ones refined
    (engine.lamp_refinement), the final one first, then from the largest down while its BUDGET
    lasts: each refined lamp becomes a new light of the problem (its kind, its column of T), the
    point's lights and strengths (NNLS per channel) and error follow. Returns (the model with
    the refined lamps and ``lamp_refinement``: what the report says of it, None when nothing was
    refined; the reduction re-fitted). A selection with its own programme (``refit``: least power
    within a tolerance, and its uniformity goal) is not refined: the refinement lowers the error
    and refits by least squares, which broke the programme's band and goal (the gallery's strip:
    U0 0.563 reported against the 0.6 'met')."""
    if not options.param("refine_lamps", False) or not offered_kinds(options) \
            or SELECTIONS[options.selection].traits.refit is not None:
        return model, red
    lights = model.lights
    todo = [i for i, pt in enumerate(red.curve)
            if (pt.n_lights <= red.final.n_lights or i == red.final_index) and pt.n_negative == 0
            and any(_placed(lights, j) for j in pt.lights)]
    # the final configuration first, then the smaller ones from the largest, while the budget lasts
    todo.sort(key=lambda i: (i != red.final_index, -red.curve[i].n_lights))
    if not todo:
        return model, red
    t0 = time.perf_counter()
    setup = _refine_setup(model, options)
    done, curve = _Refined([], [], [], [[], [], []], {}, []), list(red.curve)
    for n_done, i in enumerate(todo):
        check_cancel(cancel)
        if done.evaluations >= REFINE_BUDGET:
            break
        point = _refine_point(model.problem, lights, curve[i], i == red.final_index, setup, done,
                              lambda n_lamps: _refining(progress, cancel, n_done, len(todo), n_lamps), cancel)
        curve[i] = curve[i] if point is None else point
        if progress is not None:
            progress("refining lamps", 0.95 + 0.03 * (n_done + 1) / len(todo))
    check_cancel(cancel)  # (heard within a lamp's search: no half-refined answer)
    account = {"points": done.rows, "offered": lights.count_by_kind(), "lamps_refined": len(done.lamps),
               "evaluations": done.evaluations}
    if done.lamps:
        model = _with_lamps(model, done)
        curve = carry_refined(model.problem, curve, red.final_index, done.carried)
    account["seconds"] = time.perf_counter() - t0
    return replace(model, lamp_refinement=account), replace(red, curve=curve)


def fixed_light(model: Model) -> tuple:
    """The scene's own light that the solve keeps: per lamp, the World and per emissive object
    (inverse mode; direct mode: the World and the lamps of negative power) its share of the
    targets' radiosity (painted; direct mode: the scene's), area-weighted, channels summed
    (engine.scene_light.fixed_light_shares), and (inverse mode) a warning for each target object
    that this light alone already makes brighter than painted."""
    inverse = model.mode == "inverse"
    rows = fixed_light_shares(model.faces, model.patches, model.problem, model.lamp_irradiance, model.lamp_names,
                              model.background, excess=inverse)
    brighter = brighter_than_painted(model.faces, model.patches, model.problem) if inverse else []
    return rows, [texts.already_brighter_note(name, ratio) for name, ratio in brighter]


def _configurations(problem, red: ReductionResult, keep) -> np.ndarray:
    """(kept points, n_lights, 3): each kept configuration's strengths."""
    E = np.zeros((len(keep), problem.n_lights, 3))
    for k, ci in enumerate(keep):
        pt = red.curve[ci]
        E[k, pt.lights] = pt.exitance
    return E


def _curve_radiosity(problem, E, patches) -> np.ndarray:
    """(kept points, P, 3): B = B_background + A^-1 e of each configuration (one LU solve for all
    the points at once), or from the transfer to every patch when the problem keeps it (Live)."""
    n_pts, P = len(E), patches.n_patches
    B = np.empty((n_pts, P, 3))
    T_all = problem.prepared_rows_transfer()
    if T_all is not None:  # a retargeted problem (Live): every light's radiosity on every patch, kept
        on = np.flatnonzero(E.any(axis=(0, 2)))  # the curve's lights (a few of the columns)
        for c in range(3):
            B[:, :, c] = (T_all[c][:, on] @ np.ascontiguousarray(E[:, on, c].T)
                          + problem.background_radiosity[:, c:c + 1]).T
        return B
    H = problem.lights.irradiance
    if problem.direct_correction is not None:  # the curve's lights' direct light by the kernel (direct_stage)
        H = problem.direct_correction if H is None else (sp.csc_matrix(H) + problem.direct_correction).tocsc()
    facs = problem.factors()
    E_patch = np.zeros((P, n_pts, 3))
    for k in range(n_pts):  # the lights' exitance on their patches
        E_patch[problem.candidates, k] = problem.light_basis @ E[k]
    S = problem.source(E_patch)
    for c in range(3):  # every light's source (engine.lights), transported
        src = S[:, :, c]
        if H is not None:
            src = src + patches.reflectance[:, c:c + 1] * np.asarray(H @ E[:, :, c].T)
        if problem.lamp_excess is not None:
            src = src + np.asarray(problem.lamp_excess[c] @ E[:, :, c].T)
        B[:, :, c] = (facs[c].solve(src) + problem.background_radiosity[:, c:c + 1]).T
    return B


def assemble_curve(model: Model, red: ReductionResult, polygon_counts=None) -> Curve:
    """Stage 4: the kept configurations and the radiosity each gives, B = B_background + A^-1 e,
    and the patches -> polygons map (the model's, when it has one)."""
    t0 = time.perf_counter()
    problem, patches = model.problem, model.patches
    keep = stored_points([p.n_lights for p in red.curve], red.final_index)
    E = _configurations(problem, red, keep)
    B = _curve_radiosity(problem, E, patches)
    if not np.all(np.isfinite(B)):
        raise SceneError("the solve produced NaN or infinite values")
    pmap = model.polygons if model.polygons is not None else PolygonMap(model.faces, patches, polygon_counts)
    cells = (pmap.pairs[:, problem.candidates] > 0).astype(np.float64)  # polygons x candidate patches
    light_polygons = (cells @ problem.light_basis).T.tocsr()
    light_polygons.data[:] = 1.0
    return Curve(keep, int(np.searchsorted(keep, red.final_index)), E, B, pmap, light_polygons,
                 time.perf_counter() - t0)
