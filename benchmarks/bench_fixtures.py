"""Catalogue fixtures as candidates (issue 39, item 4): 10 fixture types at about 50 mounting positions on the
suite's living room (tests/artist_scenes.living_room(2)), time and error against spots alone.

    flock /tmp/relight-bench.lock .venv/bin/python benchmarks/bench_fixtures.py [--scene PATH] [--only fixtures ...]

The 10 types: the built-in library's 5 (engine/photometry/library.py) and 5 variants of their closed forms
(a 40 degree and a 60 degree downlight, an aimable wide one, a narrower batwing, a steeper wall washer),
written by the same generator into a temporary folder (``--fixtures DIR``). Runs, in fresh processes of
the real command line (`solve --seed 1`, cells off so that the lamps alone answer): spots alone at the
default 96 candidates; spots alone and fixtures alone at about 50 positions (``--max-lamps`` = 50 x the
lamps a position holds for 2 clusters: each kind's ``per_position``). Prints and writes
benchmarks/results/bench_fixtures.json (bench_fixtures_<runs>.json with --only): per run the candidates offered, the job's time and its stages,
the final relative error and lights, and for the fixtures the schedule.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from relight_addon.engine.photometry import library as lib  # noqa: E402

#: the variants: (stem, LUMCAT, description, closed form, lumens, watts, aimable, symmetric)
VARIANTS = (
    ("v-downlight-40", "RL-DN40", "Downlight (cos^8, 40 degrees to half peak)",
     lambda v, h: lib._lobe(v, h, 0.0, 0.0, 8.0), 1000.0, 10.0, True, True),
    ("v-downlight-60", "RL-DN60", "Downlight (cos^4, 66 degrees to half peak)",
     lambda v, h: lib._lobe(v, h, 0.0, 0.0, 4.0), 1200.0, 12.0, False, True),
    ("v-wide-aimable", "RL-DW90A", "Adjustable wide downlight (cos^1.5, aimable)", lib._wide, 1500.0, 14.0, True, True),
    ("v-batwing-narrow", "RL-BW45", "Batwing (cos v (0.3 + sin^2 v))",
     lambda v, h: lib.np.where(lib.np.cos(lib.np.radians(v)) > 0, lib.np.cos(lib.np.radians(v))
                               * (0.3 + lib.np.sin(lib.np.radians(v)) ** 2), 0.0), 2000.0, 20.0, False, True),
    ("v-washer-steep", "RL-WW20", "Wall washer (cos^10 lobe 20 degrees towards C0)",
     lambda v, h: lib._lobe(v, h, 20.0, 0.0, 10.0) * (lib.np.asarray(v) <= 90.0), 1000.0, 10.0, False, False),
)
POSITIONS = 50


def per_position(specs_aimable_symmetric, clusters=2):
    along = sum(1 for a, s in specs_aimable_symmetric if s and not a)
    return along + (len(specs_aimable_symmetric) - along) * clusters


def run(scene, report, *extra):
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "relight_addon", "solve", scene, "--report", report, "--quiet",
                           "--seed", "1", "--no-surface-lights", *extra], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": ROOT})
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{extra}: exit {proc.returncode}: {proc.stderr[-800:]}")
    with open(report) as f:
        r = json.load(f)
    kinds = {k: n for k, n in r["model"]["lights_by_kind"].items() if n}
    out = {"args": list(extra), "wall_s": wall, "timings_s": r["timings_s"], "offered": kinds,
           "relative_error": r["final"]["relative_error"], "n_lights": r["final"]["n_lights"],
           "lights": [(li["kind"], li.get("fixture"), round(li["luminous_flux_lm"], 1)) for li in r["final"]["lights"]],
           "curve": [(p["n_lights"], p["relative_error"]) for p in r["curve"]],
           "lamp_refinement_s": (r["model"]["lamp_refinement"] or {}).get("seconds")}
    if "fixture_schedule" in r:
        out["schedule"] = [{k: row[k] for k in ("fixture", "count", "lumens", "watts")} |
                           {"dimming": [round(li["dimming"], 3) for li in row["lights"]]} for row in r["fixture_schedule"]]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", help="the living room .blend (default: built by tests/artist_scenes.living_room(2))")
    ap.add_argument("--only", choices=("spots", "spots-positions", "fixtures"), action="append",
                    help="run only these (repeatable; default all three)")
    args = ap.parse_args()
    only = set(args.only or ("spots", "spots-positions", "fixtures"))
    tmp = tempfile.mkdtemp(prefix="relight-bench-fixtures-")
    scene = args.scene
    if scene is None:
        scene = os.path.join(tmp, "living_room.blend")
        code = (f"import sys; sys.path[:0] = [{ROOT!r}, {os.path.join(ROOT, 'tests')!r}]\n"
                "import bpy, artist_scenes\nbpy.ops.wm.read_factory_settings(use_empty=True)\n"
                f"artist_scenes.living_room(2)\nbpy.ops.wm.save_as_mainfile(filepath={scene!r})\n")
        subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    folder = os.path.join(tmp, "fixtures")
    os.makedirs(folder)
    specs = lib.SPECS + VARIANTS
    for spec in specs:
        with open(os.path.join(folder, f"{spec[0]}.ies"), "w", encoding="utf-8") as f:
            f.write(lib.builtin_text(spec))
    fixtures_per_position = per_position([(s[6], s[7]) for s in specs])
    spots_per_position = 2 * 6  # spot.py's CONES x candidate_lamps.MAX_CLUSTERS (the living room has more clusters)
    plan = {
        "spots": ("spots, default (96 candidates)", ("a.json",)),
        "spots-positions": (f"spots, {POSITIONS} positions", ("b.json", "--max-lamps", str(POSITIONS * spots_per_position))),
        "fixtures": (f"10 fixture types, {POSITIONS} positions", ("c.json", "--no-spot-lamps", "--fixtures", folder,
                                                                  "--max-lamps", str(POSITIONS * fixtures_per_position))),
    }
    runs = {name: run(scene, os.path.join(tmp, report), *extra)
            for key, (name, (report, *extra)) in plan.items() if key in only}
    load = os.getloadavg()
    result = {"scene": "living_room(2)", "load_at_end": load, "fixtures_per_position": fixtures_per_position,
              "runs": runs}
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    stem = "bench_fixtures" if len(only) == 3 else "bench_fixtures_" + "_".join(sorted(only))
    with open(os.path.join(HERE, "results", f"{stem}.json"), "w") as f:
        json.dump(result, f, indent=1)
    for name, r in runs.items():
        print(f"{name}: offered {r['offered']}; {r['wall_s']:.1f} s wall, job {r['timings_s'].get('total', '?')}; "
              f"relative error {r['relative_error']:.4f} with {r['n_lights']} lights {r['lights']}")
        if "schedule" in r:
            print("   schedule:", r["schedule"])
    print(f"load average at the end: {load}")


if __name__ == "__main__":
    main()
