"""The cost estimate against measured solves (issue 7: "predicts time and memory within a
factor of 2; measure this").

Each case runs in a fresh process: build or open the scene, export, then jobs.run_solve; it
measures the job's wall time and its peak memory (peak RSS during the job minus the RSS before
the export, from /proc/self/status VmHWM after resetting it) and compares them with
meshing.solve_cost (the estimate the CLI prints and the add-on's confirmation uses).

    .venv/bin/python benchmarks/bench_cost.py [--quick] [--only=NAME_PART ...]

Writes benchmarks/results/bench_cost.json and prints a table (docs/benchmarks.md, "Cost estimate").
"""
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_cost.json")

CASES = [  # name, scene, job options
    ("single room (a painted floor quad, a ceiling quad)", "single", {}),
    ("32 x 32-quad ceiling over a painted floor", "ceiling32", {}),
    ("staircase, polygon", "staircase", {"patch_model": "polygon"}),
    ("staircase, adaptive", "staircase", {"patch_model": "adaptive"}),
    ("living room 22k tris, adaptive", "room2", {"patch_model": "adaptive"}),
    ("living room 22k tris, polygon, 0.6 m", "room2", {"patch_model": "polygon", "max_patch_size": 0.6}),
    ("living room 260k tris, adaptive", "room4", {"patch_model": "adaptive"}),
    ("living room 1M tris, adaptive", "room5", {"patch_model": "adaptive"}),
]

CHILD = r'''
import json, os, sys, time
sys.path.insert(0, ROOT); sys.path.insert(0, os.path.join(ROOT, "tests"))
import bpy
from relight_addon.blender import blend_files, export
from relight_addon.pipeline import jobs, meshing
from relight_addon.engine.options import JobOptions

def rss(field):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field):
                return int(line.split()[1]) * 1024
scene, opts = sys.argv[1], json.loads(sys.argv[2])
def grid(name, n, z, flip, paint=False):  # an n x n grid of quads, 1 m across, at height z
    verts = [(i / n, j / n, z) for j in range(n + 1) for i in range(n + 1)]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)
             for j in range(n) for i in range(n)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], [f[::-1] for f in faces] if flip else faces)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    if paint:
        ob["relight_no_lights"] = True
        a = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
        a.data.foreach_set("color", [0.2, 0.2, 0.2, 1.0] * len(me.loops))

if scene == "staircase":
    blend_files.open_blend(os.path.join(ROOT, "sample_blends", "staircase_targets.blend"))
elif scene in ("single", "ceiling32"):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    grid("floor", 1 if scene == "single" else 4, 0.0, False, paint=True)
    grid("ceiling", 1 if scene == "single" else 32, 1.0, True)
else:
    import artist_scenes
    bpy.ops.wm.read_factory_settings(use_empty=True)
    artist_scenes.living_room(int(scene[4:]))
with open("/proc/self/clear_refs", "w") as fh:
    fh.write("5")  # reset the peak RSS (VmHWM)
base = rss("VmRSS:")
t0 = time.perf_counter()
exp = export.export_scene()
options = JobOptions(**opts).validate()
patches = meshing.mesh_for_job(exp.faces, options, exp.settings.get("max_patch_size"))
est = meshing.solve_cost(patches, options, len(exp.faces.triangles))
out = jobs.run_solve(exp.faces, options, patches=patches, **export.job_inputs(exp))
seconds = time.perf_counter() - t0
peak = rss("VmHWM:") - base
r = out.report
print("RESULT " + json.dumps({"seconds": seconds, "peak_bytes": peak, "est_seconds": est["seconds"],
      "est_bytes": est["memory_bytes"], "patches": r["scene"]["patches"], "triangles": r["scene"]["triangles"],
      "lights": r["inverse"]["n_candidates"], "targets": r["inverse"]["n_targets"],
      "relative_error": r["final"]["relative_error"], "timings": r["timings_s"],
      "direct_lights": (r["model"].get("direct_light") or {}).get("lights", 0),
      "refine_evaluations": (r["model"].get("lamp_refinement") or {}).get("evaluations", 0),
      "parts": {k: [v[0], v[1]] for k, v in est["parts"].items()}}))
'''


def main(quick=False, only=None):
    rows = []
    for name, scene, opts in CASES:
        if (quick and scene == "room5") or (only and not any(o in name for o in only)):
            continue
        code = f"ROOT = {ROOT!r}\n" + CHILD
        p = subprocess.run([sys.executable, "-c", code, scene, json.dumps(opts)], capture_output=True, text=True,
                           cwd=ROOT, timeout=3600)
        line = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
        if p.returncode or not line:
            print(name, "FAILED", p.stderr[-2000:])
            continue
        r = json.loads(line[-1][7:])
        r["case"] = name
        r["time_ratio"] = r["seconds"] / r["est_seconds"]
        r["memory_ratio"] = r["peak_bytes"] / r["est_bytes"]
        rows.append(r)
        print(f"{name:40s} {r['triangles']:>8d} tris {r['patches']:>6d} patches  time {r['seconds']:7.2f} s "
              f"(est {r['est_seconds']:7.2f}, x{r['time_ratio']:.2f})  memory {r['peak_bytes'] / 2**20:7.0f} MB "
              f"(est {r['est_bytes'] / 2**20:7.0f}, x{r['memory_ratio']:.2f})", flush=True)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    if only and os.path.exists(OUT):  # the other cases' rows stay as they were
        with open(OUT) as fh:
            done = {r["case"] for r in rows}
            rows = [r for r in json.load(fh)["rows"] if r["case"] not in done] + rows
    with open(OUT, "w") as fh:
        json.dump({"command": "benchmarks/bench_cost.py", "load": os.getloadavg(), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main("--quick" in sys.argv, [a[7:] for a in sys.argv[1:] if a.startswith("--only=")])
