"""The staircase's mathematical phase (form factors + inverse): time against the accuracy of what
the solve predicts, for the estimator settings that decide it (issue 7's <= 0.5 s goal, issue 9's
accuracy).

    .venv/bin/python benchmarks/bench_staircase_math.py [--seeds 8]

Scene: sample_blends/staircase_targets.blend through export.py and jobs.run_solve with the
defaults (adaptive patches, Best k Lights), as `relight solve` runs it.

Reference: the same patches and lights with 65,536 hemisphere rays per patch and the kernel
estimator at 4,096 penumbra points x 4 rays (seed 11, independent of the runs): its light-to-target
transfer T_ref (targets x lights, per channel).

Per variant and seed (1 .. seeds; variants interleaved seed by seed so that load changes hit all):
- "math s": the report's form_factors + inverse seconds (median over the seeds);
- "true error": the final configuration's relative error (Eq. 1 / ||b||) evaluated with T_ref:
  how good the lights the run chose really are;
- "prediction": || T e - T_ref e || / || T_ref e || for the final configuration e: how far what the
  run predicts for its own lights is from the reference;
- "1 light", "3 lights": the same prediction error for 100 random single lights and 100 random
  sets of 3 lights at equal exitance (mean): the transfer's accuracy light by light.

Variants: the estimator ("kernel" default, "raycast"), rays per patch (auto on these 943 patches:
2048 with the kernel's pairs, 4096 for ray casting alone), the kernel's penumbra points, and the reciprocity of the hemisphere estimate
("weighted", the default, or "rays": each row from its own rays, as before this benchmark).

Writes benchmarks/results/bench_staircase_math.json and docs/img/bench_staircase_math.png.
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from relight_addon.blender import blend_files, export
from relight_addon.pipeline import jobs  # noqa: E402
from relight_addon.engine import formfactors, kernel_transfer  # noqa: E402
from relight_addon.engine.estimators import kernel as kernel_estimator  # noqa: E402
from relight_addon.engine.estimators import raycast as raycast_estimator  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402

SCENE = ROOT / "sample_blends" / "staircase_targets.blend"
OUT_JSON = ROOT / "benchmarks" / "results" / "bench_staircase_math.json"
OUT_PNG = ROOT / "docs" / "img" / "bench_staircase_math.png"

#: (label, estimator, rays per patch (None: auto), (penumbra points, rays each), reciprocity)
VARIANTS = [
    ("kernel, 4096 rays, 256 penumbra pts x 4 rays, rays (the defaults before)", "kernel", 4096, (256, 4), "rays"),
    ("kernel, 4096 rays, 256 penumbra pts x 4 rays, weighted", "kernel", 4096, (256, 4), "weighted"),
    ("kernel, 2048 rays, 256 penumbra pts x 4 rays, weighted", "kernel", 2048, (256, 4), "weighted"),
    ("kernel, auto (2048), 64 penumbra pts x 4 rays, weighted", "kernel", None, (64, 4), "weighted"),
    ("kernel, 4096 rays, 100 penumbra pts x 2 rays, weighted", "kernel", 4096, (100, 2), "weighted"),
    ("kernel, auto (2048), 100 penumbra pts x 2 rays, weighted (default)", "kernel", None, (100, 2), "weighted"),
    ("raycast, 4096 rays, rays (before)", "raycast", 4096, None, "rays"),
    ("raycast, auto (4096), weighted (default)", "raycast", None, None, "weighted"),
]


def uptime():
    with open("/proc/loadavg") as fh:
        return " ".join(fh.read().split()[:3])


@contextlib.contextmanager
def settings(reciprocity, penumbra):
    """The estimators' compute_form_factors with this reciprocity, the kernel with these penumbra (points, rays)."""
    saved = (kernel_estimator.compute_form_factors, raycast_estimator.compute_form_factors,
             kernel_transfer.kernel_form_factors)
    cff = functools.partial(formfactors.compute_form_factors, reciprocity=reciprocity)
    kernel_estimator.compute_form_factors = raycast_estimator.compute_form_factors = cff
    if penumbra is not None:
        kernel_transfer.kernel_form_factors = functools.partial(saved[2], penumbra_points=penumbra[0],
                                                                penumbra_rays=penumbra[1])
    try:
        yield
    finally:
        kernel_estimator.compute_form_factors, raycast_estimator.compute_form_factors, \
            kernel_transfer.kernel_form_factors = saved


def transfer(problem):
    return np.stack([np.asarray(t.todense() if hasattr(t, "todense") else t) for t in problem.transfer])


