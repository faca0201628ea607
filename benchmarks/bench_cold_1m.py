"""The 1M-triangle cold solve with the candidate lamps on (issue 37: "at 1M triangles back to 30 s or
less"), stage by stage, against another checkout in the same run.

Each (checkout, round) runs in a fresh process: build ``artist_scenes.living_room(DETAIL)`` (default
5: 1,013,718 triangles; this checkout's tests/artist_scenes for every checkout: the same scene, its
sphere's faces in a fixed order), export, then ``jobs.run_solve`` with the add-on's options (adaptive model,
candidate spots on: the defaults); it measures the job's wall time (export to the end of the
solve), the meshing (``mesh_for_job``, before the solve: the report's meshing is 0 when it is given
the patches), the report's per-stage times (``timings_s``), the rest of the job ("other": in no
stage), the peak RSS during the job (VmHWM after
resetting it, minus the RSS before the export), the process's CPU time (user + system, all threads:
what a loaded machine's wall time hides), the final relative error and the final lamps.

    .venv/bin/python benchmarks/bench_cold_1m.py [--base=/work/base] [--rounds=1] [--detail=5] [--profile]

``--profile``: cProfile of this checkout's job (export, meshing, solve; the main thread only: the
chunks the worker threads run are not in it), the top functions by cumulative and own time.
Writes benchmarks/results/bench_cold_1m.json and prints a table (docs/benchmarks.md, "1M cold solve
(issue 37)").
"""
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_cold_1m.json")

CHILD = r'''
import json, os, sys, time
sys.path.insert(0, ROOT); sys.path.insert(0, SCENES)
import bpy
import artist_scenes
from relight_addon.blender import export
from relight_addon.pipeline import jobs, meshing
from relight_addon.engine.options import JobOptions

def rss(field):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field):
                return int(line.split()[1]) * 1024
detail, profile = int(sys.argv[1]), sys.argv[2] == "1"
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.living_room(detail)
with open("/proc/self/clear_refs", "w") as fh:
    fh.write("5")  # reset the peak RSS (VmHWM)
base = rss("VmRSS:")
if profile:  # the whole job: export, meshing, solve (the main thread's: worker threads are not seen)
    import cProfile, pstats
    pr = cProfile.Profile()
    pr.enable()
t0, c0 = time.perf_counter(), time.process_time()
exp = export.export_scene()
t_export = time.perf_counter() - t0
options = JobOptions(patch_model="adaptive").validate()
t1 = time.perf_counter()
patches = meshing.mesh_for_job(exp.faces, options, exp.settings.get("max_patch_size"))
t_mesh = time.perf_counter() - t1
out = jobs.run_solve(exp.faces, options, patches=patches, **export.job_inputs(exp))
if profile:
    pr.disable()
    pstats.Stats(pr, stream=sys.stderr).sort_stats("cumulative").print_stats(45)
    pstats.Stats(pr, stream=sys.stderr).sort_stats("tottime").print_stats(30)
seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
peak = rss("VmHWM:") - base
r = out.report
lamps = [{k: l.get(k) for k in ("kind", "position", "direction", "spot_size", "spot_blend", "power")}
         for l in r["final"]["lights"] if l.get("kind") in ("spot", "area", "point")]
print("RESULT " + json.dumps({"seconds": seconds, "cpu_seconds": cpu, "export": t_export, "mesh": t_mesh,
      "peak_bytes": peak,
      "patches": r["scene"]["patches"], "triangles": r["scene"]["triangles"],
      "relative_error": r["final"]["relative_error"], "n_lights": r["final"]["n_lights"],
      "timings": r["timings_s"], "refinement": r["model"].get("lamp_refinement"), "lamps": lamps}))
'''


def run(root, detail, profile=False):
    code = f"ROOT = {root!r}\nSCENES = {os.path.join(ROOT, 'tests')!r}\n" + CHILD
    p = subprocess.run([os.path.join(ROOT, ".venv", "bin", "python"), "-c", code, str(detail), "1" if profile else "0"],
                       capture_output=True, text=True, cwd=root, timeout=3600)
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    if profile:
        print(p.stderr[-30000:])
    if p.returncode or not line:
        raise SystemExit(f"{root}: FAILED {p.stderr[-3000:]}")
    return json.loads(line[-1][7:])


STAGES = ("form_factors", "lamps", "inverse", "reduction", "direct_light", "lamp_refinement", "curve")


def main(argv):
    opts = dict(a[2:].split("=", 1) if "=" in a else (a[2:], "1") for a in argv if a.startswith("--"))
    detail, rounds = int(opts.get("detail", 5)), int(opts.get("rounds", 1))
    if "profile" in opts:
        run(ROOT, detail, profile=True)
        return
    roots = ([("base", opts["base"])] if "base" in opts else []) + [("this", ROOT)]
    rows = []
    for rnd in range(rounds):
        for name, root in roots:
            r = run(root, detail)
            r.update(checkout=name, root=root, round=rnd)
            rows.append(r)
            st = "  ".join(f"{k} {r['timings'].get(k, 0):.2f}" for k in STAGES)
            # the job's time in none of the report's stages (the model's problem set-up, the report)
            r["other"] = r["seconds"] - r["export"] - r["mesh"] - sum(r["timings"].get(k, 0) for k in STAGES)
            ev = (r["refinement"] or {}).get("evaluations", 0)
            print(f"{name:5s} round {rnd}: total {r['seconds']:.2f} s (CPU {r['cpu_seconds']:.2f} s, load "
                  f"{os.getloadavg()[0]:.1f}; export {r['export']:.2f}, meshing {r['mesh']:.2f})  {st}  other {r['other']:.2f}  "
                  f"peak {r['peak_bytes'] / 2**20:.0f} MB  error {r['relative_error']:.5f}  "
                  f"{r['n_lights']} lights, {len(r['lamps'])} lamps, {ev} refinement evaluations", flush=True)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as fh:
        json.dump({"command": "benchmarks/bench_cold_1m.py " + " ".join(argv), "detail": detail,
                   "load": os.getloadavg(), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main(sys.argv[1:])
