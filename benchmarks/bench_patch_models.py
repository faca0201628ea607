"""Patch models: patch count and time against accuracy on the targets (issue 7, part 6).

Scene: tests/artist_scenes.living_room (walls and ceiling one cube of 5 big quads, dense props
with modifiers, default Principled materials). A fixed physical lighting: three rectangles of
light on the Room quads (a 1 x 1 m square in the ceiling, 60/55/50 W/m^2; 1.0 x 0.6 m on the
north wall, 40 W/m^2; 0.7 x 0.7 m on the east wall, 30/30/35 W/m^2). Every model gives each of
its Room patches the exitance of the part of its area inside a rectangle (sampled), then solves
forward; the radiosity of the painted target polygons (floor and table top) is compared with:

- a fine uniform reference: the polygon model at a quarter of the default patch size with
  8192 rays per patch (iterative solves on the sparse F);
- Cycles: the rectangles as one-sided emitting quads (the wall's reflectance) 1 mm in front of
  the walls, no clamping, 64 bounces (tests/cycles_reference.py), a per-face bake of the floor's
  target polygons (BAKED: the table's Bevel modifier gives the bake other faces). With Cycles, every material is made Lambertian first (Specular IOR Level 0,
  cycles_reference.make_lambertian), for the engine as for the bake.

Models: adaptive (refinement passes 0, 1, 2; light size and patch size the defaults, and 2x /
0.5x), uniform polygon models at 1x and 2x the default patch size. Time = meshing + form
factors + problem + forward solve, one process, measured in one run.

    .venv/bin/python benchmarks/bench_patch_models.py [--detail 2] [--no-cycles]

Writes benchmarks/results/bench_patch_models.json and docs/img/bench_patch_models.png.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

import bpy  # noqa: E402

import artist_scenes  # noqa: E402
from relight_addon.blender import export
from relight_addon.pipeline import model as models  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.pipeline.polygons import PolygonMap  # noqa: E402

W, D, H = artist_scenes.ROOM
# (wall normal axis, wall coordinate, the two in-plane axes and their ranges, exitance W/m^2)
RECTS = [
    (2, H, (0, -0.5, 0.5), (1, -0.5, 0.5), (60.0, 55.0, 50.0)),
    (1, D / 2, (0, -1.5, -0.5), (2, 1.5, 2.1), (40.0, 40.0, 40.0)),
    (0, W / 2, (1, 0.0, 0.7), (2, 1.8, 2.5), (30.0, 30.0, 35.0)),
]


def patch_exitance(patches, room_object):
    """(P, 3) W/m^2: each Room patch emits the rectangles' exitance times its area fraction inside them."""
    u, v = np.meshgrid((np.arange(12) + 0.5) / 12, (np.arange(12) + 0.5) / 12)
    keep = u + v < 1
    u, v = u[keep], v[keep]
    tv = patches.tri_vertices
    pts = tv[:, None, 0] + u[None, :, None] * (tv[:, None, 1] - tv[:, None, 0]) + v[None, :, None] * (tv[:, None, 2] - tv[:, None, 0])
    room = patches.object[patches.tri_patch] == room_object
    E = np.zeros((patches.n_patches, 3))
    for axis, coord, (a1, lo1, hi1), (a2, lo2, hi2), e in RECTS:
        inside = ((np.abs(pts[..., axis] - coord) < 1e-6) & (pts[..., a1] > lo1) & (pts[..., a1] < hi1)
                  & (pts[..., a2] > lo2) & (pts[..., a2] < hi2)).mean(axis=1) * room
        frac = np.bincount(patches.tri_patch, weights=inside * patches.tri_area, minlength=patches.n_patches)
        E += (frac / patches.area)[:, None] * np.asarray(e)
    return E


def target_rows(exp, model, B):
    pmap = PolygonMap(exp.faces, model.patches, exp.polygon_counts)
    rows = pmap.split(pmap.mean(B))
    out = {}
    for oi, name in enumerate(exp.faces.object_names):
        sel = (exp.faces.face_object == oi) & exp.faces.target
        if sel.any():
            out[name] = rows[name][np.unique(exp.faces.face_index[sel])]
    return out


def run_model(exp, **kw):
    opts = JobOptions(**kw).validate()
    t0 = time.perf_counter()
    model = models.build_inverse_model(exp.faces, opts, exp.settings.get("max_patch_size"))
    E = patch_exitance(model.patches, exp.faces.object_names.index("Room"))
    B = model.problem.forward_radiosity(E)
    seconds = time.perf_counter() - t0
    return {"patches": int(model.patches.n_patches), "seconds": seconds, "rows": target_rows(exp, model, B),
            "power": float((E * model.patches.area[:, None]).sum()), "rays": int(model.form_factors.rays_per_patch)}


def error(rows, ref):
    e = np.concatenate([np.abs(rows[k] - ref[k]).sum(axis=1) / ref[k].sum(axis=1) for k in ref])
    return float(e.mean()), float(e.max())


#: the target objects Cycles bakes: the floor (the table's Bevel modifier gives the bake faces that are
#: not the base mesh's polygons)
BAKED = ("Floor",)