def prediction_error(T, T_ref, lights, e):
    a = np.einsum("cmn,nc->mc", T[:, :, lights], e)
    b = np.einsum("cmn,nc->mc", T_ref[:, :, lights], e)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=8)
    args = ap.parse_args()
    blend_files.open_blend(str(SCENE))
    exp = export.export_scene()
    inputs = export.job_inputs(exp)

    def solve(estimator, rays, penumbra, reciprocity, seed):
        with settings(reciprocity, penumbra):
            return jobs.run_solve(exp.faces, JobOptions(estimator=estimator, rays_per_patch=rays, seed=seed), **inputs)

    load = [uptime()]
    t0 = time.perf_counter()
    ref = solve("kernel", 65536, (4096, 4), "weighted", 11)
    t_ref = time.perf_counter() - t0
    T_ref = transfer(ref.problem)
    n = T_ref.shape[2]
    rng = np.random.default_rng(3)
    singles = [rng.choice(n, 1) for _ in range(100)]
    triples = [rng.choice(n, 3, replace=False) for _ in range(100)]
    rows = {v[0]: [] for v in VARIANTS}
    for seed in range(1, args.seeds + 1):
        for label, estimator, rays, penumbra, reciprocity in VARIANTS:
            out = solve(estimator, rays, penumbra, reciprocity, seed)
            T = transfer(out.problem)
            fin = out.reduction.final
            e = np.asarray(fin.exitance, dtype=np.float64).reshape(-1, 3)
            b = out.problem.b_target
            true = np.linalg.norm(np.einsum("cmn,nc->mc", T_ref[:, :, fin.lights], e) - b) / np.linalg.norm(b)
            t = out.report["timings_s"]
            rows[label].append({
                "seed": seed, "math_s": t["form_factors"] + t["inverse"], "form_factors_s": t["form_factors"],
                "inverse_s": t["inverse"], "rays_per_patch": out.report["options"]["rays_per_patch"],
                "n_lights": fin.n_lights, "predicted_error": fin.relative_error, "true_error": float(true),
                "prediction": prediction_error(T, T_ref, fin.lights, e),
                "one_light": float(np.mean([prediction_error(T, T_ref, c, np.ones((1, 3))) for c in singles])),
                "three_lights": float(np.mean([prediction_error(T, T_ref, c, np.ones((3, 3))) for c in triples])),
            })
        print(f"seed {seed} done, load {uptime()}", flush=True)
    load.append(uptime())
    summary = []
    for label, *_ in VARIANTS:
        r = rows[label]
        summary.append({"variant": label, "math_s_median": float(np.median([x["math_s"] for x in r])),
                        **{k: float(np.mean([x[k] for x in r])) for k in
                           ("true_error", "prediction", "one_light", "three_lights")}})
    print(f"\nstaircase, {ref.patches.n_patches} patches, {n} lights; reference {t_ref:.1f} s; "
          f"{args.seeds} seeds; load {load[0]} -> {load[1]}")
    print("| variant | math s (median) | true error | prediction | 1 light | 3 lights |")
    print("|---|---|---|---|---|---|")
    for s in summary:
        print(f"| {s['variant']} | {s['math_s_median']:.3f} | {s['true_error']:.4f} | {s['prediction'] * 100:.2f} % | "
              f"{s['one_light'] * 100:.2f} % | {s['three_lights'] * 100:.2f} % |")
    OUT_JSON.parent.mkdir(parents=True, exist_ok=True)
    OUT_JSON.write_text(json.dumps({"load": load, "seeds": args.seeds, "patches": int(ref.patches.n_patches),
                                    "lights": int(n), "reference_s": t_ref, "summary": summary, "runs": rows},
                                   indent=1))
    plot(summary)


def plot(summary):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for s in summary:
        marker = "s" if s["variant"].startswith("raycast") else "o"
        ax.scatter(s["math_s_median"], s["prediction"] * 100, marker=marker, s=40)
        ax.annotate(s["variant"].replace(", weighted", ", w").replace(" penumbra pts x ", " pp x "),
                    (s["math_s_median"], s["prediction"] * 100), fontsize=6, xytext=(4, 3),
                    textcoords="offset points")
    ax.axvline(0.5, color="grey", ls=":", lw=1)
    ax.set_xlabel("form factors + inverse, s (median over seeds)")
    ax.set_ylabel("prediction error of the final lights, % (mean)")
    ax.set_yscale("log")
    ax.set_title("Staircase: time against accuracy (reference: 65,536 rays, 4,096 penumbra points)", fontsize=9)
    fig.tight_layout()
    OUT_PNG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT_PNG, dpi=120)


if __name__ == "__main__":
    main()
