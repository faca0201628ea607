"""What an artist pays per try in try-and-correct: the Cycles time to reach a target accuracy,
against Relight's solve (issue 9, benchmarks).

    .venv/bin/python benchmarks/bench_cycles_cost.py

The closed-loop room of tests/test_cycles_closed_loop.py (a cube room of 8 x 8 grids, a block,
targets on a floor corner and a red wall): `solve --out` (defaults) gives 3 lights and predicts
the targets' radiosity; Cycles then bakes the target faces of that file at 64, 256 and 1024
samples (Lambertian materials, no clamping, 64 bounces: tests/cycles_reference.py). For each:
the bake's wall time and its Monte-Carlo noise on a target face mean (standard error / mean,
averaged over the faces). Noise falls as 1/sqrt(samples), so the samples (and seconds) a bake
needs for 1 % and 0.5 % per-face noise follow; Relight's solve time, and its prediction's
difference from the 1024-sample bake, are measured in the same run.
Writes benchmarks/results/bench_cycles_cost.json.
"""
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import bpy  # noqa: E402

import cycles_reference as cr  # noqa: E402
import test_cycles_closed_loop as loop  # noqa: E402


def main():
    tmp = Path(tempfile.mkdtemp())
    scene, report_path, out = tmp / "room.blend", tmp / "r.json", tmp / "out.blend"
    loop.build_room(scene)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "relight_addon", "solve", str(scene), "--report", str(report_path),
                        "--out", str(out), "--quiet"], cwd=ROOT, capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    solve_wall = time.perf_counter() - t0
    assert p.returncode == 0, p.stderr
    report = json.loads(report_path.read_text())
    names = [n for n, o in report["objects"].items() if any(t is not None for t in o["target"] or [])]
    rows = []
    for samples in (64, 256, 1024):
        bpy.ops.wm.open_mainfile(filepath=str(out))
        t1 = time.perf_counter()
        res = cr.cycles_face_radiance(samples=samples, seed=1, cell_px=loop.CELL_PX,
                                      objects=[bpy.data.objects[n] for n in names])
        seconds = time.perf_counter() - t1
        noise, err = [], []
        for n in names:
            tgt = np.array([[np.nan] * 3 if t is None else t for t in report["objects"][n]["target"]], float)
            f = np.flatnonzero(np.all(np.isfinite(tgt), axis=1))
            noise.append(res[n].std_error[f].sum(1) / res[n].radiance[f].sum(1))
            pred = np.asarray(report["objects"][n]["radiosity"], float)[f]
            cyc = np.pi * res[n].radiance[f]
            err.append(np.abs(pred - cyc).sum(1) / cyc.sum(1))
        noise, err = np.concatenate(noise), np.concatenate(err)
        rows.append({"samples": samples, "seconds": seconds, "noise_mean": float(noise.mean()),
                     "prediction_vs_bake_mean": float(err.mean())})
        print(f"Cycles {samples:5d} samples: {seconds:6.1f} s, per-face noise {noise.mean():.4f}, "
              f"Relight's prediction vs this bake {err.mean():.4f}", flush=True)
    # noise ~ c / sqrt(samples), time ~ a * samples: from the 1024-sample bake
    last = rows[-1]
    for goal in (0.01, 0.005):
        s = last["samples"] * (last["noise_mean"] / goal) ** 2
        print(f"a bake with {goal:.1%} per-face noise: ~{s:.0f} samples, ~{last['seconds'] * s / last['samples']:.0f} s",
              flush=True)
    print(f"Relight solve --out (3 lights, prediction): {solve_wall:.1f} s wall, job {report['timings_s']['total']:.1f} s")
    (ROOT / "benchmarks" / "results").mkdir(exist_ok=True)
    (ROOT / "benchmarks" / "results" / "bench_cycles_cost.json").write_text(json.dumps(
        {"command": "benchmarks/bench_cycles_cost.py", "load": os.getloadavg(), "bakes": rows,
         "solve_wall_seconds": solve_wall, "solve_job_seconds": report["timings_s"]["total"]}, indent=1))


if __name__ == "__main__":
    main()
