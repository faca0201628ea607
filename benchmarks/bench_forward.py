"""Forward radiosity: time against accuracy at three quality levels (issue 2's first table).

Run:  .venv/bin/python benchmarks/bench_forward.py   (about 2 minutes on 2 cores)

Scenes, exported from the sample .blend files through export.py (the real path):
- the Cornell box (its own ceiling light);
- the staircase, lit by its ceiling (every ceiling face given an exitance of 100 W/m^2 here,
  since the sample has no emitter of its own).
Quality levels: draft (1024 rays/patch), automatic (the default: a ~4 M-ray budget) and
16384 rays/patch. Accuracy: per-face radiosity against a reference computed in the same run
with 131072 rays/patch and another seed (its own noise is ~sqrt(8) = 2.8x smaller than the
16384 level's, so the errors below slightly overstate the 16384 level's true error).
Reported per level: form-factor and solve seconds, rays/s, and the area-weighted mean and the
95th percentile of |B - B_ref| / B_ref over faces (faces under 1% of the median radiosity
excluded) and the relative error of the total absorbed power.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from relight_addon.blender import blend_files, export  # noqa: E402
from relight_addon.engine.formfactors import auto_rays_per_patch, compute_form_factors  # noqa: E402
from relight_addon.engine.radiosity import solve_radiosity  # noqa: E402
from relight_addon.engine.scene import face_mean, mesh_patches  # noqa: E402

LEVELS = (("draft", 1024), ("auto", None), ("16384", 16384))
REFERENCE_RAYS = 131072


def scene(name):
    blend_files.open_blend(os.path.join(ROOT, "sample_blends", f"{name}.blend"))
    exp = export.export_scene()
    faces = exp.faces
    if name == "staircase":
        ceiling = exp.faces.object_names.index("ceiling")
        faces.exitance[faces.face_object == ceiling] = 100.0
    return mesh_patches(faces, exp.settings.get("max_patch_size"))


def run(patches, rays, seed):
    F = compute_form_factors(patches, rays_per_patch=rays, seed=seed)
    t = time.perf_counter()
    B, info = solve_radiosity(F, patches.reflectance, patches.exitance)
    return F, B, time.perf_counter() - t


def main():
    print(f"load average: {os.getloadavg()}")
    rows = []
    for name in ("cornell_box", "staircase"):
        patches = scene(name)
        _, B_ref, _ = run(patches, REFERENCE_RAYS, seed=99)
        Bf_ref = face_mean(patches, B_ref).sum(axis=1)
        area_f = np.bincount(patches.face, weights=patches.area, minlength=patches.n_faces)
        ok = Bf_ref > 0.01 * np.median(Bf_ref[Bf_ref > 0])
        absorbed_ref = np.sum(patches.area[:, None] * (B_ref - patches.exitance) * (1 - patches.reflectance)
                              / np.maximum(patches.reflectance, 1e-9))
        for level, rays in LEVELS:
            F, B, t_solve = run(patches, rays, seed=0)
            Bf = face_mean(patches, B).sum(axis=1)
            rel = np.abs(Bf - Bf_ref)[ok] / Bf_ref[ok]
            absorbed = np.sum(patches.area[:, None] * (B - patches.exitance) * (1 - patches.reflectance)
                              / np.maximum(patches.reflectance, 1e-9))
            rows.append(dict(scene=name, patches=patches.n_patches, level=level, rays=F.rays_per_patch,
                             ff_s=F.seconds, solve_s=t_solve, mrays_s=F.n_rays / F.seconds / 1e6,
                             mean=float(np.average(rel, weights=area_f[ok])), p95=float(np.percentile(rel, 95)),
                             power=float(abs(absorbed / absorbed_ref - 1))))
            print(rows[-1], flush=True)
    print()
    print("| scene | patches | quality | rays/patch | form factors (s) | solve (s) | M rays/s "
          "| mean face error | 95th pct face error | absorbed power error |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['patches']} | {r['level']} | {r['rays']} | {r['ff_s']:.2f} | {r['solve_s']:.3f} "
              f"| {r['mrays_s']:.2f} | {100 * r['mean']:.2f} % | {100 * r['p95']:.2f} % | {100 * r['power']:.3f} % |")
    assert auto_rays_per_patch(1) == 16384


if __name__ == "__main__":
    main()
