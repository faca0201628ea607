"""The paper's experiment (section 5) on the real staircase: timings, errors and error curves.

Scene: sample_blends/staircase_targets.blend (1451 patches, 44 painted targets, 693
candidate lights), form factors at the automatic quality (the CLI's default).

    .venv/bin/python benchmarks/bench_staircase.py [--gs-points 40] [--ec-steps 30] [--no-cli]
    .venv/bin/python benchmarks/plot_curves.py       # charts from the JSON written here

Parts (one process, one run, so every ratio is measured under the same load):
1. the mathematical phase with each formulation: svd (driver auto = Cholesky of M M^T,
   and gelsd = LAPACK SVD), reduced, nnls; each on a fresh problem (LU and T included);
2. the reduction curves from the reduced solver's e_x (the CLI's default): the four paper
   selections x distance, exitance-elimination x every distribution, nnls-greedy, and the
   paper's pipeline (svd e_x + exitance-elimination + distance);
3. the paper's ComputeError (Gauss-Seidel, warm-started) against the T route on the first
   ``--gs-points`` points of the default curve, and the warm-start sweep saving vs cold;
4. ``solve`` end to end through the CLI, .blend in to .blend out, as a subprocess.
Writes benchmarks/results/bench_staircase.json (the curves for the charts) and prints
markdown tables.
"""
import argparse
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
from relight_addon.engine.formfactors import compute_form_factors  # noqa: E402
from relight_addon.engine.inverse import InverseProblem, solve_inverse  # noqa: E402
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.reduction import reduce_lights  # noqa: E402
from relight_addon.engine.scene import mesh_patches  # noqa: E402

SCENE = ROOT / "sample_blends" / "staircase_targets.blend"
OUT_JSON = ROOT / "benchmarks" / "results" / "bench_staircase.json"


def uptime():
    with open("/proc/loadavg") as fh:
        return " ".join(fh.read().split()[:3])


def load_staircase(rays=None, seed=0):
    """(patches, F as float64 ndarray, form-factor seconds, rays per patch) of the staircase."""
    from relight_addon.blender import export

    export.open_blend(str(SCENE))
    exp = export.export_scene()
    patches = mesh_patches(exp.faces, exp.settings.get("max_patch_size"))
    ff = compute_form_factors(patches, rays_per_patch=rays, seed=seed)
    return patches, np.asarray(ff.matrix, dtype=np.float64), ff.seconds, int(ff.rays_per_patch)


def curve_summary(curve):
    n = np.array([p.n_lights for p in curve])
    rel = np.array([p.relative_error for p in curve])
    err = np.array([p.error for p in curve])
    neg = np.array([p.n_negative for p in curve])
    pos = neg == 0

    def best(mask):
        if not mask.any():
            return None
        i = np.flatnonzero(mask)[np.argmin(rel[mask])]
        return {"n_lights": int(n[i]), "error": float(err[i]), "relative_error": float(rel[i])}

    return {"n_lights": n.tolist(), "relative_error": rel.tolist(), "error": err.tolist(),
            "n_negative": neg.tolist(), "best_positive": best(pos), "best_positive_le3": best(pos & (n <= 3)),
            "best_any_le3": best(n <= 3)}


