"""Fewer, better lights (issue 8): every k-light method on the staircase, k = 1 .. 32.

    .venv/bin/python benchmarks/bench_best_lights.py [--repeat 3] [--k-max 32]

Scene: sample_blends/staircase_targets.blend, built as ``relight solve`` builds it
(jobs.run_solve: automatic form-factor quality, seed 0, a light is a whole face; 44 target
faces, 693 candidate lights). Methods, all on the same InverseProblem:
- the paper's 4 selections x distance distribution (reduction.reduce_lights from the
  reduced solver's e_x, the CLI default), error-construction limited to k_max steps;
- nnls-greedy (reduction.reduce_lights, k_max steps);
- engine.best_lights.best_k_curve: greedy error-scored, greedy correlation-scored, each
  followed by the swap search (from every start, the default, or the best start only), and
  both scores (the defaults otherwise: exhaustive start where C(n, k) is small, here k = 1
  only);
- the certificate (lower_bounds: exact optimum for k <= 2, the NNLS floor beyond) and the
  tolerance LP at a few tolerances.
Reports the wall time of each full curve (min and median of --repeat runs, and the process
CPU time, steadier on a shared machine; the paper's curves once, they are the slow ones) and the relative error (Eq. 1 / ||b_P||) at
k = 1, 3, 5, 10, 32; writes benchmarks/results/bench_best_lights.json and the chart
docs/img/bench_best_lights.png (relative error vs k, log y).

On a loaded 2-core machine, OpenBLAS's second thread costs more than it gives on these small
products (a 693 x 30 matrix-vector product: 7 us single-threaded, 130 us with 2 threads under
load); ``OPENBLAS_NUM_THREADS=1`` before the run measures the methods without that contention
(the JSON records the setting).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
from relight_addon.engine import best_lights as bl  # noqa: E402
from relight_addon.engine.inverse import InverseProblem, solve_inverse  # noqa: E402

SCENE = ROOT / "sample_blends" / "staircase_targets.blend"
OUT_JSON = ROOT / "benchmarks" / "results" / "bench_best_lights.json"
OUT_PNG = ROOT / "docs" / "img" / "bench_best_lights.png"
REPORT_K = (1, 3, 5, 10, 32)

_CACHE = {}


def staircase_problem():
    """The staircase's InverseProblem as jobs.run_solve builds it (cached per process)."""
    if "p" not in _CACHE:
        from relight_addon.blender import blend_files, export
        from relight_addon.pipeline.model import build_inverse_model
        from relight_addon.engine.options import NO_LAMPS, JobOptions

        blend_files.open_blend(str(SCENE))
        exp = export.export_scene()
        # the paper's experiment: a patch and a light per polygon (the polygon model), no candidate lamp
        model = build_inverse_model(exp.faces, JobOptions(patch_model="polygon", seed=0, **NO_LAMPS).validate(),
                                    exp.settings.get("max_patch_size"))
        prob = model.problem
        prob.transfer  # noqa: B018 (computes and caches T)
        _CACHE["p"] = prob
    return _CACHE["p"]


def uptime():
    with open("/proc/loadavg") as fh:
        return " ".join(fh.read().split()[:3])


def per_k_from_reduction(curve, k_max, norm):
    """Relative error, negatives and power of the curve point with exactly k lights (the first one on
    the curve), or when the curve has none (nnls-greedy drops lights its refit switches off), of its
    point with the most lights below k."""
    by_n = {}
    for p in curve:
        if p.n_lights <= k_max and p.n_lights not in by_n:
            by_n[p.n_lights] = p
    rel, neg, power = [], [], []
    for k in range(1, k_max + 1):
        below = [n for n in by_n if n <= k]
        p = by_n[max(below)] if below else None
        rel.append(None if p is None else float(p.error / norm))
        neg.append(None if p is None else int(p.n_negative))
        power.append(None if p is None else float(np.sum(p.exitance.sum(1) * AREA[p.lights])))
    return rel, neg, power


AREA = None


