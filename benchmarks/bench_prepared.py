"""Prepare once, re-solve per stroke (issue 20): a stroke of 12 faces re-solved from the prepared
state against a cold solve of the same painted scene, in one process, one run each.

Per scene and patch model: the first solve through the state (it keeps what it made), a stroke
(12 unpainted faces nearest a painted one, on the painted object with the most faces the model
keeps whole, painted at that face's colour), the re-solve from the state, and a cold solve of the
painted scene; their times, the re-solve's stages, the final relative errors, and the state's
memory (the form factors and the kernel rows it keeps).

    .venv/bin/python benchmarks/bench_prepared.py

Writes benchmarks/results/bench_prepared.json and prints a table (docs/benchmarks.md).
"""
import json
import os
import sys
import time
from dataclasses import replace

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_prepared.json")

import bpy  # noqa: E402

from relight_addon.blender import blend_files, export  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.pipeline import jobs, prepared  # noqa: E402


def scene(name):
    if name == "staircase":
        blend_files.open_blend(os.path.join(ROOT, "sample_blends", "staircase_targets.blend"))
    else:
        import artist_scenes

        bpy.ops.wm.read_factory_settings(use_empty=True)
        artist_scenes.living_room(2)
    return export.export_scene()


def stroke(faces, patches, n=12):
    whole = ~prepared.clustered_faces(patches)
    painted_objects = np.unique(faces.face_object[faces.target])
    o = max(painted_objects, key=lambda k: int(np.sum(whole & ~faces.target & (faces.face_object == k))))
    free = np.flatnonzero(whole & ~faces.target & (faces.face_object == o))
    first = np.flatnonzero(faces.target & (faces.face_object == o))[0]
    V = faces.vertices
    c = np.array([V[faces.loop_vertices[faces.loop_start[i]:faces.loop_start[i] + faces.loop_total[i]]].mean(0)
                  for i in free])
    c0 = V[faces.loop_vertices[faces.loop_start[first]:faces.loop_start[first] + faces.loop_total[first]]].mean(0)
    near = free[np.argsort(np.linalg.norm(c - c0, axis=1))[:n]]
    target, rad = faces.target.copy(), faces.target_radiosity.copy()
    target[near], rad[near] = True, faces.target_radiosity[first]
    return replace(faces, target=target, target_radiosity=rad), faces.object_names[o]


#: (scene, patch model); the living room under the polygon model at its default patch size is a
#: job of minutes (docs/benchmarks.md, "Cost estimate"): not a stroke's
CASES = [("staircase", "polygon"), ("staircase", "adaptive"), ("living room 22k", "adaptive")]


def main():
    rows = []
    for name, model in CASES:
        exp = scene(name)
        options = JobOptions(patch_model=model).validate()
        size = exp.settings.get("max_patch_size")
        state = prepared.PreparedScene.prepare(exp.faces, options, size)
        t = time.perf_counter()
        first = state.solve(exp.faces)
        t_first = time.perf_counter() - t
        faces2, on = stroke(exp.faces, state.patches)
        t = time.perf_counter()
        warm = state.solve(faces2)
        t_warm = time.perf_counter() - t
        t = time.perf_counter()
        cold = jobs.run_solve(faces2, options, default_max_patch_size=size)
        t_cold = time.perf_counter() - t
        M = state.form_factors.matrix
        kept = (M.nbytes if isinstance(M, np.ndarray) else M.data.nbytes + M.indices.nbytes + M.indptr.nbytes) \
            + sum(r.nbytes for r in state.kernel_rows.values())
        r = {"scene": name, "model": model, "patches": int(state.patches.n_patches), "stroke_on": on,
             "from_state": state.reason is None, "first_s": t_first, "resolve_s": t_warm, "cold_s": t_cold,
             "resolve_stages": {k: round(v, 3) for k, v in warm.report["timings_s"].items()},
             "resolve_error": warm.report["final"]["relative_error"],
             "cold_error": cold.report["final"]["relative_error"],
             "first_error": first.report["final"]["relative_error"], "kept_bytes": int(kept)}
        rows.append(r)
        print(f"{name:16s} {model:9s} {r['patches']:6d} patches  first {t_first:6.2f} s  re-solve {t_warm:6.2f} s "
              f"(from the state: {r['from_state']})  cold {t_cold:6.2f} s  error re-solve {r['resolve_error']:.4f} "
              f"cold {r['cold_error']:.4f}  kept {kept / 2**20:.0f} MB  stages {r['resolve_stages']}", flush=True)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as fh:
        json.dump({"command": "benchmarks/bench_prepared.py", "load": os.getloadavg(), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