def point_at(curve, k):
    """The curve point with the number of lights closest to k."""
    i = int(np.argmin([abs(p.n_lights - k) for p in curve]))
    p = curve[i]
    return {"n_lights": p.n_lights, "error": p.error, "relative_error": p.relative_error,
            "n_negative": p.n_negative}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gs-points", type=int, default=40, help="curve points re-solved by Gauss-Seidel")
    ap.add_argument("--ec-steps", type=int, default=30, help="error-construction steps (max_steps)")
    ap.add_argument("--no-cli", action="store_true")
    args = ap.parse_args()
    out = {"command": "benchmarks/bench_staircase.py " + " ".join(sys.argv[1:]), "load": [uptime()]}
    print(f"load average (1/5/15 min): {uptime()}", flush=True)
    patches, F, t_ff, rays = load_staircase()
    cand = ~patches.forbidden
    print(f"scene: {patches.n_patches} patches, {int(patches.target.sum())} targets, {int(cand.sum())} "
          f"candidates; form factors {t_ff:.2f} s ({rays} rays/patch)", flush=True)
    out["scene"] = {"patches": int(patches.n_patches), "targets": int(patches.target.sum()),
                    "candidates": int(cand.sum()), "rays_per_patch": rays, "form_factors_s": t_ff}

    def fresh():
        return InverseProblem(F, patches.area, patches.reflectance,
                              [PaintedRadiance.masked(patches.target, patches.target_radiosity)],
                              cand, patches.center, patches.normal)

    # 1. the mathematical phase. One untimed solve first: the process's first dense solves pay
    # one-off costs (BLAS thread start-up, first-touch page faults) that are not the method's.
    solve_inverse(fresh(), "reduced")
    solves = {}
    rows = []
    for solver, drv in (("svd", "auto"), ("svd", "gelsd"), ("reduced", "auto"), ("nnls", "auto")):
        p = fresh()
        t = time.perf_counter()
        r = solve_inverse(p, solver, svd_driver=drv)
        dt = time.perf_counter() - t
        solves[(solver, drv)] = (p, r)
        nz = int((np.abs(r.exitance).max(axis=1) > 0).sum())
        rows.append({"solver": solver, "driver": drv, "seconds": dt, "error": r.error,
                     "relative_error": r.relative_error, "rank": r.rank, "n_negative": r.n_negative,
                     "n_nonzero": nz, "transfer_s": p.transfer_seconds})
        print(f"solve {solver} ({drv}): {dt:.3f} s, rel. error {r.relative_error:.2e}, "
              f"{r.n_negative} negative, {nz} non-zero", flush=True)
    ea, eg = solves[("svd", "auto")][1].exitance, solves[("svd", "gelsd")][1].exitance
    agree = float(np.abs(ea - eg).max() / np.abs(eg).max())
    t_gram = rows[0]["seconds"]
    t_gelsd = rows[1]["seconds"]
    print(f"svd auto vs gelsd: max |diff| / max |e| = {agree:.1e}; time ratio gelsd/auto {t_gelsd / t_gram:.1f}x",
          flush=True)
    out["solves"] = rows
    out["svd_auto_vs_gelsd"] = {"max_rel_diff": agree, "ratio": t_gelsd / t_gram}
    out["target_norm"] = solves[("reduced", "auto")][0].target_norm
    out["load"].append(uptime())

    # 2. reduction curves (from the reduced e_x, the CLI default; the problem's T is cached)
    p, r = solves[("reduced", "auto")]
    runs = [("exitance-elimination", "distance"), ("exitance-construction", "distance"),
            ("error-elimination", "distance"), ("error-construction", "distance"),
            ("exitance-elimination", "local"), ("exitance-elimination", "coplanar"),
            ("exitance-elimination", "uniform"), ("nnls-greedy", "none")]
    curves = {}
    for sel, dist in runs:
        t = time.perf_counter()
        rr = reduce_lights(p, r.exitance, sel, dist if dist != "none" else "distance",
                           max_steps=args.ec_steps if sel == "error-construction" else None)
        dt = time.perf_counter() - t
        s = curve_summary(rr.curve)
        s.update(seconds=dt, selection=sel, distribution=dist, e_x="reduced")
        curves[f"{sel} x {dist}"] = s
        if (sel, dist) == ("exitance-elimination", "distance"):
            default_curve = rr.curve
        print(f"reduce {sel} x {dist}: {dt:.3f} s, {len(rr.curve)} points, best positive {s['best_positive']}, "
              f"best positive <= 3 lights {s['best_positive_le3']}", flush=True)
    # the paper's pipeline: svd e_x (paper formulation) + exitance-elimination + distance
    ps, rs = solves[("svd", "auto")]
    t = time.perf_counter()
    rr = reduce_lights(ps, rs.exitance, "exitance-elimination", "distance")
    dt = time.perf_counter() - t
    s = curve_summary(rr.curve)
    s.update(seconds=dt, selection="exitance-elimination", distribution="distance", e_x="svd")
    curves["exitance-elimination x distance (svd e_x)"] = s
    paper_curve = rr.curve
    print(f"reduce from svd e_x, exitance-elimination x distance: {dt:.3f} s, best positive <= 3 "
          f"{s['best_positive_le3']}", flush=True)
    out["curves"] = curves
    nn = solves[("nnls", "auto")][1]
    out["nnls_point"] = {"n_lights": int((nn.exitance.max(axis=1) > 0).sum()), "error": nn.error,
                         "relative_error": nn.relative_error, "seconds": rows[3]["seconds"]}
    out["paper_points"] = {
        "reduced": {"e_x": point_at(default_curve, len(p.candidates)), "100": point_at(default_curve, 100),
                    "3": point_at(default_curve, 3)},
        "svd": {"e_x": point_at(paper_curve, len(ps.candidates)), "100": point_at(paper_curve, 100),
                "3": point_at(paper_curve, 3)},
    }
    out["load"].append(uptime())

    # 3. ComputeError: Gauss-Seidel (warm start) vs T, on the first gs_points points of the default curve
    def first(k):
        count = [0]

        def cancel():
            count[0] += 1
            return count[0] >= k
        return cancel

    k = args.gs_points
    t = time.perf_counter()
    rt = reduce_lights(p, r.exitance, "exitance-elimination", "distance", cancel=first(k))
    t_t = time.perf_counter() - t
    t = time.perf_counter()
    rg = reduce_lights(p, r.exitance, "exitance-elimination", "distance", error_route="gauss-seidel",
                       cancel=first(k))
    t_g = time.perf_counter() - t
    rc = reduce_lights(p, r.exitance, "exitance-elimination", "distance", error_route="gauss-seidel",
                       gs_compare_cold=True, cancel=first(k))
    dev = max(abs(a.error - g.error) for a, g in zip(rt.curve, rg.curve)) / p.target_norm
    warm, cold = sum(rc.gs_iterations[1:]), sum(rc.gs_cold_iterations[1:])  # the first point is cold in both
    out["compute_error"] = {"points": len(rg.curve), "transfer_s": t_t, "gauss_seidel_s": t_g,
                            "ratio": t_g / t_t, "max_diff_rel": dev, "warm_sweeps": warm, "cold_sweeps": cold,
                            "saving": 1 - warm / cold}
    print(f"ComputeError on {len(rg.curve)} points: T {t_t:.3f} s, Gauss-Seidel warm {t_g:.3f} s "
          f"({t_g / t_t:.0f}x); max diff {dev:.1e} of ||b_P||; sweeps warm {warm} vs cold {cold} "
          f"({100 * (1 - warm / cold):.0f}% fewer)", flush=True)
    out["load"].append(uptime())

    # 4. solve end to end through the CLI (subprocess): .blend in, report + .blend out
    if not args.no_cli:
        cli = []
        with tempfile.TemporaryDirectory() as d:
            for i in range(2):
                rep, blend = os.path.join(d, f"r{i}.json"), os.path.join(d, f"o{i}.blend")
                cmd = [sys.executable, "-m", "relight_addon", "solve", str(SCENE), "--report", rep, "--out", blend]
                t = time.perf_counter()
                subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
                wall = time.perf_counter() - t
                with open(rep) as fh:
                    report = json.load(fh)
                cli.append({"wall_s": wall, "timings_s": report["timings_s"], "final": {
                    k: report["final"][k] for k in ("n_lights", "error", "relative_error", "n_negative")},
                    "inverse_relative_error": report["inverse"]["relative_error"]})
                print(f"CLI solve --out: wall {wall:.2f} s, timings_s {report['timings_s']}", flush=True)
        out["cli"] = cli
        out["cli_command"] = (".venv/bin/python -m relight_addon solve sample_blends/staircase_targets.blend "
                              "--report R.json --out OUT.blend")
    out["load"].append(uptime())
    print(f"load average at the end: {uptime()}")
    OUT_JSON.parent.mkdir(exist_ok=True)
    with open(OUT_JSON, "w") as fh:
        json.dump(out, fh, indent=1)
    print(f"wrote {OUT_JSON.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
