"""Before and after a structural change, in one run: the same solves by two checkouts of Relight.

    .venv/bin/python benchmarks/bench_refactor.py --base /path/to/old/checkout [--rounds 3]

Each round runs `python -m relight_addon solve` on the shipped staircase and on the living room
(tests/artist_scenes.living_room(2), 22k triangles, written once to a temporary .blend) with the
old and the new code, alternately, in fresh processes. It prints the timings the reports give
(form factors + inverse = the mathematical phase; the job's total), in a fresh process and warm (2
more solves in one process, as the add-on runs every solve after the first), their new/old
ratios (medians),
and how far the results differ: the curve's relative errors, the final lights' exitances and the
targets' radiosity rows. Writes benchmarks/results/bench_refactor.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def living_room_blend(path):
    code = ("import sys; sys.path[:0] = [%r, %r]; import bpy, artist_scenes; bpy.ops.wm.read_factory_settings(use_empty=True); artist_scenes.living_room(2); "
            "bpy.ops.wm.save_as_mainfile(filepath=%r)") % (ROOT, os.path.join(ROOT, "tests"), path)
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def solve(tree, scene, report):
    env = dict(os.environ, PYTHONPATH=tree)
    subprocess.run([sys.executable, "-m", "relight_addon", "solve", scene, "--report", report, "--quiet"],
                   check=True, cwd=tree, env=env, capture_output=True)
    with open(report) as f:
        return json.load(f)


WARM = r"""
import json, sys, time
try:
    from relight_addon.blender import export
    from relight_addon.pipeline import jobs
except ImportError:  # the layout before the pipeline/ and blender/ split
    from relight_addon import export, jobs
try:
    from relight_addon.blender.blend_files import open_blend
except ImportError:  # before blender/blend_files.py
    open_blend = export.open_blend
try:
    from relight_addon.pipeline.meshing import mesh_for_job
except ImportError:  # before pipeline/meshing.py
    mesh_for_job = jobs.mesh_for_job
from relight_addon.engine.options import JobOptions
open_blend(sys.argv[1])
exp = export.export_scene()
inputs = export.job_inputs(exp)
options = JobOptions().validate()
patches = mesh_for_job(exp.faces, options, inputs["default_max_patch_size"])
out = []
for _ in range(int(sys.argv[2])):
    r = jobs.run_solve(exp.faces, options, patches=patches, **inputs).report["timings_s"]
    out.append([r["form_factors"] + r["inverse"], r["total"]])
print("RESULT " + json.dumps(out))
"""


def warm(tree, scene, repeats):
    """(math phase, job total) per repeated solve in one process: the add-on's every solve after the first."""
    env = dict(os.environ, PYTHONPATH=tree)
    run = subprocess.run([sys.executable, "-c", WARM, scene, str(repeats)], check=True, cwd=tree, env=env,
                         capture_output=True, text=True)
    return json.loads(next(ln for ln in run.stdout.splitlines() if ln.startswith("RESULT "))[7:])


def differences(a, b):
    ca = np.array([p["relative_error"] for p in a["curve"]], dtype=float)
    cb = np.array([p["relative_error"] for p in b["curve"]], dtype=float)
    def strengths(r):  # a surface light's exitance, a lamp's power per channel
        return np.array([li["exitance"] if li.get("exitance") is not None else li["strength"]
                         for li in r["final"]["lights"]], dtype=float)

    ea, eb = strengths(a), strengths(b)
    same_lights = [(li["object"], li["polygons"], li["kind"]) for li in a["final"]["lights"]] == \
                  [(li["object"], li["polygons"], li["kind"]) for li in b["final"]["lights"]]
    rows = [(np.array(a["objects"][k]["radiosity"], float), np.array(b["objects"][k]["radiosity"], float))
            for k in a["objects"]]
    rad = max(float(np.max(np.abs(x - y)) / max(np.max(np.abs(x)), 1e-300)) for x, y in rows)
    return {"curve_points": [len(ca), len(cb)],
            "curve_max_abs_diff": float(np.max(np.abs(ca - cb))) if len(ca) == len(cb) else None,
            "same_final_lights": bool(same_lights),
            "final_exitance_max_rel_diff": float(np.max(np.abs(ea - eb)) / max(np.max(np.abs(ea)), 1e-300))
            if ea.shape == eb.shape else None,
            "radiosity_max_rel_diff": rad,
            "final_relative_error": [a["final"]["relative_error"], b["final"]["relative_error"]]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", required=True, help="the old checkout")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="relight-bench-refactor-")
    room = os.path.join(tmp, "living_room.blend")
    living_room_blend(room)
    scenes = {"staircase": os.path.join(ROOT, "sample_blends", "staircase_targets.blend"), "living room": room}
    trees = {"old": os.path.abspath(args.base), "new": ROOT}
    times = {s: {t: {"math": [], "total": [], "warm_math": [], "warm_total": []} for t in trees} for s in scenes}
    last = {}
    for r in range(args.rounds):
        for s, path in scenes.items():
            for t in (("old", "new") if r % 2 == 0 else ("new", "old")):
                rep = solve(trees[t], path, os.path.join(tmp, f"{t}.json"))
                tm = rep["timings_s"]
                times[s][t]["math"].append(tm["form_factors"] + tm["inverse"])
                times[s][t]["total"].append(tm["total"])
                last[(s, t)] = rep
                for m, total in warm(trees[t], path, 3)[1:]:  # the first of the process is cold
                    times[s][t]["warm_math"].append(m)
                    times[s][t]["warm_total"].append(total)
    out = {}
    for s in scenes:
        med = {t: {k: float(np.median(v)) for k, v in times[s][t].items()} for t in trees}
        out[s] = {"median_s": med, "ratio_new_over_old": {k: med["new"][k] / med["old"][k] for k in med["new"]},
                  "runs": times[s], "patches": last[(s, "new")]["scene"]["patches"],
                  "differences": differences(last[(s, "old")], last[(s, "new")])}
        print(f"{s}: math phase old {med['old']['math']:.3f} s, new {med['new']['math']:.3f} s "
              f"(x{out[s]['ratio_new_over_old']['math']:.2f}); total old {med['old']['total']:.2f} s, "
              f"new {med['new']['total']:.2f} s (x{out[s]['ratio_new_over_old']['total']:.2f}); warm math phase "
              f"old {med['old']['warm_math']:.3f} s, new {med['new']['warm_math']:.3f} s "
              f"(x{out[s]['ratio_new_over_old']['warm_math']:.2f}); "
              f"differences {out[s]['differences']}")
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "bench_refactor.json"), "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
