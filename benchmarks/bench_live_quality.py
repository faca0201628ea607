"""Live strokes against a cold solve (issue 37): for each stroke, the painted-face error of

- Live's quick answer (PreparedScene.live: the last solve's model retargeted, jobs.solve_stroke),
  every stroke from the first solve, as Live mode answers it, and its later answers
  (PreparedScene.refine_live, prepared.REFINE_STEPS: the full search and the lamps refined on the
  retargeted model, then the warm solve, unkept; each kept when its error is lower), as Live
  writes them after the quick one;
- the warm solve (PreparedScene.solve: Solve & Reduce after the stroke, from the prepared state),
  pressed after every stroke;
- a cold solve (jobs.run_solve) of the same paint,

on the staircase (sample_blends/staircase_targets.blend; the adaptive model, the add-on's default,
and the polygon model) and on the living room (tests/artist_scenes.living_room(2)). The strokes, in
order (each on the paint the previous one left): ``extend`` 12 unpainted faces of the paint object
nearest its painted ones; ``new spot`` 12 faces nearest a point away from the paint; ``erase`` the
extension unpainted again; ``lux fill`` the extension's and the new spot's faces back, filled at
1.5 x the paint's radiosity (as Fill Selected (lx) sets a value). On the adaptive model a stroke on
faces it clustered is not answered from the prepared state (``-`` in the table): the benchmark paints
the faces it keeps whole unless ``--clustered``.

The table's errors: the report's (the curve's, over the target patches: what the chart shows) and,
in brackets, the painted-face error sqrt(sum a_f |B_f - T_f|^2 / sum a_f |T_f|^2) over the painted faces f
(areas a_f, T_f their target radiosity, B_f the final configuration's radiosity averaged over the
face), the same measure for every patch model; each also as a ratio to the cold solve's.

    .venv/bin/python benchmarks/bench_live_quality.py [--only staircase-adaptive ...] [--clustered]
"""
import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

import bpy  # noqa: E402

import relight_addon  # noqa: E402
from relight_addon.blender import export  # noqa: E402
from relight_addon.blender.ui import operators  # noqa: E402
from relight_addon.engine.scene import face_mean  # noqa: E402
from relight_addon.pipeline import jobs, prepared  # noqa: E402
from bench_live import open_case  # noqa: E402

#: (name, living_room detail or a sample, paint object, patch model, a point for the new spot)
CASES = [("staircase-adaptive", "staircase_targets.blend", "flight_1", "adaptive"),
         ("staircase-polygon", "staircase_targets.blend", "flight_1", "polygon"),
         ("living-room-22k", 2, "Floor", "adaptive")]


def face_error(outcome, faces):
    """The painted-face relative error of the outcome's final configuration (see the docstring)."""
    B = face_mean(outcome.patches, outcome.stored.radiosity[outcome.final_index])
    t = faces.target
    a = prepared.face_areas(faces)[t]
    d = B[t] - faces.target_radiosity[t]
    return float(np.sqrt((a[:, None] * d * d).sum() / (a[:, None] * faces.target_radiosity[t] ** 2).sum()))


def strokes(faces, obj, avoid):
    """The four strokes, as (name, target, target_radiosity) each on the previous paint."""
    o = faces.object_names.index(obj)
    on = faces.face_object == o
    area = prepared.face_areas(faces)
    cen = np.zeros((faces.n_faces, 3))
    np.add.at(cen, faces.triangle_face, faces.vertices[faces.triangles].mean(axis=1))
    cen /= np.maximum(np.bincount(faces.triangle_face, minlength=faces.n_faces), 1)[:, None]
    painted = faces.target & on
    hub = cen[painted].mean(axis=0)
    rgb = faces.target_radiosity[np.flatnonzero(painted)[0]]
    free = np.flatnonzero(on & ~faces.target & ~avoid & (area > 0))
    ext = free[np.argsort(np.linalg.norm(cen[free] - hub, axis=1))[:12]]
    rest = np.setdiff1d(free, ext)
    far = rest[np.argmax(np.linalg.norm(cen[rest] - hub, axis=1))]  # the far corner of the object
    spot = rest[np.argsort(np.linalg.norm(cen[rest] - (0.7 * cen[far] + 0.3 * hub), axis=1))[:12]]
    out, t, r = [], faces.target.copy(), faces.target_radiosity.copy()
    t[ext], r[ext] = True, rgb
    out.append(("extend", t.copy(), r.copy()))
    t[spot], r[spot] = True, rgb
    out.append(("new spot", t.copy(), r.copy()))
    t[ext], r[ext] = False, 0.0
    out.append(("erase", t.copy(), r.copy()))
    t[ext], r[ext] = True, 1.5 * rgb
    r[spot] = 1.5 * rgb
    out.append(("lux fill", t.copy(), r.copy()))
    return out


