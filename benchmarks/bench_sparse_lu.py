"""Sparse LU of the radiosity system against the cost model (engine/cost.py, the sparse terms).

Run:  .venv/bin/python benchmarks/bench_sparse_lu.py [SCENE PATCH_SIZE RAYS] ...
      (default: the Cornell box at 2 cm and the staircase at 0.3 m, 1024 rays; each a few minutes
      on 2 cores; the staircase at 0.2 m takes about 8 minutes)

Per scene, in a child process each (peak RSS): patches P (polygon model), non-zeros per row of
A = I - rho F against the rays per patch (the model's HIT_FRACTION), the fill of scipy's splu
(nnz(L) + nnz(U)) / nnz(A) (the model's LU_FILL), splu's seconds against nnz(LU)^2 / P at
FLOPS x SPLU_SPEED (the model's time), and the seconds the main thread waited between wake-ups
while splu ran in a worker thread (the Ctrl-C latency of the CLI: splu holds Python during its
column ordering).
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

DEFAULT = [("sample_blends/cornell_box.blend", 0.02, 1024), ("sample_blends/staircase.blend", 0.3, 1024)]


def child(scene, size, rays):
    import numpy as np
    import scipy.sparse.linalg as spla

    from relight_addon import export, jobs
    from relight_addon.engine import cost
    from relight_addon.engine.options import JobOptions
    from relight_addon.engine.radiosity import radiosity_matrix
    from relight_addon.engine.registry import ESTIMATORS

    export.open_blend(os.path.join(ROOT, scene))
    exp = export.export_scene()
    opt = JobOptions(max_patch_size=size, rays_per_patch=rays).validate()
    patches = jobs.mesh_for_job(exp.faces, opt, None)
    P = patches.n_patches
    F = ESTIMATORS[opt.estimator](patches, opt)
    A = radiosity_matrix(F, patches.reflectance[:, 0]).tocsc()
    result = {}
    ticks = []

    def work():
        t = time.perf_counter()
        lu = spla.splu(A)
        result["seconds"] = time.perf_counter() - t
        result["nnz_lu"] = int(lu.L.nnz + lu.U.nnz)

    th = threading.Thread(target=work)
    t0 = time.perf_counter()
    th.start()
    while th.is_alive():
        th.join(0.05)
        ticks.append(time.perf_counter() - t0)
    gaps = np.diff([0.0] + ticks)
    est = cost.estimate_cost(P, rays, 0, 0, threads=1)
    nnz_lu = result["nnz_lu"]
    print(json.dumps({
        "scene": scene, "patch_size": size, "rays": rays, "patches": P,
        "nnz_A_per_row": A.nnz / P, "hit_fraction": (A.nnz / P - 1) / rays,
        "fill": nnz_lu / A.nnz, "nnz_lu_per_row": nnz_lu / P,
        "splu_s": result["seconds"],
        "model_s_measured_fill": nnz_lu ** 2 / P / (cost.FLOPS * cost.SPLU_SPEED),
        "model_lu_s_one_channel": est["parts"]["lu"][1] / 3,
        "model_lu_bytes_one_channel": (est["parts"]["lu"][0] - 12.0 * P * min(P, cost.HIT_FRACTION * rays + 1)) / 3,
        "measured_lu_bytes": 12.0 * nnz_lu,
        "max_python_wait_s": float(gaps.max()),
        "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
    }))


def main(argv):
    if argv and argv[0] == "--child":
        return child(argv[1], float(argv[2]), int(argv[3]))
    runs = [(argv[i], float(argv[i + 1]), int(argv[i + 2])) for i in range(0, len(argv), 3)] or DEFAULT
    for scene, size, rays in runs:
        p = subprocess.run([sys.executable, __file__, "--child", scene, str(size), str(rays)],
                           capture_output=True, text=True)
        line = [ln for ln in p.stdout.splitlines() if ln.startswith("{")]
        if not line:
            print(p.stdout[-2000:], p.stderr[-2000:])
            continue
        r = json.loads(line[-1])
        print(f"{os.path.basename(r['scene'])} {r['patch_size']} m, {r['rays']} rays: P={r['patches']}, "
              f"nnz(A)/P={r['nnz_A_per_row']:.0f} (hit fraction {r['hit_fraction']:.2f}), fill {r['fill']:.1f}, "
              f"nnz(LU)/P={r['nnz_lu_per_row']:.0f}; splu {r['splu_s']:.1f} s, nnz(LU)^2/P model "
              f"{r['model_s_measured_fill']:.1f} s (with the model's fill: {r['model_lu_s_one_channel']:.1f} s); "
              f"LU {r['measured_lu_bytes'] / 1e9:.2f} GB (model {r['model_lu_bytes_one_channel'] / 1e9:.2f} GB); "
              f"Python waited at most {r['max_python_wait_s']:.1f} s; peak RSS {r['peak_rss_gb']:.2f} GB")


if __name__ == "__main__":
    main(sys.argv[1:])
