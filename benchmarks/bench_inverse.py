"""Benchmark of the inverse solve and the light-source reduction on a staircase-sized scene.

Synthetic scene of the paper's size: a 6 x 4 x 3 m room (polygon_faceset),
meshed into ~1500 patches, ray-cast form factors; targets: a band of the floor
(~45 patches, 3%) painted at the radiosity of 3 ceiling/wall lights (a feasible
effect); candidates: ~685 wall and ceiling patches.

    .venv/bin/python benchmarks/bench_inverse.py [--rays 128]
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from relight_addon.engine.formfactors import compute_form_factors  # noqa: E402
from relight_addon.engine.inverse import InverseProblem, solve_inverse  # noqa: E402
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.reduction import StopCriteria, reduce_lights  # noqa: E402
from relight_addon.engine.scene import mesh_patches, polygon_faceset  # noqa: E402


def scene(rays):
    X, Y, Z = 6.0, 4.0, 3.0
    quads = [
        [(0, 0, 0), (0, Y, 0), (X, Y, 0), (X, 0, 0)],  # floor (reversed below: normals point inside)
        [(0, 0, Z), (X, 0, Z), (X, Y, Z), (0, Y, Z)],  # ceiling, -z
        [(0, 0, 0), (X, 0, 0), (X, 0, Z), (0, 0, Z)],  # y=0 wall, +y
        [(0, Y, 0), (0, Y, Z), (X, Y, Z), (X, Y, 0)],  # y=Y wall, -y
        [(0, 0, 0), (0, 0, Z), (0, Y, Z), (0, Y, 0)],  # x=0 wall, +x
        [(X, 0, 0), (X, Y, 0), (X, Y, Z), (X, 0, Z)],  # x=X wall, -x
    ]
    faces = polygon_faceset([np.array(q[::-1], float) for q in quads], reflectance=[0.6, 0.5, 0.4])
    patches = mesh_patches(faces, max_patch_size=0.27)
    t = time.perf_counter()
    ff = compute_form_factors(patches, rays_per_patch=rays, seed=0)
    return patches, np.asarray(ff.matrix, dtype=np.float64), time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rays", type=int, default=128)
    ap.add_argument("--compare-svd-drivers", action="store_true",
                    help="also time the explicit-SVD pseudo-inverse of the paper formulation (slow)")
    args = ap.parse_args()
    patches, F, t_ff = scene(args.rays)
    P = patches.n_patches
    c, n = patches.center, patches.normal
    floor = n[:, 2] > 0.5
    band = floor & (np.abs(c[:, 1] - 2.0) < 0.6) & (np.abs(c[:, 0] - 3.0) < 1.3)
    cand = ~floor & (c[:, 0] < 3.4)  # walls and ceiling of one half: ~685 candidates
    rng = np.random.default_rng(0)
    e = np.zeros((P, 3))
    e[rng.choice(np.flatnonzero(cand), 3, replace=False)] = rng.uniform(20, 60, (3, 3))
    base = InverseProblem(F, patches.area, patches.reflectance, [PaintedRadiance.masked(band, np.zeros((P, 3)))], cand)
    b = base.forward_radiosity(e) * band[:, None]
    print(f"scene: {P} patches, {band.sum()} targets, {cand.sum()} candidates, form factors {t_ff:.2f} s "
          f"({args.rays} rays/patch)")

    def fresh():
        return InverseProblem(F, patches.area, patches.reflectance, [PaintedRadiance.masked(band, b)], cand, c, n)

    rows = []
    res = {}
    runs = [("svd", "gelsd")] + ([("svd", "svd")] if args.compare_svd_drivers else []) + [
        ("reduced", "gelsd"), ("nnls", "gelsd")]
    for solver, drv in runs:
        p = fresh()
        t = time.perf_counter()
        r = solve_inverse(p, solver, svd_driver=drv)
        dt = time.perf_counter() - t
        res[(solver, drv)] = (p, r)
        rows.append((f"solve {solver} ({drv})" if solver != "nnls" else "solve nnls (incl. LU + T)",
                     dt, f"rel. error {r.relative_error:.2e}, rank {r.rank}, {r.n_negative} negative"))
    p, r = res[("reduced", "gelsd")]
    p.transfer  # cached
    for sel, dist in (("exitance-elimination", "distance"), ("error-elimination", "distance"),
                      ("exitance-construction", "distance"), ("nnls-greedy", "distance")):
        t = time.perf_counter()
        rr = reduce_lights(p, r.exitance, sel, dist, StopCriteria(relative_error_threshold=0.05))
        dt = time.perf_counter() - t
        f = rr.final
        rows.append((f"reduce {sel} full curve ({len(rr.curve)} points)", dt,
                     f"final {f.n_lights} lights at 5% threshold, rel. error {f.relative_error:.3f}, "
                     f"{f.n_negative} negative"))
    t = time.perf_counter()
    rt = reduce_lights(p, r.exitance, "exitance-elimination", "distance")
    t_t = time.perf_counter() - t
    t = time.perf_counter()
    rg = reduce_lights(p, r.exitance, "exitance-elimination", "distance", error_route="gauss-seidel",
                       gs_compare_cold=True)
    t_g = time.perf_counter() - t
    dev = max(abs(a.error - g.error) / p.target_norm for a, g in zip(rt.curve, rg.curve))
    warm, cold = sum(rg.gs_iterations), sum(rg.gs_cold_iterations)
    rows.append(("ComputeError route T (exitance-elimination curve)", t_t, "exact"))
    rows.append(("ComputeError route Gauss-Seidel warm (+cold comparison)", t_g,
                 f"max |error diff| {dev:.1e} of ||b_P||; sweeps warm {warm} vs cold {cold} "
                 f"({100 * (1 - warm / cold):.0f}% fewer); time ratio GS/T {t_g / t_t:.0f}x (incl. cold solves)"))
    for name, dt, acc in rows:
        print(f"| {name} | {dt:.3f} s | {acc} |", flush=True)


if __name__ == "__main__":
    main()
