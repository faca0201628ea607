"""The button after a stroke (issue 37): Solve & Reduce from the prepared state (PreparedScene.solve,
the warm solve) against a cold solve (jobs.run_solve) of the same paint, in one process, one
after the other for each stroke.

Per case (the staircase under the adaptive and the polygon model, the living room of about 22k
triangles, tests/artist_scenes.living_room(2)): the first solve through the state, then each
stroke of benchmarks/bench_live_quality.strokes (extend, new spot, erase, lux fill: on the faces the
patch model keeps whole) and, on the adaptive model, a stroke on faces it clustered (12 of them,
nearest the paint); for each, the warm solve (its time, its stages, what it kept and computed: its
report's ``prepared``) and the cold solve (time, stages), their final relative errors (the report's)
and painted-face errors (bench_live_quality.face_error), and the ratios warm / cold.

    flock /tmp/relight-bench.lock .venv/bin/python benchmarks/bench_warm.py [--only staircase-adaptive ...]

Writes benchmarks/results/bench_warm.json and prints a table (docs/benchmarks.md, "The button after
a stroke").
"""
import argparse
import json
import os
import sys
import time
from dataclasses import replace

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_warm.json")
LAMPS = "candidate lamps' irradiance"  # (the report's ``prepared`` key)

import bpy  # noqa: E402,F401

import relight_addon  # noqa: E402
from relight_addon.blender import export  # noqa: E402
from relight_addon.blender.ui import operators  # noqa: E402
from relight_addon.pipeline import jobs, prepared  # noqa: E402
from bench_live import open_case  # noqa: E402
from bench_live_quality import CASES, face_error, strokes  # noqa: E402


def clustered_stroke(faces, patches, obj):
    """12 faces of ``obj`` the patch model clustered with others, nearest its paint, painted at its
    colour (None when it clusters none)."""
    on = faces.face_object == faces.object_names.index(obj)
    free = np.flatnonzero(on & prepared.clustered_faces(patches) & ~faces.target)
    if not len(free):
        return None
    cen = np.zeros((faces.n_faces, 3))
    np.add.at(cen, faces.triangle_face, faces.vertices[faces.triangles].mean(axis=1))
    cen /= np.maximum(np.bincount(faces.triangle_face, minlength=faces.n_faces), 1)[:, None]
    painted = np.flatnonzero(faces.target & on)
    ids = free[np.argsort(np.linalg.norm(cen[free] - cen[painted].mean(axis=0), axis=1))[:12]]
    t, r = faces.target.copy(), faces.target_radiosity.copy()
    t[ids], r[ids] = True, faces.target_radiosity[painted[0]]
    return "clustered faces", t, r


def stages(outcome):
    return {k: round(v, 3) for k, v in outcome.report["timings_s"].items() if v}


def case(name, source, obj, model):
    scene = open_case(source, model)
    exp = export.export_scene()
    inputs = export.job_inputs(exp)
    options = operators.job_options(scene.relight).validate()
    size, counts = inputs["default_max_patch_size"], inputs["polygon_counts"]
    state = prepared.PreparedScene.prepare(exp.faces, options, size)
    t0 = time.perf_counter()
    first = state.solve(exp.faces, counts)
    rows = [dict(case=name, stroke="(first solve)", patches=int(first.patches.n_patches),
                 cold_s=time.perf_counter() - t0, cold_stages=stages(first),
                 cold_report=first.report["final"]["relative_error"])]
    print(rows[0], flush=True)
    avoid = prepared.clustered_faces(first.patches)
    todo = strokes(exp.faces, obj, avoid)
    extra = clustered_stroke(exp.faces, first.patches, obj) if model == "adaptive" else None
    for stroke, t, r in todo + ([extra] if extra else []):
        faces = replace(exp.faces, target=t, target_radiosity=r)
        row = dict(case=name, stroke=stroke, targets=int(t.sum()))
        t0 = time.perf_counter()
        warm = state.solve(faces, counts)
        row.update(warm_s=time.perf_counter() - t0, warm_stages=stages(warm), prepared=warm.report["prepared"],
                   warm_report=warm.report["final"]["relative_error"], warm_face=face_error(warm, faces))
        t0 = time.perf_counter()
        cold = jobs.run_solve(faces, options, counts, size, notes=inputs["notes"])
        row.update(cold_s=time.perf_counter() - t0, cold_stages=stages(cold),
                   cold_report=cold.report["final"]["relative_error"], cold_face=face_error(cold, faces))
        row.update(time_ratio=row["warm_s"] / row["cold_s"], error_ratio=row["warm_report"] / row["cold_report"],
                   face_ratio=row["warm_face"] / row["cold_face"])
        rows.append(row)
        print(row, flush=True)
        if stroke == "clustered faces":  # (it re-meshed: the strokes before it are on the first mesh)
            break
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=None)
    args = ap.parse_args()
    relight_addon.register()
    load = os.getloadavg()
    rows = []
    for name, source, obj, model in CASES:
        if args.only and name not in args.only:
            continue
        rows += case(name, source, obj, model)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as fh:
        json.dump({"command": "benchmarks/bench_warm.py", "load_before": load, "load_after": os.getloadavg(),
                   "rows": rows}, fh, indent=1)
    print("| case | stroke | warm s | cold s | warm / cold | error warm / cold (ratio) | painted-face error "
          "warm / cold (ratio) | kernel rows kept / drawn | kernel pairs kept / drawn | lamps kept / computed |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "warm_s" not in r:
            print(f"| {r['case']} | {r['stroke']} | | {r['cold_s']:.2f} | | {r['cold_report']:.4f} | | | | |")
            continue
        p = r["prepared"]
        print(f"| {r['case']} | {r['stroke']}{'' if p['from_prepared_state'] else ' (from scratch)'} "
              f"| {r['warm_s']:.2f} | {r['cold_s']:.2f} | {r['time_ratio']:.2f} "
              f"| {r['warm_report']:.4f} / {r['cold_report']:.4f} ({r['error_ratio']:.3f}) "
              f"| {r['warm_face']:.4f} / {r['cold_face']:.4f} ({r['face_ratio']:.3f}) "
              f"| {p['kept']['kernel rows']} / {p['computed']['kernel rows']} "
              f"| {p['kept']['kernel pairs']} / {p['computed']['kernel pairs']} "
              f"| {p['kept'][LAMPS]} / {p['computed'][LAMPS]} |")
    stage_table(rows)


def stage_table(rows):
    """Seconds per stage of each warm solve against its cold solve (the reports' timings_s)."""
    keys = ("form_factors", "lamps", "inverse", "reduction", "direct_light", "lamp_refinement", "total")
    print("| case | stroke | " + " | ".join(f"{k} warm / cold" for k in keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for r in rows:
        if "warm_stages" in r:
            print(f"| {r['case']} | {r['stroke']} | " + " | ".join(
                f"{r['warm_stages'].get(k, 0):.2f} / {r['cold_stages'].get(k, 0):.2f}" for k in keys) + " |")


if __name__ == "__main__":
    main()
