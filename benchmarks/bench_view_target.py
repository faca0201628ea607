"""Cost of a camera-view target (issue 40): the living room (tests/artist_scenes.py) with a camera,
solved by the command line for its painted surface targets (the floor area and the table top), and
for a view target at 480 x 270 instead (an OpenEXR asking every pixel for a uniform radiance, the
paint removed). Prints each solve's timings (the report's timings_s), its peak memory, the view target's rows and
pixels (one ray a painted pixel), and the ratio pixel / surface of the solve time and of the total.

    flock /tmp/relight-bench.lock .venv/bin/python benchmarks/bench_view_target.py [--out DIR] [--rounds 3]
"""
import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests")]

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402

RADIANCE = 0.1  # W m^-2 sr^-1, asked of every pixel


def build(folder):
    cr.reset_blender()
    artist_scenes.living_room()
    scene = bpy.context.scene
    scene.world = cr.black_world()
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    cam.data.lens = 24.0
    scene.collection.objects.link(cam)
    cam.location = (0.3, 1.85, 1.6)
    d = np.subtract((0.0, -1.0, 0.5), cam.location)
    cam.rotation_euler = (math.atan2(math.hypot(d[0], d[1]), -d[2]), 0.0, math.atan2(d[1], d[0]) - math.pi / 2)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 1920, 1080
    surface = os.path.join(folder, "surface.blend")
    bpy.ops.wm.save_as_mainfile(filepath=surface)
    for ob in scene.objects:
        if ob.type == "MESH" and "relight_target" in ob.data.color_attributes:
            ob.data.color_attributes.remove(ob.data.color_attributes["relight_target"])
    pixel = os.path.join(folder, "pixel.blend")
    bpy.ops.wm.save_as_mainfile(filepath=pixel)
    from relight_addon.blender.camera_view import write_image

    rgba = np.ones((270, 480, 4))
    rgba[..., :3] = RADIANCE
    image = os.path.join(folder, "target.exr")
    write_image(image, rgba)
    cr.reset_blender()
    return surface, pixel, image


def solve(blend, report, *extra):
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "relight_addon", "solve", blend, "--report", report, "--quiet",
                           *extra], cwd=ROOT, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ROOT})
    wall = time.perf_counter() - t0
    # (the largest resident set of the children waited for so far: run the smaller solve first)
    print(f"  {os.path.basename(blend)}: peak memory of the solves so far "
          f"{resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024:.0f} MB")
    if proc.returncode:
        raise SystemExit(proc.stderr)
    with open(report) as f:
        return json.load(f), wall


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    ap.add_argument("--rounds", type=int, default=3,
                    help="surface and pixel solves alternated this many times (this machine's runs of one code "
                         "differ by up to 10-30 %%: the ratio of the medians, and of the sums)")
    args = ap.parse_args()
    folder = args.out or tempfile.mkdtemp(prefix="bench_view_")
    os.makedirs(folder, exist_ok=True)
    surface, pixel, image = build(folder)
    print("uptime:", os.popen("uptime").read().strip())
    # a first solve fills the caches both solves share (the form factors' on disk): not timed
    solve(surface, os.path.join(folder, "warm.json"))
    rounds = []
    for k in range(max(1, args.rounds)):
        rs, ws = solve(surface, os.path.join(folder, "surface.json"))
        rp, wp = solve(pixel, os.path.join(folder, "pixel.json"), "--view-target", image)
        rounds.append((rs, ws, rp, wp))
        print(f"round {k + 1}: total surface {rs['timings_s']['total']:.2f} s, pixel {rp['timings_s']['total']:.2f} s "
              f"({rp['timings_s']['total'] / rs['timings_s']['total']:.2f} x); wall {ws:.1f} / {wp:.1f} s "
              f"({wp / ws:.2f} x)", flush=True)
    rs, ws, rp, wp = rounds[-1]
    for name, r, w in (("surface", rs, ws), ("pixel", rp, wp)):
        t = r["timings_s"]
        print(f"{name} (last round): wall {w:.1f} s, " + ", ".join(f"{k} {v:.2f}" for k, v in t.items()))
        print(f"  {r['model'].get('n_patches', '?')} patches, {r['final']['n_lights']} lights, relative error "
              f"{r['final']['relative_error']:.3f}")
    print("view target:", rp["view_target"])

    def of(i, key=None):
        return np.array([r[i]["timings_s"][key] if key else r[i] for r in rounds])

    for label, a, b in (("solve", of(0, "solve"), of(2, "solve")), ("total", of(0, "total"), of(2, "total")),
                        ("wall", of(1), of(3))):
        print(f"ratio pixel / surface, {label}: median {np.median(b) / np.median(a):.2f}, sums {b.sum() / a.sum():.2f}, "
              f"rounds {', '.join(f'{x:.2f}' for x in b / a)}")
    print("uptime:", os.popen("uptime").read().strip())


if __name__ == "__main__":
    main()
