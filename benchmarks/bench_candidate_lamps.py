"""What candidate lamps (issue 17) do to a solve: the error at 3 lights and the time, with and without.

    .venv/bin/python benchmarks/bench_candidate_lamps.py [--rounds 3]

Scenes (each written once, then solved by `relight solve` in fresh processes, in turn):
- the staircase (sample_blends/staircase_targets.blend);
- the living room (tests/artist_scenes.living_room(2), 22k triangles);
- issue 17's gallery (tests/artist_scenes.gallery: a painting bright, the wall around it dim, only
  the ceiling may hold lights);
- the suite's other solved rooms: the cube room of tests/test_cycles_closed_loop.py (two target
  regions) and the lamp-lit room of tests/test_cycles_lamps.py's closed loop (lit_rooms.lamp_room,
  floor targets, ceiling lights).
Each solve runs four ways: `--no-spot-lamps` (cells alone, as before issue 17),
`--no-lamp-refinement` (cells and spots, the chosen lamps as offered), the defaults (cells and
spots, the chosen lamps refined: engine/lamp_refinement.py) and `--area-lamps --point-lamps`
(every kind); per scene and way the median of the job's total, form factors, lamps (their
irradiance), inverse, reduction and lamp refinement times (and its evaluations), the
final (3-light) relative error, the kinds of its lights and the lamps offered. Writes
benchmarks/results/bench_candidate_lamps.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from bench_scene_light import solve  # noqa: E402  (benchmarks/ is the script's folder)

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MODES = {"cells": ["--no-spot-lamps"], "cells + spots, unrefined": ["--no-lamp-refinement"], "cells + spots": [],
         "cells + spots, areas, points": ["--area-lamps", "--point-lamps"]}

BUILD = r"""
import sys
from pathlib import Path
sys.path[:0] = [%r, %r]
import bpy, artist_scenes, lit_rooms
import test_cycles_closed_loop as closed_loop
living, gallery, cube, lamp_room = sys.argv[-4:]
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.living_room(2)
bpy.ops.wm.save_as_mainfile(filepath=living)
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.gallery()
bpy.ops.wm.save_as_mainfile(filepath=gallery)
closed_loop.build_room(Path(cube))
lit_rooms.lamp_room(lamp_room)
bpy.ops.wm.open_mainfile(filepath=lamp_room)
objs = bpy.data.objects
lit_rooms.paint(objs["floor"], [j * 4 + i for j in range(1, 3) for i in range(0, 3)], (2.2, 2.0, 1.8))
for name in ("floor", "wall_s", "wall_n", "wall_w", "wall_e"):
    objs[name]["relight_no_lights"] = True
bpy.ops.wm.save_as_mainfile(filepath=lamp_room)
"""
TIMES = ("total", "form_factors", "lamps", "inverse", "reduction", "lamp_refinement")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="relight-bench-lamps-")
    built = {name: os.path.join(tmp, f"{name}.blend") for name in ("living room", "gallery", "cube room", "lamp room")}
    subprocess.run([sys.executable, "-c", BUILD % (ROOT, os.path.join(ROOT, "tests")), *built.values()],
                   check=True, capture_output=True)
    files = {"staircase": os.path.join(ROOT, "sample_blends", "staircase_targets.blend"), **built}
    cases = [(scene, mode) for scene in files for mode in MODES]
    runs = {c: [] for c in cases}
    last = {}
    for r in range(args.rounds):
        for scene, mode in cases[r % len(cases):] + cases[:r % len(cases)]:
            rep = solve(files[scene], os.path.join(tmp, "r.json"), MODES[mode])
            t = rep["timings_s"]
            runs[(scene, mode)].append({k: float(t.get(k, 0.0)) for k in TIMES})
            last[(scene, mode)] = rep
    rows = []
    for (scene, mode), v in runs.items():
        rep = last[(scene, mode)]
        by_kind = rep["model"]["lights_by_kind"]
        rows.append({"scene": scene, "mode": mode, "patches": rep["scene"]["patches"],
                     "median_s": {k: float(np.median([x[k] for x in v])) for k in TIMES},
                     "relative_error": rep["final"]["relative_error"], "n_lights": rep["final"]["n_lights"],
                     "bound_relative_error": rep["final"]["bound_relative_error"],
                     "kinds": [li["kind"] for li in rep["final"]["lights"]],
                     "lamps_offered": {k: by_kind[k] for k in ("spot", "area", "point")},
                     "lamp_refinement": {k: (rep["model"]["lamp_refinement"] or {}).get(k, 0)
                                         for k in ("lamps_refined", "evaluations")},
                     "estimate_s": rep["estimate"]["seconds"], "runs": v})
    for row in rows:
        print(f"{row['scene']:12s} {row['mode']:28s} error {row['relative_error']:.4f} {row['kinds']} "
              f"total {row['median_s']['total']:.2f} s (lamps {row['median_s']['lamps']:.2f} s, refinement "
              f"{row['median_s']['lamp_refinement']:.2f} s, {row['lamp_refinement']['evaluations']} evaluations, "
              f"estimate {row['estimate_s']:.2f} s) offered {row['lamps_offered']}")
    out = {"command": "benchmarks/bench_candidate_lamps.py", "rounds": args.rounds, "load": os.getloadavg(),
           "rows": rows}
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "bench_candidate_lamps.json"), "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