def cycles_rows(exp, samples):
    """Cycles bake of the target polygons with the three rectangles as emitting quads."""
    import cycles_reference as cr

    room = bpy.data.objects["Room"]
    wall = room.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value[:3]
    for k, (axis, coord, (a1, lo1, hi1), (a2, lo2, hi2), e) in enumerate(RECTS):
        n = np.zeros(3)
        n[axis] = -np.sign(coord)  # into the room
        corners = []
        for p1, p2 in ((lo1, lo2), (hi1, lo2), (hi1, hi2), (lo1, hi2)):
            c = np.zeros(3)
            c[axis], c[a1], c[a2] = coord, p1, p2
            corners.append(c + 1e-3 * n)
        corners = np.array(corners)
        face = [0, 1, 2, 3] if np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ n > 0 else [0, 3, 2, 1]
        mat = cr._material(f"rect{k}", wall, emission=tuple(np.asarray(e) / np.pi), strength=1.0)
        cr.add_mesh_object(f"rect{k}", corners, [face], mat)
    objs = [bpy.data.objects[n] for n in BAKED]
    res = cr.cycles_face_radiance(samples=samples, seed=1, cell_px=12, objects=objs)
    out = {}
    for name in BAKED:
        oi = exp.faces.object_names.index(name)
        sel = (exp.faces.face_object == oi) & exp.faces.target
        idx = np.unique(exp.faces.face_index[sel])
        out[name] = np.pi * res[name].radiance[idx]
        out[name + "_noise"] = float(res[name].rel_noise[idx].mean())
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--detail", type=int, default=2)
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--samples", type=int, default=512)
    args = ap.parse_args()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    artist_scenes.living_room(args.detail)
    if not args.no_cycles:  # Lambertian for the engine as for the bake: the comparison is of the models
        import cycles_reference as cr

        cr.make_lambertian()
    tris = artist_scenes.triangle_count()
    exp = export.export_scene()
    s = float(np.linalg.norm(np.ptp(exp.faces.vertices, axis=0))) / 20  # the default patch size
    print(f"living room, {tris} triangles, default patch size {s:.3f} m", flush=True)
    ref = run_model(exp, patch_model="polygon", max_patch_size=s / 4, rays_per_patch=8192)
    print(f"reference: uniform {s / 4:.3f} m, {ref['patches']} patches, {ref['seconds']:.1f} s", flush=True)
    configs = [
        ("adaptive, no refinement", dict(patch_model="adaptive", refine_passes=0)),
        ("adaptive, 1 refinement pass", dict(patch_model="adaptive", refine_passes=1)),
        ("adaptive, 2 refinement passes", dict(patch_model="adaptive", refine_passes=2)),
        ("adaptive, 0.5x sizes", dict(patch_model="adaptive", refine_passes=0, max_patch_size=s / 2, light_size=s / 2)),
        ("adaptive, 2x sizes", dict(patch_model="adaptive", refine_passes=0, max_patch_size=2 * s, light_size=2 * s)),
        ("uniform polygons, 1x", dict(patch_model="polygon", max_patch_size=s)),
        ("uniform polygons, 2x", dict(patch_model="polygon", max_patch_size=2 * s)),
        ("uniform polygons, 0.5x", dict(patch_model="polygon", max_patch_size=s / 2)),
    ]
    rows = []
    for name, kw in configs:
        r = run_model(exp, **kw)
        m, x = error(r["rows"], ref["rows"])
        rows.append({"model": name, "options": kw, "patches": r["patches"], "seconds": r["seconds"],
                     "rays_per_patch": r["rays"], "error_mean": m, "error_max": x, "power": r["power"]})
        print(f"{name:32s} {r['patches']:6d} patches {r['seconds']:7.2f} s  vs reference: mean {m:.4f} max {x:.4f}",
              flush=True)
    result = {"command": "benchmarks/bench_patch_models.py " + " ".join(sys.argv[1:]), "triangles": tris,
              "patch_size": s, "reference": {"patches": ref["patches"], "seconds": ref["seconds"]},
              "rows": rows, "load": os.getloadavg()}
    if not args.no_cycles:
        cyc = cycles_rows(exp, args.samples)
        ref_vs = error(ref["rows"], {k: cyc[k] for k in BAKED})
        result["cycles"] = {"baked": list(BAKED), "reference_vs_cycles": ref_vs, "noise": [cyc[k + "_noise"] for k in BAKED]}
        print(f"reference vs Cycles ({', '.join(BAKED)}): mean {ref_vs[0]:.4f} max {ref_vs[1]:.4f} (Cycles noise "
              f"{[round(cyc[k + '_noise'], 4) for k in BAKED]})", flush=True)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        artist_scenes.living_room(args.detail)
        cr.make_lambertian()
        exp = export.export_scene()
        for row in rows:
            r = run_model(exp, **row["options"])
            row["cycles_error_mean"], row["cycles_error_max"] = error(r["rows"], {k: cyc[k] for k in BAKED})
            print(f"{row['model']:32s} vs Cycles: mean {row['cycles_error_mean']:.4f} max {row['cycles_error_max']:.4f}",
                  flush=True)
    os.makedirs(os.path.join(ROOT, "benchmarks", "results"), exist_ok=True)
    with open(os.path.join(ROOT, "benchmarks", "results", "bench_patch_models.json"), "w") as fh:
        json.dump(result, fh, indent=1)
    plot(result)


def plot(result):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, label in ((axes[0], "patches", "patches"), (axes[1], "seconds", "seconds (model + form factors + solve)")):
        for r in result["rows"]:
            mk = "o" if r["model"].startswith("adaptive") else "s"
            ax.loglog(r[key], max(r["error_mean"], 1e-4), mk, label=r["model"])
        ax.set_xlabel(label)
        ax.set_ylabel("mean target error vs fine uniform reference")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Living room, {result['triangles']} triangles: accuracy on the targets against model size and time")
    fig.tight_layout()
    fig.savefig(os.path.join(ROOT, "docs", "img", "bench_patch_models.png"), dpi=110)


if __name__ == "__main__":
    main()