def case(name, source, obj, model, clustered=False):
    scene = open_case(source, model)
    exp = export.export_scene()
    inputs = export.job_inputs(exp)
    options = operators.job_options(scene.relight).validate()
    size = inputs["default_max_patch_size"]
    counts = inputs["polygon_counts"]
    t0 = time.perf_counter()
    live_state = prepared.PreparedScene.prepare(exp.faces, options, size)
    first = live_state.solve(exp.faces, counts)
    t_first = time.perf_counter() - t0
    live_state.prepare_live(exp.faces)
    warm_state = prepared.PreparedScene.prepare(exp.faces, options, size)
    warm_state.solve(exp.faces, counts)
    avoid = np.zeros(exp.faces.n_faces, dtype=bool) if clustered else prepared.clustered_faces(first.patches)
    rows = [dict(case=name, stroke="(first solve)", targets=int(exp.faces.target.sum()),
                 cold=face_error(first, exp.faces), cold_report=first.report["final"]["relative_error"],
                 cold_s=t_first)]
    for stroke, t, r in strokes(exp.faces, obj, avoid):
        faces = replace(exp.faces, target=t, target_radiosity=r)
        row = dict(case=name, stroke=stroke, targets=int(t.sum()))
        t0 = time.perf_counter()
        out = live_state.live(faces, counts)
        row["live_s"] = time.perf_counter() - t0
        if out is not None:
            row.update(live=face_error(out, faces), live_report=out.report["final"]["relative_error"],
                       live_n=out.report["final"]["n_lights"])
            best = out
            for step, what in enumerate(prepared.REFINE_STEPS):  # Live's later answers, each kept if better
                t0 = time.perf_counter()
                better = live_state.refine_live(best, step, counts)
                row[f"step{step}_s"] = time.perf_counter() - t0
                best = better or best
            row.update(later=face_error(best, faces), later_report=best.report["final"]["relative_error"],
                       later_n=best.report["final"]["n_lights"])
        t0 = time.perf_counter()
        out = warm_state.solve(faces, counts)
        row.update(warm_s=time.perf_counter() - t0, warm=face_error(out, faces),
                   warm_from_state=warm_state.reason is None,
                   warm_report=out.report["final"]["relative_error"], warm_n=out.report["final"]["n_lights"])
        t0 = time.perf_counter()
        out = jobs.run_solve(faces, options, counts, size, notes=inputs["notes"])
        row.update(cold_s=time.perf_counter() - t0, cold=face_error(out, faces),
                   cold_report=out.report["final"]["relative_error"], cold_n=out.report["final"]["n_lights"])
        rows.append(row)
        print(row, flush=True)
    return rows


def fmt(x, spec=".4f"):
    return "-" if x is None else format(x, spec)


def table(rows):
    """Errors: the report's (the curve's, over the target patches) and, in brackets, the
    painted-face one; each answer's / the cold solve's."""
    print("| case | stroke | targets | Live quick | Live, later answers | warm solve | cold solve "
          "| s: quick / full search / warm step / warm / cold |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        def cell(k):
            if r.get(k) is None:
                return "-"
            return (f"{r[k + '_report']:.4f} ({r[k]:.4f}): {r[k + '_report'] / r['cold_report']:.3f} "
                    f"({r[k] / r['cold']:.3f})")
        times = " / ".join(fmt(r.get(k), ".2f") for k in ("live_s", "step0_s", "step1_s", "warm_s", "cold_s"))
        print(f"| {r['case']} | {r['stroke']} | {r['targets']} | {cell('live')} | {cell('later')} | {cell('warm')}"
              f"{'' if r.get('warm_from_state', True) else ' (from scratch)'} "
              f"| {r['cold_report']:.4f} ({r['cold']:.4f}) "
              f"| {times} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", action="append", help="run only the cases of these names")
    ap.add_argument("--clustered", action="store_true", help="paint the adaptive model's clustered faces too")
    args = ap.parse_args()
    relight_addon.register()
    rows = []
    for name, source, obj, model in CASES:
        if args.only and name not in args.only:
            continue
        rows += case(name, source, obj, model, args.clustered)
    table(rows)


if __name__ == "__main__":
    main()
