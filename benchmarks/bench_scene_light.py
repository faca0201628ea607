"""What the scene's own light costs a solve: the living room with and without a Sun and a World.

    .venv/bin/python benchmarks/bench_scene_light.py [--rounds 3]

The suite's living room (tests/artist_scenes.living_room(2), 22k triangles) is written three
times: as it is, with a Sun (strength 3, angle 0.5 degrees) and a uniform World (0.3, 0.4, 0.6),
and with the same Sun and an HDRI World (tests/lit_rooms.hdri_world: a 512 x 256 OpenEXR sky with
a sun); and the small window room of tests/test_cycles_world.py (1,200 patches) with a uniform
World and with the HDRI, where the HDRI is rendered (engine.world's map and its sun). Each file is solved by `relight solve` (defaults) in fresh processes, in turn; the
report's job total, export (where a textured World would be rendered), form factors and
inverse (where the lamps' and the World's rays are cast) are compared. Rays: a sun 64 per patch,
the World 1,024 per patch that sees the sky (engine.world), and 200k to find whether any face
does (engine.world.sees_sky). Writes benchmarks/results/bench_scene_light.json.
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

BUILD = r"""
import math, sys
sys.path[:0] = [%r, %r]
import bpy, artist_scenes, lit_rooms
plain, lit, hdri, win_uniform, win_hdri, exr = sys.argv[-6:]
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.living_room(2)
bpy.ops.wm.save_as_mainfile(filepath=plain)
lit_rooms.uniform_world((0.3, 0.4, 0.6))
ld = bpy.data.lights.new("sun", "SUN")
ld.energy, ld.angle = 3.0, math.radians(0.5)
ob = bpy.data.objects.new("sun", ld)
bpy.context.scene.collection.objects.link(ob)
ob.rotation_euler = (math.radians(40), 0.0, math.radians(30))
bpy.ops.wm.save_as_mainfile(filepath=lit)
lit_rooms.hdri_world(exr)
bpy.ops.wm.save_as_mainfile(filepath=hdri)
lit_rooms.lamp_room(win_uniform)
bpy.ops.wm.open_mainfile(filepath=win_uniform)
lit_rooms.remove_lamps()
lit_rooms.cut_window()
lit_rooms.paint(bpy.data.objects["floor"], [j * 4 + i for j in (1, 2) for i in range(4)], (0.6, 0.55, 0.5))
for name in ("floor", "wall_s", "wall_n", "wall_w", "wall_e"):
    bpy.data.objects[name]["relight_no_lights"] = True
lit_rooms.uniform_world((0.3, 0.4, 0.6))
bpy.ops.wm.save_as_mainfile(filepath=win_uniform)
lit_rooms.hdri_world(exr)
bpy.ops.wm.save_as_mainfile(filepath=win_hdri)
"""


def solve(scene, report, extra=()):
    """`relight solve SCENE --report REPORT --quiet [extra]` in a fresh process: its report."""
    subprocess.run([sys.executable, "-m", "relight_addon", "solve", scene, "--report", report, "--quiet", *extra],
                   check=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=ROOT), capture_output=True)
    with open(report) as f:
        return json.load(f)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="relight-bench-light-")
    files = {name: os.path.join(tmp, f"room_{i}.blend") for i, name in enumerate(
        ("plain", "sun + world", "sun + hdri", "window + world", "window + hdri"))}
    subprocess.run([sys.executable, "-c", BUILD % (ROOT, os.path.join(ROOT, "tests")), *files.values(),
                    os.path.join(tmp, "sky.exr")], check=True, capture_output=True)
    runs = {name: [] for name in files}
    last = {}
    order = list(files.items())
    for r in range(args.rounds):
        for name, path in order[r % len(order):] + order[:r % len(order)]:
            rep = solve(path, os.path.join(tmp, "r.json"))
            t = rep["timings_s"]
            runs[name].append({k: t[k] for k in ("total", "export", "form_factors", "inverse")})
            last[name] = rep
    med = {n: {k: float(np.median([x[k] for x in v])) for k in v[0]} for n, v in runs.items()}
    base = {n: "window + world" if n.startswith("window") else "plain" for n in files}
    out = {"median_s": med, "ratio": {n: med[n]["total"] / med[base[n]]["total"] for n in files if base[n] != n},
           "runs": runs, "patches": last["plain"]["scene"]["patches"],
           "fixed_light": {n: last[n]["fixed_light"] for n in files if n != "plain"},
           "warnings": {n: [w for w in last[n]["warnings"] if "World" in w] for n in files},
           "relative_error": {n: last[n]["final"]["relative_error"] for n in last}}
    print(json.dumps({k: out[k] for k in ("median_s", "ratio", "patches", "relative_error", "warnings")}, indent=1))
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "bench_scene_light.json"), "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
