"""The lamp refinement's answers across seeds (issues 17 and 40): the command line's solve of three
scenes whose answers hold placed lamps -- the camera-view target of bench_view_target.py (480 x 270,
every pixel asked a uniform radiance), the staircase sample and issue 17's gallery
(tests/artist_scenes.gallery) -- at each seed, one process a solve, with the code of ``--root``
(default this checkout: another worktree's code for an A/B). Prints and writes each run's final
relative error, the refinement's time and the curve's refined configurations (n_lights:
relative error after / evaluations); docs/benchmarks.md, "The lamp refinement's second round".

    .venv/bin/python benchmarks/bench_refinement.py [--root DIR] [--seeds 0,1,2,3,4]
        [--scenes view,staircase,gallery] [--out DIR] [--tag NAME]

A change to the search is judged on all fifteen runs (a search's answer moves from seed to seed by
more than most changes do at one).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests"), os.path.join(ROOT, "benchmarks")]
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_refinement.json")


def scenes(folder) -> dict:
    """{name: the solve's arguments} (the files made in ``folder`` when absent)."""
    view = [os.path.join(folder, n) for n in ("pixel.blend", "target.exr")]
    gallery = os.path.join(folder, "gallery.blend")
    if not all(os.path.exists(p) for p in view):
        import bench_view_target

        _, pixel, image = bench_view_target.build(folder)
        view = [pixel, image]
    if not os.path.exists(gallery):
        import bpy

        import artist_scenes
        import cycles_reference as cr

        cr.reset_blender()
        artist_scenes.gallery()
        bpy.ops.wm.save_as_mainfile(filepath=gallery)
        cr.reset_blender()
    return {"view": [view[0], "--view-target", view[1]],
            "staircase": [os.path.join(ROOT, "sample_blends", "staircase_targets.blend")],
            "gallery": [gallery]}


def solve(root, args, seed, report) -> dict:
    p = subprocess.run([sys.executable, "-m", "relight_addon", "solve", *args, "--seed", str(seed),
                        "--report", report, "--quiet"], cwd=root, capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": root})
    if p.returncode:
        raise SystemExit(f"the solve failed ({p.returncode}): {p.stderr[-500:]}")
    r = json.load(open(report))
    refinement = r["model"].get("lamp_refinement") or {}
    return {"final": r["final"]["relative_error"], "refinement_s": r["timings_s"]["lamp_refinement"],
            "total_s": r["timings_s"]["total"],
            "points": [[q["n_lights"], q["relative_error_after"], q["evaluations"]] for q in refinement.get("points", [])]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", default=ROOT, help="the checkout whose code solves (default this one)")
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--scenes", default="view,staircase,gallery")
    ap.add_argument("--out", default=os.path.join(tempfile.gettempdir(), "relight-bench-refinement"),
                    help="where the scenes are made (kept: made once)")
    ap.add_argument("--tag", default="")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    made = scenes(args.out)
    rows = []
    for name in args.scenes.split(","):
        for seed in map(int, args.seeds.split(",")):
            row = {"scene": name, "seed": seed, **solve(os.path.abspath(args.root), made[name], seed,
                                                         os.path.join(args.out, f"report_{name}_{seed}.json"))}
            rows.append(row)
            points = " ".join(f"{k}:{e:.4f}/{n}" for k, e, n in row["points"])
            print(f"{args.tag} {name} seed {seed}: final {row['final']:.4f}, refinement {row['refinement_s']:.2f} s, "
                  f"total {row['total_s']:.2f} s; refined {points}", flush=True)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as fh:
        json.dump({"command": "benchmarks/bench_refinement.py", "root": os.path.abspath(args.root), "tag": args.tag,
                   "load": os.getloadavg(), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
