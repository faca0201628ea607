"""Scale from what matters (issue 34): the living room of tests/artist_scenes.py (detail 2, about
22k triangles) solved with the defaults as it is, on a ground plane 9 km wide (forbidden, 1 cm
under its floor), and scaled by 0.01 and 1000: the region the automatic lengths come from
(engine/extent.py), the patches, the time, the final lights and the relative error, in one
process.

    .venv/bin/python benchmarks/bench_extent.py

Writes benchmarks/results/bench_extent.json and prints a table (docs/benchmarks.md).
"""
import json
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests")]

import bpy  # noqa: E402

from artist_scenes import living_room, scale_scene  # noqa: E402
from relight_addon.blender import export  # noqa: E402
from relight_addon.engine.extent import decisive_region  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.pipeline import jobs  # noqa: E402

CASES = {"room": dict(), "room on a 9 km ground": dict(ground=9000.0), "room x 0.01": dict(scale=0.01),
         "room x 1000": dict(scale=1000.0)}


def run(ground=0.0, scale=1.0):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    living_room(2)
    if ground:
        me = bpy.data.meshes.new("Ground")
        g = ground / 2
        me.from_pydata([(-g, -g, -0.01), (g, -g, -0.01), (g, g, -0.01), (-g, g, -0.01)], [], [(0, 1, 2, 3)])
        ob = bpy.data.objects.new("Ground", me)
        bpy.context.scene.collection.objects.link(ob)
        ob["relight_no_lights"] = True
    scale_scene(scale)
    exp = export.export_scene()
    region = decisive_region(exp.faces)
    t0 = time.perf_counter()
    out = jobs.run_solve(exp.faces, JobOptions().validate(), default_max_patch_size=exp.settings.get("max_patch_size"))
    r = out.report
    return {"region_diagonal_m": region.diagonal, "scene_diagonal_m": region.scene_diagonal,
            "patches": r["scene"]["patches"], "seconds": time.perf_counter() - t0,
            "relative_error": r["final"]["relative_error"],
            "lights": [(li["kind"], li["power"]) for li in r["final"]["lights"]]}


def main():
    rows = {name: run(**kw) for name, kw in CASES.items()}
    os.makedirs(os.path.join(ROOT, "benchmarks", "results"), exist_ok=True)
    with open(os.path.join(ROOT, "benchmarks", "results", "bench_extent.json"), "w") as f:
        json.dump(rows, f, indent=1)
    print("| case | region diagonal m | scene diagonal m | patches | solve s | relative error | lights (kind, W) |")
    print("|---|---|---|---|---|---|---|")
    for name, r in rows.items():
        lights = ", ".join(f"{k} {p:.3g}" for k, p in r["lights"])
        print(f"| {name} | {r['region_diagonal_m']:.4g} | {r['scene_diagonal_m']:.4g} | {r['patches']} | "
              f"{r['seconds']:.1f} | {r['relative_error']:.4f} | {lights} |")


if __name__ == "__main__":
    main()
