"""What the scene's own light costs a solve: the living room with and without a Sun and a World.

    .venv/bin/python benchmarks/bench_scene_light.py [--rounds 3]

The suite's living room (tests/artist_scenes.living_room(2), 22k triangles) is written twice: as
it is, and with a Sun (strength 3, angle 0.5 degrees) and a uniform World (0.3, 0.4, 0.6). Each
file is solved by `relight solve` (defaults) in fresh processes, alternately; the report's job
total, form factors and inverse (where the lamps' and the World's rays are cast) are compared.
Rays: a sun 64 per patch, the World 1,024 per patch (engine.lamps). Writes
benchmarks/results/bench_scene_light.json.
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
import bpy, artist_scenes
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.living_room(2)
bpy.ops.wm.save_as_mainfile(filepath=%r)
world = bpy.data.worlds.new("sky")
bpy.context.scene.world = world
if bpy.app.version < (5, 0, 0):
    world.use_nodes = True
bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
bg.inputs["Color"].default_value = (0.3, 0.4, 0.6, 1.0)
ld = bpy.data.lights.new("sun", "SUN")
ld.energy, ld.angle = 3.0, math.radians(0.5)
ob = bpy.data.objects.new("sun", ld)
bpy.context.scene.collection.objects.link(ob)
ob.rotation_euler = (math.radians(40), 0.0, math.radians(30))
bpy.ops.wm.save_as_mainfile(filepath=%r)
"""


def solve(scene, report):
    subprocess.run([sys.executable, "-m", "relight_addon", "solve", scene, "--report", report, "--quiet"],
                   check=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=ROOT), capture_output=True)
    with open(report) as f:
        return json.load(f)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="relight-bench-light-")
    plain, lit = os.path.join(tmp, "room.blend"), os.path.join(tmp, "room_sun_world.blend")
    subprocess.run([sys.executable, "-c", BUILD % (ROOT, os.path.join(ROOT, "tests"), plain, lit)], check=True,
                   capture_output=True)
    runs = {"plain": [], "sun + world": []}
    last = {}
    for r in range(args.rounds):
        for name, path in (("plain", plain), ("sun + world", lit))[::1 if r % 2 == 0 else -1]:
            rep = solve(path, os.path.join(tmp, "r.json"))
            t = rep["timings_s"]
            runs[name].append({"total": t["total"], "form_factors": t["form_factors"], "inverse": t["inverse"]})
            last[name] = rep
    med = {n: {k: float(np.median([x[k] for x in v])) for k in v[0]} for n, v in runs.items()}
    out = {"median_s": med, "ratio": med["sun + world"]["total"] / med["plain"]["total"], "runs": runs,
           "patches": last["plain"]["scene"]["patches"],
           "fixed_light": last["sun + world"]["fixed_light"],
           "relative_error": {n: last[n]["final"]["relative_error"] for n in last}}
    print(json.dumps({k: out[k] for k in ("median_s", "ratio", "patches", "relative_error")}, indent=1))
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "bench_scene_light.json"), "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
