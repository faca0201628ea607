"""Every registered selection on several scenes, k = 1 .. 32 lights (issue 8: "choose the defaults
by measurement").

    .venv/bin/python benchmarks/bench_selections.py

Scenes (each built as `relight solve` builds it, model.build_inverse_model with the default estimator):
- staircase, polygon model (the paper's experiment: a light per face, 693 candidates);
- staircase, adaptive model (the default: cells + groups);
- living room (tests/artist_scenes.py, 22k triangles: a cube room of 5 big quads, furniture,
  targets on the floor and the table top), adaptive model;
- the closed-loop room of tests/test_cycles_closed_loop.py (a cube room of 8 x 8 grids, a block,
  two target regions: a floor corner and a red wall), adaptive model.
The paper's heuristics run on single-scale lights (cells: their redistribution needs a
partition), the others on the multi-scale lights; every selection from the same form factors.
Relative error (Eq. 1 / ||b_P||) of the curve point with exactly k lights (or the nearest below),
negatives, power (W) and the wall time of the whole curve; the stop criteria are not applied.
Writes benchmarks/results/bench_selections.json and docs/img/bench_selections.png.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import bpy  # noqa: E402

from relight_addon.blender import blend_files, export
from relight_addon.engine.best_lights import total_power
from relight_addon.pipeline import stages  # noqa: E402
from relight_addon.pipeline.model import build_inverse_model  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.engine.reduction import StopCriteria, reduce_lights  # noqa: E402
from relight_addon.engine.registry import SELECTIONS  # noqa: E402

K = (1, 2, 3, 5, 10, 20, 32)


def scenes():
    yield "staircase (polygon model)", lambda: blend_files.open_blend(str(ROOT / "sample_blends" / "staircase_targets.blend")), "polygon"
    yield "staircase (adaptive)", lambda: blend_files.open_blend(str(ROOT / "sample_blends" / "staircase_targets.blend")), "adaptive"

    def room():
        import artist_scenes

        bpy.ops.wm.read_factory_settings(use_empty=True)
        artist_scenes.living_room(2)
    yield "living room (adaptive)", room, "adaptive"

    def closed_loop_room():
        import test_cycles_closed_loop as t

        path = Path(tempfile.mkdtemp()) / "room.blend"
        t.build_room(path)
        blend_files.open_blend(str(path))
    yield "cube room, 2 target regions (adaptive)", closed_loop_room, "adaptive"


def at_k(curve, k):
    pts = [p for p in curve if p.n_lights <= k]
    if not pts:
        return None
    best = max(p.n_lights for p in pts)
    return min((p for p in pts if p.n_lights == best), key=lambda p: p.error)


def main():
    out = {"command": "benchmarks/bench_selections.py", "load": os.getloadavg(), "scenes": []}
    for name, build, model_name in scenes():
        build()
        exp = export.export_scene()
        rows = []
        models = {}
        for sel in SELECTIONS:
            multi = sel.traits.multiscale
            if multi not in models:
                opts = JobOptions(patch_model=model_name, selection=sel.name,
                                  tolerance=0.1 if sel.traits.needs_tolerance else None).validate()
                models[multi] = build_inverse_model(exp.faces, opts, exp.settings.get("max_patch_size"))
                models[multi].problem.transfer  # noqa: B018
            m = models[multi]
            opts = JobOptions(patch_model=model_name, selection=sel.name,
                              tolerance=0.1 if sel.traits.needs_tolerance else None).validate()
            e_x, _ = stages.solve_stage(m, opts)
            t0 = time.perf_counter()
            red = reduce_lights(m.problem, e_x, sel.bind(opts), "distance", StopCriteria(max_lights=32),
                                max_steps=32 if sel.name == "error-construction" else None)
            seconds = time.perf_counter() - t0
            row = {"selection": sel.name, "lights": int(m.problem.n_lights), "seconds": seconds, "by_k": {}}
            for k in K:
                p = at_k(red.curve, k)
                if p is not None:
                    row["by_k"][k] = {"n_lights": p.n_lights, "relative_error": p.relative_error,
                                      "n_negative": p.n_negative, "power": total_power(p.exitance, m.problem.light_watts, p.lights)}
            rows.append(row)
            r3 = row["by_k"].get(3)
            print(f"{name:42s} {sel.name:22s} {m.problem.n_lights:5d} lights {seconds:7.2f} s  k=3: "
                  f"{'-' if r3 is None else round(r3['relative_error'], 4)}"
                  f"{'' if r3 is None or not r3['n_negative'] else ' (negatives)'}", flush=True)
        out["scenes"].append({"scene": name, "patch_model": model_name, "rows": rows})
    os.makedirs(ROOT / "benchmarks" / "results", exist_ok=True)
    (ROOT / "benchmarks" / "results" / "bench_selections.json").write_text(json.dumps(out, indent=1))
    plot(out)


def plot(out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(out["scenes"])
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4), sharey=True)
    for ax, sc in zip(np.atleast_1d(axes), out["scenes"]):
        for row in sc["rows"]:
            ks = sorted(int(k) for k in row["by_k"])
            if not ks:
                continue
            err = [max(row["by_k"][k]["relative_error"], 1e-3) for k in ks]
            style = "-" if SELECTIONS[row["selection"]].traits.paper else "--"
            ax.plot(ks, err, style, marker="o", ms=3, label=row["selection"])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(sc["scene"], fontsize=9)
        ax.set_xlabel("lights")
        ax.grid(True, which="both", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("relative error (Eq. 1 / ||b_P||)")
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "img" / "bench_selections.png", dpi=100)


if __name__ == "__main__":
    main()
