"""Same results before and after a structural change: every number of the reports, compared.

    .venv/bin/python benchmarks/same_results.py --base /path/to/old/checkout [--cache DIR]

Builds the scenes once (the shipped staircase; the suite's living room, artist_scenes.living_room(2);
issue 17's gallery, artist_scenes.gallery(); a lamp room, tests/lit_rooms.lamp_room with an Area
lamp added, its floor painted and its walls forbidden), runs the real command line on each with the
old and the new code (fresh processes, default options): `solve` on the four, `radiosity` and
`reduce` on the lamp room, and compares the two reports of each run key by key (times and paths
left out). Prints, per run, the number of values compared, how many differ and the largest
relative difference with its key; exit 1 when any differs. ``--cache DIR`` keeps the old code's
reports (and the scenes) there, so that later runs only run the new code.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

BUILD = r"""
import sys, math
sys.path[:0] = [%(root)r, %(tests)r]
import bpy, numpy as np
import artist_scenes, lit_rooms
out = %(out)r
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.living_room(2)
bpy.ops.wm.save_as_mainfile(filepath=out + "/living_room.blend")
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.gallery()
bpy.ops.wm.save_as_mainfile(filepath=out + "/gallery.blend")
lit_rooms.lamp_room(out + "/lamp_room.blend", lambertian=False)
bpy.ops.wm.open_mainfile(filepath=out + "/lamp_room.blend")
lit_rooms.light("AREA", (2.0, 2.2, 2.45), name="lamp_area", energy=80.0, size=0.5)
lit_rooms.paint(bpy.data.objects["floor"], [0, 1, 4, 5, 10, 11], (0.3, 0.28, 0.25))
for name in ("wall_s", "wall_n", "wall_w", "wall_e"):
    bpy.data.objects[name]["relight_no_lights"] = True
bpy.ops.wm.save_as_mainfile(filepath=out + "/lamp_room.blend")
"""

RUNS = [("solve", "staircase"), ("solve", "living_room"), ("solve", "gallery"), ("solve", "lamp_room"),
        ("radiosity", "lamp_room"), ("reduce", "lamp_room")]

SKIP = ("time", "timings", "path", "file", "elapsed", "seconds", "_s", "version", "estimate", "input", "output")


def build(out):
    os.makedirs(out, exist_ok=True)
    code = BUILD % {"root": ROOT, "tests": os.path.join(ROOT, "tests"), "out": out}
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    return {"staircase": os.path.join(ROOT, "sample_blends", "staircase_targets.blend"),
            **{k: os.path.join(out, k + ".blend") for k in ("living_room", "gallery", "lamp_room")}}


def run(tree, command, scene, report):
    env = dict(os.environ, PYTHONPATH=tree)
    proc = subprocess.run([sys.executable, "-m", "relight_addon", command, scene, "--report", report, "--quiet",
                           "--seed", "1"], cwd=tree, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{tree}: {command} {scene}: exit {proc.returncode}: {proc.stderr[-600:]}")
    with open(report) as f:
        return json.load(f)


def skipped(key):
    k = str(key).lower()
    return any(k == s or k.endswith(s) or s in k for s in SKIP if s != "_s") or k.endswith("_s")


def compare(a, b, key="", acc=None):
    """{n, differ, largest: (rel diff, key), missing: [keys]}"""
    acc = acc if acc is not None else {"n": 0, "differ": 0, "largest": (0.0, ""), "missing": []}
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if skipped(k):
                continue
            if k not in a or k not in b:
                acc["missing"].append(f"{key}.{k}")
                continue
            compare(a[k], b[k], f"{key}.{k}", acc)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            acc["missing"].append(f"{key} (length {len(a)} -> {len(b)})")
        for i, (x, y) in enumerate(zip(a, b)):
            compare(x, y, f"{key}[{i}]", acc)
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        acc["n"] += 1
        if a != b:
            acc["differ"] += 1
            rel = abs(a - b) / max(abs(a), abs(b), 1e-300)
            if rel > acc["largest"][0]:
                acc["largest"] = (rel, key)
    else:
        acc["n"] += 1
        if a != b:
            acc["differ"] += 1
            if acc["largest"][0] < 1.0:
                acc["largest"] = (1.0, f"{key}: {str(a)[:60]!r} -> {str(b)[:60]!r}")
    return acc


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", required=True, help="the old checkout")
    ap.add_argument("--cache", default=os.path.join("/tmp", "relight-same-results"),
                    help="where the scenes and the old code's reports are kept")
    ap.add_argument("--only", nargs="*", help="runs to do, as command:scene")
    args = ap.parse_args()
    scenes_dir = os.path.join(args.cache, "scenes")
    if not os.path.exists(os.path.join(scenes_dir, "lamp_room.blend")):
        build(scenes_dir)
    scenes = {"staircase": os.path.join(ROOT, "sample_blends", "staircase_targets.blend"),
              **{k: os.path.join(scenes_dir, k + ".blend") for k in ("living_room", "gallery", "lamp_room")}}
    new_dir = tempfile.mkdtemp(prefix="relight-same-results-new-")  # (several checkouts may compare at once)
    bad = 0
    for command, scene in RUNS:
        if args.only and f"{command}:{scene}" not in args.only:
            continue
        old_path = os.path.join(args.cache, f"old_{command}_{scene}.json")
        if os.path.exists(old_path):
            with open(old_path) as f:
                old = json.load(f)
        else:
            old = run(os.path.abspath(args.base), command, scenes[scene], old_path)
        new = run(ROOT, command, scenes[scene], os.path.join(new_dir, f"{command}_{scene}.json"))
        acc = compare(old, new)
        ok = acc["differ"] == 0 and not acc["missing"]
        bad += not ok
        print(f"{command} {scene}: {acc['n']} values, {acc['differ']} differ, largest relative difference "
              f"{acc['largest'][0]:.3g} at {acc['largest'][1] or '-'}"
              + (f"; keys only in one: {acc['missing'][:6]}" if acc["missing"] else ""))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
