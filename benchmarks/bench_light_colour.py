"""Light colour (issue 21): the error each light colour costs against free colours, per scene, in
one process per scene (jobs.run_solve, the default options but the light colour), with the time,
the certificate and, for automatic, the mode it took.

Scenes: issue 17's gallery (grey targets on a warm room), the same with its painting painted red
(coloured targets), the living room (22k triangles: grey-ish targets on a wood floor) and the
staircase sample (its painted targets are bluish).

    .venv/bin/python benchmarks/bench_light_colour.py [--only NAME]

Writes benchmarks/results/bench_light_colour.json and prints a table (docs/benchmarks.md, "Light colour").
"""
import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_light_colour.json")
SCENES = ("gallery", "gallery, red painting", "living room 22k", "staircase")
MODES = ("free", "white", "blackbody", "one-colour", "auto")


def run_scene(name):
    sys.path[:0] = [ROOT, os.path.join(ROOT, "tests"), os.path.join(ROOT, "benchmarks")]
    import bpy
    import numpy as np

    import artist_scenes
    import bench_prepared
    from relight_addon.blender import export
    from relight_addon.engine.options import JobOptions
    from relight_addon.pipeline import jobs

    if name.startswith("gallery"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        obs = artist_scenes.gallery()
        if "red" in name:
            artist_scenes.paint(obs["Painting"], [0], (1.2, 0.15, 0.1))
        exp = export.export_scene()
    else:
        exp = bench_prepared.scene(name)
    rows = []
    for mode in MODES:
        t0 = time.perf_counter()
        out = jobs.run_solve(exp.faces, JobOptions(light_colour=mode).validate(),
                             default_max_patch_size=exp.settings.get("max_patch_size"))
        seconds = time.perf_counter() - t0
        f = out.report["final"]
        chroma = [np.round(np.asarray(li["strength"] if li["exitance"] is None else li["exitance"]) /
                           max(float(np.sum(li["strength"] if li["exitance"] is None else li["exitance"])), 1e-30),
                           3).tolist() for li in f["lights"]]
        rows.append({"scene": name, "mode": mode, "took": out.report["light_colour"]["mode"], "seconds": seconds,
                     "n_lights": f["n_lights"], "relative_error": f["relative_error"],
                     "bound": f["bound_relative_error"], "chromaticity": chroma,
                     "temperatures_K": [li.get("temperature_K") for li in f["lights"]]})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", action="append")
    ap.add_argument("--scene", help=argparse.SUPPRESS)  # (one scene, in a process of its own)
    args = ap.parse_args()
    if args.scene:
        print("ROWS " + json.dumps(run_scene(args.scene)))
        return
    rows = json.load(open(OUT)) if os.path.exists(OUT) else []
    for name in SCENES:
        if args.only and name not in args.only:
            continue
        res = subprocess.run([sys.executable, __file__, "--scene", name], capture_output=True, text=True)
        got = [json.loads(line[5:]) for line in res.stdout.splitlines() if line.startswith("ROWS ")]
        if res.returncode or not got:
            sys.exit(f"{name}: failed\n{res.stderr[-2000:]}")
        rows = [r for r in rows if r["scene"] != name] + got[0]
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    json.dump(rows, open(OUT, "w"), indent=1)
    print("| scene | light colour | took | relative error (3 lights) | vs free | certificate | time |")
    print("|---|---|---|---:|---:|---:|---:|")
    for name in SCENES:
        free = next((r for r in rows if r["scene"] == name and r["mode"] == "free"), None)
        for r in (r for r in rows if r["scene"] == name):
            cost = "" if free is None else f"{r['relative_error'] / free['relative_error']:.2f} x"
            print(f"| {name} | {r['mode']} | {r['took']} | {r['relative_error']:.4f} | {cost} | "
                  f"{r['bound']:.4f} | {r['seconds']:.1f} s |")


if __name__ == "__main__":
    main()
