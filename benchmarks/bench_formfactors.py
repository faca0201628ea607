"""Form-factor benchmark: accuracy per ray, speed vs raw embreex, threads, memory.

Run:  .venv/bin/python benchmarks/bench_formfactors.py [--only accuracy]   (about 2 minutes on 2 cores)

1. Accuracy per ray: relative error of F_12 and F_21 against Howell's closed forms on the
   9 configurations of tests/test_engine_formfactors.py x 6 seeds: Sobol at
   1024 ... 16384 and 262144 rays per patch, each row from its own rays ("rays") and
   with the reciprocity weighting (``weigh_reciprocity``, the default, from the same
   rays), random and stratified sampling at the default.
2. Speed: rays/s of compute_form_factors (all cores) divided by rays/s of raw
   embreex ``scene.run`` on the very same rays (pre-generated) with a thread pool
   of the same size, alternated 3 times in the same run (best and median).
3. Thread scaling: compute_form_factors and raw embreex with 1 vs all threads.
4. Form-factor time of the ~1500-patch room of bench_inverse.py per rays/patch.
5. Peak memory of a ~20,000-patch closed box (sparse matrix), in a child process.
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
from relight_addon.engine.formfactors import QUALITY, _Tracer, compute_form_factors, weigh_reciprocity  # noqa: E402
from relight_addon.engine.scene import mesh_patches, polygon_faceset  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))
from test_engine_formfactors import CONFIGS  # noqa: E402  (the tests' 9 configurations)

SOBOL_RAYS = (1024, 2048, 4096, 8192, 16384, QUALITY["high"])


def accuracy_table(seeds=6):
    scenes = [(name, mesh_patches(polygon_faceset(p), max_patch_size=1e3), ref) for name, p, ref in CONFIGS]
    runs = [("sobol", n) for n in SOBOL_RAYS] + [(s, QUALITY["default"]) for s in ("random", "stratified")]
    rows, per_config = [], {}
    for sampling, n in runs:
        err = {False: [], True: []}
        for name, ps, ref in scenes:
            e, w = [], []
            ref21 = ref * ps.area[0] / ps.area[1]
            for seed in range(seeds):
                M = compute_form_factors(ps, n, seed=seed, sampling=sampling, reciprocity="rays").matrix
                e += [M[0, 1] / ref - 1, M[1, 0] / ref21 - 1]
                W = weigh_reciprocity(M, ps.area, n)
                w += [W[0, 1] / ref - 1, W[1, 0] / ref21 - 1]
            err[False] += e
            err[True] += w
            if sampling == "sobol":
                per_config[(name, n)] = float(np.sqrt(np.mean(np.square(e)))), float(np.sqrt(np.mean(np.square(w))))
        for sym in (False, True):
            e = np.abs(err[sym])
            rows.append((sampling, sym, n, float(np.sqrt(np.mean(e**2))), float(e.max())))
    return rows, per_config


def box_patches(n_per_side):
    return mesh_patches(polygon_faceset(cf.box_polygons()), max_patch_size=1.0 / n_per_side)


def speed(rays_per_patch=1024, n_per_side=22, repeats=3):
    ps = box_patches(n_per_side)
    threads = os.cpu_count() or 1
    compute_form_factors(ps, 64, threads=threads)  # warm-up
    # raw embreex on the same rays (pre-generated, same chunks), same pool size
    tr = _Tracer(ps, rays_per_patch, 0, "sobol")
    rays = [tr.rays(ci)[:2] for ci in range(len(tr.chunks))]

    def raw(th):
        t0 = time.perf_counter()
        with ThreadPoolExecutor(max_workers=th) as ex:
            list(ex.map(lambda od: tr.trace(*od), rays))
        return time.perf_counter() - t0

    t = {"stage": [], "raw": [], "stage1": [], "raw1": []}
    for _ in range(repeats):  # alternate, so that changes in machine load hit both
        ff = compute_form_factors(ps, rays_per_patch, threads=threads)
        t["stage"].append(ff.seconds)
        t["raw"].append(raw(threads))
        ff1 = compute_form_factors(ps, rays_per_patch, threads=1)
        t["stage1"].append(ff1.seconds)
        t["raw1"].append(raw(1))
    return dict(P=ps.n_patches, rays=ff.n_rays, threads=threads,
                best={k: min(v) for k, v in t.items()}, median={k: float(np.median(v)) for k, v in t.items()},
                rowsum_err=float(np.abs(ff.row_sums() - 1).max()),
                same=bool(np.array_equal(ff.matrix, ff1.matrix)))


def room(rays_list=(1024, 2048, 4096, 8192, 16384)):
    """Form-factor time on bench_inverse.py's 6 x 4 x 3 m room (~1500 patches), all cores."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_inverse import scene

    out = []
    for n in rays_list:
        patches, F, t = scene(n)
        out.append((n, patches.n_patches, t))
    return out


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
    import argparse

    ap = argparse.ArgumentParser(description="form-factor benchmark")
    ap.add_argument("--only", choices=("accuracy",), help="run only this part")
    args = ap.parse_args()
    t0 = time.perf_counter()
    print(os.popen("uptime").read().strip())
    rows, per_config = accuracy_table()
    print("## Accuracy per ray (relative error of F_12 and F_21 vs closed forms, 9 configs x 6 seeds)")
    print("| sampling | reciprocity | rays/patch | RMS rel. error | max rel. error |")
    print("|---|---|---|---|---|")
    for s, sym, n, rms, mx in rows:
        print(f"| {s} | {'weighted' if sym else 'rays'} | {n} | {rms * 100:.2f} % | {mx * 100:.2f} % |")
    print("\n## Sobol, per configuration: RMS relative error of F_12 and F_21 over 6 seeds, rays / weighted")
    print("| configuration | F_12 | " + " | ".join(str(n) for n in SOBOL_RAYS) + " |")
    print("|---|---|" + "---|" * len(SOBOL_RAYS))
    for name, _, ref in CONFIGS:
        cells = [f"{per_config[(name, n)][0] * 100:.2f} / {per_config[(name, n)][1] * 100:.2f} %" for n in SOBOL_RAYS]
        print(f"| {name} | {ref:.4f} | " + " | ".join(cells) + " |")
    print(os.popen("uptime").read().strip())
    if args.only == "accuracy":
        return
    sp_ = speed()
    b, m = sp_["best"], sp_["median"]
    print("\n## Speed (closed box, dense), best / median of 3 alternated runs")
    print(f"patches {sp_['P']}, rays {sp_['rays']}, threads {sp_['threads']}")
    for key, label in (("stage", f"compute_form_factors ({sp_['threads']} threads)"),
                       ("raw", f"raw embreex run, same rays ({sp_['threads']} threads)"),
                       ("stage1", "compute_form_factors (1 thread)"), ("raw1", "raw embreex run, same rays (1 thread)")):
        print(f"| {label} | {b[key]:.3f} s / {m[key]:.3f} s | {sp_['rays'] / b[key] / 1e6:.2f} M/s |")
    print(f"ratio stage/raw rays/s, all threads: best {b['raw'] / b['stage']:.2f}, median {m['raw'] / m['stage']:.2f}; "
          f"1 thread: best {b['raw1'] / b['stage1']:.2f}, median {m['raw1'] / m['stage1']:.2f}")
    print(f"speed-up {sp_['threads']} threads vs 1: stage {b['stage1'] / b['stage']:.2f}x, raw {b['raw1'] / b['raw']:.2f}x; "
          f"identical matrices: {sp_['same']}; max |row sum - 1| = {sp_['rowsum_err']:.2e}")
    print(os.popen("uptime").read().strip())
    print("\n## Room of bench_inverse.py (form factors, all cores)")
    for n, P, t in room():
        print(f"| {n} | {P} | {t:.2f} s | {n * P / t / 1e6:.2f} M/s |")
    m = memory()
    print("\n## Memory (closed box, sparse)")
    print(f"patches {m['P']}, rays {m['rays']}, {m['seconds']:.2f} s, {m['kind']} nnz {m['nnz']}, "
          f"peak RSS {m['peak_mb']:.0f} MB (before the form factors: {m['base_mb']:.0f} MB), "
          f"peak numpy/Python allocations during compute_form_factors (tracemalloc) {m['traced_mb']:.0f} MB, "
          f"max |row sum - 1| = {m['rowsum_err']:.2e}")
    print(os.popen("uptime").read().strip())
    print(f"\nbenchmark wall time {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
