"""Accuracy against time of the transport from light cells to target patches: the kernel
estimator (engine/kernel_transfer.py) vs hemisphere ray casting (engine/formfactors.py).

    .venv/bin/python benchmarks/bench_kernel_transfer.py [--quick] [--ref-rays 22]

Scenes
(a) the staircase sample (sample_blends/staircase_targets.blend, loaded through export.py as
    bench_staircase.py does): its target patches x its candidate patches;
(b) a furnished room built here: 4 x 3 x 2.5 m, every surface meshed into 0.25 m cells, a table
    (top and four legs) and a sofa (seat, back, arms) of boxes; targets: the floor cells around and
    under the table and the table top; sources: the ceiling cells.

Metric: the direct light of each target, D_r = sum_s F_rs E_s, for
  "all": every source lit at the same exitance, and
  "few": 8 random sources lit (20 draws; the few-lights case that a solve ends with);
per-target relative error against the reference, RMS over the targets (targets with
D_ref >= 5 % of the mean only, for "few"; mean over the draws). The reference is an independent
hemisphere estimate of the target rows with 2^ref_rays (default 2^22) rays per target patch;
the reference is the mean of two such estimates (seeds apart) and its own noise is measured
from their difference; the chart shows the raw error (reference noise included, dotted line),
the JSON also the error with the reference's variance subtracted ("corrected").

Estimators, several quality levels each, timed on the same machine in one run:
- "hemisphere (full F)": compute_form_factors at N rays per patch, the whole scene: what a
  solve pays today to get these rows;
- "hemisphere (target rows)": rays shot from the target patches only (the cheapest ray-cast
  route to these rows; formfactors._Tracer with one chunk per target);
- "kernel": kernel_form_factors on targets x sources at several settings (a solve still needs
  the full F for the rest of the matrix: the "hemisphere (full F)" row marked auto).
Two seeds per setting (one for the two slowest kernel levels), run seed by seed.

Writes benchmarks/results/bench_kernel_transfer.json and docs/img/bench_kernel_transfer.png.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from relight_addon.engine.formfactors import _Tracer, auto_rays_per_patch, compute_form_factors  # noqa: E402
from relight_addon.engine.kernel_transfer import kernel_form_factors  # noqa: E402
from relight_addon.engine.scene import mesh_patches, polygon_faceset  # noqa: E402

SCENE = ROOT / "sample_blends" / "staircase_targets.blend"
OUT_JSON = ROOT / "benchmarks" / "results" / "bench_kernel_transfer.json"
OUT_PNG = ROOT / "docs" / "img" / "bench_kernel_transfer.png"

#: kernel settings, cheapest first: (label, keyword arguments of kernel_form_factors)
KERNEL_LEVELS = [
    ("k1", dict(points_per_patch=4, shadow_rays=1, penumbra_points=16, penumbra_rays=1)),
    ("k2", dict(points_per_patch=8, shadow_rays=2, penumbra_points=64, penumbra_rays=2)),
    ("k3", dict(points_per_patch=16, shadow_rays=4, penumbra_points=144, penumbra_rays=2)),
    ("k4 (default)", dict()),  # 100 penumbra points x 2 rays
    ("k4-64x4", dict(penumbra_points=64, penumbra_rays=4)),
    ("k4-256x4 (before)", dict(penumbra_points=256, penumbra_rays=4)),  # the default until issue 7's staircase work
    ("k5", dict(points_per_patch=16, shadow_rays=8, penumbra_points=1024, penumbra_rays=8)),
    ("k6", dict(points_per_patch=32, shadow_rays=8, penumbra_points=2048, penumbra_rays=8)),
]
FULL_RAYS = [1024, 2048, 4096, 16384, 65536]
ROWS_RAYS = [4096, 16384, 65536, 262144]


def uptime():
    with open("/proc/loadavg") as fh:
        return " ".join(fh.read().split()[:3])


# ------------------------------------------------------------------------------------ scenes

def box_polygons_out(x0, x1, y0, y1, z0, z1, skip_bottom=True):
    """The faces of an axis-aligned box, facing outwards (the bottom left out when it rests on the floor)."""
    q = np.array
    faces = [
        q([[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]),  # top, +z
        q([[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]]),  # -y
        q([[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]]),  # +y
        q([[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]]),  # -x
        q([[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]]),  # +x
    ]
    if not skip_bottom:
        faces.append(q([[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]]))  # bottom, -z
    return [f.astype(np.float64) for f in faces]


def furnished_room(cell=0.25):
    """(patches, targets, sources, name) of a 4 x 3 x 2.5 m room, 0.25 m cells."""
    from relight_addon.engine import closed_forms as cf

    sx, sy, sz = 4.0, 3.0, 2.5
    polys = cf.box_polygons((sx, sy, sz))  # floor, ceiling, 4 walls, facing in
    kind = ["floor", "ceiling"] + ["wall"] * 4
    # table: a 1.2 x 0.8 top (5 cm thick) at 0.75 m, four 5 cm legs
    tx0, tx1, ty0, ty1 = 1.2, 2.4, 1.4, 2.2
    top = box_polygons_out(tx0, tx1, ty0, ty1, 0.70, 0.75, skip_bottom=False)
    polys += top
    kind += ["table top"] + ["table"] * (len(top) - 1)
    for lx, ly in ((tx0, ty0), (tx1 - 0.05, ty0), (tx0, ty1 - 0.05), (tx1 - 0.05, ty1 - 0.05)):
        leg = box_polygons_out(lx, lx + 0.05, ly, ly + 0.05, 0.0, 0.70)
        polys += leg
        kind += ["table"] * len(leg)
    # sofa along the y = 0 wall: seat 2.0 x 0.9 x 0.45, back 0.2 thick up to 0.85, arms
    for box in ((1.0, 3.0, 0.05, 0.95, 0.0, 0.45), (1.0, 3.0, 0.05, 0.25, 0.45, 0.85),
                (0.8, 1.0, 0.05, 0.95, 0.0, 0.65), (3.0, 3.2, 0.05, 0.95, 0.0, 0.65)):
        b = box_polygons_out(*box)
        polys += b
        kind += ["sofa"] * len(b)
    fs = polygon_faceset(polys, reflectance=0.5)
    ps = mesh_patches(fs, max_patch_size=cell)
    pk = np.array(kind)[ps.face]
    c = ps.center
    near_table = (c[:, 0] > tx0 - 0.6) & (c[:, 0] < tx1 + 0.6) & (c[:, 1] > ty0 - 0.6) & (c[:, 1] < ty1 + 0.6)
    targets = np.flatnonzero(((pk == "floor") & near_table) | (pk == "table top"))
    sources = np.flatnonzero(pk == "ceiling")
    return ps, targets, sources


def staircase():
    from relight_addon.blender import blend_files, export as bridge

    blend_files.open_blend(str(SCENE))
    exp = bridge.export_scene()
    ps = mesh_patches(exp.faces, exp.settings.get("max_patch_size"))
    return ps, np.flatnonzero(ps.target), np.flatnonzero(~ps.forbidden)


# ------------------------------------------------------------------------------ estimators

def hemisphere_rows(ps, rows, rays, seed, threads):
    """F[rows, :] by hemisphere ray casting from the given patches only (float64, counts / N)."""
    t0 = time.perf_counter()
    tr = _Tracer(ps, int(rays), seed, "sobol")
    P = ps.n_patches
    # one chunk per target patch: shoot from the targets only
    tr.chunks = [(int(r), int(r) + 1) for r in rows]
    out = np.zeros((len(rows), P))

    def work(i):
        key = tr.keys(i)  # receiving patch, P for a miss
        out[i] = np.bincount(key, minlength=P + 1)[:P] / tr.N

    with ThreadPoolExecutor(max_workers=threads) as ex:
        list(ex.map(work, range(len(rows))))
    return out, time.perf_counter() - t0


def direct_errors(F, refs, lightings):
    """Per-target relative error of the direct light D = F @ E against the reference (the mean
    of two independent estimates ``refs``), RMS over the targets, mean over the lightings'
    draws: ``raw``; the reference's own noise from the two estimates' difference,
    Var(mean) ~ (D_a - D_b)^2 / 4 (``ref_noise``, RMS relative); ``corrected`` = sqrt(raw^2 -
    ref_noise^2) (0 when negative). ``lightings``: name -> list of exitance vectors."""
    ref = 0.5 * (refs[0] + refs[1])
    out = {}
    for name, Es in lightings.items():
        raw, noise, mx = [], [], []
        for E in Es:
            d, dr = F @ E, ref @ E
            keep = dr >= (0.05 * dr.mean() if name != "all" else 0) + 1e-300
            rel2 = ((d[keep] - dr[keep]) / dr[keep]) ** 2
            var = ((refs[0][keep] @ E - refs[1][keep] @ E) / 2) ** 2 / dr[keep] ** 2
            raw.append(rel2.mean())
            noise.append(var.mean())
            mx.append(np.sqrt(rel2.max()))
        r, v = float(np.mean(raw)), float(np.mean(noise))
        out[name + "_raw"] = float(np.sqrt(r))
        out[name + "_ref_noise"] = float(np.sqrt(v))
        out[name] = float(np.sqrt(max(r - v, 0.0)))
        out[name + "_max"] = float(np.mean(mx))
    return out


def run_scene(name, ps, targets, sources, args, threads):
    print(f"\n== {name}: {ps.n_patches} patches, {len(targets)} targets x {len(sources)} sources; "
          f"load {uptime()}", flush=True)
    rng = np.random.default_rng(7)
    few = []
    for _ in range(20):
        E = np.zeros(len(sources))
        E[rng.choice(len(sources), min(8, len(sources)), replace=False)] = 1.0
        few.append(E)
    lightings = {"all": [np.ones(len(sources))], "few": few}
    N_ref = 1 << args.ref_rays
    t = time.perf_counter()
    refs = [hemisphere_rows(ps, targets, N_ref, seed=sd, threads=threads)[0][:, sources] for sd in (987654, 192837)]
    t_ref = time.perf_counter() - t
    print(f"reference: 2 x {N_ref} rays per target, {t_ref:.1f} s", flush=True)
    res = {"patches": int(ps.n_patches), "targets": int(len(targets)), "sources": int(len(sources)),
           "reference_rays_per_target": N_ref, "reference_s": t_ref, "runs": []}

    def record(method, label, seconds, F, extra=None):
        e = direct_errors(F, refs, lightings)
        row = {"method": method, "label": label, "seconds": seconds, **e, **(extra or {})}
        res["runs"].append(row)
        print(f"{method:26s} {label:14s} {seconds:7.2f} s   all {100 * e['all_raw']:6.3f} % (corrected "
              f"{100 * e['all']:.3f}, ref {100 * e['all_ref_noise']:.3f})   few {100 * e['few_raw']:6.3f} % (corrected "
              f"{100 * e['few']:.3f}, ref {100 * e['few_ref_noise']:.3f})", flush=True)

    seeds = (0,) if args.quick else (0, 1)
    auto = auto_rays_per_patch(ps.n_patches)
    res["auto_rays_per_patch"] = auto
    full = FULL_RAYS if not args.quick else FULL_RAYS[:3]
    rows = ROWS_RAYS if not args.quick else ROWS_RAYS[:2]
    levels = KERNEL_LEVELS if not args.quick else KERNEL_LEVELS[:4]
    for s in seeds:  # seed by seed, so that load changes hit every method
        for N in full:
            ff = compute_form_factors(ps, N, seed=s, threads=threads)
            F = np.asarray(ff.matrix[np.ix_(targets, sources)], dtype=np.float64)
            record("hemisphere (full F)", f"{N}{' (auto)' if N == auto else ''}", ff.seconds, F, {"rays_per_patch": N})
        for N in rows:
            R, dt = hemisphere_rows(ps, targets, N, seed=s, threads=threads)
            record("hemisphere (target rows)", str(N), dt, R[:, sources], {"rays_per_patch": N})
        for label, kw in levels:
            if s > 0 and label in ("k5", "k6"):
                continue  # the slowest levels once
            st = {}
            t = time.perf_counter()
            K = kernel_form_factors(ps, targets, sources, seed=s, threads=threads, stats=st, **kw)
            dt = time.perf_counter() - t
            record("kernel", label, dt, K, {"settings": kw, "stats": st})
        res.setdefault("load", []).append(uptime())
    return res


def plot(out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(out["scenes"])
    fig, axes = plt.subplots(2, len(scenes), figsize=(6 * len(scenes), 8.5), squeeze=False)
    style = {"hemisphere (full F)": ("C0", "o"), "hemisphere (target rows)": ("C2", "s"), "kernel": ("C3", "^")}
    for j, sc in enumerate(scenes):
        d = out["scenes"][sc]
        for i, metric in enumerate(("all", "few")):
            ax = axes[i, j]
            for method, (color, marker) in style.items():
                rows = [r for r in d["runs"] if r["method"] == method]
                labels = list(dict.fromkeys(r["label"] for r in rows))
                xs = [np.mean([r["seconds"] for r in rows if r["label"] == lb]) for lb in labels]
                ys = [np.mean([r[metric + "_raw"] for r in rows if r["label"] == lb]) for lb in labels]
                ax.plot(xs, ys, "-" + marker, color=color, label=method)
                for x, y, lb in zip(xs, ys, labels):
                    ax.annotate(lb.replace(" (default)", "*").replace(" (auto)", "*"), (x, y), fontsize=7,
                                xytext=(3, 3), textcoords="offset points")
            ax.axhline(0.01, color="0.6", lw=0.8, ls="--")
            noise = np.mean([r[metric + "_ref_noise"] for r in d["runs"]])
            ax.axhline(noise, color="k", lw=0.8, ls=":", label="reference's own noise")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("seconds (2 cores)")
            ax.set_ylabel("RMS per-target relative error of direct light")
            what = "all sources lit" if metric == "all" else "8 random sources lit (20 draws)"
            ax.set_title(f"{sc}: {d['targets']} targets x {d['sources']} sources\n{what}", fontsize=10)
            ax.grid(True, which="both", lw=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=8)
    fig.suptitle("Light cells -> target patches: error against time (reference: mean of two independent "
                 f"hemisphere estimates, 2 x 2^{out.get('ref_rays', 22)} rays per target; * = default)", fontsize=10)
    fig.tight_layout()
    OUT_PNG.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT_PNG, dpi=110)
    print(f"wrote {OUT_PNG.relative_to(ROOT)}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer levels and seeds, small reference")
    ap.add_argument("--ref-rays", type=int, default=22, help="log2 of the reference's rays per target")
    ap.add_argument("--scenes", default="staircase,room")
    ap.add_argument("--plot-only", action="store_true")
    args = ap.parse_args()
    if args.plot_only:
        plot(json.loads(OUT_JSON.read_text()))
        return
    if args.quick and args.ref_rays == 22:
        args.ref_rays = 19
    threads = os.cpu_count() or 1
    out = {"command": "benchmarks/bench_kernel_transfer.py " + " ".join(sys.argv[1:]), "threads": threads,
           "ref_rays": args.ref_rays,
           "load": [uptime()], "scenes": {}}
    for sc in args.scenes.split(","):
        if sc == "staircase":
            ps, tg, src = staircase()
            out["scenes"]["staircase"] = run_scene("staircase", ps, tg, src, args, threads)
        elif sc == "room":
            ps, tg, src = furnished_room()
            out["scenes"]["furnished room"] = run_scene("furnished room", ps, tg, src, args, threads)
        else:
            raise SystemExit(f"unknown scene {sc!r}")
        out["load"].append(uptime())
    OUT_JSON.parent.mkdir(exist_ok=True)
    OUT_JSON.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT_JSON.relative_to(ROOT)}")
    plot(out)


if __name__ == "__main__":
    main()
