"""Accuracy where the artist looks (issue 18): every painted face, several points of the curve, as
Cycles renders the written file with its own settings.

    .venv/bin/python benchmarks/bench_face_accuracy.py [--samples 512] [--quick]

Per case: `relight solve --out --seed 1` (with the case's flags), then for each configuration
measured the written copy is re-applied at that row (``--row``: the add-on's curve row), opened and
baked by Cycles (tests/cycles_reference.cycles_face_radiance: the file's own materials, World and
light paths; each face's mean outgoing radiance along its normal) on the objects holding painted
faces; each painted face's prediction is the report's ``radiance_normal`` (its normal-view
radiance; Lambertian: radiosity / pi). Per configuration: the signed mean (the bias, area-weighted
over the painted faces), the per-face mean and max of |ours - Cycles| / Cycles, and Cycles' own
noise (its per-face standard error, mean over the faces). Writes
benchmarks/results/bench_face_accuracy.json.

Cases: the shipped staircase at 3 and 10 lights; the suite's living room (default Principled
materials, tests/artist_scenes.living_room) at 3 lights.
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
PY = sys.executable

BAKE = r"""
import sys, json
sys.path[:0] = [%r, %r]
import bpy
import numpy as np
import cycles_reference as cr
blend, faces, samples, out = sys.argv[-4], json.loads(sys.argv[-3]), int(sys.argv[-2]), sys.argv[-1]
bpy.ops.wm.open_mainfile(filepath=blend)
baked = cr.cycles_face_radiance(samples=samples, seed=2, objects=[bpy.data.objects[n] for n in faces],
                                keep_world=True, keep_materials=True, keep_light_paths=True, threads=2,
                                faces=faces)
json.dump({n: {"radiance": b.radiance.tolist(), "noise": b.rel_noise.tolist()} for n, b in baked.items()},
          open(out, "w"))
"""

BUILD = r"""
import sys
sys.path[:0] = [%r, %r]
import bpy, artist_scenes
bpy.ops.wm.read_factory_settings(use_empty=True)
artist_scenes.living_room(2)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])
"""


def relight(*args):
    r = subprocess.run([PY, "-m", "relight_addon", *map(str, args)], cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    return r


def measure(blend, tmp, flags, samples, label):
    report_path, out = os.path.join(tmp, "r.json"), os.path.join(tmp, "out.blend")
    relight("solve", blend, "--report", report_path, "--out", out, "--seed", "1", *flags)
    report = json.load(open(report_path))
    faces = {n: [i for i, t in enumerate(o["target"]) if t is not None] for n, o in report["objects"].items()}
    faces = {n: f for n, f in faces.items() if f}
    names = list(faces)
    baked_path = os.path.join(tmp, "baked.json")
    subprocess.run([PY, "-c", BAKE % (ROOT, os.path.join(ROOT, "tests")), out, json.dumps(faces), str(samples),
                    baked_path], check=True, capture_output=True, text=True)
    baked = json.load(open(baked_path))
    signed, noise, area = [], [], []
    for n in names:
        o = report["objects"][n]
        tg = np.array([t is not None for t in o["target"]])
        rn = o.get("radiance_normal")
        ours = (np.array([r if r is not None else [np.nan] * 3 for r in rn], dtype=np.float64) if rn is not None
                else np.asarray(o["radiosity"], dtype=np.float64) / np.pi)[tg].sum(axis=1)
        got = np.asarray(baked[n]["radiance"], dtype=np.float64)[tg].sum(axis=1)
        signed.append((ours - got) / got)
        noise.append(np.asarray(baked[n]["noise"], dtype=np.float64)[tg])
        area.append(np.asarray(o.get("area", np.ones(len(tg))), dtype=np.float64)[tg] if "area" in o
                    else np.ones(int(tg.sum())))
    s, w = np.concatenate(signed), np.concatenate(area)
    row = {"case": label, "n_lights": report["final"]["n_lights"],
           "relative_error": report["final"]["relative_error"], "faces": int(len(s)),
           "signed": float((s * w).sum() / w.sum()), "face_mean": float(np.abs(s).mean()),
           "face_max": float(np.abs(s).max()), "cycles_noise": float(np.concatenate(noise).mean()),
           "kinds": [li["kind"] for li in report["final"]["lights"]], "patches": report["scene"]["patches"],
           "target_rows": report["inverse"]["n_targets"], "solve_s": report["timings_s"]["total"]}
    print(f"{label:32s} {row['n_lights']:2d} lights, {row['faces']} faces ({row['target_rows']} rows): signed "
          f"{row['signed']:+.4f} face mean {row['face_mean']:.4f} max {row['face_max']:.4f} (Cycles noise "
          f"{row['cycles_noise']:.4f}); solve {row['solve_s']:.2f} s", flush=True)
    return row


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=512)
    ap.add_argument("--quick", action="store_true", help="the staircase cases only")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="relight-bench-faces-")
    stair = os.path.join(ROOT, "sample_blends", "staircase_targets.blend")
    cases = [(stair, [], "staircase, 3 lights"), (stair, ["--max-lights", "10"], "staircase, 10 lights")]
    if not args.quick:
        living = os.path.join(tmp, "living.blend")
        subprocess.run([PY, "-c", BUILD % (ROOT, os.path.join(ROOT, "tests")), living], check=True,
                       capture_output=True)
        cases.append((living, [], "living room (Principled), 3 lights"))
    rows = []
    for b, f, label in cases:
        try:
            rows.append(measure(b, tmp, f, args.samples, label))
        except subprocess.CalledProcessError as exc:  # e.g. a face too small for the bake's texels
            print(f"{label}: the bake failed ({exc.stderr.strip().splitlines()[-1] if exc.stderr else exc})")
            rows.append({"case": label, "error": "bake failed"})
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "bench_face_accuracy.json"), "w") as f:
        json.dump({"command": "benchmarks/bench_face_accuracy.py", "samples": args.samples, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