def main():
    global AREA
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3, help="runs of each new method (min and median reported)")
    ap.add_argument("--k-max", type=int, default=32)
    args = ap.parse_args()
    K = args.k_max
    out = {"command": "benchmarks/bench_best_lights.py " + " ".join(sys.argv[1:]), "load": [uptime()],
           "env": {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}}
    t = time.perf_counter()
    prob = staircase_problem()
    T, b, AREA = prob.transfer, prob.b_target, prob.light_area
    norm = prob.target_norm
    print(f"staircase: {prob.m} targets, {prob.n_lights} candidate lights, ||b|| = {norm:.4g} W/m^2 "
          f"(set-up {time.perf_counter() - t:.1f} s); load {uptime()}", flush=True)
    out["scene"] = {"targets": prob.m, "lights": prob.n_lights, "target_norm": norm}
    methods = {}

    # the paper's selections and nnls-greedy (reduction.reduce_lights), from the reduced e_x
    from relight_addon.engine.reduction import reduce_lights

    inv = solve_inverse(prob, "reduced")
    for sel in ("exitance-elimination", "exitance-construction", "error-elimination", "error-construction",
                "nnls-greedy"):
        t = time.perf_counter()
        red = reduce_lights(prob, inv.exitance, sel, "distance",
                            max_steps=K if sel in ("error-construction", "nnls-greedy") else None)
        dt = time.perf_counter() - t
        rel, neg, power = per_k_from_reduction(red.curve, K, norm)
        name = sel if sel == "nnls-greedy" else f"{sel} x distance (paper)"
        methods[name] = {"seconds": [dt], "relative_error": rel, "n_negative": neg, "power": power,
                         "kind": "reduction"}
        print(f"{name}: {dt:.3f} s", flush=True)

    # the new methods
    variants = {
        "greedy, error-scored": dict(swap=False, score="error"),
        "greedy, correlation-scored": dict(swap=False, score="correlation"),
        "greedy + swap from the best start, error-scored": dict(swap=True, score="error", swap_all=False),
        "greedy + swap, error-scored (default)": dict(swap=True, score="error"),
        "greedy + swap, correlation-scored": dict(swap=True, score="correlation"),
        "greedy + swap, both scores": dict(swap=True, score="both"),
    }
    bl.best_k_curve(T, b, 3, AREA)  # warm-up (first-call costs are not the method's)
    for name, kw in variants.items():
        secs, cpu = [], []
        for _ in range(max(1, args.repeat)):
            st = {}
            t, c0 = time.perf_counter(), time.process_time()
            curve = bl.best_k_curve(T, b, K, AREA, stats=st, **kw)
            secs.append(time.perf_counter() - t)
            cpu.append(time.process_time() - c0)
        methods[name] = {"seconds": secs, "cpu_seconds": cpu, "relative_error": [p.relative_error for p in curve],
                         "n_negative": [0] * len(curve), "power": [p.power for p in curve],
                         "n_lights": [p.n_lights for p in curve], "lights_k3": curve[2].lights.tolist(),
                         "stats": st, "kind": "best_lights", "options": kw}
        print(f"{name}: min {min(secs):.3f} s, median {np.median(secs):.3f} s (CPU min {min(cpu):.3f} s); k=3 {curve[2].relative_error:.4f}, "
              f"k=32 {curve[-1].relative_error:.4f}; {st}", flush=True)

    # the certificate
    t = time.perf_counter()
    lb = bl.lower_bounds(T, b, K)
    t_lb = time.perf_counter() - t
    out["lower_bounds"] = {"seconds": t_lb, "relative": lb.relative.tolist(), "exact": lb.exact.tolist(),
                           "nnls_relative": lb.nnls_relative,
                           "optimum_lights": [None if s is None else s.tolist() for s in lb.optimum_lights]}
    print(f"lower bounds: {t_lb:.3f} s; exact k = {np.flatnonzero(lb.exact) + 1}; k=1 {lb.relative[0]:.4f}, "
          f"k=2 {lb.relative[1]:.4f}, NNLS floor {lb.nnls_relative:.4f}", flush=True)
    # the exact optimum as a start (what a caller can pass from the certificate)
    t = time.perf_counter()
    curve = bl.best_k_curve(T, b, K, AREA, initial=lb.optimum_lights)
    dt = time.perf_counter() - t
    methods["greedy + swap + exact starts (k <= 2)"] = {
        "seconds": [dt], "relative_error": [p.relative_error for p in curve], "n_negative": [0] * len(curve),
        "power": [p.power for p in curve], "kind": "best_lights", "note": "plus lower_bounds' time"}

    # the tolerance LP
    lp = []
    for tol in (0.1, 0.2, 0.3, 0.5):
        t = time.perf_counter()
        r = bl.least_power_within_tolerance(T, b, AREA, tol)
        dt = time.perf_counter() - t
        lp.append({"tolerance": tol, "seconds": dt, "status": r.status, "n_lights": r.n_lights, "power": r.power,
                   "max_deviation": r.max_deviation, "relative_error": r.relative_error,
                   "reachable_tolerance": r.reachable_tolerance, "message": r.message})
        print(f"LP +-{tol:.0%}: {dt:.3f} s, {r.message}; rel. error {r.relative_error:.3f}", flush=True)
    out["tolerance_lp"] = lp
    out["methods"] = methods
    out["load"].append(uptime())

    # table
    print()
    head = " | ".join(f"k = {k}" for k in REPORT_K)
    print(f"| method | full curve k = 1..{K} (s) | {head} | power at k = 3 (W) |")
    print("|---|---|" + "---|" * len(REPORT_K) + "---|")
    for name, m in methods.items():
        secs = m["seconds"]
        ts = f"{min(secs):.3f}" if len(secs) == 1 else f"{min(secs):.3f} (median {np.median(secs):.3f})"
        if "cpu_seconds" in m:
            ts += f", CPU {min(m['cpu_seconds']):.3f}"
        cells = []
        for k in REPORT_K:
            v = m["relative_error"][k - 1] if k <= len(m["relative_error"]) else None
            ng = m["n_negative"][k - 1] if k <= len(m["n_negative"]) else None
            cells.append("-" if v is None else f"{v:.3f}" + (f" ({ng} neg.)" if ng else ""))
        pw = m["power"][2] if len(m["power"]) > 2 else None
        print(f"| {name} | {ts} | " + " | ".join(cells) + f" | {'-' if pw is None else f'{pw:.4g}'} |")
    cells = [f"{lb.relative[k - 1]:.3f}{' (exact)' if lb.exact[k - 1] else ''}" for k in REPORT_K]
    print(f"| lower bound (certificate) | {t_lb:.3f} | " + " | ".join(cells) + " | - |")
    print(f"\nload average: {out['load']}")

    OUT_JSON.parent.mkdir(exist_ok=True)
    with open(OUT_JSON, "w") as fh:
        json.dump(out, fh, indent=1)
    print(f"wrote {OUT_JSON.relative_to(ROOT)}")
    plot(out, K)


