"""Material export against the number of materials (issue 19, case 6: "1,000 materials export
in under 2 s; tables are computed once and cached, not per material").

Each count runs in a fresh process (cold caches, as the CLI starts): a 6-face room and a 33 x 33
grid whose faces cycle through N random Principled BSDFs (Base Color, Roughness in [0, 1],
Metallic 0 or 1, IOR in [1.3, 1.7]); it times export.export_scene and counts the VNDF quadratures
(engine.principled._vndf_samples calls). Accuracy in the same run: each material's white-furnace
albedo and R(1) against the direct quadrature at its own roughness (what the code did before the
roughness nodes), largest difference over the materials.

    .venv/bin/python benchmarks/bench_materials.py [--counts 1 10 100 1000]

Writes benchmarks/results/bench_materials.json and prints a table (docs/benchmarks.md).
"""
import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_materials.json")

CHILD = r'''
import json, sys, time
sys.path.insert(0, ROOT)
import numpy as np
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_cube_add(size=6)
bpy.ops.mesh.primitive_grid_add(x_subdivisions=33, y_subdivisions=33, size=2)
me = bpy.context.object.data
rng = np.random.default_rng(0)
for i in range(N):
    m = bpy.data.materials.new(f"m{i}")
    m.use_nodes = True
    p = m.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*rng.random(3), 1)
    p.inputs["Roughness"].default_value = float(rng.random())
    p.inputs["Metallic"].default_value = float(rng.random() < 0.2)
    p.inputs["IOR"].default_value = float(1.3 + 0.4 * rng.random())
    me.materials.append(m)
me.polygons.foreach_set("material_index", (np.arange(len(me.polygons)) % N).astype(np.int32))
from relight_addon.blender import export, materials
from relight_addon.engine import principled as P
calls = [0]
samples = P._vndf_samples
def counted(*a):
    calls[0] += 1
    return samples(*a)
P._vndf_samples = counted
t = time.perf_counter()
export.export_scene()
seconds = time.perf_counter() - t
quadratures = calls[0]
# the reference: the direct quadrature at each material's own roughness (no nodes)
def direct(rough, mus, eta=None, exponents=()):
    c, gw, vw = samples(rough, mus)
    out = {"E": gw.sum(1), "EB5": (gw * (1 - c) ** 5).sum(1), "EB6": (gw * c * (1 - c) ** 6).sum(1)}
    if eta is not None:
        F = P.fresnel_dielectric(c, eta)
        F0 = float(P.F0_from_ior(eta))
        sh = np.clip((F - F0) / (1 - F0), 0, 1) if F0 < 1 else np.ones_like(F)
        out.update(EF=(gw * F).sum(1), ES=(gw * sh).sum(1), S=(vw * sh).sum(1))
    for p in exponents:
        out[f"S{p}"] = (vw * (1 - c) ** p).sum(1)
    return out
params = [materials.surface_closure(m).lobes[0][2] for m in me.materials]
got = [P.principled_albedo(p) for p in params]
P._vndf_terms = direct
P._albedo_cached.cache_clear()
ref = [P.principled_albedo(p) for p in params]
err_rho = max(float(np.abs(a.albedo - b.albedo).max()) for a, b in zip(got, ref))
err_r1 = max(float(np.abs(a.normal - b.normal).max()) for a, b in zip(got, ref))
print(json.dumps({"materials": N, "export_s": seconds, "vndf_quadratures": quadratures,
                  "max_albedo_diff": err_rho, "max_R1_diff": err_r1}))
'''


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--counts", type=int, nargs="+", default=[1, 10, 100, 1000])
    args = ap.parse_args()
    rows = []
    for n in args.counts:
        code = f"ROOT = {ROOT!r}\nN = {n}\n" + CHILD
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        rows.append(json.loads(out.strip().splitlines()[-1]))
        r = rows[-1]
        print(f"{n:5d} materials: export {r['export_s']:.2f} s, {r['vndf_quadratures']} VNDF quadratures; "
              f"albedo within {r['max_albedo_diff']:.1e}, R(1) within {r['max_R1_diff']:.1e} of the direct quadrature",
              flush=True)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
