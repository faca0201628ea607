"""Form-factor benchmark: accuracy per ray, speed vs raw embreex, threads, memory.

Run:  .venv/bin/python benchmarks/bench_formfactors.py   (about 2 minutes on 2 cores)

1. Accuracy per ray: RMS relative error of F_12 against Howell's closed forms
   over 6 configurations x 6 seeds, for the three samplers, with and without
   reciprocity symmetrisation, at 256 / 4096 / 65536 rays per patch.
2. Speed: rays/s of compute_form_factors (all cores) divided by rays/s of raw
   embreex ``scene.run`` on the very same rays with the same thread pool.
3. Thread scaling: compute_form_factors with 1 vs 2 threads.
4. Peak memory of a ~20,000-patch closed box (sparse matrix), in a child process.
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight_addon.engine import closed_forms as cf  # noqa: E402
from relight_addon.engine.formfactors import QUALITY, _Tracer, compute_form_factors, symmetrise  # noqa: E402
from relight_addon.engine.scene import mesh_patches, polygon_faceset  # noqa: E402

CONFIGS = [
    ("parallel 1x1 at 1", cf.parallel_rectangles_polygons(1, 1, 1), cf.parallel_rectangles(1, 1, 1)),
    ("parallel 2x1 at 0.5", cf.parallel_rectangles_polygons(2, 1, 0.5), cf.parallel_rectangles(2, 1, 0.5)),
    ("perpendicular l1 w1 h1", cf.perpendicular_rectangles_polygons(1, 1, 1), cf.perpendicular_rectangles(1, 1, 1)),
    ("perpendicular l1 w2 h0.5", cf.perpendicular_rectangles_polygons(1, 2, 0.5), cf.perpendicular_rectangles(1, 2, 0.5)),
    ("disks r1 r1 h1", cf.coaxial_disks_polygons(1, 1, 1), cf.coaxial_disks(1, 1, 1)),
    ("disks r1 r0.5 h0.5", cf.coaxial_disks_polygons(1, 0.5, 0.5), cf.coaxial_disks(1, 0.5, 0.5)),
]


def accuracy_table(seeds=6):
    scenes = [(name, mesh_patches(polygon_faceset(p), max_patch_size=1e3), ref) for name, p, ref in CONFIGS]
    rows = []
    for sampling in ("random", "stratified", "sobol"):
        for n in (QUALITY["draft"], QUALITY["default"], QUALITY["high"]):
            err = {False: [], True: []}
            for _, ps, ref in scenes:
                for seed in range(seeds):
                    M = compute_form_factors(ps, n, seed=seed, sampling=sampling).matrix
                    err[False].append(M[0, 1] / ref - 1)
                    err[True].append(symmetrise(M, ps.area)[0, 1] / ref - 1)
            for sym in (False, True):
                e = np.abs(err[sym])
                rows.append((sampling, sym, n, float(np.sqrt(np.mean(e**2))), float(e.max())))
    return rows


def box_patches(n_per_side):
    return mesh_patches(polygon_faceset(cf.box_polygons()), max_patch_size=1.0 / n_per_side)


def speed(rays_per_patch=1024, n_per_side=22):
    ps = box_patches(n_per_side)
    threads = os.cpu_count() or 1
    compute_form_factors(ps, 64, threads=threads)  # warm-up
    ff = compute_form_factors(ps, rays_per_patch, threads=threads)
    t_stage = ff.seconds
    ff1 = compute_form_factors(ps, rays_per_patch, threads=1)
    # raw embreex on the same rays, same chunks, same pool size
    tr = _Tracer(ps, rays_per_patch, 0, "sobol")
    rays = [tr.rays(ci)[:2] for ci in range(len(tr.chunks))]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=threads) as ex:
        list(ex.map(lambda od: tr.trace(*od), rays))
    t_raw = time.perf_counter() - t0
    n = ff.n_rays
    return dict(P=ps.n_patches, rays=n, threads=threads, t_stage=t_stage, t_raw=t_raw, t_1=ff1.seconds,
                rowsum_err=float(np.abs(ff.row_sums() - 1).max()),
                same=bool(np.array_equal(ff.matrix, ff1.matrix)))


CHILD = r"""
import resource, sys, time, numpy as np
sys.path.insert(0, sys.argv[1])
from relight_addon.engine import closed_forms as cf
from relight_addon.engine.formfactors import compute_form_factors, QUALITY
from relight_addon.engine.scene import mesh_patches, polygon_faceset
ps = mesh_patches(polygon_faceset(cf.box_polygons()), max_patch_size=1.0 / 58)
import tracemalloc
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
tracemalloc.start()
ff = compute_form_factors(ps, int(sys.argv[2]))
traced = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
rs = ff.row_sums()
print(ps.n_patches, ff.n_rays, ff.seconds, type(ff.matrix).__name__, ff.matrix.nnz,
      base, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, float(np.abs(rs - 1).max()), traced)
"""


def memory(rays_per_patch=QUALITY["draft"]):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", CHILD, root, str(rays_per_patch)], check=True,
                         capture_output=True, text=True).stdout.split()
    P, n, sec, kind, nnz, base, peak, rs, traced = out
    return dict(P=int(P), rays=int(n), seconds=float(sec), kind=kind, nnz=int(nnz),
                base_mb=int(base) / 1024, peak_mb=int(peak) / 1024, rowsum_err=float(rs),
                traced_mb=int(traced) / 2**20)


def main():
    t0 = time.perf_counter()
    print("## Accuracy per ray (RMS / max relative error of F_12 vs closed forms, 6 configs x 6 seeds)")
    print("| sampling | symmetrised | rays/patch | RMS rel. error | max rel. error |")
    print("|---|---|---|---|---|")
    for s, sym, n, rms, mx in accuracy_table():
        print(f"| {s} | {'yes' if sym else 'no'} | {n} | {rms * 100:.3f} % | {mx * 100:.3f} % |")
    sp_ = speed()
    print("\n## Speed (closed box, dense)")
    print(f"patches {sp_['P']}, rays {sp_['rays']}, threads {sp_['threads']}")
    print(f"form-factor stage: {sp_['t_stage']:.3f} s = {sp_['rays'] / sp_['t_stage'] / 1e6:.2f} Mrays/s")
    print(f"raw embreex run (same rays, same pool): {sp_['t_raw']:.3f} s = {sp_['rays'] / sp_['t_raw'] / 1e6:.2f} Mrays/s")
    print(f"ratio stage/raw rays/s: {sp_['t_raw'] / sp_['t_stage']:.2f}")
    print(f"1 thread: {sp_['t_1']:.3f} s; speed-up {sp_['threads']} threads vs 1: {sp_['t_1'] / sp_['t_stage']:.2f}x; "
          f"identical matrices: {sp_['same']}; max |row sum - 1| = {sp_['rowsum_err']:.2e}")
    m = memory()
    print("\n## Memory (closed box, sparse)")
    print(f"patches {m['P']}, rays {m['rays']}, {m['seconds']:.2f} s, {m['kind']} nnz {m['nnz']}, "
          f"peak RSS {m['peak_mb']:.0f} MB (before the form factors: {m['base_mb']:.0f} MB), "
          f"peak numpy/Python allocations during compute_form_factors (tracemalloc) {m['traced_mb']:.0f} MB, "
          f"max |row sum - 1| = {m['rowsum_err']:.2e}")
    print(f"\nbenchmark wall time {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