def plot(out, K):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5.5))
    ks = np.arange(1, K + 1)
    styles = {"reduction": dict(ls="--", lw=1.2), "best_lights": dict(ls="-", lw=1.8)}
    for name, m in out["methods"].items():
        y = np.array([np.nan if v is None else v for v in m["relative_error"]], dtype=float)[:K]
        neg = np.array([0 if v is None else v for v in m["n_negative"]])[:K]
        line, = ax.plot(ks[:len(y)], y, label=name, marker="o" if m["kind"] == "best_lights" else None, ms=3,
                        **styles[m["kind"]])
        if (neg > 0).any():  # configurations with negative lights: hollow markers
            ax.plot(ks[:len(y)][neg > 0], y[neg > 0], "o", mfc="none", color=line.get_color(), ms=5)
    lbd = out["lower_bounds"]
    ax.plot(ks, lbd["relative"][:K], color="k", lw=1, ls=":", label="lower bound (exact for k <= 2, then NNLS floor)")
    ax.set_yscale("log")
    ax.set_xlabel("number of lights k")
    ax.set_ylabel("relative error  ||T e - b|| / ||b||")
    ax.set_title("Staircase (693 candidate lights, 44 targets): best k-light configurations\n"
                 "dashed: the paper's reductions and nnls-greedy; hollow markers: negative lights", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper right")
    fig.tight_layout()
    OUT_PNG.parent.mkdir(exist_ok=True)
    fig.savefig(OUT_PNG, dpi=110)
    print(f"wrote {OUT_PNG.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
