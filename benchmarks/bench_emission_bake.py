"""What baking a linked emission costs the export: an open grid with an image on its Emission Color.

    .venv/bin/python benchmarks/bench_emission_bake.py [--faces 10000 100000] [--rounds 2]

Per size, a square grid (Blender's Grid primitive, 4 m) whose Principled BSDF has a 64 x 64 image
on its Emission Color is exported with ``export.export_scene`` (the bake of blender/emission_bake.py
included), then again with the link removed (the same faces, nothing baked: the back rays of
engine/two_sided.emitting_backs are in both). Writes benchmarks/results/bench_emission_bake.json.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)


def run(n_faces: int) -> dict:
    import bpy
    import numpy as np

    from relight_addon.blender import export

    side = max(1, round(math.sqrt(n_faces)))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=side + 1, y_subdivisions=side + 1, size=4)
    ob = bpy.context.active_object
    img = bpy.data.images.new("texture", 64, 64, float_buffer=True)
    img.pixels.foreach_set(np.random.default_rng(0).random(64 * 64 * 4).astype(np.float32))
    m = bpy.data.materials.new("textured")
    nt = m.node_tree
    p = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    nt.links.new(tex.outputs[0], p.inputs["Emission Color"])
    p.inputs["Emission Strength"].default_value = 1.0
    ob.data.materials.append(m)
    t0 = time.perf_counter()
    export.export_scene()
    baked = time.perf_counter() - t0
    nt.links.remove(p.inputs["Emission Color"].links[0])
    t0 = time.perf_counter()
    export.export_scene()
    plain = time.perf_counter() - t0
    return {"faces": len(ob.data.polygons), "export_baked_s": baked, "export_unlinked_s": plain}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[10000, 100000])
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)
    rows = []
    for n in args.faces:
        for _ in range(args.rounds):
            rows.append(run(n))
            r = rows[-1]
            print(f"{r['faces']} faces: export {r['export_baked_s']:.2f} s baked, {r['export_unlinked_s']:.2f} s "
                  "unlinked", flush=True)
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "bench_emission_bake.json"), "w") as fh:
        json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
